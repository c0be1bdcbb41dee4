"""The textile lab's cantilever test (ASTM D1388, Peirce 1930), run on ti_cloth's fabrics.

A 2.5 cm strip lies on a ledge, clamped level at its edge (the two columns of particles over
the ledge are pinned), and its overhang l is slid out until the tip touches the line 41.5
degrees below the ledge: there the bending length is c = l / 2 and the flexural rigidity
G = W c^3 (W the weight per area). This script finds that overhang for each preset by a
secant search on l (each candidate settled by implicit Euler under drag), at four mesh
resolutions (segments along the overhang), and reports G back against the preset's G
(warp-wise strips):

- G_astm = W (l/2)^3, what the standard reports;
- G_elastica = W l^3 / lambda*, lambda* the W l^3 / G at which the heavy elastica
  G theta'' = -W (l - s) cos theta (scipy's BVP solver) has its chord at 41.5 degrees
  (8.004: Peirce chose the angle so that c = l / 2 holds to 0.05 %). Both must approach the
  preset's G as the mesh is refined.

Each preset runs twice: with its rigidity constant at the zero-curvature sample (`flat`), and
with its measured BendingCurve (`curve`: the rigidity changes as the strip bends,
body/bending_curve.py). For the curve the overhang is also compared with the heavy elastica
of that law, M = D(kappa) kappa (`l_law`, shot from the clamp; "-" where the table's moment
falls somewhere below the root curvature the strip needs: that elastica has no unique
solution, the strip creases at the clamp), and G_astm is given against the flat G: what a lab
would report for the fabric the table describes.

    python benchmarks/cantilever.py [--presets denim interlock] [--segments 8 16 32 64]
                                    [--laws flat curve]
"""

import argparse
import math
import time

import numpy as np
from scipy.integrate import solve_bvp, solve_ivp
from scipy.optimize import brentq

import ti_cloth as tc

ANGLE = math.radians(41.5)     # ASTM D1388's line
WIDTH = 0.025                  # strip width [m]
ROWS = 4                       # particles across the strip
GRAVITY = 9.81
trapezoid = getattr(np, "trapezoid", None) or np.trapz     # numpy < 2 names it trapz


def elastica_chord(load: float) -> float:
    """Chord angle [rad] below the clamp of the heavy elastica with W l^3 / G = load."""
    s = np.linspace(0.0, 1.0, 101)

    def slope(x, y):
        return np.vstack([y[1], -load * (1.0 - x) * np.cos(y[0])])

    solution = solve_bvp(slope, lambda a, b: np.array([a[0], b[1]]), s, np.zeros((2, s.size)),
                         tol=1e-10, max_nodes=100_000)
    theta = solution.sol(np.linspace(0.0, 1.0, 4001))[0]
    return math.atan2(trapezoid(np.sin(theta), dx=1 / 4000), trapezoid(np.cos(theta), dx=1 / 4000))


def critical_load() -> float:
    """lambda*: the W l^3 / G whose heavy elastica has its chord at 41.5 degrees."""
    return brentq(lambda load: elastica_chord(load) - ANGLE, 1.0, 30.0, xtol=1e-12)


def law_chord(curve, weight: float, overhang: float) -> float | None:
    """Chord angle [rad] of the heavy elastica of length `overhang` whose moment is
    D(kappa) kappa, D the warp row of `curve`: theta' = kappa(M), M' = -W (l - s) cos theta,
    shot from the clamp with the root moment that leaves M(l) = 0; None where the moment is
    not increasing up to the curvature needed."""
    kappa = np.linspace(0.0, 4000.0, 400001)
    moment = np.interp(kappa, curve.curvature, curve.warp) * kappa
    root_moment = weight * overhang ** 2 / 2          # the most a root can carry
    reach = np.searchsorted(moment, root_moment) + 1
    if reach >= len(kappa) or np.any(np.diff(moment[:reach]) <= 0):
        return None

    def slope(s, y):
        return [np.interp(y[1], moment[:reach], kappa[:reach]),
                -weight * (overhang - s) * math.cos(y[0]), math.cos(y[0]), math.sin(y[0])]

    def shoot(root):
        return solve_ivp(slope, (0.0, overhang), [0.0, root, 0.0, 0.0], rtol=1e-10,
                         atol=1e-14, max_step=overhang / 1000)

    root = brentq(lambda m: shoot(m).y[1, -1], 0.0, root_moment, xtol=1e-15)
    end = shoot(root).y[2:, -1]
    return math.atan2(end[1], end[0])


