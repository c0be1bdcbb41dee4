"""Taichi runtime set-up: architecture, floating-point precision and thread count.

`init` is the only place ti_cloth calls ``ti.init``; importing the package never does.
Kernels compile with exact IEEE arithmetic (``fast_math=False``): fast math lets LLVM
reassociate sums and contract multiply-adds per kernel and per CPU model, so the same formula
could round differently in two launch plans or on two machines. Exact, every plan, thread
count and x86-64 CPU computes the same operations in the same order, at no measurable cost
(docs/performance.md).
Every Taichi field ti_cloth allocates uses the precision chosen here, and Taichi's
``default_fp`` is set to match so float literals inside kernels have the same type.
Calling `init` again resets Taichi: fields and simulations created before become invalid
(a Simulation then raises errors.StaleSimulation instead of touching freed memory).
"""

from __future__ import annotations

import contextlib
import functools
import gc
import inspect
import io
import os
import weakref
from dataclasses import dataclass

import numpy as np
import taichi as ti

from ..inputs import limits
from ..inputs.validation import count
from . import frontend

ARCHS = {name: name for name in limits.ARCH_NAMES}          # ti.<value>
PRECISIONS = dict(zip(limits.PRECISION_NAMES, (ti.f32, ti.f64)))
NUMPY_PRECISIONS = {"f32": np.float32, "f64": np.float64}
# Taichi's offline cache of compiled kernels keeps 100 MB by default, least recently used out
# at each re-initialisation; ti_cloth's kernels are specialised per scene and the test suite's
# come to about 380 MB, so at 100 MB a rerun compiled most of them again (docs/performance.md,
# "The quick start and the suite"). TI_OFFLINE_CACHE_MAX_SIZE_OF_FILES still sets it.
OFFLINE_CACHE_BYTES = 1 << 30


@dataclass(frozen=True)
class BackendConfig:
    """What `init` was called with."""

    arch: str
    precision: str
    threads: int | None


_config: BackendConfig | None = None
_generation = 0   # bumped by every init: trees of an earlier runtime must not be destroyed
_tree_count = 0   # trees of this runtime FieldGroup allocated and has not destroyed


def gpu_arch() -> str:
    """What arch="gpu" starts: "cuda" where the CUDA driver library is installed, else
    "vulkan" where the Vulkan loader is, else "cpu". Chosen here rather than by Taichi's own
    probe, which also tries OpenGL and crashed the process (a segmentation fault) on a
    machine with OpenGL libraries and no GPU."""
    import ctypes.util

    for arch, library in (("cuda", "cuda"), ("vulkan", "vulkan")):
        if ctypes.util.find_library(library):
            return arch
    return "cpu"


def init(arch: str = "cpu", precision: str = "f32", threads: int | None = None,
         debug: bool = False) -> BackendConfig:
    """Start (or restart) the Taichi runtime.

    arch: "cpu" | "cuda" | "vulkan" | "gpu" (the first GPU backend found, else CPU:
        gpu_arch).
    precision: "f32" | "f64", the float type of every particle and spring field.
    threads: CPU worker threads (None: all cores).
    debug: Taichi's bounds-checking debug mode (slow).
    """
    global _config
    if arch not in ARCHS:
        raise ValueError(f"arch must be one of {sorted(ARCHS)}, got {arch!r}")
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {sorted(PRECISIONS)}, got {precision!r}")
    if threads is not None:
        count("threads", threads, limits.THREADS)
    # cfg_optimization off: Taichi's control-flow-graph passes (store forwarding, dead
    # stores) took most of the compile of big kernels (a Fabric's implicit Euler step 16.5 s,
    # 4.1 s without) for no measured change in steps/s (docs/performance.md)
    if arch == "gpu":
        arch = gpu_arch()
    frontend.install()      # Taichi's front end, memoised (a warm build of the cape: 1.7x)
    options = dict(arch=getattr(ti, ARCHS[arch]), default_fp=PRECISIONS[precision],
                   default_ip=ti.i32, random_seed=0, debug=debug, log_level=ti.WARN,
                   fast_math=False, cfg_optimization=False)
    if threads is not None:
        options["cpu_max_num_threads"] = threads
    if not os.environ.get("TI_OFFLINE_CACHE_MAX_SIZE_OF_FILES"):
        options["offline_cache_max_size_of_files"] = OFFLINE_CACHE_BYTES
    for user in list(_closed_by_init):    # dead ones too, until the cycle collector runs
        user.close()
    _closed_by_init.clear()
    if os.environ.get("ENABLE_TAICHI_HEADER_PRINT", "True").lower() in ("false", "0", "f"):
        with contextlib.redirect_stdout(io.StringIO()):   # its "Starting on arch" line too
            ti.init(**options)
    else:
        ti.init(**options)
    global _generation, _tree_count
    _generation += 1
    _tree_count = 0
    _config = BackendConfig(arch=arch, precision=precision, threads=threads)
    return _config


