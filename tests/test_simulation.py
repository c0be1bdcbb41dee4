"""Conservation, pins, handles, tearing, determinism, input errors and the divergence guard."""

import numpy as np
import pytest
from helpers import compiled, forget_compiled, report

import ti_cloth as tc
from ti_cloth.physics import tearing as tearing_module
from ti_cloth.runtime import backend

ALL = list(tc.INTEGRATORS)


def hanging_cloth(rows=8, cols=8, pinned=(56, 63), **material):
    soft = dict(density=0.2, stretch=tc.SpringParams(200.0, 0.2), shear=tc.SpringParams(20.0, 0.02),
                bend=tc.SpringParams(2.0, 0.002))
    return tc.Cloth(tc.grid_mesh(rows, cols, size=(0.5, 0.5)), tc.Material(**(soft | material)),
                    pinned=pinned)


def stable_step(cloth, integrator, fraction=0.5):
    limit = tc.stable_dt(cloth, integrator)
    return 1e-3 if np.isinf(limit) else fraction * limit


@pytest.mark.parametrize("integrator", ALL)
def test_pinned_particles_never_move(f64, integrator):
    cloth = hanging_cloth()
    sim = tc.Simulation(cloth, integrator=integrator, dt=stable_step(cloth, integrator))
    sim.step(int(0.05 / sim.dt))
    x = sim.positions()
    assert np.array_equal(x[cloth.pinned], cloth.particle_position[cloth.pinned])
    assert np.abs(x[~cloth.pinned] - cloth.particle_position[~cloth.pinned]).max() > 1e-5  # it moved


@pytest.mark.parametrize("integrator", ALL)
def test_cloth_at_rest_without_gravity_stays_at_rest(f64, integrator):
    cloth = hanging_cloth(pinned=())
    sim = tc.Simulation(cloth, integrator=integrator, dt=stable_step(cloth, integrator), gravity=(0, 0, 0))
    sim.step(500)
    # only rounding of rest lengths (1e-16 relative) can act: a bound of 1e-9 m over < 1 s
    drift = np.abs(sim.positions() - cloth.particle_position).max()
    report(f"{integrator} drift [m]", drift, "< 1e-9")
    assert drift < 1e-9


@pytest.mark.parametrize("integrator", ALL)
def test_momentum_conserved_without_gravity_or_pins(f64, integrator):
    cloth = hanging_cloth(pinned=(), damping="relative")
    rng = np.random.default_rng(3)
    # implicit Euler conserves momentum exactly only when its linear system is solved exactly:
    # CG to a relative residual of 1e-14 here (the default 1e-5 drifts by ~1e-7 relative)
    # (and Newton's solves of implicit midpoint and TR-BDF2 likewise)
    spec = {"implicit_euler": tc.ImplicitEuler(tolerance=1e-14, max_iterations=1000),
            "implicit_midpoint": tc.ImplicitMidpoint(tolerance=1e-14, cg_tolerance=1e-14),
            "tr_bdf2": tc.TRBDF2(tolerance=1e-14, cg_tolerance=1e-14)}.get(integrator, integrator)
    sim = tc.Simulation(cloth, integrator=spec, dt=stable_step(cloth, integrator, 0.3),
                        gravity=(0, 0, 0))
    sim.set_positions(cloth.particle_position + rng.normal(scale=0.003, size=(64, 3)))
    sim.set_velocities(rng.normal(scale=0.1, size=(64, 3)))
    m = cloth.particle_mass[:, None]
    p0 = (m * sim.velocities()).sum(axis=0)
    sim.step(200)
    p1 = (m * sim.velocities()).sum(axis=0)
    scale = (m * np.abs(sim.velocities())).sum()
    report(f"{integrator} momentum", p1, p0)
    np.testing.assert_allclose(p1, p0, atol=1e-12 * scale)


