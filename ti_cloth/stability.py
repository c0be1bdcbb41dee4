"""Largest stable step of a body for an integrator, and the step dt="auto" takes. The rule is
each integrator's own (Integrator.stable_step, from the spring analysis in modes.py)."""

from __future__ import annotations

import math

from .body.topology import Cloth, index_mask
from .inputs import limits
from .inputs.validation import in_range, require
from .integrators import make_integrator

AUTO_MAX_DT = 1.0 / 240.0     # "auto" steps: at most half the predicted stable step and at most this [s]


def stable_dt(cloth, integrator="symplectic_euler", drag: float = 0.0, pinned=None) -> float:
    """Largest stable step [s] predicted for `integrator` (a name or an Integrator) on `cloth`
    with uniform drag [1/s] and `pinned` (particle indices or an (N,) bool mask; default the
    cloth's pins): inf when it has no limit,
    0 when no stable step exists (explicit Euler on undamped springs). Each integrator's
    docstring states its rule."""
    require(isinstance(cloth, Cloth), "cloth", cloth if isinstance(cloth, str) else type(cloth),
            "a Cloth (tc.Cloth(mesh, material), tc.string(...), ...)")
    drag = in_range("drag", drag, limits.DRAG)
    pinned = cloth.pinned if pinned is None else index_mask("pinned", pinned,
                                                            cloth.particle_count)
    return make_integrator(integrator).stable_step(cloth, drag, pinned)

def auto_dt(cloth, integrator="symplectic_euler", drag: float = 0.0, pinned=None) -> float:
    """The step dt="auto" picks [s]: min(stable_dt / 2, AUTO_MAX_DT). Raises ValueError when
    no stable step exists (explicit Euler on undamped springs)."""
    stable = stable_dt(cloth, integrator, drag, pinned)
    if stable == 0:
        raise ValueError(f"dt='auto': no stable step exists for {make_integrator(integrator).name} "
                         "with these springs (undamped springs make explicit Euler and "
                         "stabilized_rk2 unstable at any step); add damping (a Material's kd, a "
                         "Fabric's damping) or choose another integrator")
    return min(0.5 * stable, AUTO_MAX_DT)


def auto_substeps(cloth, integrator, frame_dt: float, drag: float = 0.0, pinned=None) -> int:
    """Steps per frame of substeps="auto": the fewest with dt = frame_dt / substeps <= auto_dt."""
    frame_dt = in_range("frame_dt", frame_dt, limits.DT)
    return max(1, math.ceil(frame_dt / auto_dt(cloth, integrator, drag, pinned) - 1e-9))