def ensure(arch: str = "cpu", precision: str = "f32", threads: int | None = None) -> BackendConfig:
    """`init` unless the runtime already runs with these settings, which then keeps its
    compiled kernels, pooled simulations and open renderers. threads=None asks for no thread
    count: a runtime of this arch and precision is kept with the count it was given (a
    caller's ti_cloth.init(threads=...) before run_scene or a demo holds), and a new one gets
    Taichi's default."""
    if arch == "gpu":
        arch = gpu_arch()
    if (_config is not None and _config.arch == arch and _config.precision == precision
            and threads in (None, _config.threads)):
        return _config
    return init(arch=arch, precision=precision, threads=threads)


# Objects holding Taichi ndarrays. An ndarray freed after `init` asks the *new* runtime to
# delete it, and the new runtime may hold a live ndarray at the same address: it frees that one
# (a later launch reads freed memory). So `init` closes these first, the unreachable ones not
# yet collected included (a weak set keeps them until then): their ndarrays go with the
# runtime they belong to.
_closed_by_init: weakref.WeakSet = weakref.WeakSet()


def close_at_init(user) -> None:
    """Have `user.close()` release its Taichi ndarrays when `init` next ends this runtime."""
    _closed_by_init.add(user)


def generation() -> int:
    """How many times `init` has run: objects holding fields remember it, since an `init`
    after theirs freed those fields."""
    return _generation


def config() -> BackendConfig:
    """The active configuration; raises if `init` has not been called."""
    if _config is None:
        raise RuntimeError("ti_cloth is not initialised: call ti_cloth.init(arch=..., precision=...) first")
    return _config


def cpu_threads() -> int:
    """How many CPU threads Taichi's thread pool has: the `threads` of init, else Taichi's
    default, one per hardware thread."""
    threads = config().threads
    return threads if threads is not None else (os.cpu_count() or 1)


def current() -> BackendConfig | None:
    """The active configuration, None before the first `init`."""
    return _config


def cpu_cores() -> int:
    """How many CPU cores this process may run on."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


DTYPES = {np.dtype(np.float32): ti.f32, np.dtype(np.float64): ti.f64, np.dtype(np.int8): ti.i8,
          np.dtype(np.int32): ti.i32, np.dtype(np.int64): ti.i64}   # numpy -> Taichi, one map


def taichi_dtype(dtype):
    """The Taichi type of a numpy dtype (DTYPES)."""
    return DTYPES[np.dtype(dtype)]


def numpy_dtype(dtype):
    """The numpy dtype of a Taichi type (DTYPES read backwards)."""
    return next(np_type for np_type, ti_type in DTYPES.items() if ti_type == dtype)


_counting = False
_launched: dict = {}   # kernel -> the distinct template arguments it was launched with
TEMPLATE = type(ti.template())


def kernel(function):
    """ti.kernel, and a count of its compilations (compilations()): Taichi compiles a
    kernel once for each distinct set of template arguments, each object argument keyed by a
    weak reference (an equal live object finds the same compiled kernel), so ti_cloth counts
    the distinct sets it launched it with, keyed the same way, while count_compilations()
    is on (tests: a scene compiles only the features it uses; the pool keeps compiled
    kernels serving new simulations)."""
    compiled = ti.kernel(function)
    templates = [i for i, parameter in enumerate(inspect.signature(function).parameters.values())
                 if isinstance(parameter.annotation, TEMPLATE)]

    @functools.wraps(function)
    def launch(*args):
        if _before_launch is not None:
            _before_launch()
        if _counting:
            _launched.setdefault(launch, set()).add(tuple(_key(args[i]) for i in templates))
        return compiled(*args)

    return launch


_before_launch = None   # called before any kernel launches (transfer.batched: its uploads)


def before_launch(hook) -> None:
    """Call hook() (None: nothing) before each launch of a ti_cloth kernel from now on: a
    batch of uploads is sent before a kernel can read the fields it fills."""
    global _before_launch
    _before_launch = hook


def _key(value):
    """A template argument as Taichi keys it: a weak reference to an object, else the value."""
    try:
        return weakref.ref(value)
    except TypeError:
        return value


def count_compilations(on: bool = True) -> None:
    """Start (or stop) counting the compilations of ti_cloth's kernels (compilations())."""
    global _counting
    _counting = on


def counting() -> bool:
    """Whether compilations are being counted (count_compilations)."""
    return _counting


def note_launch(function, key) -> None:
    """Count a launch of `function` (a ti.func a kernel inlines: plan.py's phase bodies)
    with compile-time key `key`, as a kernel's launches are counted (compilations)."""
    if _counting:
        _launched.setdefault(function, set()).add(key)


def compilations(kernel_function) -> int:
    """How many distinct compilations of `kernel_function` (a ti_cloth kernel) were launched
    since counting started or forget_compilations; 0: it never ran."""
    return len(_launched.get(kernel_function, ()))