def test_handle_moves_its_particle_along_the_path(f64):
    cloth = hanging_cloth(pinned=(56,))
    path = lambda t: (0.0, 0.0, 0.2 * np.sin(3 * t))
    sim = tc.Simulation(cloth, integrator="symplectic_euler", dt=2e-4, handles=[tc.Handle([63], path)])
    expected = np.zeros(64, bool)
    expected[[56, 63]] = True
    assert np.array_equal(sim.pinned(), expected), "pins and held particles"
    for _ in range(5):
        sim.step(100)
        np.testing.assert_allclose(sim.positions()[63], cloth.particle_position[63] + path(sim.time),
                                   atol=1e-12)
    assert np.array_equal(sim.positions()[56], cloth.particle_position[56])


@pytest.mark.parametrize("integrator", ["symplectic_euler", "verlet"])
def test_a_released_particle_flies_on_with_the_velocity_it_had(f64, integrator):
    """A lone particle carried at u = (1, 0.5, 0) m/s and let go at T = 0.1 s: from then on
    both methods' discrete free flight, x_n = x_T + n u h + g h^2 n (n + 1) / 2, exactly
    (no jump in position or velocity)."""
    h, u, g = 1e-3, np.array([1.0, 0.5, 0.0]), np.array([0.0, -9.81, 0.0])
    body = tc.Cloth.from_particles([[0.0, 1.0, 0.0]], [0.05], np.zeros((0, 2), int))
    handle = tc.Handle([0], lambda t: u * t, release=0.1)
    sim = tc.Simulation(body, integrator=integrator, dt=h, handles=[handle])
    sim.step(100)
    x_release = sim.positions()[0]
    np.testing.assert_allclose(x_release, [0.1, 1.05, 0.0], atol=1e-14)
    assert not sim.pinned()[0], "let go"
    for n in (1, 2, 50):
        sim.step(n - (sim.step_count - 100))
        expected = x_release + n * u * h + g * h * h * n * (n + 1) / 2
        np.testing.assert_allclose(sim.positions()[0], expected, atol=1e-12)
    sim.restart()
    assert sim.pinned()[0], "held again after restart"


def test_a_released_corner_swings_back_under_gravity(f64):
    """The bottom-left corner of a sheet hung by its top corners is pulled 0.2 m out of the
    plane, held still, and let go at 1 s: it swings back through half of that within 0.4 s;
    held forever (release=None) it stays."""
    cloth = hanging_cloth()
    path = lambda t: (0.0, 0.0, 0.2 * min(t / 0.5, 1.0))
    runs = {}
    for release in (1.0, None):
        sim = tc.Simulation(cloth, integrator="symplectic_euler", dt=2e-4,
                            handles=[tc.Handle([0], path, release=release)])
        sim.step(5000)
        out = sim.positions()[0, 2] - cloth.particle_position[0, 2]
        sim.step(2000)
        runs[release] = (out, sim.positions()[0, 2] - cloth.particle_position[0, 2])
    report("corner out of plane at release, 0.4 s later [m]", runs, "0.2 -> < 0.1; held: 0.2")
    assert runs[1.0][0] == pytest.approx(0.2, abs=1e-12) and runs[1.0][1] < 0.1
    assert runs[None][1] == pytest.approx(0.2, abs=1e-12)


def test_tearing_removes_exactly_the_overstretched_springs(f64):
    cloth = hanging_cloth(pinned=())
    sim = tc.Simulation(cloth, integrator="symplectic_euler", dt=1e-6, gravity=(0, 0, 0), tearing=0.3)
    x = cloth.particle_position.copy()
    x[27] += (0.0, 0.0, 0.1)   # pull one particle off the sheet
    x[0] += (0.02, 0.0, 0.0)
    sim.set_positions(x)
    sim.step(1)
    p = sim.positions()
    i, j = cloth.spring_indices.T
    over = np.linalg.norm(p[i] - p[j], axis=1) > 1.3 * cloth.spring_rest_length
    report("torn", sim.torn_springs().tolist(), np.flatnonzero(over).tolist())
    assert over.sum() > 0
    assert np.array_equal(sim.torn_springs(), np.flatnonzero(over))
    assert sim.torn_count == over.sum()
    torn_edges = np.isin(cloth.triangle_edge_spring, np.flatnonzero(over)).any(axis=1)
    assert np.array_equal(sim.torn_triangles(), np.flatnonzero(torn_edges))
    sim.step(1)   # once torn a spring stays torn; nothing else is over-stretched yet
    assert np.array_equal(sim.torn_springs(), np.flatnonzero(over))
    assert np.array_equal(sim.spring_torn_step(), np.where(over, 0, -1)), "all tore in step 0"


