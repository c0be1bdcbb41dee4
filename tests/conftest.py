"""Tests run on the CPU. Most run in f64 so tolerances can follow the method, not rounding;
the `f32` fixture switches precision for the tests that are about f32 itself. Shared helpers are
in helpers.py.

Where a test of an integrator goes:
- test_integrators.py: what every integrator must satisfy against a closed form (free fall,
  oscillator period, statics, energy laws of the explicit ones), parametrised over them;
- test_implicit_and_xpbd.py: the implicit solves (backward Euler's CG, xpbd's multipliers)
  against a dense solve and the exact decay of backward Euler;
- test_convergence.py: observed order of accuracy; test_stability.py: predicted stable steps;
- test_stepping.py: launch plans and the per-step order (the same bits whichever plan runs);
- test_simulation.py: what Simulation adds around any integrator (pins, momentum, handles,
  tearing, divergence, determinism).
"""

import atexit
import os
import shutil
import tempfile

import pytest
from helpers import use

from ti_cloth.runtime import backend

# The suite compiles without Taichi's advanced optimization: its own IR passes, half the
# compile time of the garments' and the implicit solvers' kernels, which is most of the
# suite (10 min 13 s against 8 min 11 s cold on 2 cores, the same 1,124 tests passing;
# docs/performance.md). Users' runs keep it (their garments' steps are 0-10 % faster with
# it); the tests of one thread against every core run their one thread as users compile
# (helpers.users_runtime), so they also show that both builds step to the same bits. A
# developer's own TI_ADVANCED_OPTIMIZATION is kept.
os.environ.setdefault("TI_ADVANCED_OPTIMIZATION", "0")

# mesh colliders cache their distance grids on disk: the tests' go to a folder of their own,
# removed when the process (each xdist worker has its own) exits
os.environ["TI_CLOTH_CACHE"] = tempfile.mkdtemp(prefix="ti_cloth_test_cache_")
atexit.register(shutil.rmtree, os.environ["TI_CLOTH_CACHE"], ignore_errors=True)
backend.count_compilations()    # tests ask which kernels a scene compiled (helpers.compiled)


def pytest_collection_modifyitems(items):
    """Tests marked slow first (in their order), so that with one worker per core (xdist)
    the longest ones do not start last and leave a core idle at the end; then those in f64,
    then those in f32: switching precision re-initialises Taichi, which drops every kernel the
    worker compiled, so the switches are kept few. Tests that call tc.init themselves (a
    thread count, a precision or a fresh runtime of their own) go last, so the tests after
    them do not compile everything again (marked `reinitialises`); before them those that
    need two threads (the `threads` fixture: every other test runs on its process's share of
    the cores). A test both slow and reinitialising goes first, with the slow ones: at a
    worker's start it drops no kernel, and run last (the self-collision check of one thread
    against every core, about a minute) it left the other worker idle for the last 58 s of a
    clean run on 2 cores (both now end within 2 s of each other)."""
    items.sort(key=lambda item: (reinitialises(item) and not slow(item),
                                 "threads" in getattr(item, "fixturenames", ()),
                                 not slow(item),
                                 "f32" in getattr(item, "fixturenames", ())))


def slow(item) -> bool:
    """Whether the test is marked `slow` (a longer verification run)."""
    return item.get_closest_marker("slow") is not None


def reinitialises(item) -> bool:
    """Whether the test starts a Taichi runtime of its own (marked `reinitialises`)."""
    return item.get_closest_marker("reinitialises") is not None


@pytest.fixture
def f64():
    use("f64")


@pytest.fixture
def f32():
    use("f32")


@pytest.fixture
def threads():
    """f64 on at least two Taichi CPU threads, so a team of two can run (on a one-core
    machine too)."""
    use("f64", threads=max(2, backend.cpu_cores()))
