"""Simulations reuse the kernel arguments of collected ones (pool.py): a process that builds and
drops simulations stays flat in memory, and a reused set gives the bits a fresh one gives."""

import gc
import os
import warnings

import numpy as np
import pytest

import ti_cloth as tc
from ti_cloth import simulation, stepping
from ti_cloth.inputs import limits
from ti_cloth.runtime import backend, pool
from ti_cloth.runtime.pool import Pool


def resident_mb() -> float:
    """This process's resident set now [MB] (Linux)."""
    with open("/proc/self/statm") as f:
        pages = int(f.read().split()[1])
    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


DT = 5e-4      # below cloth()'s stable step (8.8e-4 s or more; a single step needs none)


def cloth(k=500.0, damping="axial", pinned=(0, 7), density=0.2):
    material = tc.Material(density=density, stretch=tc.SpringParams(k, 0.5), damping=damping)
    return tc.Cloth(tc.grid_mesh(8, 8, plane="xz"), material, pinned=list(pinned))


def every_stage(body, integrator="symplectic_euler", radius=0.3, strain=0.1, wind=(1.0, 0, 0)):
    return tc.Simulation(body, integrator=integrator, dt=DT,
                         colliders=[tc.Sphere(centre=(0.5, -0.4, 0.5), radius=radius)],
                         handles=[tc.Handle([63], lambda t: (0, 0.2 * t, 0))], tearing=2.0,
                         strain_limit=tc.StrainLimit(max_strain=strain),
                         wind=tc.Wind(velocity=wind))


@pytest.mark.parametrize("features", ["plain", "every stage"])
def test_building_and_dropping_simulations_does_not_grow_memory(f64, features):
    """The issue's loop: 30 simulations built, stepped and dropped. Before the pool each left
    its compiled kernels behind: +3.3 MB (plain) and +4.4 MB (every stage) per simulation,
    so +66 MB and +88 MB over the last 20. A flat process moves by allocator noise only."""
    integrators = ["symplectic_euler", "verlet", "xpbd"]
    body = cloth()
    rss = []
    for index in range(30):
        integrator = integrators[index % len(integrators)]
        sim = (tc.Simulation(body, integrator=integrator, dt=DT) if features == "plain"
               else every_stage(body, integrator))
        sim.step(5)
        sim.step(1)
        del sim
        gc.collect()
        rss.append(resident_mb())
    growth = rss[-1] - rss[9]
    print(f"resident {rss[9]:.0f} MB after 10 simulations, {rss[-1]:.0f} MB after 30")
    assert growth < 20, f"+{growth:.1f} MB over 20 simulations"


def test_a_dropped_simulations_kernels_serve_the_next_one(f64):
    """The runtime's count of the step kernel's compilations (backend.compilations: the
    distinct template arguments it was launched with, keyed as Taichi keys them) stays put."""
    body = cloth()
    backend.forget_compilations(stepping.advance_many)
    tc.Simulation(body, dt=DT).step(1)
    gc.collect()
    assert backend.compilations(stepping.advance_many) == 1
    for _ in range(5):
        tc.Simulation(body, dt=DT).step(1)
        gc.collect()
    assert backend.compilations(stepping.advance_many) == 1


BALL = tc.Sphere(centre=(0.5, -0.4, 0.5), radius=0.42)   # the sheet's middle starts in it
PAIRS = {
    "other stiffness, density and pins": (
        lambda: tc.Simulation(cloth(), dt=DT),
        lambda: tc.Simulation(cloth(k=900.0, density=0.3, pinned=(0,)), dt=DT)),
    "other integrator options": (
        lambda: tc.Simulation(cloth(), integrator=tc.Verlet(damping=0.0), dt=DT),
        lambda: tc.Simulation(cloth(k=700.0), integrator=tc.Verlet(damping=0.01), dt=DT)),
    "other colliders, stiffness and wind": (
        lambda: every_stage(cloth()),
        lambda: every_stage(cloth(k=800.0), radius=0.2, wind=(0, 0, 2.0))),
    # the strain limit is a constant of strain limiting's phases (StrainLimiter.structure)
    "other strain limit": (
        lambda: every_stage(cloth()),
        lambda: every_stage(cloth(), strain=0.05)),
    # a fused integrator's particles collide inside its step (stepping.TeamStages), xpbd's
    # after it: the second must not inherit the first's plan
    "a fused then a position-based integrator": (
        lambda: tc.Simulation(cloth(), dt=DT, colliders=[BALL]),
        lambda: tc.Simulation(cloth(), integrator="xpbd", dt=DT, colliders=[BALL])),
    # a solve's tolerances and caps and a position-based step's passes are read at run time
    # (Integrator.runtime_options): the second runs the first's kernels with its own values
    "other solve tolerances and caps": (
        lambda: tc.Simulation(cloth(), integrator=tc.ImplicitEuler(tolerance=1e-3,
                                                                   max_iterations=4), dt=1e-2),
        lambda: tc.Simulation(cloth(k=700.0), integrator=tc.ImplicitEuler(tolerance=1e-9),
                              dt=1e-2)),
    "other Newton settings": (
        lambda: tc.Simulation(cloth(), integrator=tc.ImplicitMidpoint(), dt=1e-2),
        lambda: tc.Simulation(cloth(), integrator=tc.ImplicitMidpoint(
            **tc.ImplicitMidpoint.presets["loose"]), dt=1e-2)),
    "other passes": (
        lambda: tc.Simulation(cloth(), integrator=tc.XPBD(iterations=2), dt=DT),
        lambda: tc.Simulation(cloth(), integrator=tc.XPBD(iterations=9), dt=DT)),
    "other damping model": (
        lambda: tc.Simulation(cloth(), dt=DT),
        lambda: tc.Simulation(cloth(damping="relative"), dt=DT)),
}