def test_renamed_options_keep_working_with_a_deprecation_warning():
    with pytest.warns(DeprecationWarning, match="Tearing.strain"):
        old = tc.Tearing(stretch=0.3)
    assert old == tc.Tearing(0.3) == tc.Tearing(strain=0.3)
    with pytest.warns(DeprecationWarning, match="Tearing.strain"):
        assert old.stretch == 0.3
    with pytest.warns(DeprecationWarning, match="tearable"):
        assert tc.ForceSettings(tearable=True).tearing is True


def test_without_tearing_nothing_is_removed_and_the_kernel_never_runs(f64):
    forget_compiled(tearing_module.tear_spring)
    cloth = hanging_cloth(pinned=())
    sim = tc.Simulation(cloth, integrator="symplectic_euler", dt=1e-6, gravity=(0, 0, 0))
    x = cloth.particle_position.copy()
    x[27] += (0.0, 0.0, 0.1)
    sim.set_positions(x)
    sim.step(3)
    assert sim.torn_count == 0
    assert not compiled(tearing_module.tear_spring)


@pytest.mark.parametrize("integrator", ALL)
def test_two_runs_are_bit_identical(f32, integrator):
    cloth = hanging_cloth(16, 16, pinned=(240, 255))
    runs = []
    for _ in range(2):
        sim = tc.Simulation(cloth, integrator=integrator, dt=stable_step(cloth, integrator), drag=0.1)
        sim.step(200)
        runs.append(sim.positions())
        del sim              # the rerun gets its fields and compiled kernels (pool.py)
    assert np.array_equal(runs[0], runs[1])


def test_unstable_step_raises_divergence_with_step_and_stable_dt(f64):
    cloth = hanging_cloth()
    limit = tc.stable_dt(cloth, "symplectic_euler")
    sim = tc.Simulation(cloth, integrator="symplectic_euler", dt=20 * limit)
    with pytest.raises(tc.SimulationDiverged) as err:
        sim.step(2000)
    print(err.value)
    assert 0 <= err.value.step < 2000 and err.value.time == pytest.approx((err.value.step + 1) * sim.dt)
    assert err.value.stable_dt == pytest.approx(limit)
    assert f"step {err.value.step}" in str(err.value) and "stable dt" in str(err.value)
    with pytest.raises(tc.SimulationDiverged):
        sim.step(1)


@pytest.mark.parametrize("kwargs, field", [
    (dict(dt=0.0), "dt"), (dict(dt=-1e-3), "dt"), (dict(dt=float("nan")), "dt"),
    (dict(integrator="leapfrog"), "integrator"), (dict(gravity=(0, -9.8)), "gravity.shape"),
    (dict(drag=-1.0), "drag"), (dict(tearing=-0.1), "Tearing.strain"),
    (dict(handles=[tc.Handle([99], lambda t: (0, 0, 0))]), "Handle.particles"),
    (dict(position_limit=0.0), "position_limit"),
])
def test_simulation_rejects_bad_input(f64, kwargs, field):
    with pytest.raises(ValueError, match=field) as err:
        tc.Simulation(hanging_cloth(), **kwargs)
    print(err.value)


@pytest.mark.parametrize("make, field", [
    (lambda: tc.Verlet(damping=1.0), "Verlet.damping"), (lambda: tc.PBD(iterations=0), "PBD.iterations"),
    (lambda: tc.PBD(stiffness={"stretch": 2.0}), "PBD.stiffness"),
    (lambda: tc.PBD(stiffness={"twist": 1.0}), "PBD.stiffness keys"),
    (lambda: tc.init(precision="f16"), "precision"), (lambda: tc.init(arch="tpu"), "arch"),
])
def test_integrator_and_backend_options_validated(make, field):
    with pytest.raises(ValueError, match=field):
        make()