def law_overhang(curve, weight: float, guess: float) -> float | None:
    """The overhang whose law elastica (law_chord) has its chord at 41.5 degrees."""
    def miss(length):
        chord = law_chord(curve, weight, length)
        if chord is None:
            raise ValueError
        return chord - ANGLE
    try:
        low, high = 0.5 * guess, 2.0 * guess
        while miss(low) > 0:
            low *= 0.7
        while miss(high) < 0:
            high *= 1.4
        return brentq(miss, low, high, xtol=1e-7)
    except ValueError:
        return None


def chord_angle(fabric: tc.Fabric, overhang: float, segments: int) -> float:
    """The settled strip's chord angle [rad] below the ledge for `overhang` [m]."""
    h = overhang / segments
    mesh = tc.grid_mesh(ROWS, segments + 2, (overhang + h, WIDTH), plane="xz", origin=(-h, 0, 0))
    clamped = np.flatnonzero(mesh.vertices[:, 0] <= 1e-12)
    cloth = tc.Cloth(mesh, fabric, pinned=clamped, warp=(1.0, 0.0, 0.0))
    sim = tc.Simulation(cloth, integrator=tc.ImplicitEuler(tolerance=1e-7, max_iterations=2000),
                        dt=2e-3, drag=20.0)
    for _ in range(40):                       # settle: up to 4 s, until at rest
        sim.step(50)
        if sim.energy()["kinetic"] < 0.5 * cloth.particle_mass.sum() * 1e-5 ** 2:
            break
    x = sim.positions()
    tip = np.isclose(mesh.vertices[:, 0], overhang)
    return math.atan2(-x[tip, 1].mean(), x[tip, 0].mean())


def overhang_at_line(fabric: tc.Fabric, segments: int, guess: float) -> float:
    """The overhang [m] whose settled chord is at 41.5 degrees: a secant search in log l."""
    a, b = guess * 0.9, guess * 1.1
    fa, fb = chord_angle(fabric, a, segments) - ANGLE, chord_angle(fabric, b, segments) - ANGLE
    for _ in range(12):
        if abs(fb) < 1e-4:
            break
        c = math.exp(math.log(b) - fb * (math.log(b) - math.log(a)) / (fb - fa))
        a, fa = b, fb
        b, fb = c, chord_angle(fabric, c, segments) - ANGLE
    return b


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--presets", nargs="+", default=list(tc.FABRICS))
    parser.add_argument("--segments", type=int, nargs="+", default=[8, 16, 32, 64])
    parser.add_argument("--laws", nargs="+", choices=("flat", "curve"), default=["flat", "curve"])
    args = parser.parse_args()
    tc.init(arch="cpu", precision="f64")
    load = critical_load()
    print(f"heavy elastica: chord at 41.5 deg for W l^3 / G = {load:.4f} "
          f"(Peirce's c = l/2 assumes 8)")
    print(f"{'preset':13} {'law':5} {'segments':>8} {'overhang [cm]':>13} {'l_law [cm]':>10} "
          f"{'G preset [uN m]':>16} {'G_astm / G':>10} {'G_elastica / G':>14} {'s':>6}")
    for name in args.presets:
        for law in args.laws:
            fabric = tc.Fabric.preset(name)
            curve = fabric.bending_curve
            if law == "flat":
                fabric = tc.Fabric.preset(name, bending_curve=None)
            w = fabric.density * GRAVITY
            g = fabric.bending[0]
            guess = (load * g / w) ** (1 / 3)
            exact = law_overhang(curve, w, guess) if law == "curve" else None
            for segments in args.segments:
                start = time.perf_counter()
                overhang = overhang_at_line(fabric, segments, guess)
                guess = overhang
                astm = w * (overhang / 2) ** 3
                elastica = w * overhang ** 3 / load
                law_text = "-" if exact is None else f"{100 * exact:.3f}"
                print(f"{name:13} {law:5} {segments:8d} {100 * overhang:13.3f} {law_text:>10} "
                      f"{1e6 * g:16.2f} {astm / g:10.4f} {elastica / g:14.4f} "
                      f"{time.perf_counter() - start:6.0f}", flush=True)


if __name__ == "__main__":
    main()
