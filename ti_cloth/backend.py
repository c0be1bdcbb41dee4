"""Taichi runtime set-up: architecture, floating-point precision and thread count.

`init` is the only place ti_cloth calls ``ti.init``; importing the package never does.
Every Taichi field ti_cloth allocates uses the precision chosen here, and Taichi's
``default_fp`` is set to match so float literals inside kernels have the same type.
Calling `init` again resets Taichi: fields and simulations created before become invalid.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import taichi as ti

ARCHS = {"cpu": "cpu", "cuda": "cuda", "vulkan": "vulkan", "gpu": "gpu"}
PRECISIONS = {"f32": ti.f32, "f64": ti.f64}
NUMPY_PRECISIONS = {"f32": np.float32, "f64": np.float64}


@dataclass(frozen=True)
class BackendConfig:
    """What `init` was called with."""

    arch: str
    precision: str
    threads: int | None


_config: BackendConfig | None = None


def init(arch: str = "cpu", precision: str = "f32", threads: int | None = None,
         debug: bool = False) -> BackendConfig:
    """Start (or restart) the Taichi runtime.

    arch: "cpu" | "cuda" | "vulkan" | "gpu" (first GPU backend found, else CPU).
    precision: "f32" | "f64", the float type of every particle and spring field.
    threads: CPU worker threads (None: all cores).
    debug: Taichi's bounds-checking debug mode (slow).
    """
    global _config
    if arch not in ARCHS:
        raise ValueError(f"arch must be one of {sorted(ARCHS)}, got {arch!r}")
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {sorted(PRECISIONS)}, got {precision!r}")
    if threads is not None and (not isinstance(threads, int) or threads < 1):
        raise ValueError(f"threads must be a positive int or None, got {threads!r}")
    options = dict(arch=getattr(ti, ARCHS[arch]), default_fp=PRECISIONS[precision],
                   default_ip=ti.i32, random_seed=0, debug=debug, log_level=ti.WARN)
    if threads is not None:
        options["cpu_max_num_threads"] = threads
    ti.init(**options)
    _config = BackendConfig(arch=arch, precision=precision, threads=threads)
    return _config


def config() -> BackendConfig:
    """The active configuration; raises if `init` has not been called."""
    if _config is None:
        raise RuntimeError("ti_cloth is not initialised: call ti_cloth.init(arch=..., precision=...) first")
    return _config


def real():
    """The Taichi float type of the active precision (ti.f32 or ti.f64)."""
    return PRECISIONS[config().precision]


def numpy_real():
    """The numpy float type matching `real()`."""
    return NUMPY_PRECISIONS[config().precision]
