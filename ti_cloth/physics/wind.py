"""Wind and per-triangle aerodynamics (a flat-plate model), compiled in only when a scene has wind.

Each triangle of area A and unit normal n sees the air velocity relative to its own motion,
u = w(centroid, t) - (v_a + v_b + v_c) / 3. With q = 1/2 rho |u|^2 A, u_hat = u / |u| and
c = n . u_hat (the cosine between the normal and the flow), its force is

    drag = q (C_drag |c| + C_friction) u_hat            along the flow; |c| A is the area facing it
    lift = q C_lift c (n - c u_hat)                      across the flow, |lift| = q C_lift |c| sin

and a third of it goes to each corner. Lift vanishes both face-on (c = +-1) and edge-on (c = 0),
where only the skin-friction drag C_friction remains. In still air (w = 0) the same model is an
aerodynamic damping that resists motion across the surface far more than along it, unlike the
uniform `drag` of ForceSettings (the cheap option, kept).

The wind field: w(x, t) = velocity (1 + gust sin(2 pi t / gust_period)) + turbulence * sum of
`TURBULENCE_MODES` travelling sine waves carried along by the mean wind (frozen turbulence),
each with a random wave vector of length 2 pi / turbulence_scale and a direction perpendicular
to it (so the fluctuation is divergence-free, like incompressible air); their sum is scaled so
its root-mean-square speed is `turbulence`.
"""

from dataclasses import dataclass

import numpy as np
import taichi as ti

from ..body.mesh import vertex_triangles
from ..inputs import limits
from ..inputs.validation import as_array, finite_number, in_range, integer, require
from ..runtime import backend
from ..runtime.plan import ITEM, NOW, STATE, Loop, Phase
from ..runtime.transfer import upload

TURBULENCE_MODES = 8


