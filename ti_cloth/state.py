"""State: the time-varying part of a simulation, as struct-of-arrays Taichi fields."""


import numpy as np
import taichi as ti

from .runtime import backend, transfer

# Largest coordinate or speed the divergence guard accepts; anything beyond (or NaN) flags
# the step. Well inside f32 range, so an exponential blow-up is caught before it overflows.
GUARD_LIMIT = 1e30
NO_BAD_STEP = 2**31 - 1


@backend.kernel_argument
class State:
    """Per-particle and per-spring quantities that change every step.

    particle_position       current positions [m], shape (particle_count,)
    particle_velocity       velocities [m/s], shape (particle_count,)
    particle_prev_position  positions one step earlier [m] (Verlet and PBD history)
    particle_force          total force of the last evaluation [N]
    spring_force            force of each spring on its first end at the last evaluation [N]
                            (its second end feels the negation)
    altitude_force          force of altitude spring a on its corner c at the last evaluation
                            [N], at index 4 a + c (Selle et al. 2008; forces.py)
    face_force              force of a Fabric's triangle f on its corner c [N], at 3 f + c
    hinge_force             bending force of hinge e on its corner k [N], at 4 e + k
    hinge_tangent, hinge_rate  t - t_rest of each hinge and dt/dt [1/s] (energies/bending.py)
    particle_bend_force     the isometric bending force on each particle [N] (a flat
                            sheet's: energies/isometric.isometric_forces)
    face_moment             dE/dt of triangle f's bending on the hinge across its edge i [J],
                            at 3 f + i
    spring_alive            1 while a spring exists, 0 once torn (Stuyck 4.5); lives here, not
                            in the Model, so the Model stays immutable and state() starts whole
    spring_torn_step        step index at which each spring tore, -1 if intact
    face_alive, face_torn_step  the same for a Fabric's triangles (a hinge beside a torn
                            triangle is gone too)
    first_bad_step          smallest step index whose result held a NaN, an inf or a coordinate
                            beyond position_limit (NO_BAD_STEP if none)
    position_limit          largest |coordinate| [m] the guard accepts: configuration, set here
                            once and never changed (it sits with the time-varying fields because
                            the kernels read it next to them: the step's code, and so its
                            rounding, stays as it was)
    prev_valid              False until particle_prev_position holds a real previous step
    """

    def __init__(self, particle_count: int, spring_count: int, position_limit: float = 1e6,
                 altitude_count: int = 0, face_count: int = 0, hinge_count: int = 0):
        real = backend.real()
        fields = backend.FieldGroup()
        self.particle_position = fields.vector(3, real, particle_count)
        self.particle_velocity = fields.vector(3, real, particle_count)
        self.particle_prev_position = fields.vector(3, real, particle_count)
        self.particle_force = fields.vector(3, real, particle_count)
        # Taichi fields cannot have length 0; kernels loop over model.spring_count instead.
        self.spring_force = fields.vector(3, real, max(spring_count, 1))
        self.spring_alive = fields.scalar(ti.i8, max(spring_count, 1))
        self.spring_torn_step = fields.scalar(ti.i32, max(spring_count, 1))
        self.altitude_force = fields.vector(3, real, max(4 * altitude_count, 1))
        self.face_force = fields.vector(3, real, 3 * max(face_count, 1))
        self.face_moment = fields.scalar(real, 3 * max(face_count, 1))
        self.hinge_force = fields.vector(3, real, 4 * max(hinge_count, 1))
        self.hinge_tangent = fields.scalar(real, max(hinge_count, 1))
        self.hinge_rate = fields.scalar(real, max(hinge_count, 1))
        self.particle_bend_force = fields.vector(3, real, particle_count if hinge_count else 1)
        self.face_alive = fields.scalar(ti.i8, max(face_count, 1))
        self.face_torn_step = fields.scalar(ti.i32, max(face_count, 1))
        self.first_bad_step = fields.scalar(ti.i32, ())
        self.position_limit = fields.scalar(real, ())
        fields.finalize(self)
        self.limit = position_limit
        self.prev_valid = False
        self._workspaces = {}

    @staticmethod
    def structure(particle_count: int, spring_count: int, position_limit: float = 1e6,
                  altitude_count: int = 0, face_count: int = 0, hinge_count: int = 0) -> tuple:
        """What the kernels of a State read at compile time: its field shapes (pool.py)."""
        return ("State", particle_count, spring_count, altitude_count, face_count, hinge_count)

    def load(self, particle_count: int, spring_count: int, position_limit: float = 1e6,
             altitude_count: int = 0, face_count: int = 0, hinge_count: int = 0) -> None:
        """Guard at position_limit from the next reset() on (a State of this structure)."""
        self.limit = position_limit

    def workspace(self, key, make):
        """Working storage of this state made by make() on first use under `key` (an
        integrator's buffers), kept for the state's life."""
        if key not in self._workspaces:
            with transfer.batched():     # its tables (colourings, packed springs) in one launch
                self._workspaces[key] = make()
        return self._workspaces[key]

    # what a step reads from the steps before it (Simulation.save_state)
    SAVED = ("particle_position", "particle_velocity", "particle_prev_position", "particle_force",
             "spring_force", "spring_alive", "spring_torn_step", "altitude_force",
             "face_alive", "face_torn_step", "first_bad_step")

    def saved(self) -> dict:
        """The fields of SAVED as numpy arrays, and whether the history is valid."""
        arrays = {name: getattr(self, name).to_numpy() for name in self.SAVED}
        arrays["prev_valid"] = np.array(self.prev_valid)
        return arrays

    def restore(self, arrays: dict) -> None:
        """Load what saved() returned (from a State of this structure and precision)."""
        for name in self.SAVED:
            getattr(self, name).from_numpy(arrays[name])
        self.prev_valid = bool(arrays["prev_valid"])

    POSITION, VELOCITY = 0, 1   # what read() and write() move

    def read(self, which: int) -> np.ndarray:
        """Particle positions (which POSITION) or velocities (VELOCITY), (N, 3) in the
        fields' type: one kernel serves both (Taichi's to_numpy compiles one per field)."""
        out = np.empty(self.particle_position.shape + (3,), backend.numpy_real())
        read_particles(self, which, out)
        return out

    def write(self, which: int, values: np.ndarray) -> None:
        """Overwrite positions (which POSITION) or velocities (VELOCITY) with (N, 3) values
        in the fields' type: one kernel serves both."""
        write_particles(self, which, np.ascontiguousarray(values, backend.numpy_real()))

    def reset(self, rest_position: np.ndarray) -> None:
        """Positions (and history) = rest_position (N, 3) [m], at rest, every spring and
        triangle intact, no bad step: one upload (in a simulation's build, sent with its
        model's tables: transfer.batched)."""
        springs, faces = self.spring_alive.shape[0], self.face_alive.shape[0]
        transfer.upload(((self.particle_position, rest_position),
                         (self.particle_prev_position, rest_position),
                         (self.particle_velocity, np.zeros_like(rest_position)),
                         (self.spring_alive, np.ones(springs, np.int8)),
                         (self.spring_torn_step, np.full(springs, -1, np.int32)),
                         (self.face_alive, np.ones(faces, np.int8)),
                         (self.face_torn_step, np.full(faces, -1, np.int32)),
                         (self.first_bad_step, NO_BAD_STEP), (self.position_limit, self.limit)))
        self.prev_valid = False


