"""Input checks shared by the public constructors: every failure names the field, the value
and what is allowed."""

from __future__ import annotations

import dataclasses
import functools
import math
import warnings

import numpy as np


def require(ok: bool, field: str, value, allowed: str) -> None:
    """Raise ValueError("<field> must be <allowed>, got <value>") unless `ok`."""
    if not ok:
        raise ValueError(f"{field} must be {allowed}, got {value!r}")


def _float(field: str, value, allowed: str) -> float:
    """`value`, a number and not a bool, as a float; an int too big for one (10**400) is
    refused like any value out of range, naming the field."""
    require(isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool),
            field, value, allowed)
    try:
        return float(value)
    except OverflowError:
        raise ValueError(f"{field} must be {allowed}, got an integer of {len(str(value))} "
                         "digits") from None


def finite_number(field: str, value, minimum: float | None = None, *, strict: bool = False,
                  unit: str = "") -> float:
    """`value` as a float, finite and >= minimum (> minimum when `strict`)."""
    unit = f" {unit}" if unit else ""
    bound = "" if minimum is None else f" {'>' if strict else '>='} {minimum}{unit}"
    allowed = f"a finite number{bound}"
    value = _float(field, value, allowed)
    require(math.isfinite(value), field, value, allowed)
    if minimum is not None:
        require(value > minimum if strict else value >= minimum, field, value, allowed)
    return value


def integer(field: str, value, minimum: int | None = None, maximum: int | None = None) -> int:
    """`value` as an int (a Python or numpy integer, never a bool) in [minimum, maximum]."""
    bounds = [f">= {minimum}" if minimum is not None and maximum is None else "",
              f"in [{minimum}, {maximum}]" if minimum is not None and maximum is not None else "",
              f"<= {maximum}" if minimum is None and maximum is not None else ""]
    allowed = " ".join(["an int"] + [b for b in bounds if b])
    require(isinstance(value, (int, np.integer)) and not isinstance(value, bool), field, value,
            allowed)
    require((minimum is None or value >= minimum) and (maximum is None or value <= maximum),
            field, value, allowed)
    return int(value)


def as_array(field: str, value, dtype, shape: tuple) -> np.ndarray:
    """`value` as a numpy array of `dtype` whose shape matches `shape` (None = any length);
    float arrays must be finite."""
    try:
        array = np.asarray(value, dtype=dtype)
    except (TypeError, ValueError, OverflowError) as err:
        raise ValueError(f"{field} must be an array of {np.dtype(dtype).name} with shape "
                         f"{_shape_text(shape)}, got {value!r:.80}") from err
    if array.size == 0 and len(shape) == 2 and shape[1] is not None:
        array = array.reshape(0, shape[1])
    ok = array.ndim == len(shape) and all(s is None or s == n for s, n in zip(shape, array.shape))
    require(ok, f"{field}.shape", array.shape, _shape_text(shape))
    if np.issubdtype(array.dtype, np.floating):
        bad = np.argwhere(~np.isfinite(array))
        require(len(bad) == 0, f"{field}[{', '.join(map(str, bad[0])) if len(bad) else ''}]",
                array[tuple(bad[0])] if len(bad) else None, "finite")
    if np.issubdtype(np.dtype(dtype), np.integer):
        require(np.array_equal(array, np.asarray(value)) if np.size(value) else True, field,
                value, "integers")
    return array


def _shape_text(shape: tuple) -> str:
    return "(" + ", ".join("N" if s is None else str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"


def in_range(field: str, value, allowed) -> float:
    """`value` as a float in the limits.Range `allowed`: 'must be a finite number in [a, b]'."""
    text = f"a finite number {allowed.text()}"
    value = _float(field, value, text)
    require(math.isfinite(value) and allowed.low <= value <= allowed.high, field, value, text)
    return value


def count(field: str, value, allowed) -> int:
    """`value` as an int in the limits.Range `allowed`: 'must be an int in [a, b]'."""
    ok = (isinstance(value, (int, np.integer)) and not isinstance(value, bool)
          and allowed.low <= value <= allowed.high)
    require(ok, field, value, f"an int {allowed.text()}")
    return int(value)


def keyword_only(cls):
    """Class decorator for a settings dataclass made with kw_only=True: positional values,
    the form of the last release, still work for one more, given to the fields in their order,
    with a DeprecationWarning naming the keywords (a value given both ways is a TypeError)."""
    init = cls.__init__
    names = [f.name for f in dataclasses.fields(cls) if f.init]

    @functools.wraps(init)
    def __init__(self, *positional, **options):
        if positional:
            if len(positional) > len(names):
                raise TypeError(f"{cls.__name__} takes at most {len(names)} values "
                                f"({', '.join(names)}), got {len(positional)}")
            given = names[:len(positional)]
            twice = sorted(set(given) & set(options))
            if twice:
                raise TypeError(f"{cls.__name__} got {', '.join(map(repr, twice))} both by "
                                "position and by keyword")
            warnings.warn(f"{cls.__name__}'s fields are keyword-only: write "
                          f"{cls.__name__}({', '.join(f'{n}=...' for n in given)}); values by "
                          "position work until the next release", DeprecationWarning,
                          stacklevel=2)
            options = dict(zip(given, positional)) | options
        init(self, **options)

    cls.__init__ = __init__
    return cls
