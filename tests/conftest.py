"""Tests run on the CPU. Most run in f64 so tolerances can follow the method, not rounding;
the `f32` fixture switches precision for the tests that are about f32 itself."""

import pytest

import ti_cloth as tc
from ti_cloth import backend


def use(precision: str) -> None:
    if backend._config is None or backend._config.precision != precision:
        tc.init(arch="cpu", precision=precision)


@pytest.fixture
def f64():
    use("f64")


@pytest.fixture
def f32():
    use("f32")


def report(label, got, expected):
    """Print got vs expected so a failure (and -s runs) show both."""
    print(f"{label}: got {got!r}, expected {expected!r}")
