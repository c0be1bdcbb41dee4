"""Strict reading of nested TOML tables: every key is typed, range-checked and accounted for.

A `Table` wraps one TOML table with its path in the file ("bodies[1].material"); each getter
checks one key and records it as read; `finish()` rejects the keys nobody read, so a typo is an
error naming the key, its value and the keys allowed there, never a silently ignored setting.
"""

from __future__ import annotations

import difflib
import inspect
import math
from typing import Any

from .limits import Range

MISSING = object()


class SceneError(ValueError):
    """A scene file that cannot be run: names the file, the key, the value and what is allowed."""


QUOTED = 80       # a value's repr longer than this is summarised in a message


def quoted(value) -> str:
    """`value` as a message shows it: its repr whole when short, else a summary that says
    what it is (never a repr cut in the middle of a structure)."""
    text = repr(value)
    if len(text) <= QUOTED:
        return text
    if isinstance(value, str):
        return f"{value[:40]!r}... ({len(value)} characters)"
    if isinstance(value, (list, tuple)):
        return f"a list of {len(value)} items, starting {quoted(value[0])}"
    if isinstance(value, dict):
        return f"a table of keys {sorted(value)[:8]}"
    return text[:QUOTED - 3] + "..."


def did_you_mean(word: str, allowed) -> str:
    """ " (did you mean 'x'?)" for the allowed word nearest to `word`, if any is near."""
    near = difflib.get_close_matches(str(word).lower(), [str(a) for a in allowed], n=1,
                                     cutoff=0.6)
    return f" (did you mean {near[0]!r}?)" if near else ""


def argument_default(constructor, name: str):
    """The default of a constructor's argument: the scene reader repeats none of them."""
    return inspect.signature(constructor).parameters[name].default


def load_toml(path) -> dict:
    """Parse a TOML file (tomllib on Python 3.11+, tomli before)."""
    try:
        import tomllib
    except ModuleNotFoundError:      # Python 3.10
        import tomli as tomllib
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except tomllib.TOMLDecodeError as err:
        raise SceneError(f"{path}: not valid TOML: {err}") from None
    except UnicodeDecodeError as err:
        raise SceneError(f"{path}: not valid TOML: not UTF-8 text (byte {err.object[err.start]:#04x} "
                         f"at offset {err.start}); save the file as UTF-8") from None
    except RecursionError:
        raise SceneError(f"{path}: not valid TOML: arrays or tables nested too deeply") from None
    except OSError as err:
        raise SceneError(f"{path}: cannot read the scene file: {err.strerror}") from None


