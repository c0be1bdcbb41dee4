"""Scripted motion for handles and colliders: keyframed and periodic paths.

A path is any callable t [s] -> displacement [m] (shape (3,)); Handle.path and Collider.path
take these or a plain function.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..inputs import limits
from ..inputs.validation import as_array, finite_number, require

INTERPOLATIONS = ("linear", "smooth")


@dataclass(frozen=True)
class Keyframes:
    """Displacements [m] `values` (K, 3) at strictly increasing `times` [s] (K,).

    interpolation: "linear" (piecewise linear: constant speed between keys) or "smooth"
    (cubic Hermite with finite-difference tangents (Catmull-Rom on uneven spacing): the path
    passes through every key with a continuous velocity, and keys on a straight line at even
    speed give exactly that motion; the first and last keys are approached at the speed of
    their one-sided difference). Before the first key the path holds the first value, after
    the last it holds the last.
    """

    times: tuple
    values: tuple
    interpolation: str = "linear"

    def __post_init__(self):
        times = as_array("Keyframes.times", self.times, np.float64, (None,))
        values = as_array("Keyframes.values", self.values, np.float64, (len(times), 3))
        require(len(times) >= 1, "Keyframes.times", times.tolist(), "at least one key")
        _within_reach("Keyframes.values", values)
        require(bool(np.all(np.diff(times) > 0)), "Keyframes.times", times.tolist(),
                "strictly increasing times [s]")
        require(self.interpolation in INTERPOLATIONS, "Keyframes.interpolation",
                self.interpolation, f"one of {INTERPOLATIONS}")
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "values", values)
        times.flags.writeable = values.flags.writeable = False

    def __call__(self, t: float) -> np.ndarray:
        times, values = self.times, self.values
        if t <= times[0] or len(times) == 1:
            return values[0].copy()
        if t >= times[-1]:
            return values[-1].copy()
        k = int(np.searchsorted(times, t, side="right")) - 1
        h = times[k + 1] - times[k]
        s = (t - times[k]) / h
        if self.interpolation == "linear":
            return (1 - s) * values[k] + s * values[k + 1]
        m0, m1 = self._tangent(k), self._tangent(k + 1)
        s2, s3 = s * s, s * s * s
        return ((2 * s3 - 3 * s2 + 1) * values[k] + (s3 - 2 * s2 + s) * h * m0
                + (-2 * s3 + 3 * s2) * values[k + 1] + (s3 - s2) * h * m1)

    def _tangent(self, k: int) -> np.ndarray:
        """Velocity [m/s] at key k: the centred difference, one-sided at the ends."""
        lo, hi = max(k - 1, 0), min(k + 1, len(self.times) - 1)
        return (self.values[hi] - self.values[lo]) / (self.times[hi] - self.times[lo])


@dataclass(frozen=True)
class Oscillation:
    """amplitude (3,) [m] x sin(2 pi frequency (t - start) + phase) after `start` [s], 0 before:
    waving, shaking, a bobbing head. frequency [Hz] > 0; phase [rad] (not 0 or pi: the path
    jumps to amplitude sin(phase) at `start`)."""

    amplitude: tuple
    frequency: float
    phase: float = 0.0
    start: float = 0.0

    def __post_init__(self):
        amplitude = as_array("Oscillation.amplitude", self.amplitude, np.float64, (3,))
        _within_reach("Oscillation.amplitude", amplitude)
        object.__setattr__(self, "amplitude", tuple(float(a) for a in amplitude))
        object.__setattr__(self, "frequency", finite_number("Oscillation.frequency", self.frequency,
                                                            0.0, strict=True, unit="Hz"))
        object.__setattr__(self, "phase", finite_number("Oscillation.phase", self.phase, unit="rad"))
        object.__setattr__(self, "start", finite_number("Oscillation.start", self.start, unit="s"))

    def __call__(self, t: float) -> np.ndarray:
        if t < self.start:
            return np.zeros(3)
        angle = 2 * np.pi * self.frequency * (t - self.start) + self.phase
        return np.asarray(self.amplitude) * np.sin(angle)


def _within_reach(field: str, values: np.ndarray) -> None:
    """Displacements no larger than the coordinate range (limits.COORDINATE)."""
    far = np.argwhere(np.abs(values) > limits.COORDINATE.high)
    require(len(far) == 0, f"{field}{list(far[0]) if len(far) else ''}",
            values[tuple(far[0])] if len(far) else None, f"{limits.COORDINATE.text()}")
