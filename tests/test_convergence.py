"""Observed order of accuracy: halve dt repeatedly on a small cloth (f64, smooth conservative
forces) and compare positions at a fixed time with an rk4 reference at a much smaller step."""

import numpy as np
import pytest
from helpers import report

import ti_cloth as tc

# Smooth, undamped forces (velocity-dependent forces make Verlet first order). The error is
# C h^p (1 + O(h)), so log2 of successive error ratios approaches p as h shrinks; at the finest
# pair below (h0/4 -> h0/8, w h <= 0.13) the next term still shifts it by up to 0.11 (measured:
# rk4 4.29, 4.18, 4.10 over the three pairs; implicit Euler 0.87, 0.94, 0.975 and XPBD the same
# (backward Euler's second term is larger); explicit 1.014, symplectic 1.007, Verlet 2.0003).
# The tolerance is about twice that shift. The rk4 reference at h0/64 is ~1e-13 m off.
ORDERS = {"explicit_euler": 1, "symplectic_euler": 1, "implicit_euler": 1, "xpbd": 1, "verlet": 2,
          "rk4": 4, "implicit_midpoint": 2, "stabilized_rk2": 2}
# solved to convergence, so the error measured is the method's, not the solver's
SPECS = {"implicit_euler": lambda: tc.ImplicitEuler(tolerance=1e-12),
         "xpbd": lambda: tc.XPBD(iterations=50),
         "implicit_midpoint": lambda: tc.ImplicitMidpoint(tolerance=1e-14, cg_tolerance=1e-13)}
TOLERANCE = 0.2


def cloth():
    material = tc.Material(density=0.2, stretch=tc.SpringParams(50.0), shear=tc.SpringParams(5.0),
                           bend=tc.SpringParams(0.5))
    return tc.Cloth(tc.grid_mesh(5, 5, size=(0.4, 0.4), plane="xz"), material, pinned=[0, 4])


def positions_at(sim, dt, steps, start):
    """Positions after `steps` steps of dt from `start` at rest (restart keeps the kernels)."""
    sim.restart(dt)
    sim.set_positions(start)
    sim.step(steps)
    return sim.positions()


@pytest.mark.parametrize("integrator", sorted(ORDERS))
def test_observed_order_of_accuracy(f64, integrator):
    body = cloth()
    start = body.particle_position + np.random.default_rng(2).normal(scale=0.01, size=(25, 3))
    start[body.pinned] = body.particle_position[body.pinned]
    h0 = 0.25 * tc.stable_dt(body, "symplectic_euler")
    steps0 = 8
    reference = positions_at(tc.Simulation(body, integrator="rk4"), h0 / 64, steps0 * 64, start)
    sim = tc.Simulation(body, integrator=SPECS[integrator]() if integrator in SPECS else integrator)
    errors = [np.abs(positions_at(sim, h0 / 2 ** k, steps0 * 2 ** k, start) - reference).max()
              for k in range(4)]
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    report(f"{integrator} errors [m] at h0/1..8 (h0 = {h0:.3g} s)", errors, "")
    report(f"{integrator} observed orders", orders, ORDERS[integrator])
    assert abs(orders[-1] - ORDERS[integrator]) < TOLERANCE
    assert errors[-1] > 1e3 * np.finfo(float).eps * np.abs(reference).max(), "error must not be rounding"
