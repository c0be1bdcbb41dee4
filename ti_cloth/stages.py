"""The stages of a step, written once: their order, and what a stage is.

One step, in this order, in every launch plan (Simulation's launch per stage and the
many-steps launches of stepping.py):

    integrator (forces, move)  ->  handles  ->  sewing  ->  strain limiting  ->  colliders
        ->  self-collision  ->  tearing

Held particles are on their paths before strain limiting and the colliders see them (a
limiter run before would pull free particles towards where the handle's particles were).

A stage after the integrator is the object Simulation makes for it when the scene has it (a
scene without it compiles and launches none of its code), kept under its STEP_ORDER name: a
Stage. Its work is written once, as phases (runtime/plan.py), which its after_step launches
and which many-steps launches (stepping.py) run inside the launch on the stage's `launched`
object. Self-collision's contact passes are phases too, but it has no `launched` object: its
candidate list is made again on the host whenever the cloth has moved more than the list's
skin (it may grow, and the growth is a new kernel), so it runs launch by launch: a
simulation that has it runs each step's integrator and earlier stages in one team launch on
the CPU, then self-collision and tearing launch by launch.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

STEP_ORDER = ("integrator", "handles", "sewing", "strain_limit", "colliders", "self_collision",
              "tearing")


@runtime_checkable
class Stage(Protocol):
    """A stage of a step after the integrator.

    launched: the kernel argument whose `phases(model, forces, work)` a many-steps launch runs
        for this stage (`work` is that object): the stage itself, or the table it fills
        before each launch (the handles'); None for a stage that runs only launch by launch.
    """

    launched: object | None

    def after_step(self, model, state, t: float, dt: float, step_index: int) -> None:
        """The stage of step `step_index`, which ended at time t [s]: a launch of its own."""


def in_order(stages: dict) -> dict:
    """{name: stage} of the stages present (not None), in STEP_ORDER; KeyError for a name that
    is not a stage."""
    unknown = set(stages) - set(STEP_ORDER[1:])
    if unknown:
        raise KeyError(f"not stages of a step: {sorted(unknown)}")
    return {name: stages[name] for name in STEP_ORDER[1:] if stages.get(name) is not None}