def test_energy_reports_each_spring_kind(f64):
    cloth = hanging_cloth(pinned=())
    sim = tc.Simulation(cloth, gravity=(0, -9.81, 0))
    x = cloth.particle_position * np.array([1.1, 1.0, 1.0])  # stretch along x by 10 %
    sim.set_positions(x)
    e = sim.energy()
    i, j = cloth.spring_indices.T
    dl = np.linalg.norm(x[i] - x[j], axis=1) - cloth.spring_rest_length
    for kind in tc.SpringKind:
        sel = cloth.spring_kind == kind
        expected = 0.5 * np.sum(cloth.spring_stiffness[sel] * dl[sel] ** 2)
        assert e[f"spring_{kind.name.lower()}"] == pytest.approx(expected, rel=1e-12)
    assert e["gravity"] == pytest.approx(9.81 * np.sum(cloth.particle_mass * x[:, 1]), rel=1e-12)
    assert e["kinetic"] == 0.0


@pytest.mark.slow
def test_simulations_free_their_taichi_fields_when_dropped(f64):
    """Each Model/State/feature allocates its fields in one SNode tree, freed (in batches)
    after the object is collected: creating simulation after simulation must not use up
    Taichi's 512 trees (before, a process crashed after about 40 simulations)."""
    import gc

    sizes = []
    for _ in range(4):
        sim = tc.Simulation(tc.Cloth(tc.grid_mesh(4, 4), tc.Material(), pinned=[0]), dt=1e-4,
                            integrator="rk4", colliders=[tc.Plane(point=(0, -1, 0))])
        sim.step(1)
        del sim
        gc.collect()
        backend.free_dead_trees()
        sizes.append(backend.tree_count())
    report("SNode trees in use after each simulation", sizes, "constant")
    assert sizes[-1] == sizes[1]


def test_options_by_position_still_work_for_a_release_with_a_warning(f64):
    """Simulation's options are keyword-only; the positional form of the last release gives
    the same simulation, with a DeprecationWarning, and an option given twice is refused."""
    cloth = tc.Cloth(tc.grid_mesh(4, 4), tc.Material(), pinned=[0])
    keyword = tc.Simulation(cloth, integrator="verlet", dt=2e-4, gravity=(0.0, -1.0, 0.0))
    with pytest.warns(DeprecationWarning, match="keyword-only"):
        positional = tc.Simulation(cloth, "verlet", 2e-4, (0.0, -1.0, 0.0))
    assert positional.integrator == keyword.integrator and positional.dt == keyword.dt
    keyword.step(20)
    positional.step(20)
    np.testing.assert_array_equal(positional.positions(), keyword.positions())
    with pytest.warns(DeprecationWarning), pytest.raises(TypeError, match="'dt'"):
        tc.Simulation(cloth, "verlet", 2e-4, dt=1e-4)


@pytest.mark.parametrize("make, keywords", [
    (tc.StrainLimit, dict(max_strain=0.2, passes=3)),
    (tc.SelfCollision, dict(thickness=0.01, friction=0.3)),
    (tc.Sewing, dict(speed=0.25)),
    (tc.Fabric, dict(density=0.3, stretch=(2e3, 1e3))),
    (tc.Material, dict(density=0.4)),
])
def test_settings_are_keyword_only_and_positional_values_warn_for_a_release(make, keywords):
    """A settings object is made by keyword; values by position (the last release's form)
    give the same object with a DeprecationWarning naming the keywords, and a value given
    both ways, or one too many, is a TypeError."""
    names = list(keywords)
    with pytest.warns(DeprecationWarning, match=f"{make.__name__}\\({names[0]}=\\.\\.\\."):
        positional = make(*keywords.values())
    assert positional == make(**keywords)
    with pytest.raises(TypeError, match=f"'{names[0]}' both"):
        make(keywords[names[0]], **{names[0]: keywords[names[0]]})
    with pytest.raises(TypeError, match="at most"):
        make(*range(50))