def forget_compilations(*kernel_functions) -> None:
    """Start these kernels' counts afresh (all kernels' when none is named)."""
    for function in kernel_functions or list(_launched):
        _launched.pop(function, None)


def kernel_argument(cls):
    """Class decorator: instances may be passed to kernels as ti.template() arguments, whose
    fields and Python attributes the kernels read (attributes at compile time).

    It sets the marker Taichi checks (`_data_oriented`), as ti.data_oriented does, without
    ti.data_oriented's __getattribute__ hook: the hook binds @ti.kernel methods (these
    classes define none; TypeError if one does) and runs on every attribute access, a third
    of the Python time of a launch taking a Model, a State and the ForceSettings
    (docs/performance.md).
    """
    kernels = [name for name, value in vars(cls).items() if hasattr(value, "_is_wrapped_kernel")]
    if kernels:
        raise TypeError(f"{cls.__name__} defines @ti.kernel methods {kernels}: use ti.data_oriented")
    cls._data_oriented = True
    return cls


def real():
    """The Taichi float type of the active precision (ti.f32 or ti.f64)."""
    return PRECISIONS[config().precision]


def numpy_real():
    """The numpy float type matching `real()`."""
    return NUMPY_PRECISIONS[config().precision]


class FieldGroup:
    """The Taichi fields of one object, allocated together in one SNode tree that is freed
    after the object is garbage-collected.

    Without it Taichi gives every batch of fields created after a kernel has run a tree of its
    own and never frees it; a process runs out of trees (512) after a few dozen simulations.
    Freeing a tree makes Taichi drop every compiled kernel, so dead trees are freed in batches
    of DEAD_TREE_BATCH, when a new group is allocated, not one by one as objects die (or
    sooner, when the live ones reach TREE_BUDGET; then the releases registered with
    `on_tree_shortage`, the pool's free lists, give theirs up too: past TREE_LIMIT Taichi
    crashes, so a group still beyond the budget is refused with a RuntimeError instead).
    Create every field through `scalar` / `vector`, then call `finalize(owner)` before use.
    """

    def __init__(self):
        """Raises RuntimeError, naming the cause, when Taichi has no tree left to give."""
        if len(_dead_trees) >= DEAD_TREE_BATCH or tree_count() >= TREE_BUDGET:
            free_dead_trees()
        if tree_count() >= TREE_BUDGET and _shortage_releases:
            gc.collect()                  # dropped simulations give their sets back first
            for weak in list(_shortage_releases):
                release = weak()
                if release is not None:
                    release()
            gc.collect()                  # what they held, cycles included, dies now
            free_dead_trees()
        if tree_count() >= TREE_BUDGET:
            raise RuntimeError(
                f"Taichi holds {tree_count()} live field trees, the most ti_cloth uses of its "
                f"{TREE_LIMIT}: too many simulations, models or renderers alive at once (each "
                "holds a few); drop some, or run them in separate processes")
        self._builder = ti.FieldsBuilder()

    def scalar(self, dtype, shape):
        """A scalar field of `shape` (an int, or () for a single value)."""
        return self._place(ti.field(dtype), shape)

    def vector(self, n: int, dtype, shape):
        """A field of n-vectors of `shape` (an int)."""
        return self._place(ti.Vector.field(n, dtype), shape)

    def _place(self, field, shape):
        if shape == ():
            self._builder.place(field)
        else:
            self._builder.dense(ti.i, shape).place(field)
        return field

    def finalize(self, owner) -> None:
        """Allocate the fields; their tree is freed some time after `owner` is collected."""
        tree = self._builder.finalize()
        global _tree_count
        _tree_count += 1
        finalizer = weakref.finalize(owner, _dead_trees.append, (tree, _generation))
        finalizer.atexit = False


TREE_LIMIT = 512       # SNode trees a Taichi 1.7 program can hold (beyond it: a crash)
TREE_BUDGET = 448      # trees ti_cloth allocates before it must free dead ones or refuse
DEAD_TREE_BATCH = 192
_dead_trees: list = []
_shortage_releases: list = []   # weak methods: objects holding trees they can give up


def on_tree_shortage(release) -> None:
    """Call `release` (a bound method, held weakly) when the live trees reach TREE_BUDGET,
    before a new group is refused: it drops the objects it keeps that hold trees."""
    _shortage_releases[:] = [r for r in _shortage_releases if r() is not None]
    _shortage_releases.append(weakref.WeakMethod(release))


def tree_count() -> int:
    """Field trees of this runtime allocated by FieldGroup and not yet destroyed."""
    return _tree_count


def free_dead_trees() -> None:
    """Free the trees of collected objects now (those of an earlier runtime are already gone)."""
    global _tree_count
    dead, _dead_trees[:] = list(_dead_trees), []
    for tree, generation in dead:
        if generation == _generation:
            tree.destroy()
            _tree_count -= 1
