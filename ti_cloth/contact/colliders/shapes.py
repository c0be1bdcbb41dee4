"""Colliders: an infinite plane, a sphere, an axis-aligned box and a capsule, each with a
thickness, Coulomb friction and an optional scripted path (a triangle mesh is one too:
mesh_collider.py). The collision stage that applies them is collision.py.

The response is applied after every step, at position level, so it is the same for every
integrator: a particle closer than `thickness` to a shape is projected out along the shape's
normal; its displacement over the step relative to the shape loses its tangential part when
that part is at most static_friction x the penetration depth (it sticks), and is shortened by
kinetic_friction x depth otherwise (it slides: Coulomb's law with the depth standing in for the
normal impulse, as in position-based contact, Macklin et al. 2014). The velocity becomes that
displacement / dt, without any component into the shape (restitution 0); Verlet-type history is
rewritten to match. A resting particle on a slope of angle a gains depth g cos(a) dt^2 and
tangential displacement g sin(a) dt^2 per step, so it sticks exactly when tan(a) <= static.
"""

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
import taichi as ti

from ...inputs import limits
from ...inputs.validation import as_array, finite_number, in_range, require

PLANE, SPHERE, BOX, CAPSULE, MESH, ANIMATED = 0, 1, 2, 3, 4, 5   # mesh_collider.py, animated_mesh.py


# A collider's default thickness, as a fraction of the cloth's mean rest edge L: a flat
# triangle whose corners rest on a sphere of radius R sags L^2 / (8 R) into it between them,
# so at 0.2 L the cloth's faces stay outside (and are drawn in front of) every sphere, capsule
# or curved mesh of radius >= 0.625 L; flat colliders need none, and the cloth is not drawn
# coplanar with them (docs/api.md, Colliders).
AUTO_THICKNESS = 0.2


@dataclass(frozen=True, kw_only=True)
class Collider:
    """thickness: particles are kept this far outside the surface [m], >= 0; None (the
    default): AUTO_THICKNESS x the mean rest edge of the cloth it meets (for_cloth).
    static_friction, kinetic_friction: Coulomb coefficients, >= 0 (kinetic None: = static).
    path: t [s] -> displacement [m] of the whole shape from where it was defined, or None."""

    thickness: float | None = None
    static_friction: float = 0.0
    kinetic_friction: float | None = None
    path: Callable[[float], object] | None = None

    def __post_init__(self):
        name = type(self).__name__
        if self.thickness is not None:
            object.__setattr__(self, "thickness", finite_number(
                f"{name}.thickness", self.thickness, 0.0, unit="m"))
            require(self.thickness <= limits.LENGTH.high, f"{name}.thickness", self.thickness,
                    f"in [0, {limits.LENGTH.high:g}] m")
        static = finite_number(f"{name}.static_friction", self.static_friction, 0.0)
        kinetic = static if self.kinetic_friction is None else finite_number(
            f"{name}.kinetic_friction", self.kinetic_friction, 0.0)
        object.__setattr__(self, "static_friction", static)
        object.__setattr__(self, "kinetic_friction", kinetic)
        require(self.path is None or callable(self.path), f"{name}.path", self.path,
                "None or a callable t -> displacement")

    def for_cloth(self, cloth) -> "Collider":
        """This collider with a thickness: its own, or AUTO_THICKNESS x `cloth`'s mean rest
        edge (Cloth.mean_edge) when it has none."""
        if self.thickness is not None:
            return self
        return replace(self, thickness=AUTO_THICKNESS * cloth.mean_edge)

    def offset(self, t: float) -> np.ndarray:
        """Displacement [m] of the shape at time t."""
        if self.path is None:
            return np.zeros(3)
        offset = as_array(f"{type(self).__name__}.path({t})", self.path(t), np.float64, (3,))
        return offset

    def placed(self, t: float) -> "Collider":
        """This shape where its path has it at time t [s], without a path (itself if it has
        none)."""
        if self.path is None:
            return self
        return self.moved(self.offset(t))

    def carried(self, points: np.ndarray, t: float) -> np.ndarray:
        """Where points (N, 3) [m] fixed to the shape as it is at t = 0 are at time t [s]."""
        return points + self.offset(t) - self.offset(0.0)

    def moved(self, offset: np.ndarray) -> "Collider":
        """A copy translated by `offset` [m], without a path."""
        raise NotImplementedError

    def bounds(self) -> np.ndarray | None:
        """Corners (2, 3) [m] of the shape's bounding box where it is defined (placed(t)
        moves it); None for an unbounded one (a plane)."""
        return None

    def packed(self) -> tuple[int, np.ndarray, np.ndarray, float]:
        """(kind, a, b, radius) as the collision kernel reads them."""
        raise NotImplementedError


