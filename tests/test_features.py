"""Model only what a scene requires: optional features are compile-time switches, so a scene
that does not use one never compiles nor launches its kernels (benchmarks/feature_cost.py
measures what that saves)."""

import numpy as np
import pytest
from helpers import compiled, forget_compiled

import ti_cloth as tc
from ti_cloth.contact.broad_phase import contact_pairs
from ti_cloth.contact.colliders.collision import resolve
from ti_cloth.energies import springs
from ti_cloth.integrators import rk4, xpbd
from ti_cloth.physics import handles, strain_limit, tearing, wind
from ti_cloth.state import copy_positions

OPTIONAL = {
    "wind": wind.wind_on_triangle, "collisions": resolve,
    "collision snapshot": copy_positions, "relaxation": strain_limit.relax_stretched,
    "strain-limit velocity": strain_limit.follow_velocity, "tearing": tearing.tear_spring,
    "handles": handles.move_held, "xpbd": springs.xpbd_update,
    "xpbd prediction": xpbd.xpbd_predict, "implicit solve": springs.linearise_spring,
    "rk4 stages": rk4.rk4_stage, "self-collision": contact_pairs.list_pairs,
}


def minimal_cloth(n=8):
    """Gravity and stretch springs only."""
    full = tc.Cloth(tc.grid_mesh(n, n, plane="xz"), tc.Material())
    stretch = full.spring_indices[full.spring_kind == tc.SpringKind.STRETCH]
    return tc.Cloth(tc.grid_mesh(n, n, plane="xz"), tc.Material(), pinned=[0, n - 1],
                    springs={tc.SpringKind.STRETCH: stretch})


def full_simulation(integrator, n=8):
    cloth = tc.Cloth(tc.grid_mesh(n, n, plane="xz"), tc.Material(), pinned=[0, n - 1])
    return tc.Simulation(
        cloth, integrator=integrator, dt=1e-4, drag=0.2, tearing=0.5,
        wind=tc.Wind(velocity=(1.0, 0.0, 0.5), turbulence=0.5),
        handles=[tc.Handle([n * n - 1], tc.Oscillation(amplitude=(0.0, 0.05, 0.0), frequency=1.0))],
        colliders=[tc.Sphere(centre=(0.5, -0.3, 0.5), radius=0.2)], strain_limit=tc.StrainLimit(max_strain=0.1),
        self_collision=tc.SelfCollision(thickness=0.01))


@pytest.fixture
def fresh_kernels():
    forget_compiled(*OPTIONAL.values())


def compiled_features():
    return {name for name, kernel in OPTIONAL.items() if compiled(kernel)}


def test_minimal_scene_compiles_no_optional_kernel(f64, fresh_kernels):
    cloth = minimal_cloth()
    assert set(cloth.spring_kind) == {tc.SpringKind.STRETCH}
    sim = tc.Simulation(cloth, integrator="symplectic_euler", dt=1e-4)
    sim.step(20)
    assert np.abs(sim.positions() - cloth.particle_position).max() > 1e-5, "it ran"
    assert compiled_features() == set()


@pytest.mark.parametrize("integrator, own", [("symplectic_euler", set()), ("rk4", {"rk4 stages"}),
                                            ("implicit_euler", {"implicit solve"}),
                                            ("xpbd", {"xpbd", "xpbd prediction"})])
def test_each_feature_compiles_its_kernels_only_when_used(f64, fresh_kernels, integrator, own):
    sim = full_simulation(integrator)
    sim.step(5)
    features = {"wind", "collisions", "collision snapshot", "relaxation", "strain-limit velocity",
                "tearing", "handles", "self-collision"}
    assert compiled_features() == features | own
