"""A scene's preview (`ti-cloth view --preview`, `load_scene(path, preview=True)`): the scene
file as read, with the values that set its cost per simulated second changed, as Marvelous
Designer's particle distance and Vellum's substeps are turned down while a garment is
arranged: the garment panels cut coarser, by one factor, until they hold about
PREVIEW_PARTICLES particles in all (the demos' cape, 3,795 particles at 1.5 cm, is cut at
4.1 cm: 541), and a position-based integrator (xpbd, pbd) stepping at most PREVIEW_STEP
(two steps a frame at 30 frames a second, where the demos' garments take eight). The cape
and the skirt then keep real time on two cores (docs/performance.md, "A preview of the
garments in real time"). Other bodies keep their particles and other integrators their
step: an explicit step is bounded by its stability, and an implicit one costs as much per
simulated second at a larger step (docs/performance.md, "Where a garment's step goes").

It changes the file's values before they are read, so every check of the reader applies to
the preview's values too, and `Scene.preview` says what it changed.
"""

from __future__ import annotations

import copy
import math
from numbers import Real

from ..inputs import limits
from ..inputs.scene_file import argument_default
from ..integrators import INTEGRATORS
from ..simulation import Simulation

PREVIEW_PARTICLES = 500     # a preview's garment panels hold about this many particles
PREVIEW_STEP = 1.0 / 60.0   # s: a preview's longest step, for a position-based integrator


def previewed(raw: dict) -> tuple[dict, tuple[str, ...]]:
    """(the scene file's TOML tables `raw` with its preview's values, what they change, in
    words). Values that are not what the reader accepts are left for it to name."""
    raw = copy.deepcopy(raw)
    changes = []
    cut = _coarser_panels(raw.get("bodies"))
    if cut:
        changes.append("garment panels cut at " + ", ".join(
            f"{new * 100:.3g} cm (the file's {old * 100:.3g})" for old, new in cut))
    steps = _longer_steps(raw.get("simulation"))
    if steps:
        changes.append(steps)
    return raw, tuple(changes)


def _coarser_panels(bodies) -> list[tuple[float, float]]:
    """Every garment panel's edge_length times one factor, in place, so that the panels hold
    about PREVIEW_PARTICLES particles in all (never finer than the file's); the distinct
    (file's, preview's) lengths. A panel's particles are estimated from its outline's area,
    a particle for each two equilateral triangles of its edge length."""
    panels = [(panel, panel["edge_length"], _area(panel.get("outline")))
              for body in (bodies if isinstance(bodies, list) else ())
              if isinstance(body, dict) and body.get("type") == "garment"
              for panel in (body.get("panels") if isinstance(body.get("panels"), list) else ())
              if isinstance(panel, dict) and _positive(panel.get("edge_length"))]
    particles = sum(area / (math.sqrt(3.0) / 2.0 * length ** 2)
                    for _, length, area in panels)
    factor = math.sqrt(particles / PREVIEW_PARTICLES)
    if factor <= 1.0:
        return []
    cut = {}
    for panel, length, _ in panels:
        panel["edge_length"] = cut.setdefault(length, float(f"{factor * length:.2g}"))
    return sorted(cut.items())


def _area(outline) -> float:
    """The area of a panel's outline [(x, y), ...] (the shoelace formula), 0 where it is not
    one (the reader names it)."""
    if not (isinstance(outline, list) and len(outline) >= 3
            and all(isinstance(p, list) and len(p) == 2 and all(map(_number, p))
                    for p in outline)):
        return 0.0
    x, y = zip(*outline)
    return 0.5 * abs(sum(x[k] * y[k - 1] - x[k - 1] * y[k] for k in range(len(x))))


def _number(value) -> bool:
    return isinstance(value, Real) and not isinstance(value, bool) and math.isfinite(value)


def _positive(value) -> bool:
    return _number(value) and value > 0


def _longer_steps(simulation) -> str | None:
    """A position-based integrator's steps made at most PREVIEW_STEP long, in place (no fewer
    than the file asks): what changed, or None."""
    if not isinstance(simulation, dict):     # the default integrator is not position-based
        return None
    spec = simulation.get(
        "integrator", argument_default(Simulation, "integrator"))
    name = spec.get("name") if isinstance(spec, dict) else spec
    fps = simulation.get("fps", limits.FPS_DEFAULT)
    if (not isinstance(name, str) or name not in INTEGRATORS
            or not INTEGRATORS[name].position_based
            or not _positive(fps)):
        return None
    fewest = max(1, math.ceil(1.0 / (fps * PREVIEW_STEP) - 1e-9))
    given = simulation.get("substeps", "auto")
    if "dt" in simulation:
        dt = simulation["dt"]
        if not _positive(dt):
            return None
        given = max(1, math.ceil(1.0 / fps / dt - 1e-9))
    elif given != "auto" and not (_positive(given) and isinstance(given, int)):
        return None
    if given != "auto" and given <= fewest:      # (auto steps at most 1/240 s: more)
        return None
    simulation.pop("dt", None)
    simulation["substeps"] = fewest
    file_step = "auto" if given == "auto" else f"1/{fps * given:g} s"
    return f"steps of 1/{fps * fewest:g} s (the file's: {file_step})"
