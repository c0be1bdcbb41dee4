"""The documented range of every count and rate ti_cloth accepts, and the memory and work a
simulation needs, estimated from its counts before anything is allocated or stepped.

The ranges keep every value where the float precisions, the stable-step estimate and the
int32 indices of the kernels stay exact (a stiffness of 1e20 makes the auto step 1e-9 s;
a gravity of 1e300 overflows f32), and every run within hours rather than geological time.
The README's "Limits" table is `markdown()`; a test keeps the two equal.
"""

from __future__ import annotations

import os
from dataclasses import dataclass


@dataclass(frozen=True)
class Range:
    """Allowed values of one quantity: low <= value <= high, in `unit`."""

    low: float
    high: float
    unit: str
    applies_to: str

    def text(self) -> str:
        """"in [low, high] unit", for messages."""
        return f"in [{_number(self.low)}, {_number(self.high)}]{' ' + self.unit if self.unit else ''}"


def _number(value: float) -> str:
    return f"{value:_}" if isinstance(value, int) else f"{value:g}"


STIFFNESS = Range(0.0, 1e9, "N/m", "spring stiffness k (stretch, shear, bend)")
DAMPING = Range(0.0, 1e6, "kg/s", "spring damping kd")
DENSITY = Range(1e-6, 1e5, "kg/m^2 (cloth), kg/m^3 (soft bodies)", "material density")
MASS = Range(1e-9, 1e6, "kg", "string and strand mass, hem mass (0 allowed)")
LENGTH = Range(1e-6, 1e4, "m", "sizes, lengths, radii, thicknesses (0 allowed for thickness)")
SCALE = Range(1e-6, 1e6, "", "mesh scale factor")
COORDINATE = Range(-1e5, 1e5, "m", "positions: origins, anchors, collider centres, paths")
ACCELERATION = Range(-1e4, 1e4, "m/s^2", "each gravity component")
SPEED_COMPONENT = Range(-1e3, 1e3, "m/s", "each wind velocity component")
GUARD = Range(1e-6, 1e12, "m", "position_limit: the divergence guard's box")
SEWING_SPEED = Range(1e-4, 1e3, "m/s", "how fast a seam closes (Sewing.speed)")
GATHER = Range(0.05, 1.0, "", "a panel's top edge placed gathered: its placed length over the "
               "pattern's (Panel.wrapped gather)")
DRAG = Range(0.0, 1e4, "1/s", "air drag")
DT = Range(1e-7, 1.0, "s", "time step dt")
FPS = Range(1.0, 1000.0, "frames/s", "frame rate")
FPS_DEFAULT = 30.0      # frames/s: a scene file's [simulation] fps when it gives none
DURATION = Range(1e-3, 3600.0, "s", "scene duration")
TIME = Range(0.0, 1e6, "s", "handle release time")
SUBSTEPS = Range(1, 100_000, "", "steps per frame")
FRAMES = Range(1, 3_600_000, "", "frames (checkpoint_every)")
ITERATIONS = Range(1, 10_000, "", "pbd/xpbd passes, strain-limit passes, implicit CG iterations")
AGGREGATE = Range(1, 1_000_000, "", "particles per aggregate of a coarse level (aggregate_size)")
THREADS = Range(1, 1024, "", "CPU threads (init(threads=...))")
GRID_SIDE = Range(2, 10_000, "", "grid rows, cols")
CHAIN = Range(2, 10_000_000, "", "string particles n")
STRANDS = Range(1, 1_000_000, "", "hair strands")
SEGMENTS = Range(1, 10_000, "", "segments per strand")
CELLS = Range(1, 1_000, "", "tet_block cells per axis")
STEPS = Range(0, 2**31 - 2, "", "steps of one simulation (the kernels index steps in int32)")
IMAGE_SIDE = Range(16, 8192, "px", "frame width, height, gif_width")
SUPERSAMPLE = Range(1, 8, "", "supersampling factor")
FOV = Range(1.0, 170.0, "degrees", "camera field of view")
LINE_WIDTH = Range(0.0, 64.0, "px", "style line widths and particle sizes")
SUBDIVISIONS = Range(0, 8, "", "sphere_mesh subdivisions (20 x 4^n triangles)")
SDF_RESOLUTION = Range(8, 256, "", "mesh collider distance grid: cells along the longest side")
RESOLUTION = Range(1, 64, "", "refinement of a scene's bodies (scene.build(resolution=f))")
SAMPLES = 2**26                # width x height x supersample^2: ~1.6 GB of raster buffers
MOTION_VALUES = 2**27          # an animated mesh: samples x vertices x 3 numbers (1 GiB float64)
NAME_LENGTH = 100              # scene names: letters, digits, "_", "-", "." (file names)

TABLE = (STIFFNESS, DAMPING, DENSITY, MASS, LENGTH, SCALE, COORDINATE, ACCELERATION, SPEED_COMPONENT, DRAG, GUARD, DT,
         FPS, DURATION, TIME, SUBSTEPS, ITERATIONS, THREADS, GRID_SIDE, CHAIN, STRANDS, SEGMENTS, CELLS,
         STEPS, IMAGE_SIDE, SUPERSAMPLE, FOV, LINE_WIDTH, SUBDIVISIONS, SDF_RESOLUTION,
         RESOLUTION)

