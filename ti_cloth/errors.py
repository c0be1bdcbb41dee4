"""Exceptions ti_cloth raises while running."""

from __future__ import annotations

import math


class SimulationDiverged(RuntimeError):
    """A step produced NaN, inf, a runaway coordinate or a tear avalanche (`reason` says which).

    step: index of the first bad step (0-based); time: simulated time at its end [s];
    dt: the step used [s]; stable_dt: predicted largest stable step [s] (inf: no limit known,
    0: no stable step for this integrator); integrator: its name.
    """

    def __init__(self, step: int, time: float, dt: float, stable_dt: float, integrator: str,
                 reason: str | None = None):
        self.step, self.time, self.dt, self.stable_dt, self.integrator = step, time, dt, stable_dt, integrator
        self.reason = reason or "positions or velocities became non-finite or left the guard box"
        if stable_dt == 0:
            advice = (f"{integrator} has no stable step for undamped springs; add spring damping "
                      "(kd) or use symplectic_euler, verlet or pbd")
        elif math.isinf(stable_dt):
            advice = "no step-size limit is predicted; check forces, masses and scripted paths"
        else:
            advice = f"a stable dt for {integrator} is about {stable_dt:.3g} s or less"
        super().__init__(f"simulation diverged at step {step} (t = {time:.6g} s, dt = {dt:.3g} s): "
                         f"{self.reason}; {advice}")


class CrushedContact(RuntimeError):
    """Self-collision found more pairs within reach than any cloth near its thickness has (a
    step so large that the cloth folded through itself): the stage raises it with the step,
    and Simulation.step reports it as the SimulationDiverged of that step."""

    def __init__(self, step: int, message: str):
        super().__init__(message)
        self.step = step


class StaleSimulation(RuntimeError):
    """A Simulation used after ti_cloth.init was called again: that init reset Taichi and
    freed the simulation's fields."""

    def __init__(self):
        super().__init__("this Simulation was built before ti_cloth.init was called again; that "
                         "init reset Taichi and freed its fields: build the Simulation again")


class TeamStalled(RuntimeError):
    """A barrier of a many-steps CPU launch (stepping.Team) waited seconds for a worker that
    never arrived: the Taichi thread pool did not give every worker a thread of its own. The
    steps of that launch ran unsynchronised, so the state is not to be trusted."""



class StateMismatch(ValueError):
    """A saved state (Simulation.load_state, a resumed run) that this simulation cannot take:
    not a state file, another state format, or saved by a different simulation."""


class OutputError(OSError):
    """A file ti_cloth writes (a frame, a checkpoint, an export, the GIF/MP4, a study's table)
    could not be written: the disk is full, the folder is not writable or is on a read-only
    file system. `path` is the file, `reason` the system's words for why; nothing is left
    under the file's name (files are written to a temporary name, then renamed)."""

    HINTS = {"ENOSPC": "free some space", "EDQUOT": "free some of your quota",
             "EACCES": "choose a folder you can write to", "EPERM": "choose a folder you can write to",
             "EROFS": "choose a folder on a writable file system"}

    def __init__(self, path, cause: OSError):
        import errno

        self.path, self.cause = path, cause
        code = errno.errorcode.get(cause.errno, "")
        self.reason = f"{cause.strerror or cause}" + (f" ({code})" if code else "")
        self.hint = self.HINTS.get(code, "check the folder and the disk")
        super().__init__(cause.errno, f"cannot write {path}: {self.reason}; {self.hint}")

    def __str__(self) -> str:
        return self.args[1]
