"""A Fabric that resists compression less than tension (Fabric.compression, energies/membrane.py):
its forces against its energy and against the plane-stress law's closed form, shear left as it
is, every integrator's equilibrium against a closed form, and the implicit solvers' Newton on
a compressed sheet."""

import warnings

import numpy as np
import pytest
from helpers import central_gradient
from scipy.optimize import brentq

import ti_cloth as tc
from ti_cloth.energies.membrane import BUCKLING
from ti_cloth.physics.forces import compute_forces, energies

SOFT = 0.05


def give_way(strain: float, compression: float) -> tuple[float, float]:
    """(phi(E), phi'(E)) of energies/membrane.py's module doc, written again here."""
    if strain >= 0:
        return strain, 1.0
    r, fade = np.sqrt(compression), np.exp(strain / BUCKLING)
    return r * strain + (1 - r) * BUCKLING * (fade - 1), r + (1 - r) * fade


def forces_at(cloth: tc.Cloth, x: np.ndarray) -> np.ndarray:
    sim = tc.Simulation(cloth, gravity=(0.0, 0.0, 0.0))
    sim.set_positions(x)
    compute_forces(sim.model, sim.state, sim.forces)
    return sim.state.particle_force.to_numpy()


def test_the_softened_forces_are_the_gradient_of_their_energy(f64):
    """Against central differences of the float64 energy, on a sheet whose triangles are
    shortened along the warp, the weft, both and neither (a random deformation, Poisson
    coupling on): the difference is the differences' own error."""
    fabric = tc.Fabric(stretch=(100.0, 300.0), shear=20.0, bending=0.0, damping=0.0,
                       poisson=0.3, compression=SOFT)
    mesh = tc.grid_mesh(5, 6, (0.1, 0.12), plane="xz")
    cloth = tc.Cloth(mesh, fabric)
    x = mesh.vertices + 0.004 * np.random.default_rng(0).normal(size=mesh.vertices.shape)
    f = np.einsum("tci,tcj->tij", x[cloth.face_indices], cloth.face_gradient)
    e11, e22 = 0.5 * (np.sum(f[:, :, 0] ** 2, 1) - 1), 0.5 * (np.sum(f[:, :, 1] ** 2, 1) - 1)
    for warp_short in (True, False):
        for weft_short in (True, False):
            assert np.any(((e11 < 0) == warp_short) & ((e22 < 0) == weft_short))
    h = 1e-7

    def energy(y):
        return energies(cloth, y, np.zeros_like(y), (0.0, 0.0, 0.0))["membrane"]

    gradient = central_gradient(energy, x, h)
    force = forces_at(cloth, x)
    np.testing.assert_allclose(force, -gradient, atol=1e-6 * np.abs(gradient).max())
    stiff = forces_at(tc.Cloth(mesh, tc.Fabric(stretch=(100.0, 300.0), shear=20.0, bending=0.0,
                                              damping=0.0, poisson=0.3)), x)
    assert np.abs(stiff - force).max() > 0.05 * np.abs(force).max()     # softened, it differs


