"""Helpers the tests share (imported as `from helpers import ...`; fixtures live in conftest.py)."""

import gc
import os
import re
import sys
from contextlib import contextmanager
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

import ti_cloth as tc
from ti_cloth import stepping
from ti_cloth.render import write_png
from ti_cloth.runtime import backend

# A 6-particle string swinging from one end for 0.2 s: the study's and advisor's small scene
SWINGING_STRING = """
[scene]
name = "swinging_string"
[simulation]
fps = 30
duration = 0.2
[[bodies]]
type = "string"
n = 6
length = 0.5
mass = 0.05
fixed = "start"
stretch = { k = 50.0, kd = 0.01 }
"""


def use(precision: str, threads: int | None = None) -> None:
    """Taichi on the CPU in `precision` with `threads` CPU threads (default: this process's
    share of the cores: pytest-xdist runs a process per core, and Taichi threads beyond a
    process's share would spin against the other processes' at team barriers),
    re-initialised only when either changes."""
    if threads is None:
        workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
        threads = max(1, backend.cpu_cores() // workers)
    config = backend.current()
    if config is None or config.precision != precision or backend.cpu_threads() != threads:
        tc.init(arch="cpu", precision=precision, threads=threads)


OPTIMIZATION = "TI_ADVANCED_OPTIMIZATION"      # Taichi's, read by every ti.init (conftest.py)


@contextmanager
def users_runtime(precision: str = "f64", threads: int = 1):
    """A runtime of `threads` CPU threads that compiles as users' runs do, with Taichi's
    advanced optimization (the suite's runtimes compile without it: conftest.py); then a
    runtime of every core as the suite compiles. A test that compares the two compares the
    builds too."""
    import taichi as ti

    suites = os.environ.get(OPTIMIZATION)
    os.environ[OPTIMIZATION] = "1"
    try:
        tc.init(arch="cpu", precision=precision, threads=threads)
        assert ti.cfg.advanced_optimization, "the users' build"
        yield
    finally:
        if suites is None:
            del os.environ[OPTIMIZATION]
        else:
            os.environ[OPTIMIZATION] = suites
        tc.init(arch="cpu", precision=precision)


def forget_compiled(*kernels) -> None:
    """Start counting these kernels' compilations afresh, so `compiled` tells what runs from
    now on (backend.compilations; counting is on for the whole suite: conftest.py)."""
    backend.forget_compilations(*kernels)


def compiled(kernel) -> bool:
    """Whether `kernel` (a ti_cloth kernel) was compiled and launched for any arguments since
    forget_compiled. Feature tests use it to show that a scene without a feature never
    compiles that feature's kernels."""
    return backend.compilations(kernel) > 0


def stretched_energy_ratios(sim, steps=30):
    """Pull particle 1 of a spring pair 0.1 m along x, then E_(n+1) / E_n of each of `steps`
    single steps (the energy map of a linear oscillator)."""
    x = sim.positions()
    x[1, 0] += 0.1
    sim.set_positions(x)
    energy = [sim.energy()["total"]]
    for _ in range(steps):
        sim.step(1)
        energy.append(sim.energy()["total"])
    return np.array(energy[1:]) / np.array(energy[:-1])


def central_gradient(energy, x: np.ndarray, h: float) -> np.ndarray:
    """The gradient of energy(positions) at x by central differences of step h, coordinate by
    coordinate (an independent check of the kernels' forces)."""
    gradient = np.zeros_like(x)
    for i in range(len(x)):
        for c in range(3):
            step = np.zeros_like(x)
            step[i, c] = h
            gradient[i, c] = (energy(x + step) - energy(x - step)) / (2 * h)
    return gradient


def report(label, got, expected):
    """Print got vs expected so a failure (and -s runs) show both."""
    print(f"{label}: got {got!r}, expected {expected!r}")


def xpbd_positions(cloth, steps: int, **options) -> np.ndarray:
    """The positions of `cloth` after `steps` xpbd steps of 1/240 s, tc.XPBD(**options)."""
    sim = tc.Simulation(cloth, integrator=tc.XPBD(**options), dt=1 / 240)
    sim.step(steps)
    return sim.positions()


def largest_distance(a: np.ndarray, b: np.ndarray) -> float:
    """The largest distance between the rows of two (N, 3) position arrays."""
    return float(np.linalg.norm(a - b, axis=1).max())


def check_xpbd_option_read_at_run_time(cloth, option: str, values) -> None:
    """Three XPBDs (6 passes) that differ only in `option`, the first and third with the same
    value, step `cloth` 12 times each through one compiled step: the first two runs differ,
    the third gives the first's bits again (values of None: the option not named)."""
    backend.forget_compilations(stepping.advance_many)
    runs = []
    for value in values:
        options = {} if value is None else {option: value}
        runs.append(xpbd_positions(cloth, 12, iterations=6, **options))
        gc.collect()                    # the simulation's fields, as a run of many would
    assert backend.compilations(stepping.advance_many) == 1
    assert largest_distance(runs[0], runs[1]) > 0.0
    np.testing.assert_array_equal(runs[2], runs[0])


def check_xpbd_scene_option(tmp_path, option: str, good: float, bad: float) -> None:
    """A scene file's `integrator = { name = "xpbd", ... }` table sets `option` to `good`, and
    one with `bad` is refused naming XPBD.<option> and the value."""
    from ti_cloth.app.scene import load_scene
    from ti_cloth.inputs.scene_file import SceneError
    path = tmp_path / "scene.toml"
    for value in (good, bad):
        path.write_text(f"""
[simulation]
integrator = {{ name = "xpbd", iterations = 4, {option} = {value!r} }}

[[bodies]]
type = "grid"
rows = 4
cols = 4
""")
        if value == good:
            assert getattr(load_scene(path).integrator, option) == good
    with pytest.raises(SceneError, match=rf"XPBD\.{option}.*{re.escape(repr(bad))}"):
        load_scene(path)


GOLDEN = Path(__file__).parent / "golden"
GOLDEN_PIXEL_TOLERANCE = 2 / 255     # 8-bit rounding of a shaded colour, either way
GOLDEN_OUTLIER_FRACTION = 0.005      # pixels allowed beyond it: edge samples that flip


def assert_matches_golden(image, name: str, failure_dir: Path) -> None:
    """Compare an (H, W, 3) uint8 render with tests/golden/<name>.png in float (never uint8
    subtraction, which wraps around).

    Threshold: renders are deterministic on one machine; another CPU or LLVM version may round
    a shaded colour to the next 8-bit level (1/255) or flip a sample lying within rounding of a
    triangle edge (with 2 x 2 supersampling, a quarter of the contrast in one pixel). So every
    pixel may differ by 2/255 and 0.5 % of the pixels by more; a moved camera, a missing
    triangle or a wrong colour changes far more. On failure the render and an amplified diff
    are written to `failure_dir` and named in the message. TI_CLOTH_UPDATE_GOLDEN=1 rewrites
    the golden instead (review the image before committing it).
    """
    path = GOLDEN / f"{name}.png"
    if os.environ.get("TI_CLOTH_UPDATE_GOLDEN") == "1":
        write_png(path, image)
    expected = iio.imread(path).astype(np.float64) / 255
    got = np.asarray(image).astype(np.float64) / 255
    assert got.shape == expected.shape, f"{name}: shape {got.shape} != golden {expected.shape}"
    diff = np.abs(got - expected).max(axis=2)
    outliers = float(np.mean(diff > GOLDEN_PIXEL_TOLERANCE + 1e-9))
    report(f"golden {name}: max diff, outlier fraction", (diff.max(), outliers),
           f"outliers <= {GOLDEN_OUTLIER_FRACTION}")
    if outliers > GOLDEN_OUTLIER_FRACTION:
        failure_dir.mkdir(parents=True, exist_ok=True)
        write_png(failure_dir / f"{name}.actual.png", np.asarray(image))
        amplified = (np.clip(diff * 4, 0, 1) * 255).astype(np.uint8)
        diff_path = write_png(failure_dir / f"{name}.diff.png", np.repeat(amplified[..., None], 3, 2))
        raise AssertionError(f"{name}: {outliers:.2%} of pixels differ by more than "
                             f"{GOLDEN_PIXEL_TOLERANCE * 255:.0f}/255 from {path} "
                             f"(max {diff.max() * 255:.0f}/255); diff image: {diff_path}")


def winding_numbers(points, vertices, triangles, chunk=64):
    """The winding number of the closed triangle mesh around each point: the sum of the
    triangles' signed solid angles over 4 pi (Van Oosterom & Strackee 1983)."""
    found = []
    for start in range(0, len(points), chunk):
        p = points[start:start + chunk]
        a, b, c = (vertices[triangles[:, k]][None] - p[:, None] for k in range(3))
        la, lb, lc = (np.linalg.norm(r, axis=2) for r in (a, b, c))
        numerator = np.sum(a * np.cross(b, c), axis=2)
        denominator = (la * lb * lc + np.sum(a * b, axis=2) * lc + np.sum(b * c, axis=2) * la
                       + np.sum(c * a, axis=2) * lb)
        found.append(2.0 * np.arctan2(numerator, denominator).sum(axis=1) / (4.0 * np.pi))
    return np.concatenate(found)


# ---------------------------------------------------------------- what the base install holds

ROOT = Path(__file__).parents[1]
MODULES = {"taichi": "taichi", "numpy": "numpy", "imageio": "imageio", "pillow": "PIL",
           "meshio": "meshio", "tqdm": "tqdm", "scipy": "scipy", "libigl": "igl",
           "tomli": "tomli", "imageio-ffmpeg": "imageio_ffmpeg", "matplotlib": "matplotlib",
           "usd-core": "pxr", "distributed": "distributed"}
ALSO_FROM = {"distributed": {"dask"}}      # a distribution's other top-level modules


def _distributions(requirements) -> set:
    return {re.split(r"[<>=!;\[ ]", r, maxsplit=1)[0].strip() for r in requirements}


def _modules(names) -> set:
    out = set()
    for name in names:
        out |= {MODULES[name]} | ALSO_FROM.get(name, set())
    return out


def base_and_optional_modules() -> tuple[set, set]:
    """(the top-level modules of pyproject.toml's base dependencies, those only its extras
    other than [test] bring)."""
    try:
        import tomllib
    except ImportError:          # Python 3.10
        import tomli as tomllib
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    base = _modules(_distributions(project["dependencies"]))
    extras = project["optional-dependencies"]
    optional = _modules(_distributions(r for name, reqs in extras.items() if name != "test"
                                       for r in reqs)) - base
    return base, optional


@contextmanager
def base_install():
    """Run the block as on a base install: importing a module only an extra brings raises
    ImportError (sys.modules[name] = None), whether or not it was imported before."""
    _, optional = base_and_optional_modules()
    saved = {name: module for name, module in sys.modules.items()
             if name.split(".")[0] in optional}
    for name in saved:
        del sys.modules[name]
    for name in optional:
        sys.modules[name] = None
    try:
        yield optional
    finally:
        for name in optional:
            sys.modules.pop(name, None)
        sys.modules.update(saved)


def twisted_sheet(n=12, size=0.4, turns=1.0, seconds=1.0):
    """An n x n sheet whose two opposite edges (handles) turn opposite ways about its middle
    line, `turns` half turns each a second for `seconds` (Newton's cloth_twist: a third of a
    half turn for 10 s); with the edges held."""
    body = tc.Cloth(tc.grid_mesh(n, n, size=(size, size), plane="xz", origin=(0.0, 0.5, -size / 2)),
                    tc.Material.preset("cotton_springs"))
    x = body.particle_position
    handles = []
    for edge, sense in ((np.isclose(x[:, 0], 0.0), 1.0), (np.isclose(x[:, 0], size), -1.0)):
        for i in np.flatnonzero(edge):
            y, z = x[i, 1] - 0.5, x[i, 2]

            def turned(t, y=y, z=z, sense=sense):
                a = sense * np.pi * turns * min(t, seconds)
                return (0.0, y * np.cos(a) - z * np.sin(a) - y, y * np.sin(a) + z * np.cos(a) - z)
            handles.append(tc.Handle([i], turned))
    held = np.concatenate([h.particles for h in handles])
    return body, handles, held


def wound_twist() -> tc.Simulation:
    """A 24 x 24 twisted_sheet (0.6 m) turned a half turn a second each way, xpbd with 10
    iterations at 1/240 s, no gravity, self-collision at 5 mm with keep_thickness: it winds
    onto itself within its first second (tests of self-contact's near pairs)."""
    body, handles, _ = twisted_sheet(n=24, size=0.6, turns=1.0)
    return tc.Simulation(body, integrator=tc.XPBD(iterations=10), dt=1 / 240, handles=handles,
                         gravity=(0.0, 0.0, 0.0),
                         self_collision=tc.SelfCollision(thickness=0.005, keep_thickness=True))


def positions_over(sim: tc.Simulation, steps: int) -> np.ndarray:
    """The positions after each of `steps` steps of sim, (steps, N, 3)."""
    ends = []
    for _ in range(steps):
        sim.step(1)
        ends.append(sim.positions())
    return np.array(ends)
