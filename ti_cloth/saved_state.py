"""Saved states (Simulation.save_state / load_state): the files, and the fingerprint naming the
simulation a state belongs to.

A state file is an npz holding the arrays a simulation needs to continue bit for bit and a
JSON header: the state format, the fingerprint and the counters. The fingerprint is a hash of
everything that decides the motion: the bodies (every array of the Cloth), the integrator and
the options it was given away from their defaults (so that an option added at a default that
keeps the motion leaves older states loadable), dt, gravity, drag, wind, tearing, strain limiting, self-collision, handles,
colliders (meshes included) and the precision. A path given as a Python function counts by its
name and code (not the values its closure captured).
"""

from __future__ import annotations

import dataclasses
import enum
import hashlib
import json
import zipfile
import zlib
from pathlib import Path

import numpy as np

from .errors import StateMismatch
from .inputs.files import atomic_path

FORMAT = 3      # bump when what a state holds or means changes: older files are refused
                # (2: a Fabric's torn triangles, face_alive and face_torn_step; 3: the last
                # step's self-contact report, its passes and the rows of a list made again)


def fingerprint(*parts) -> str:
    """Hex digest of `parts`, walked by value (module doc)."""
    digest = hashlib.sha256()
    for part in parts:
        _feed(digest, part)
    return digest.hexdigest()[:32]


def _feed(digest, value) -> None:
    tag = type(value).__qualname__
    if value is None or isinstance(value, (bool, int, float, str, bytes, enum.Enum)):
        digest.update(f"{tag}:{value!r};".encode())
    elif isinstance(value, np.generic):
        _feed(digest, value.item())
    elif isinstance(value, np.ndarray):
        array = np.ascontiguousarray(value)
        digest.update(f"array:{array.dtype.str}:{array.shape};".encode())
        digest.update(array.tobytes())
    elif isinstance(value, (list, tuple)):
        digest.update(f"{tag}[{len(value)}];".encode())
        for item in value:
            _feed(digest, item)
    elif isinstance(value, dict):
        digest.update(f"dict[{len(value)}];".encode())
        for key in sorted(value, key=str):
            _feed(digest, str(key))
            _feed(digest, value[key])
    elif dataclasses.is_dataclass(value):
        digest.update(f"{tag}{{".encode())
        for field in dataclasses.fields(value):
            _feed(digest, field.name)
            _feed(digest, getattr(value, field.name))
    elif hasattr(value, "__code__"):
        digest.update(f"function:{value.__module__}.{value.__qualname__};".encode())
        _feed_code(digest, value.__code__)
    elif hasattr(value, "__dict__"):
        digest.update(f"{tag}{{".encode())
        for key in sorted(k for k in vars(value) if not k.startswith("_")):
            _feed(digest, key)
            _feed(digest, getattr(value, key))
    else:
        digest.update(f"{tag}:{value!r};".encode())


def _feed_code(digest, code) -> None:
    digest.update(code.co_code)
    _feed(digest, code.co_names)
    for const in code.co_consts:
        if hasattr(const, "co_code"):
            _feed_code(digest, const)
        else:
            _feed(digest, repr(const))


def write(path, fingerprint_: str, header: dict, arrays: dict[str, np.ndarray]) -> Path:
    """Write a state file atomically: `arrays` and `header` (JSON values) with the format and
    the fingerprint."""
    path = Path(path)
    header = {"format": FORMAT, "fingerprint": fingerprint_, **header}
    with atomic_path(path) as tmp, open(tmp, "wb") as file:
        np.savez(file, header=np.array(json.dumps(header)), **arrays)
    return path


def read(path, fingerprint_: str) -> tuple[dict, dict[str, np.ndarray]]:
    """(header, arrays) of the state file at `path`. Raises FileNotFoundError, or StateMismatch
    when it is not a state file, holds another format or belongs to another simulation."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"saved state not found: {path}")
    try:
        _check_sizes(path)
        with np.load(path, allow_pickle=False) as data:
            header = json.loads(str(data["header"]))
            arrays = {key: data[key] for key in data.files if key != "header"}
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, zlib.error) as err:
        raise StateMismatch(f"{path} is damaged or not a ti_cloth saved state (a copy that "
                            f"stopped half-way, a full disk? {type(err).__name__}: {err})"
                            ) from None
    if not isinstance(header, dict):
        raise StateMismatch(f"{path}: its header is not a table of values: {header!r:.80}")
    if header.get("format") != FORMAT:
        raise StateMismatch(f"{path} holds a state of format {header.get('format')!r}; this "
                            f"ti_cloth reads format {FORMAT} only: run the simulation again")
    if header.get("fingerprint") != fingerprint_:
        raise StateMismatch(
            f"{path} was saved by a different simulation (fingerprint "
            f"{header.get('fingerprint')}, this one {fingerprint_}): its bodies, integrator, "
            "step, forces, handles, colliders or precision differ; run it from the start")
    return header, arrays


def _check_sizes(path: Path) -> None:
    """Read every array's .npy header before its data: ValueError for an array whose header
    claims more bytes than the file holds for it (a damaged or forged header would otherwise
    have numpy allocate what it claims: 179 GiB from a 2 KB file)."""
    with zipfile.ZipFile(path) as archive:
        for info in archive.infolist():
            with archive.open(info) as member:
                version = np.lib.format.read_magic(member)
                shape, _, dtype = (np.lib.format.read_array_header_1_0(member) if version == (1, 0)
                                   else np.lib.format.read_array_header_2_0(member))
                claimed = int(np.prod(shape, dtype=object)) * dtype.itemsize
                if claimed > info.file_size:
                    raise ValueError(f"array {info.filename!r} claims shape {shape} of "
                                     f"{dtype} ({claimed:,} bytes) but holds {info.file_size:,}")


def check_arrays(path, arrays: dict, expected: dict, limit: float) -> None:
    """StateMismatch naming the array unless `arrays` holds every array of `expected`
    ({name: an array of the shape and dtype it must have}) with that shape and dtype, and
    only finite values, coordinates within `limit` [m] for positions."""
    missing = sorted(set(expected) - set(arrays))
    if missing:
        raise StateMismatch(f"{path}: arrays missing: {missing}; it is damaged: run it again")
    for name, like in expected.items():
        array = arrays[name]
        if array.shape != like.shape or array.dtype != like.dtype:
            raise StateMismatch(f"{path}: array {name!r} is {array.dtype}{list(array.shape)}, "
                                f"this simulation's is {like.dtype}{list(like.shape)}")
        if np.issubdtype(array.dtype, np.floating):
            bad = np.argwhere(~np.isfinite(array))
            if len(bad):
                raise StateMismatch(f"{path}: array {name!r} holds non-finite values (at "
                                    f"{tuple(int(i) for i in bad[0])}); it is damaged: run it "
                                    "again")
            if "position" in name and array.size and np.abs(array).max() > limit:
                raise StateMismatch(f"{path}: array {name!r} holds a coordinate of "
                                    f"{np.abs(array).max():.3g} m, beyond the simulation's "
                                    f"position limit {limit:g} m")