@dataclass(frozen=True, kw_only=True)
class Wind:
    """Moving air acting on every triangle of a body.

    velocity: mean wind [m/s], shape (3,).
    gust: relative amplitude of a periodic gust, >= 0: the mean wind is scaled by
        1 + gust sin(2 pi t / gust_period).
    gust_period: [s], > 0.
    turbulence: RMS speed [m/s] of the spatially varying part, >= 0 (0: uniform wind, the
        turbulence code is not compiled).
    turbulence_scale: wavelength [m] of the turbulent waves, > 0.
    air_density: [kg/m^3], > 0 (1.2 at sea level).
    drag_coefficient, lift_coefficient, friction_coefficient: C_drag, C_lift, C_friction of the
        flat-plate model (module doc), >= 0.
    seed: random seed of the turbulent waves.
    """

    velocity: tuple = (0.0, 0.0, 0.0)
    gust: float = 0.0
    gust_period: float = 2.0
    turbulence: float = 0.0
    turbulence_scale: float = 1.0
    air_density: float = 1.2
    drag_coefficient: float = 1.0
    lift_coefficient: float = 1.0
    friction_coefficient: float = 0.02
    seed: int = 0

    def __post_init__(self):
        velocity = as_array("Wind.velocity", self.velocity, np.float64, (3,))
        for axis in range(3):
            in_range(f"Wind.velocity[{axis}]", velocity[axis], limits.SPEED_COMPONENT)
        object.__setattr__(self, "velocity", tuple(float(v) for v in velocity))
        for name, strict, unit in (("gust", False, ""), ("gust_period", True, "s"),
                                   ("turbulence", False, "m/s"), ("turbulence_scale", True, "m"),
                                   ("air_density", True, "kg/m^3"), ("drag_coefficient", False, ""),
                                   ("lift_coefficient", False, ""),
                                   ("friction_coefficient", False, "")):
            object.__setattr__(self, name, finite_number(f"Wind.{name}", getattr(self, name), 0.0,
                                                         strict=strict, unit=unit))
        object.__setattr__(self, "seed", integer("Wind.seed", self.seed, 0, 2**63 - 1))

    def mean_velocity(self, t: float) -> np.ndarray:
        """The spatially uniform part of the wind [m/s] at time t."""
        return np.asarray(self.velocity) * (1.0 + self.gust * np.sin(2 * np.pi * t / self.gust_period))

    def turbulence_modes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(wave vectors [1/m] (K, 3), unit directions (K, 3) perpendicular to them, phases (K,))."""
        rng = np.random.default_rng(self.seed)
        wave = rng.normal(size=(TURBULENCE_MODES, 3))
        wave /= np.linalg.norm(wave, axis=1, keepdims=True)
        direction = np.cross(wave, rng.normal(size=(TURBULENCE_MODES, 3)))
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        phase = rng.uniform(0.0, 2 * np.pi, TURBULENCE_MODES)
        return wave * (2 * np.pi / self.turbulence_scale), direction, phase


@backend.kernel_argument
class WindField:
    """A Wind bound to one body: its triangles, the particle -> triangle adjacency used to
    gather the triangle forces deterministically, the turbulence modes, and the mean wind's
    velocity and gust, from which a step evaluates the wind of its start time."""

    def __init__(self, wind: Wind, cloth):
        self.structure(wind, cloth)
        real = backend.real()
        self.triangle_count = len(cloth.mesh.triangles)
        fields = backend.FieldGroup()
        self.triangle = fields.vector(3, ti.i32, self.triangle_count)
        self.triangle_edge_spring = fields.vector(3, ti.i32, self.triangle_count)
        self.triangle_face = fields.scalar(ti.i32, self.triangle_count)
        self.triangle_force = fields.vector(3, real, self.triangle_count)
        self.particle_wind_force = fields.vector(3, real, cloth.particle_count)
        self.particle_triangle_start = fields.scalar(ti.i32, cloth.particle_count + 1)
        self.adjacency_triangle = fields.scalar(ti.i32, 3 * self.triangle_count)
        self.mode_wave = fields.vector(3, real, TURBULENCE_MODES)
        self.mode_direction = fields.vector(3, real, TURBULENCE_MODES)
        self.mode_phase = fields.scalar(real, TURBULENCE_MODES)
        self.velocity = fields.vector(3, ti.f64, ())    # float64: evaluated as on the host
        self.gust = fields.vector(3, ti.f64, ())        # gust, 2 pi, gust_period
        fields.finalize(self)
        self.load(wind, cloth)

    @staticmethod
    def structure(wind: Wind, cloth) -> tuple:
        """What the kernel of a WindField reads at compile time (the counts and the Wind's
        attributes wind_forces reads; velocity, gust and seed are uploaded): fields of
        equal structure are interchangeable once load() has run (pool.py). Raises ValueError
        unless `wind` is a Wind and the cloth has triangles."""
        require(isinstance(wind, Wind), "wind", wind, "None or a ti_cloth.Wind")
        require(len(cloth.mesh.triangles) > 0, "wind", wind,
                "used only with a body that has triangles (strings and hair: use drag=)")
        compiled = (wind.turbulence, wind.air_density, wind.drag_coefficient,
                    wind.lift_coefficient, wind.friction_coefficient)
        return ("WindField", compiled, cloth.particle_count, len(cloth.mesh.triangles))

    def load(self, wind: Wind, cloth) -> None:
        """Upload `cloth`'s triangles and `wind`'s velocity, gust and turbulence."""
        self.wind = wind
        triangles = cloth.mesh.triangles
        start, adjacent = vertex_triangles(triangles, cloth.particle_count)
        wave, direction, phase = wind.turbulence_modes()
        upload(((self.triangle, triangles), (self.particle_triangle_start, start),
                (self.triangle_edge_spring, cloth.triangle_edge_spring),
                (self.triangle_face, cloth.triangle_face),
                (self.adjacency_triangle, adjacent), (self.mode_wave, wave),
                (self.mode_direction, direction), (self.mode_phase, phase)))
        self.velocity[None] = wind.velocity
        self.gust[None] = (wind.gust, 2 * np.pi, wind.gust_period)

    @ti.func
    def mean_and_drift(self, t):
        """(the mean wind [m/s] at time t [s] (Wind.mean_velocity), how far it has carried the
        turbulence [m]), computed in float64 with the host's operations in its order, then
        rounded to the working precision."""
        velocity, gust = self.velocity[None], self.gust[None]
        mean = velocity * (1.0 + gust[0] * ti.sin(gust[1] * t / gust[2]))
        return ti.cast(mean, float), ti.cast(velocity * t, float)

    @ti.func
    def turbulence_at(self, x):
        """The turbulent part of the wind at x [m] (x already moved back by the drift)."""
        u = ti.Vector([0.0, 0.0, 0.0])
        for k in ti.static(range(TURBULENCE_MODES)):
            u += self.mode_direction[k] * ti.sin(self.mode_wave[k].dot(x) + self.mode_phase[k])
        return u * ti.sqrt(2.0 / TURBULENCE_MODES)


@ti.func
def wind_on_triangle(state: ti.template(), forces: ti.template(), t, now: ti.template()):
    """Triangle t's aerodynamic force (module doc) in the wind of the step's start (now.time,
    held during the step), a third of it kept per corner in triangle_force. The WindField is a
    template argument, so its frozen Wind's coefficients are compile-time constants."""
    wind = forces.wind
    mean, drift = wind.mean_and_drift(now.time)
    a, b, c = wind.triangle[t][0], wind.triangle[t][1], wind.triangle[t][2]
    xa, xb, xc = state.particle_position[a], state.particle_position[b], state.particle_position[c]
    u = mean - (state.particle_velocity[a] + state.particle_velocity[b]
                + state.particle_velocity[c]) / 3.0
    if ti.static(wind.wind.turbulence > 0):
        u += wind.wind.turbulence * wind.turbulence_at((xa + xb + xc) / 3.0 - drift)
    area_vector = 0.5 * (xb - xa).cross(xc - xa)
    area = area_vector.norm()
    speed = u.norm()
    intact = True
    if ti.static(forces.tearable):
        for e in ti.static(range(3)):
            s = wind.triangle_edge_spring[t][e]
            if s >= 0 and state.spring_alive[s] == 0:
                intact = False
        face = wind.triangle_face[t]
        if face >= 0 and state.face_alive[ti.max(face, 0)] == 0:     # a torn Fabric triangle
            intact = False
    f = ti.Vector([0.0, 0.0, 0.0])
    if intact and area > 0 and speed > 0:
        n = area_vector / area
        flow = u / speed
        cos = n.dot(flow)
        q = 0.5 * wind.wind.air_density * speed * speed * area
        drag = wind.wind.drag_coefficient * ti.abs(cos) + wind.wind.friction_coefficient
        f = q * (drag * flow + wind.wind.lift_coefficient * cos * (n - cos * flow))
    wind.triangle_force[t] = f / 3.0


@ti.func
def wind_on_particle(forces: ti.template(), i):
    """Particle i's wind force: the forces of its triangles, gathered in a fixed order."""
    wind = forces.wind
    f = ti.Vector([0.0, 0.0, 0.0])
    for k in range(wind.particle_triangle_start[i], wind.particle_triangle_start[i + 1]):
        f += wind.triangle_force[wind.adjacency_triangle[k]]
    wind.particle_wind_force[i] = f


def phases(model, forces) -> tuple:
    """The wind's phases at the current state (plan.py), none without wind: every
    triangle's force, then every particle's share (forces.gather_force adds it)."""
    if forces.wind is None:
        return ()
    return (Phase(Loop(forces.wind.triangle_count, wind_on_triangle, STATE, forces, ITEM, NOW)),
            Phase(Loop(model.particle_count, wind_on_particle, forces, ITEM)))