@pytest.mark.parametrize("e11", [-0.04, -0.002, 0.02])
def test_a_sheet_shortened_along_its_warp_pushes_back_by_the_softened_law(f64, e11):
    """A homogeneous strain E11 along the warp (the weft held): the edges feel the traction
    F11 S11 per rest width, S11 = phi'(E11) C11 phi(E11) (C11 E11 pulled; pushed well past
    the buckling strain b, compression x C11 E11 and an offset of (1 - r) b / (r |E11|),
    8.7 % at 4 %), and S22 = C12 phi(E11) across; the interior nothing (test_fabric's
    homogeneous stretch, shortened)."""
    fabric = tc.Fabric(stretch=(400.0, 100.0), shear=30.0, poisson=0.3, bending=0.0,
                       damping=0.0, compression=SOFT)
    rows, cols = 7, 9
    mesh = tc.grid_mesh(rows, cols, (0.4, 0.3), plane="xy")
    stretch = np.sqrt(1 + 2 * e11)
    force = forces_at(tc.Cloth(mesh, fabric), mesh.vertices * [stretch, 1.0, 1.0])
    c11, c12, _, _ = fabric.membrane
    u, slope = give_way(e11, SOFT)
    traction = stretch * slope * c11 * u
    across = c12 * u
    if e11 == -0.04:
        assert traction == pytest.approx(SOFT * c11 * e11 * stretch, rel=0.1)
    c = np.arange(rows * cols) % cols
    r = np.arange(rows * cols) // cols
    inside = (c > 0) & (c < cols - 1) & (r > 0) & (r < rows - 1)
    np.testing.assert_allclose(force[inside], 0.0, atol=1e-10 * abs(traction))
    np.testing.assert_allclose(force[c == cols - 1, 0].sum(), -traction * 0.3, rtol=1e-10)
    np.testing.assert_allclose(force[r == rows - 1, 1].sum(), -across * 0.4, rtol=1e-9)


def test_shear_is_not_softened(f64):
    """A simple shear (the warp kept, the weft turned): the same forces as the sheet that
    resists compression fully. (A split by principal stresses would soften shear by about
    half: a shear's principal stresses are +-C33 gamma.)"""
    mesh = tc.grid_mesh(5, 6, (0.1, 0.12), plane="xy")
    x = mesh.vertices + np.outer(0.2 * mesh.vertices[:, 1], [1.0, 0.0, 0.0])
    fabric = dict(stretch=(100.0, 300.0), shear=20.0, bending=0.0, damping=0.0)
    soft = forces_at(tc.Cloth(mesh, tc.Fabric(compression=SOFT, **fabric)), x)
    stiff = forces_at(tc.Cloth(mesh, tc.Fabric(**fabric)), x)
    assert np.abs(stiff).max() > 0.1
    np.testing.assert_array_equal(soft, stiff)


L = 0.1              # the triangle's legs [m]
PUSH = -641.0        # gravity along -x [m/s^2]: shortens the warp by about 10 % at SOFT


def pushed_triangle(compression: float) -> tc.Cloth:
    """One right triangle in the xy plane, the warp along x, its two corners at x = 0
    pinned: gravity along -x pushes the third along its warp edge."""
    fabric = tc.Fabric(density=0.2, stretch=1000.0, shear=100.0, bending=0.0, damping=1e-3,
                       compression=compression)
    mesh = tc.Mesh(np.array([[0.0, 0.0, 0.0], [L, 0.0, 0.0], [0.0, L, 0.0]]),
                   np.array([[0, 1, 2]]))
    return tc.Cloth(mesh, fabric, pinned=[0, 2], warp=(1.0, 0.0, 0.0))


def pushed_ratio(cloth: tc.Cloth, compression: float) -> float:
    """The free corner's x / L at rest: F = diag(l, 1), E11 = (l^2 - 1) / 2, and its force
    -A S11 F11 / L, S11 = phi'(E11) C11 phi(E11), balances m g (the root on the branch that
    starts at l = 1)."""
    area, m, c11 = L * L / 2, cloth.particle_mass[1], cloth.face_moduli[0, 0]

    def balance(ratio):
        u, slope = give_way(0.5 * (ratio * ratio - 1), compression)
        return area * slope * c11 * u * ratio / L - m * PUSH

    return brentq(balance, 0.8, 1.0, xtol=1e-14)


def settled_ratio(cloth: tc.Cloth, integrator, dt) -> float:
    sim = tc.Simulation(cloth, integrator=integrator, dt=dt, gravity=(PUSH, 0.0, 0.0),
                        drag=20.0)
    sim.step(int(np.ceil(1.0 / sim.dt)))
    x = sim.positions()
    assert np.all(x[1, 1:] == 0.0)                 # no force across the warp, none out of plane
    return x[1, 0] / L