@pytest.mark.parametrize("pair", sorted(PAIRS))
def test_a_reused_set_gives_the_bits_of_a_fresh_one(f64, pair, monkeypatch):
    """The second simulation runs on what the first left (when its structure matches, else on
    new objects) and must give exactly what it gives built on fresh objects (an empty pool)."""
    first, second = PAIRS[pair]
    sim = first()
    sim.step(30)
    model = sim.model
    del sim
    gc.collect()
    reused = second()
    same_structure = pair not in ("other damping model", "other strain limit")
    assert (reused.model is model) == same_structure
    reused.step(40)
    monkeypatch.setattr(simulation, "POOL", Pool())
    fresh = second()
    assert fresh.model is not model
    fresh.step(40)
    assert np.abs(fresh.positions() - fresh.cloth.particle_position).max() > 1e-3, "it moved"
    np.testing.assert_array_equal(reused.positions(), fresh.positions())
    np.testing.assert_array_equal(reused.velocities(), fresh.velocities())


RUNTIME_OPTIONS = {   # two sets of each integrator's runtime_options
    "implicit_euler": (tc.ImplicitEuler, {"tolerance": 1e-2, "max_iterations": 3},
                       {"tolerance": 1e-9, "max_iterations": 400}),
    "implicit_midpoint": (tc.ImplicitMidpoint, {"tolerance": 1e-2, "most_newton": 1,
                                                "cg_tolerance": 0.5, "most_cg": 2}, {}),
    "tr_bdf2": (tc.TRBDF2, {"most_newton": 2, "most_cg": 5}, {"cg_tolerance": 1e-6}),
    "xpbd": (tc.XPBD, {"iterations": 1}, {"iterations": 12}),
    "pbd": (tc.PBD, {"iterations": 1}, {"iterations": 6}),
}


@pytest.mark.parametrize("name", sorted(RUNTIME_OPTIONS))
def test_a_solves_tolerances_caps_and_passes_compile_nothing(f64, name):
    """Integrators that differ only in their runtime_options (a solve's tolerances and caps,
    the passes of a position-based step) run one compiled step (stepping.advance_many's count
    of distinct template arguments stays 1), each with its own values: the runs differ,
    the first's values give its bits again after the second's, and each solve reports
    within its own caps. Before, every set of options compiled the step anew."""
    cls, first, second = RUNTIME_OPTIONS[name]
    body = cloth()
    backend.forget_compilations(stepping.advance_many)
    runs = []
    for options in (first, second, first):
        integrator = cls(**options)
        sim = tc.Simulation(body, integrator=integrator, dt=1 / 100)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)     # the capped solves' warning
            sim.step(8)
        runs.append(sim.positions())
        if hasattr(integrator, "last_iterations"):
            assert 0 < integrator.last_iterations <= integrator.max_iterations
        if hasattr(integrator, "last_newton"):
            assert 0 < integrator.last_newton <= integrator.settings.most_newton
        del sim
        gc.collect()
    assert backend.compilations(stepping.advance_many) == 1
    assert np.abs(runs[0] - runs[1]).max() > 1e-6, "the second's options changed its steps"
    np.testing.assert_array_equal(runs[2], runs[0])


