"""The stages of a step, written once: their order, and what a stage is.

One step, in this order, in every launch plan (Simulation's launch per stage and the
many-steps launches of stepping.py):

    integrator (forces, move)  ->  handles  ->  sewing  ->  strain limiting  ->  colliders
        ->  self-collision  ->  tearing

Held particles are on their paths before strain limiting and the colliders see them (a
limiter run before would pull free particles towards where the handle's particles were).

A stage after the integrator is the object Simulation makes for it when the scene has it (a
scene without it compiles and launches none of its code), kept under its STEP_ORDER name:
a Stage. Those that also have `phases` (a LaunchedStage) run inside many-steps launches; the
others (self-collision) keep a launch per stage, and a simulation with one steps launch by
launch.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

STEP_ORDER = ("integrator", "handles", "sewing", "strain_limit", "colliders", "self_collision",
              "tearing")


@runtime_checkable
class Stage(Protocol):
    """A stage of a step after the integrator."""

    def after_step(self, model, state, t: float, dt: float, step_index: int) -> None:
        """The stage of the step `step_index` that ended at time t [s], a launch of its own."""


@runtime_checkable
class LaunchedStage(Stage, Protocol):
    """A stage whose work is also written as phases (runtime/plan.py), so that many-steps
    launches run it inside the launch, in STEP_ORDER, with the same bits as after_step."""

    def phases(self, model, forces, work) -> tuple:
        """The stage's work as plan nodes (`work` is the stage itself)."""


def in_order(stages: dict) -> dict:
    """{name: stage} of the stages present (not None), in STEP_ORDER; KeyError for a name that
    is not a stage."""
    unknown = set(stages) - set(STEP_ORDER[1:])
    if unknown:
        raise KeyError(f"not stages of a step: {sorted(unknown)}")
    return {name: stages[name] for name in STEP_ORDER[1:] if stages.get(name) is not None}