def test_every_integrator_settles_a_pushed_triangle_at_the_closed_form(f64):
    """Symplectic Euler, implicit Euler and TR-BDF2 settle where the closed form puts the
    corner (the settling's tolerance); XPBD O(h) from it, closer at half the step (its
    rest state leaves out the constraint's gradient turning within a step: test_fabric's
    cantilever). The sheet that resists compression fully rests 10x closer to the rest
    length."""
    cloth = pushed_triangle(SOFT)
    expected = pushed_ratio(cloth, SOFT)
    stiff = pushed_ratio(cloth, 1.0)
    assert 0.89 < expected < 0.91 and stiff - expected > 0.09
    for integrator in ("symplectic_euler", "implicit_euler", "tr_bdf2"):
        assert abs(settled_ratio(cloth, integrator, "auto") - expected) < 1e-8, integrator
    errors = [abs(settled_ratio(cloth, "xpbd", dt) - expected) for dt in (1 / 480, 1 / 960)]
    assert errors[0] < 0.01 and errors[1] < errors[0] / 1.6


def compressed_sheet_solves(compression: float) -> tuple[int, int]:
    """(solves stopped at the cap, solves) of TR-BDF2 with the loose solves at 1/120 s over
    0.1 s of a 20² denim sheet (issue 53's, 0.5 m) started 3 % short each way, rippled 1 mm
    (benchmarks/compressed_cloth.py)."""
    n = 20
    fabric = tc.Fabric(density=0.324, stretch=5e3, shear=1e3, bending=1e-4,
                       compression=compression)
    cloth = tc.Cloth(tc.grid_mesh(n, n, (0.5, 0.5), plane="xz"), fabric, pinned=[0, n - 1])
    integrator = tc.TRBDF2(**tc.TRBDF2.presets["loose"])
    sim = tc.Simulation(cloth, integrator=integrator, dt=1 / 120)
    x0 = sim.positions()
    x = x0.mean(axis=0) + 0.97 * (x0 - x0.mean(axis=0))
    x[:, 1] += 1e-3 * np.sin(14 * np.pi * x0[:, 0]) * np.sin(10 * np.pi * x0[:, 2])
    sim.set_positions(x)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")              # the stalled solves' warning
        sim.step(12, plan="per stage")
    return integrator.unconverged_solves, 12 * integrator.solves


def test_large_steps_converge_on_a_compressed_sheet_that_softens_compression(f64):
    """A sheet started shorter than its rest length is a buckling problem: its compressive
    stress's negative geometric stiffness outweighs the inertia of a sub-step above about
    1 ms here, and Newton stalls in every solve (docs/integrators.md, "Compressed cloth").
    Resisting compression by 0.05 of the tension, TR-BDF2's solves converge in most steps."""
    stalled, solves = compressed_sheet_solves(1.0)
    assert stalled == solves
    stalled, solves = compressed_sheet_solves(SOFT)
    assert stalled <= solves // 3


def test_a_scene_reads_compression_and_a_bad_one_names_the_range(tmp_path):
    """Fabric.table() writes compression (when not 1) and a scene file reads it back; a value
    outside (0, 1] names the field and the range."""
    fabric = tc.Fabric.preset("denim", compression=0.1)
    assert "compression = 0.1" in fabric.table()
    assert "compression" not in tc.Fabric.preset("denim").table()
    scene = tmp_path / "scene.toml"
    scene.write_text("[simulation]\nintegrator = \"tr_bdf2\"\n\n[[bodies]]\ntype = \"grid\"\n"
                     "rows = 4\ncols = 4\n\n" + fabric.table())
    assert tc.load_scene(scene).bodies[0].material == fabric
    for value in (0.0, 1.5, float("nan")):
        with pytest.raises(ValueError, match=r"Fabric\.compression must be a finite number "
                                             r"in \[0\.0001, 1\]"):
            tc.Fabric(compression=value)