class Table:
    """One table of a scene file, read key by key."""

    def __init__(self, data, where: str, source: str):
        self.where, self.source = where, source
        if not isinstance(data, dict):
            self.fail(f"{where} must be a table, got {quoted(data)}")
        self.data, self.read, self.known = data, set(), set()

    def fail(self, message: str):
        raise SceneError(f"{self.source}: {message}")

    def path(self, key: str) -> str:
        return f"{self.where}.{key}" if self.where else key

    def has(self, key: str) -> bool:
        return key in self.data

    def _get(self, key: str, default):
        self.read.add(key)
        if key in self.data:
            return self.data[key]
        if default is MISSING:
            self.fail(f"{self.path(key)} is required")
        return default

    def bad(self, key: str, value, allowed: str, choices=()):
        """Raise the scene file's error for `key`: its path, what is allowed, the value (and
        the nearest of `choices` to it)."""
        hint = did_you_mean(value, choices) if isinstance(value, str) else ""
        self.fail(f"{self.path(key)} must be {allowed}, got {quoted(value)}{hint}")

    def allow(self, *keys: str) -> None:
        """Keys this table may hold that its reader reads only in some cases (the message for
        an unknown key lists every allowed one, not only those read so far)."""
        self.known.update(keys)

    def number(self, key: str, default=MISSING, minimum: float | None = None, *,
               strict: bool = False, unit: str = "", within: Range | None = None) -> float:
        """A finite number >= minimum (> when strict), or within a limits.Range."""
        value = self._get(key, default)
        bound = "" if minimum is None else f" {'>' if strict else '>='} {minimum}"
        allowed = f"a number{bound}{' ' + unit if unit else ''}"
        if within is not None:
            allowed, minimum, strict = f"a number {within.text()}", within.low, False
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            self.bad(key, value, allowed)
        if minimum is not None and (value <= minimum if strict else value < minimum):
            self.bad(key, value, allowed)
        if within is not None and value > within.high:
            self.bad(key, value, allowed)
        return float(value)

    def integer(self, key: str, default=MISSING, minimum: int | None = None, *,
                within: Range | None = None) -> int:
        """An integer >= minimum, or within a limits.Range."""
        value = self._get(key, default)
        low, high = (minimum, None) if within is None else (within.low, within.high)
        allowed = "an integer" + (f" {within.text()}" if within else
                                  "" if minimum is None else f" >= {minimum}")
        if (isinstance(value, bool) or not isinstance(value, int) or (low is not None and value < low)
                or (high is not None and value > high)):
            self.bad(key, value, allowed)
        return value

    def string(self, key: str, default=MISSING, choices=None) -> str:
        value = self._get(key, default)
        if not isinstance(value, str) or (choices is not None and value not in choices):
            self.bad(key, value, "a string" if choices is None else f"one of {list(choices)}",
                     choices or ())
        return value

    def boolean(self, key: str, default=MISSING) -> bool:
        value = self._get(key, default)
        if not isinstance(value, bool):
            self.bad(key, value, "true or false")
        return value

    def switch(self, key: str, default=MISSING) -> bool | str:
        """true, false or "auto"."""
        value = self._get(key, default)
        if not (isinstance(value, bool) or value == "auto"):
            self.bad(key, value, 'true, false or "auto"')
        return value

    def vector(self, key: str, default=MISSING, length: int = 3, unit: str = "",
               within: Range | None = None) -> tuple:
        """A list of `length` finite numbers, each within a limits.Range if given."""
        value = self._get(key, default)
        low, high = (-math.inf, math.inf) if within is None else (within.low, within.high)
        ok = (isinstance(value, (list, tuple)) and len(value) == length
              and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                      and low <= v <= high for v in value))
        if not ok:
            each = f", each {within.text()}" if within else f" [{unit}]" if unit else ""
            self.bad(key, value, f"a list of {length} numbers{each}")
        return tuple(float(v) for v in value)

    def value(self, key: str, default=MISSING) -> Any:
        """The raw value, for keys whose type depends on the value (checked by the caller)."""
        return self._get(key, default)

    def optional(self, options: dict, key: str, getter="number", **kwargs) -> None:
        """options[key] = the value read by getter (the name of a getter here: "number",
        "integer", "string", "vector", ...; or a function of the key) if the table has `key`;
        else nothing, so the constructor the options go to applies its own default (defaults
        live in one place). The key is allowed either way."""
        self.known.add(key)
        if key in self.data:
            read = getattr(self, getter) if isinstance(getter, str) else getter
            options[key] = read(key, **kwargs)

    def table(self, key: str, required: bool = False) -> Table | None:
        value = self._get(key, MISSING if required else None)
        return None if value is None else Table(value, self.path(key), self.source)

    def tables(self, key: str) -> list[Table]:
        value = self._get(key, [])
        if not isinstance(value, list):
            self.bad(key, value, "an array of tables ([[" + self.path(key) + "]])")
        return [Table(v, f"{self.path(key)}[{i}]", self.source) for i, v in enumerate(value)]

    def finish(self, also=()) -> None:
        """Reject every key that no getter asked for; `also`: further keys allowed here (for
        the message) that this file did not use."""
        unknown = [k for k in self.data if k not in self.read]
        if unknown:
            key = unknown[0]
            names = sorted(self.read | self.known | set(also))
            self.fail(f"{self.path(key)} is not a known key (value {quoted(self.data[key])})"
                      f"{did_you_mean(key, names)}; allowed here: {', '.join(names) or 'none'}")

    def build(self, make, *args, **kwargs):
        """Call a constructor, reporting its ValueError under this table's path."""
        try:
            return make(*args, **kwargs)
        except ValueError as err:
            self.fail(f"{self.where}: {err}")