# Memory, measured: a 512 x 512 grid (262,144 particles, 1,567,746 springs) peaks at 663 MB
# above the interpreter while its Cloth and Simulation are built (numpy topology, then the
# Taichi fields); these rates give 692 MB for it.
BYTES_PER_PARTICLE = 250
BYTES_PER_SPRING = 400
ALTITUDE_SPRINGS = 4   # an altitude spring (four corners' forces, adjacency) costs about four
FACE_SPRINGS = 3       # a Fabric's triangle (membrane, moments, three corners' forces): three
HINGE_SPRINGS = 4      # and its hinge (angle, gradient, four corners' forces): four
                       # springs, in memory and in work
MEMORY_SHARE = 0.75            # refuse a body needing more than this share of physical memory

# Work: spring updates per second of the slowest common case on one CPU core (pbd and
# implicit Euler at 128 x 128 run about 1.5e7 per second on two cores), for "this run is long".
SPRING_STEPS_PER_SECOND = 1e7
LONG_RUN_SECONDS = 60.0
CHECKPOINT_SECONDS = 5.0       # a run saves its state about this often (of estimated work)
SCHEDULED_STEPS = 64           # steps of a many-steps launch whose colliders or handles move
                               # along callable paths (tabled before it)
LARGE_BODY = 1_000_000         # springs: the stable-step analysis (modes.py) takes seconds


def physical_memory() -> int:
    """Bytes of physical memory of this machine (0 when the OS does not say)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return 0


def memory_needed(particles: int, springs: int) -> int:
    """Bytes a body of these counts needs while it is built and simulated (estimate)."""
    return BYTES_PER_PARTICLE * particles + BYTES_PER_SPRING * springs


def check_memory(field: str, value, particles: int, springs: int) -> None:
    """Raise ValueError naming `field` when a body of these counts would need more than
    MEMORY_SHARE of this machine's memory: called before anything is allocated."""
    needed, have = memory_needed(particles, springs), physical_memory()
    if have and needed > MEMORY_SHARE * have:
        raise ValueError(f"{field} = {value} makes {particles:,} particles and {springs:,} "
                         f"springs, which need about {_gigabytes(needed)}; this machine has "
                         f"{_gigabytes(have)} (at most {MEMORY_SHARE:.0%} of it may be used)")


def _gigabytes(size: float) -> str:
    return f"{size / 2**30:.3g} GB" if size >= 2**27 else f"{size / 2**20:.3g} MB"


@dataclass(frozen=True)
class Work:
    """What a run will do: steps and spring updates (springs x steps x passes)."""

    steps: int
    spring_steps: float

    @property
    def seconds(self) -> float:
        """A rough wall time at SPRING_STEPS_PER_SECOND (slow integrators; fast ones beat it)."""
        return self.spring_steps / SPRING_STEPS_PER_SECOND

    def describe(self) -> str:
        return (f"{self.steps:,} steps, {self.spring_steps:.3g} spring updates: up to about "
                f"{describe_duration(self.seconds)} at {SPRING_STEPS_PER_SECOND:.0e} spring "
                "updates/s (the slow integrators' pace; the pace measured on the first frames "
                "follows)")


def work(particles: int, springs: int, steps: int, passes: int = 1) -> Work:
    """The Work of `steps` steps of a body, each `passes` sweeps over its springs."""
    return Work(steps=steps, spring_steps=float(max(springs, particles)) * steps * passes)


def describe_duration(seconds: float) -> str:
    for unit, size in (("days", 86400.0), ("h", 3600.0), ("min", 60.0)):
        if seconds >= size:
            return f"{seconds / size:.3g} {unit}"
    return f"{max(seconds, 0.0):.2g} s"


def markdown() -> str:
    """The README's Limits table."""
    rows = ["| quantity | allowed | unit |", "|---|---|---|"]
    for r in TABLE:
        rows.append(f"| {r.applies_to} | {_number(r.low)} .. {_number(r.high)} | {r.unit or '-'} |")
    rows.append(f"| frame samples (width x height x supersample^2) | .. {SAMPLES:,} | - |")
    rows.append(f"| scene name | 1 .. {NAME_LENGTH} characters of A-Z a-z 0-9 _ - . | - |")
    rows.append(f"| memory of one simulation | {BYTES_PER_PARTICLE} B per particle + "
                f"{BYTES_PER_SPRING} B per spring, .. {MEMORY_SHARE:.0%} of physical memory | - |")
    return "\n".join(rows)


def spring_equivalents(body) -> int:
    """What a body (a Cloth or a Model) costs in springs, in memory and in a step's work:
    its springs, ALTITUDE_SPRINGS per altitude spring, FACE_SPRINGS per Fabric triangle and
    HINGE_SPRINGS per hinge."""
    return (body.spring_count + ALTITUDE_SPRINGS * body.altitude_count
            + FACE_SPRINGS * body.face_count + HINGE_SPRINGS * body.hinge_count)


CENTIMETRE_SIZE = 20.0   # m: bodies wider than this in a scene file are warned about (cm?)

# allowed values of the choices every entry point offers (the command line reads them without
# importing Taichi)
ARCH_NAMES = ("cpu", "cuda", "gpu", "vulkan")
PRECISION_NAMES = ("f32", "f64")
EXPORT_FORMATS = ("obj", "ply", "pc2", "npz", "usd")