@backend.kernel
def read_particles(state: ti.template(), which: ti.i32, out: ti.types.ndarray()):
    """out[i] = particle i's position (which: State.POSITION) or velocity (State.VELOCITY)."""
    for i in state.particle_position:
        value = state.particle_position[i]
        if which == State.VELOCITY:
            value = state.particle_velocity[i]
        for c in ti.static(range(3)):
            out[i, c] = value[c]


@backend.kernel
def write_particles(state: ti.template(), which: ti.i32, values: ti.types.ndarray()):
    """Particle i's position (which: State.POSITION) or velocity (State.VELOCITY) = values[i]."""
    for i in state.particle_position:
        value = ti.Vector([values[i, 0], values[i, 1], values[i, 2]])
        if which == State.VELOCITY:
            state.particle_velocity[i] = value
        else:
            state.particle_position[i] = value


@ti.func
def store_particle(state: ti.template(), i, x, v, step):
    """Write particle i's new position and velocity; flag the step if either is not finite
    or the position left the guard box (the comparison is false for NaN)."""
    state.particle_position[i] = x
    state.particle_velocity[i] = v
    if not ((abs(x) <= state.position_limit[None]).all() and (abs(v) <= GUARD_LIMIT).all()):
        ti.atomic_min(state.first_bad_step[None], step)


@backend.kernel
def copy_positions(state: ti.template(), target: ti.template()):
    """target[i] = particle_position[i] (a snapshot for corrections applied after a step)."""
    for i in target:
        target[i] = state.particle_position[i]


@backend.kernel
def restore_positions(state: ti.template(), source: ti.template()):
    """particle_position[i] = source[i] (copy_positions the other way)."""
    for i in source:
        state.particle_position[i] = source[i]