def test_live_simulations_never_share_a_set(f64):
    """Two simulations alive at once each get their own State and Model, and step apart."""
    body = cloth()
    a, b = tc.Simulation(body, dt=DT), tc.Simulation(body, dt=DT)
    assert a.state is not b.state and a.model is not b.model
    a.step(20)
    np.testing.assert_array_equal(b.positions(), body.particle_position)


def test_a_users_integrator_is_the_one_its_simulation_steps_with(f64):
    """Two live simulations with equal integrators of their own: each steps with and reports
    on its user's object (an equal kept one only keeps the compiled kernels alive)."""
    body = cloth()
    first, second = tc.ImplicitEuler(), tc.ImplicitEuler()
    a = tc.Simulation(body, integrator=first, dt=DT)
    b = tc.Simulation(body, integrator=second, dt=DT)
    assert a.integrator is first and b.integrator is second
    b.step(3)
    assert second.last_iterations > 0 and first.last_iterations == 0
    a.step(1, plan="per stage")
    assert first.last_iterations > 0


@pytest.mark.reinitialises
def test_a_new_runtime_drops_the_pool(f64):
    body = cloth()
    sim = tc.Simulation(body, dt=DT)
    model = sim.model
    del sim
    gc.collect()
    tc.init(precision="f64")
    assert tc.Simulation(body, dt=DT).model is not model


def test_the_free_list_is_bounded_in_count_and_bytes(f64, monkeypatch):
    """A sweep over ever new structures keeps at most FREE_LIMIT sets of FREE_BYTES; a set
    bigger than FREE_BYTES goes back to the system when its simulation is dropped."""
    monkeypatch.setattr(simulation, "POOL", Pool())
    monkeypatch.setattr(pool, "FREE_LIMIT", 2)
    for rows in (4, 5, 6, 7):
        tc.Simulation(tc.Cloth(tc.grid_mesh(rows, 4), tc.Material()), dt=DT).step(1)
        gc.collect()
        assert simulation.POOL.free_count() == min(rows - 3, 2)
    body = tc.Cloth(tc.grid_mesh(4, 4), tc.Material())
    small = limits.memory_needed(body.particle_count, body.spring_count)
    monkeypatch.setattr(pool, "FREE_BYTES", small)
    tc.Simulation(body, dt=DT).step(1)
    gc.collect()
    assert simulation.POOL.free_count() == 1 and simulation.POOL.free_bytes() <= small
    tc.Simulation(tc.Cloth(tc.grid_mesh(9, 9), tc.Material()), dt=DT).step(1)
    gc.collect()
    assert simulation.POOL.free_bytes() <= small


def test_the_pool_gives_its_field_trees_to_a_live_simulation_that_needs_them(f64, monkeypatch):
    """Sets waiting in the free list hold field trees; when the live ones reach the budget the
    pool gives them up and the new simulation is built (without that it would be refused)."""
    simulation.POOL.release()          # only this test's sets wait
    monkeypatch.setattr(simulation, "POOL", Pool())
    gc.collect()
    backend.free_dead_trees()
    for rows in (4, 5, 6):             # three structures waiting, a model and a state each
        tc.Simulation(tc.Cloth(tc.grid_mesh(rows, 4), tc.Material()), dt=DT).step(1)
        gc.collect()
    assert simulation.POOL.free_count() == 3
    monkeypatch.setattr(backend, "TREE_BUDGET", backend.tree_count() + 2)
    alive = [tc.Simulation(cloth(), dt=DT) for _ in range(3)]     # 6 trees, room for 2
    assert len(alive) == 3 and simulation.POOL.free_count() == 0
    assert backend.tree_count() <= backend.TREE_BUDGET


def test_too_many_live_field_trees_is_refused_before_taichi_crashes(f64, monkeypatch):
    """Taichi 1.7 crashes past 512 field trees; ti_cloth refuses at its budget, naming why, and
    builds again once simulations are dropped (with no free list, their trees die with them)."""
    simulation.POOL.release()          # earlier tests' sets would give their trees up too
    monkeypatch.setattr(simulation, "POOL", Pool())
    monkeypatch.setattr(pool, "FREE_LIMIT", 0)
    gc.collect()
    backend.free_dead_trees()
    monkeypatch.setattr(backend, "TREE_BUDGET", backend.tree_count() + 4)
    body = cloth()
    alive = []
    with pytest.raises(RuntimeError, match="too many simulations"):
        for _ in range(5):
            alive.append(tc.Simulation(body, dt=DT))
    assert len(alive) == 2                      # a model and a state each
    alive.clear()
    gc.collect()
    tc.Simulation(body, dt=DT).step(1)        # the dead ones' trees are freed for it
