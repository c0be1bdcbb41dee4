"""A scene's preview (`ti-cloth view --preview`, `load_scene(path, preview=True)`): the scene
file as read, with the values that set its cost per simulated second changed, as Marvelous
Designer's particle distance and Vellum's substeps are turned down while a garment is
arranged: every garment panel cut at PREVIEW_COARSENING times its edge length (about a
quarter of the particles), and a position-based integrator (xpbd, pbd) stepping at most
PREVIEW_STEP (two steps a frame at 30 frames a second, where the demos' garments take eight).
Other bodies and integrators are left as the file has them: a grid, a string or hair is
resolution-free to read only at its own size, and an explicit step is bounded by its
stability, an implicit one costs as much per simulated second at a larger step
(docs/performance.md, "Where a garment's step goes").

It changes the file's values before they are read, so every check of the reader applies to
the preview's values too, and `Scene.preview` says what it changed.
"""

from __future__ import annotations

import copy
import inspect
import math
from numbers import Real

from ..integrators import INTEGRATORS
from ..simulation import Simulation

PREVIEW_COARSENING = 2.0    # a preview's garment panels: this many times their edge length
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
    """Every garment panel's edge_length times PREVIEW_COARSENING, in place; the distinct
    (file's, preview's) lengths."""
    cut = {}
    for body in bodies if isinstance(bodies, list) else ():
        if not (isinstance(body, dict) and body.get("type") == "garment"):
            continue
        panels = body.get("panels")
        for panel in panels if isinstance(panels, list) else ():
            length = panel.get("edge_length") if isinstance(panel, dict) else None
            if isinstance(length, Real) and not isinstance(length, bool) and length > 0:
                panel["edge_length"] = cut.setdefault(length, PREVIEW_COARSENING * length)
    return sorted(cut.items())


def _longer_steps(simulation) -> str | None:
    """A position-based integrator's steps made at most PREVIEW_STEP long, in place (no fewer
    than the file asks): what changed, or None."""
    if not isinstance(simulation, dict):     # the default integrator is not position-based
        return None
    spec = simulation.get(
        "integrator", inspect.signature(Simulation).parameters["integrator"].default)
    name = spec.get("name") if isinstance(spec, dict) else spec
    fps = simulation.get("fps", 30.0)
    if (not isinstance(name, str) or name not in INTEGRATORS
            or not INTEGRATORS[name].position_based
            or not isinstance(fps, Real) or isinstance(fps, bool) or not fps > 0):
        return None
    fewest = max(1, math.ceil(1.0 / (fps * PREVIEW_STEP) - 1e-9))
    given = simulation.get("substeps", "auto")
    if "dt" in simulation:
        dt = simulation["dt"]
        if not (isinstance(dt, Real) and not isinstance(dt, bool) and dt > 0):
            return None
        given = max(1, math.ceil(1.0 / fps / dt - 1e-9))
    elif given != "auto" and not (isinstance(given, int) and not isinstance(given, bool)
                                  and given >= 1):
        return None
    if given != "auto" and given <= fewest:      # (auto steps at most 1/240 s: more)
        return None
    simulation.pop("dt", None)
    simulation["substeps"] = fewest
    file_step = "auto" if given == "auto" else f"1/{fps * given:g} s"
    return f"steps of 1/{fps * fewest:g} s (the file's: {file_step})"
