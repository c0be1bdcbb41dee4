"""The two-level preconditioner of the implicit solves (integrators/coarse.py): its coarse
matrix is P^T A P of the mass, the springs and the membrane exactly (with an aggregate per
particle, CG's iterations no longer grow with the stiffness, as Jacobi's do), it solves to the
same motion as Jacobi (pins, a pinned aggregate, seams), and it takes fewer CG iterations on
a denim sheet. Its bits across plans and thread counts: tests/test_stepping.py (the implicit
solvers' rows run it, the default; TR-BDF2 on a sewn garment among them)."""

import warnings

import numpy as np
import pytest

import ti_cloth as tc
from ti_cloth.integrators import coarse


def spring_sheet(n: int) -> tc.Cloth:
    material = tc.Material(density=0.3, stretch=tc.SpringParams(5e3, 0.0),
                           shear=tc.SpringParams(5e2, 0.0), bend=tc.SpringParams(50.0, 0.0))
    return tc.Cloth(tc.grid_mesh(n, n, (0.5, 0.5)), material, pinned=[0, n - 1])


def membrane_sheet(n: int) -> tc.Cloth:
    """A Fabric without bending: its hinges add nothing to A, so A_c can be all of it."""
    fabric = tc.Fabric(density=0.3, stretch=5e3, shear=1e3, bending=0.0, damping=0.0)
    return tc.Cloth(tc.grid_mesh(n, n, (0.5, 0.5)), fabric, pinned=[0, n - 1])


def strands(n: int) -> tc.Cloth:
    """Two hair strands of n segments: ghost particles and altitude springs (their blocks in
    A_c too)."""
    return tc.hair(2, n, 0.3, mass=1e-3, stretch=tc.SpringParams(2e3, 0.0),
                   bend=tc.SpringParams(20.0, 0.0))


def disturbed(cloth: tc.Cloth, seed: int = 3) -> np.ndarray:
    """The rest sheet with every free particle moved a few millimetres (every mode loaded)."""
    x = cloth.particle_position.copy()
    move = np.random.default_rng(seed).normal(scale=3e-3, size=x.shape)
    x[~cloth.pinned] += move[~cloth.pinned]
    return x


def iterations(cloth: tc.Cloth, kind: str, size=None) -> int:
    """CG iterations of one implicit Euler step of 1/60 s from the disturbed sheet, to 1e-8."""
    integrator = tc.ImplicitEuler(tolerance=1e-8, max_iterations=5000, preconditioner=kind,
                                  aggregate_size=size)
    sim = tc.Simulation(cloth, integrator=integrator, dt=1 / 60, gravity=(0.0, 0.0, 0.0))
    sim.set_positions(disturbed(cloth))
    sim.step(1)
    assert integrator.last_residual <= 1e-8
    return integrator.last_iterations


@pytest.mark.parametrize("make", [spring_sheet, membrane_sheet, strands])
def test_an_exact_coarse_level_makes_the_solve_blind_to_the_mesh(f64, make):
    """With an aggregate per particle P is the identity (on free particles) and A_c is A, so
    z = D^-1 r + A^-1 r and CG runs on I + D^-1 A, whose eigenvalues lie in
    [1, 1 + lambda_max(D^-1 A)] on any mesh. Jacobi's iterations grow with the square root of
    D^-1 A's condition number, which a mesh three times finer makes about nine times larger
    (the membrane's stiffness is a Laplacian: h^2 k / m is 10^3-10^4 here). A coarse matrix
    that missed a term's blocks (the springs', the membrane's, the altitude springs', the
    mass), a sign or a transposed block would leave that part to the diagonal and grow like
    Jacobi. (Two hair strands: a chain, whose condition number grows likewise.)"""
    jacobi = [iterations(make(n), "jacobi") for n in (6, 18)]
    exact = [iterations(make(n), "two-level", 1) for n in (6, 18)]
    print(f"{make.__name__}: jacobi {jacobi}, an aggregate per particle {exact}")
    assert jacobi[1] > 2 * jacobi[0]
    assert exact[1] <= exact[0] + 3
    assert exact[1] * 10 < jacobi[1]


def test_a_narrow_body_is_its_own_coarse_level_by_default(f64):
    """A body whose particles lie in a Cuthill-McKee band of at most coarse.EXACT_BAND
    particles (hair strands, a sheet 14 particles wide) is its own coarse level by default:
    its solve is aggregate_size=1's, iteration for iteration, where aggregates of 12 particles
    leave a chain's stiff bending to the diagonal (the hair demo's CG ran out of its 200
    iterations in most steps). A sheet wider than the band keeps its aggregates."""
    hair = strands(18)
    assert coarse.Layout(hair).count == hair.particle_count
    default, exact, aggregated = (iterations(strands(18), "two-level", size)
                                  for size in (None, 1, 12))
    print(f"two strands of 18 segments: default {default}, an aggregate per particle {exact}, "
          f"aggregates of 12 {aggregated} CG iterations")
    assert default == exact and 5 * default < aggregated
    for n in (14, 17):
        layout = coarse.Layout(membrane_sheet(n))
        print(f"{n} x {n} sheet: {layout.count} aggregates, band {layout.band}")
        assert (layout.count == n * n) == (n <= coarse.EXACT_BAND)
        assert layout.count < n * n or layout.band <= coarse.EXACT_BAND


