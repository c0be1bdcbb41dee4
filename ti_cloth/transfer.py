"""Moving arrays from numpy into Taichi fields in one launch per set of fields."""

import numpy as np
import taichi as ti

from .backend import numpy_dtype


def upload(pairs) -> None:
    """Copy numpy arrays into Taichi fields in one launch: one compiled kernel for the whole
    set, where field.from_numpy compiles a kernel per field (about 0.1 s each on a 2-core CPU,
    most of the cost of building a small Model before this).

    pairs: (field, values); values has the field's shape, or fewer rows (the rest keep their
    values: the padding of a field that cannot have length 0). Values are rounded to the
    field's type in numpy, then carried exactly, so the result is that of field.from_numpy.
    """
    targets, layout, chunks, offset = [], [], [], 0
    for field, values in pairs:
        values = np.asarray(values)
        if len(values) == 0:
            continue
        width = values.shape[1] if values.ndim == 2 else 0
        typed = np.ascontiguousarray(values, dtype=numpy_dtype(field.dtype))
        chunks.append(typed.astype(np.float64).ravel())   # exact for f32, f64, i8 and i32
        targets.append(field)
        layout.append((offset, len(values), width, field.dtype))
        offset += typed.size
    if targets:
        _copy_in(tuple(targets), np.concatenate(chunks), tuple(layout))


@ti.kernel
def _copy_in(targets: ti.template(), data: ti.types.ndarray(), layout: ti.template()):
    """targets[k][i] = data[offset + i] (scalar fields) or targets[k][i][c] =
    data[offset + i * width + c] (vector fields), layout[k] = (offset, rows, width, dtype)."""
    for k in ti.static(range(len(layout))):
        offset, rows, width, dtype = ti.static(layout[k])
        for i in range(rows):
            if ti.static(width == 0):
                targets[k][i] = ti.cast(data[offset + i], dtype)
            else:
                for c in ti.static(range(width)):
                    targets[k][i][c] = ti.cast(data[offset + i * width + c], dtype)
