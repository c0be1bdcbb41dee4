"""Taichi's front end memoised (runtime/frontend.py): the same locations and source as Taichi's
own, and compile errors that still point at the line."""

import inspect

import numpy as np
import pytest
import taichi as ti
from helpers import use
from taichi.lang import kernel_impl
from taichi.lang.ast import ast_transformer_utils

import ti_cloth as tc
from ti_cloth.contact.broad_phase import contact_pairs
from ti_cloth.energies import membrane
from ti_cloth.runtime import backend, frontend


def test_every_location_of_a_fabric_step_is_taichis_own(f64, monkeypatch):
    """A Fabric step of a structure no other test builds (so its kernels go through the front
    end here: a warm offline cache still runs it), in xpbd: every debug
    location the memo returns equals Taichi's own get_pos_info for the same node, and most
    of them came from the memo."""
    assert frontend.installed()
    memoised = ast_transformer_utils.ASTTransformerContext.get_pos_info
    calls, differing = [], []

    def checked(context, node):
        mine = memoised(context, node)
        if mine != frontend.original("get_pos_info")(context, node):
            differing.append((context.file, node.lineno, mine))
        calls.append(1)
        return mine

    monkeypatch.setattr(ast_transformer_utils.ASTTransformerContext, "get_pos_info", checked)
    before = frontend.location_count()
    cloth = tc.Cloth(tc.grid_mesh(5, 7, (0.2, 0.3)), tc.Fabric.preset("denim", compression=0.5),
                     pinned=[0, 4])
    for integrator in ("xpbd",):
        sim = tc.Simulation(cloth, integrator=integrator, dt=1 / 240)
        sim.step(2)
        assert np.isfinite(sim.positions()).all()
    new = frontend.location_count() - before
    print(f"{len(calls)} locations asked for, {new} new to the memo")
    assert len(calls) > 1000, "the kernels went through the front end"
    assert differing == []
    assert new < len(calls) / 3, "most locations come from the memo"


def test_the_memoised_source_is_taichis_own(f64):
    """The source the front end reads for a ti.func and a kernel is what Taichi's own reader
    returns, and a second read gives the same object (memoised)."""
    for function in (membrane.gauge, contact_pairs.list_pairs):
        function = inspect.unwrap(function)
        lines = kernel_impl.getsourcelines(function)
        assert lines == frontend.original("getsourcelines")(function)
        assert kernel_impl.getsourcelines(function) is lines
        assert kernel_impl.getsourcefile(function) == frontend.original("getsourcefile")(function)


def test_a_compile_error_still_names_the_line_with_carets(f64):
    """A kernel naming an undefined variable: Taichi's error names this file, the line and
    the function, and marks the name with carets, as without the memo."""
    @ti.kernel
    def broken() -> ti.f64:
        return undefined_name * 2.0     # noqa: F821

    line = inspect.getsourcelines(broken)[1] + 2
    with pytest.raises(ti.TaichiCompilationError) as raised:
        broken()
    message = str(raised.value)
    assert f'line {line}, in broken' in message and __file__ in message
    assert "undefined_name * 2.0" in message
    assert "^" * len("undefined_name") in message


@pytest.mark.reinitialises
def test_the_offline_cache_keeps_a_suites_kernels_unless_the_user_says(monkeypatch):
    """Taichi's offline cache kept 100 MB, least recently used out at each init, where the
    suite's kernels come to about 380 MB: a rerun compiled most of them again. init asks
    Taichi for backend.OFFLINE_CACHE_BYTES, and leaves it to Taichi's own environment
    variable where a user set it."""
    asked = []
    real = ti.init
    monkeypatch.setattr(ti, "init", lambda **options: (asked.append(options), real(**options)))
    try:
        tc.init(arch="cpu", precision="f32")
        monkeypatch.setenv("TI_OFFLINE_CACHE_MAX_SIZE_OF_FILES", str(50 * 2**20))
        tc.init(arch="cpu", precision="f32")
    finally:
        monkeypatch.delenv("TI_OFFLINE_CACHE_MAX_SIZE_OF_FILES", raising=False)
        use("f64")              # another precision: the worker's runtime starts again
    assert backend.OFFLINE_CACHE_BYTES >= 400 * 2**20
    assert asked[0]["offline_cache_max_size_of_files"] == backend.OFFLINE_CACHE_BYTES
    assert "offline_cache_max_size_of_files" not in asked[1]