@pytest.mark.parametrize("graph", ["grid", "chain", "random"])
def test_cuthill_mckee_gives_up_only_on_a_band_wider_than_asked(graph):
    """The order is given up (None) only where its band exceeds `most`, and otherwise it is
    the order made without a limit: the queue's length is a lower bound of the band."""
    rng = np.random.default_rng(7)
    gave_up = kept = 0
    for size in (4, 9, 14, 20):
        if graph == "grid":
            index = np.arange(size * size).reshape(size, size)
            pairs = np.concatenate([np.stack([index[:, :-1].ravel(), index[:, 1:].ravel()], 1),
                                    np.stack([index[:-1].ravel(), index[1:].ravel()], 1)])
            count = size * size
        elif graph == "chain":
            count = 10 * size
            pairs = np.stack([np.arange(count - 2), np.arange(count - 2) + 2], 1)
        else:
            count = 6 * size
            pairs = np.unique(np.sort(rng.integers(0, count, (3 * count, 2)), axis=1), axis=0)
            pairs = pairs[pairs[:, 0] != pairs[:, 1]]
        full = coarse.cuthill_mckee(pairs, count)
        assert sorted(full) == list(range(count))
        band = int(np.abs(full[pairs[:, 0]] - full[pairs[:, 1]]).max())
        for most in (2, 5, 8, 12, 16):
            limited = coarse.cuthill_mckee(pairs, count, most)
            if limited is None:
                assert band > most
                gave_up += 1
            else:
                assert np.array_equal(limited, full)
                kept += 1
    assert kept and (gave_up or graph == "chain")     # a chain is never wide


def pinned_edge() -> tuple:
    """A denim sheet hung from its whole first row, in aggregates of two particles: the first
    ones (particles 0 and 1) pinned both, a coarse unknown that solves for 0."""
    n = 8
    cloth = tc.Cloth(tc.grid_mesh(n, n, (0.4, 0.4)), tc.Fabric.preset("denim"),
                     pinned=list(range(n)))
    return cloth, disturbed(cloth), tc.ImplicitMidpoint, 2


def seamed() -> tuple:
    """Two panels sewn by a seam (the solve moves each sewn group as one particle; an
    aggregate holds a group whole)."""
    piece = tc.panel([(0, 0), (0.3, 0), (0.3, 0.4), (0, 0.4)], 0.08)
    garment = tc.Garment([piece, piece.moved(translate=(0.3, 0.0, 0.0))], [(0, 1, 1, 3)])
    cloth = tc.Cloth(garment.mesh, tc.Fabric.preset("denim"), seams=garment.seam_pairs,
                     pinned=garment.particles(0, 2))
    return cloth, disturbed(cloth), tc.ImplicitMidpoint, None


def corners() -> tuple:
    """A spring sheet hung by two corners."""
    cloth = spring_sheet(9)
    return cloth, disturbed(cloth), tc.ImplicitMidpoint, None


@pytest.mark.parametrize("body", [pinned_edge, seamed, corners])
def test_it_solves_to_the_same_motion_as_jacobi(f64, body):
    """Solved tightly (CG to 1e-11, Newton to 1e-11 m or its 8 iterations: the same
    iterations either way, as each linear solve is exact to that) both preconditioners reach
    the same implicit solution: 12 steps of 1/120 s agree to 1e-8 m, where the sheet moves
    centimetres (a wrong coarse correction would stall CG at most_cg and leave Newton's
    updates short)."""
    cloth, start, integrator, size = body()
    ends = []
    for kind in ("jacobi", "two-level"):
        sim = tc.Simulation(cloth, dt=1 / 120, integrator=integrator(
            tolerance=1e-11, cg_tolerance=1e-11, most_cg=5000, preconditioner=kind,
            aggregate_size=size))
        sim.set_positions(start)
        with warnings.catch_warnings():       # Newton stops at its 8 iterations (counted)
            warnings.simplefilter("ignore", RuntimeWarning)
            sim.step(12)
        ends.append(sim.positions())
    moved = np.abs(ends[0] - start).max()
    apart = np.abs(ends[1] - ends[0]).max()
    print(f"{body.__name__}, {integrator.__name__}: moved {moved:.3g} m, apart {apart:.3g} m")
    assert moved > 5e-3 and np.isfinite(ends).all()
    assert apart < 1e-8


def test_it_takes_half_the_iterations_on_a_denim_sheet(f32):
    """Issue 53's denim sheet (24 x 24 here) at 1/120 s with the trade's loose solves: the
    coarse level takes the smooth membrane modes that Jacobi leaves to hundreds of iterations
    (measured: 103 CG iterations a step against 214 at 32 x 32; docs/performance.md)."""
    n = 24
    totals = {}
    for kind in ("jacobi", "two-level"):
        cloth = tc.Cloth(tc.grid_mesh(n, n, (0.5, 0.5), plane="xz"),
                         tc.Fabric(density=0.324, stretch=5e3, shear=1e3, bending=1e-4),
                         pinned=[0, n - 1])
        integrator = tc.ImplicitMidpoint(tolerance=1e-4, cg_tolerance=0.1, preconditioner=kind)
        sim = tc.Simulation(cloth, dt=1 / 120, integrator=integrator)
        totals[kind] = 0
        for _ in range(18):
            sim.step(1)
            totals[kind] += integrator.last_cg
    print(totals)
    assert totals["two-level"] < 0.6 * totals["jacobi"]
