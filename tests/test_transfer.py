"""Uploads (runtime/transfer.py) and the state's particle reads and writes: what arrives in
the fields against the arrays sent, a batch's order and timing against a kernel that reads
the fields, and how many kernels a simulation's build and its reads compile
(backend.compilations)."""

import numpy as np
import pytest
import taichi as ti
from helpers import forget_compiled

import ti_cloth as tc
from ti_cloth import state as state_module
from ti_cloth.runtime import backend, transfer


@backend.kernel
def _sum(values: ti.template(), scalar: ti.template()) -> ti.f64:
    """sum(values) + scalar[None], read by a kernel."""
    total = ti.f64(0.0)
    for i in range(values.shape[0]):
        total += values[i]
    return total + scalar[None]


def fields(n=5):
    return ti.field(ti.f64, n), ti.field(ti.f64, ())


def test_an_upload_fills_vector_scalar_and_0d_fields_with_the_values_rounded_to_their_type(f64):
    vectors, ints, scalar = ti.Vector.field(3, ti.f32, 4), ti.field(ti.i8, 6), ti.field(ti.f64, ())
    v = np.random.default_rng(0).normal(size=(4, 3))
    transfer.upload(((vectors, v), (ints, [1, -2, 3]), (scalar, 2.5)))
    np.testing.assert_array_equal(vectors.to_numpy(), v.astype(np.float32))
    np.testing.assert_array_equal(ints.to_numpy()[:3], [1, -2, 3])    # fewer rows: a prefix
    assert scalar[None] == 2.5


def test_a_batch_is_sent_before_a_kernel_reads_it_and_in_the_order_given(f64):
    values, scalar = fields()
    with transfer.batched():
        transfer.upload(((values, np.arange(5.0)),))
        transfer.upload(((scalar, 100.0),))
        assert values.to_numpy().sum() == 0.0            # not sent yet
        assert _sum(values, scalar) == 110.0             # a kernel launch sends it first
        transfer.upload(((values, np.ones(5)),))
        later = np.full(5, 2.0)
        transfer.upload(((values, later),))              # the same field again: the later wins
        later[:] = 3.0                                   # the values as they were uploaded
    np.testing.assert_array_equal(values.to_numpy(), np.full(5, 2.0))
    assert scalar[None] == 100.0


def test_a_batch_left_by_an_exception_sends_nothing_and_the_next_upload_goes_at_once(f64):
    values, _ = fields()
    with pytest.raises(RuntimeError), transfer.batched():
        transfer.upload(((values, np.ones(5)),))
        raise RuntimeError("a failed build")
    assert values.to_numpy().sum() == 0.0
    transfer.upload(((values, np.ones(5)),))
    assert values.to_numpy().sum() == 5.0


def test_a_build_compiles_one_upload_and_positions_and_velocities_share_a_kernel(f64):
    """A Fabric with strain limiting and the wind: its model, state, stages and tables in
    one upload kernel (an upload each compiled four), and one kernel reads (and one writes) both
    positions and velocities, whose values are those of the fields."""
    forget_compiled(transfer.copy_in, state_module.read_particles,
                    state_module.write_particles)
    mesh = tc.grid_mesh(5, 5, (0.2, 0.2))
    sim = tc.Simulation(tc.Cloth(mesh, tc.Fabric.preset("denim"), pinned=[20, 24]), dt=1e-4,
                        strain_limit=tc.StrainLimit(max_strain=0.1), wind=tc.Wind(velocity=(1.0, 0.0, 0.0)))
    assert backend.compilations(transfer.copy_in) == 1
    sim.step(3)
    np.testing.assert_array_equal(sim.positions(), sim.state.particle_position.to_numpy())
    np.testing.assert_array_equal(sim.velocities(), sim.state.particle_velocity.to_numpy())
    assert sim.positions().dtype == np.float64
    assert backend.compilations(state_module.read_particles) == 1
    x, v = sim.positions() + 0.01, sim.velocities() - 0.5
    sim.set_positions(x)
    sim.set_velocities(v)
    np.testing.assert_array_equal(sim.positions(), x)
    np.testing.assert_array_equal(sim.velocities(), v)
    assert backend.compilations(state_module.write_particles) == 1
    sim.restart()
    np.testing.assert_array_equal(sim.positions(), mesh.vertices)
    assert not sim.velocities().any()