def _vector(owner: Collider, name: str) -> None:
    field = f"{type(owner).__name__}.{name}"
    value = as_array(field, getattr(owner, name), np.float64, (3,))
    for axis in range(3):
        in_range(f"{field}[{axis}]", value[axis], limits.COORDINATE)
    object.__setattr__(owner, name, tuple(float(v) for v in value))


@dataclass(frozen=True, kw_only=True)
class Plane(Collider):
    """The infinite plane through `point` [m]; `normal` points to the free side."""

    point: tuple = (0.0, 0.0, 0.0)
    normal: tuple = (0.0, 1.0, 0.0)

    def __post_init__(self):
        super().__post_init__()
        _vector(self, "point")
        _vector(self, "normal")
        length = float(np.linalg.norm(self.normal))
        require(length > 0, "Plane.normal", self.normal, "a non-zero vector")
        object.__setattr__(self, "normal", tuple(float(v) / length for v in self.normal))

    def moved(self, offset):
        return replace(self, point=tuple(np.add(self.point, offset)), path=None)

    def packed(self):
        return PLANE, np.asarray(self.point), np.asarray(self.normal), 0.0


@dataclass(frozen=True, kw_only=True)
class Sphere(Collider):
    """A sphere of `radius` [m] around `centre` [m]."""

    centre: tuple = (0.0, 0.0, 0.0)
    radius: float = 1.0

    def __post_init__(self):
        super().__post_init__()
        _vector(self, "centre")
        object.__setattr__(self, "radius", in_range("Sphere.radius", self.radius,
                                                    limits.LENGTH))

    def moved(self, offset):
        return replace(self, centre=tuple(np.add(self.centre, offset)), path=None)

    def bounds(self):
        return np.array([self.centre]) + [[-self.radius], [self.radius]]

    def packed(self):
        return SPHERE, np.asarray(self.centre), np.zeros(3), self.radius


@dataclass(frozen=True, kw_only=True)
class Box(Collider):
    """The axis-aligned box between corners `lo` and `hi` [m]."""

    lo: tuple = (-0.5, -0.5, -0.5)
    hi: tuple = (0.5, 0.5, 0.5)

    def __post_init__(self):
        super().__post_init__()
        _vector(self, "lo")
        _vector(self, "hi")
        require(all(h > l for l, h in zip(self.lo, self.hi)), "Box.hi", self.hi,
                f"greater than Box.lo {self.lo} on every axis")

    def moved(self, offset):
        return replace(self, lo=tuple(np.add(self.lo, offset)), hi=tuple(np.add(self.hi, offset)),
                       path=None)

    def bounds(self):
        return np.array([self.lo, self.hi], np.float64)

    def packed(self):
        return BOX, np.asarray(self.lo), np.asarray(self.hi), 0.0


@dataclass(frozen=True, kw_only=True)
class Capsule(Collider):
    """The points within `radius` [m] of the segment a-b [m]."""

    a: tuple = (0.0, 0.0, 0.0)
    b: tuple = (1.0, 0.0, 0.0)
    radius: float = 0.1

    def __post_init__(self):
        super().__post_init__()
        _vector(self, "a")
        _vector(self, "b")
        object.__setattr__(self, "radius", in_range("Capsule.radius", self.radius,
                                                    limits.LENGTH))

    def moved(self, offset):
        return replace(self, a=tuple(np.add(self.a, offset)), b=tuple(np.add(self.b, offset)),
                       path=None)

    def bounds(self):
        ends = np.array([self.a, self.b], np.float64)
        return np.array([ends.min(axis=0) - self.radius, ends.max(axis=0) + self.radius])

    def packed(self):
        return CAPSULE, np.asarray(self.a), np.asarray(self.b), self.radius


@ti.func
def signed_distance(kind, a, b, radius, x):
    """Distance [m] from x to the shape's surface (negative inside) and the outward normal."""
    d, n = 0.0, ti.Vector([0.0, 1.0, 0.0])
    if kind == PLANE:
        n = b
        d = (x - a).dot(n)
    elif kind == SPHERE or kind == CAPSULE:
        centre = a
        if kind == CAPSULE:
            ab = b - a
            centre = a + ab * ti.math.clamp((x - a).dot(ab) / ti.max(ab.dot(ab), 1e-30), 0.0, 1.0)
        r = x - centre
        length = r.norm()
        d = length - radius
        if length > 0:
            n = r / length
    else:                                       # BOX, a = lo, b = hi
        half, mid = 0.5 * (b - a), 0.5 * (a + b)
        q = ti.abs(x - mid) - half
        sign = ti.math.sign(x - mid)
        outside = ti.max(q, 0.0)
        if outside.norm() > 0:
            d = outside.norm()
            n = outside * sign / d
        else:                                   # inside: leave through the nearest face
            d = ti.max(q[0], q[1], q[2])
            n = ti.Vector([0.0, 0.0, 0.0])
            for k in ti.static(range(3)):
                if q[k] == d and n.norm() == 0:
                    n[k] = ti.select(sign[k] >= 0, 1.0, -1.0)
    return d, n
