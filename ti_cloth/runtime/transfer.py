"""Moving arrays from numpy into Taichi fields in one launch per set of fields."""

from contextlib import contextmanager

import numpy as np
import taichi as ti

from . import backend

_batch: list | None = None   # (field, values) waiting while a batch is open (batched())


@contextmanager
def batched():
    """Uploads made inside the block are sent together, in one launch when it ends, or
    earlier when a ti_cloth kernel is about to launch (it may read them) or a field is
    uploaded twice: a simulation's build sends its model's and its stages' tables as one
    kernel, where an upload each compiled one each (docs/performance.md). Nested blocks
    belong to the outermost; a block left by an exception sends nothing."""
    global _batch
    if _batch is not None:
        yield
        return
    _batch = []
    backend.before_launch(flush)
    try:
        yield
        flush()
    finally:
        _batch = None
        backend.before_launch(None)


def flush() -> None:
    """Send what the open batch holds (batched())."""
    if _batch:
        pending = list(_batch)
        _batch.clear()
        _send(pending)


def upload(pairs) -> None:
    """Copy numpy arrays into Taichi fields in one launch: one compiled kernel with one loop
    for the whole set, where field.from_numpy compiles a kernel per field (most of the cost
    of building a small Model: docs/performance.md). Inside batched(), later, with the
    block's other uploads.

    pairs: (field, values); values has the field's shape, or fewer rows (the rest keep their
    values: the padding of a field that cannot have length 0); a 0-d field takes a scalar.
    Values are rounded to the field's type in numpy, then carried exactly, so the result is
    that of field.from_numpy.
    """
    pairs = [(field, np.asarray(values)) for field, values in pairs]
    if _batch is None:
        _send(pairs)
        return
    pending = {id(field) for field, _ in _batch}
    if any(id(field) in pending for field, _ in pairs):
        flush()                       # a field's values arrive in the order they were given
    _batch.extend((field, values.copy()) for field, values in pairs)   # as they were now


def _send(pairs) -> None:
    """One launch of copy_in for `pairs` (upload())."""
    targets, groups, chunks, offset = [], {}, [], 0
    for field, values in pairs:
        scalar = field.shape == ()
        if scalar:
            values = values.reshape(1)
        if len(values) == 0:
            continue
        width = -1 if scalar else values.shape[1] if values.ndim == 2 else 0
        typed = np.ascontiguousarray(values, dtype=backend.numpy_dtype(field.dtype))
        chunks.append(typed.astype(np.float64).ravel())   # exact for f32, f64, i8 and i32
        groups.setdefault(len(values), []).append((len(targets), offset, width, field.dtype))
        targets.append(field)
        offset += typed.size
    if targets:
        longest_first = sorted(groups.items(), reverse=True)
        layout = tuple((rows, tuple(members)) for rows, members in longest_first)
        copy_in(tuple(targets), np.concatenate(chunks), layout)


@backend.kernel
def copy_in(targets: ti.template(), data: ti.types.ndarray(), layout: ti.template()):
    """One loop over the most rows (layout[0], the longest group, first); in it, for each
    group (rows, members) of layout that has row i, for each member (k, offset, width,
    dtype): targets[k][i] = data[offset + i] (a scalar field), targets[k][i][c] =
    data[offset + i * width + c] (a vector field) or, width -1, targets[k][None] =
    data[offset] (a 0-d field, one row)."""
    for i in range(ti.static(layout[0][0])):
        for g in ti.static(range(len(layout))):
            rows, members = ti.static(layout[g])
            if i < rows:
                for m in ti.static(range(len(members))):
                    k, offset, width, dtype = ti.static(members[m])
                    if ti.static(width < 0):
                        targets[k][None] = ti.cast(data[offset], dtype)
                    elif ti.static(width == 0):
                        targets[k][i] = ti.cast(data[offset + i], dtype)
                    else:
                        for c in ti.static(range(width)):
                            targets[k][i][c] = ti.cast(data[offset + i * width + c], dtype)
