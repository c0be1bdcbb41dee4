"""Print integrators/stabilized_rk2.py's POLYNOMIALS: for each damping ratio gamma of a
grid, the stability polynomial R(z) = 1 + z + z^2/2 + a3 z^3 + ... + a6 z^6 (six stages,
order 2) whose region holds, with a margin, the spectrum of Rayleigh-damped modes (x'' =
-w^2 x - beta w^2 x', 0 < w <= w_max, gamma = beta w_max / 2) at every step up to the
largest h w_max.

For a fixed step the conditions |R(z_j)| <= 1 are convex in the coefficients, so the largest
step is found by bisection, each step a linear feasibility problem: Ketcheson & Ahmadia,
"Optimal stability polynomials for numerical integration of initial value problems", CAMCoS
7(2), 2012. Four details decide whether the result holds on a cloth:

- **Every step up to h, not h alone.** A step h' < h puts the modes at h' lambda, which is not
  a part of h lambda's set. The union over h' <= h is a region (the circle |1 + beta lambda|
  = 1 scaled, the over-damped modes' real segment, the segment to the stiffest mode), and
  since R is analytic |R| <= 1 on it exactly when on its boundary (the maximum modulus
  principle): `region` samples that boundary.
- **|R| <= 1 itself, not a polygon around the disc.** Re(e^{i t} R) <= 1 over N directions
  allows |R| up to 1 / cos(pi / N); an optimal polynomial touches the bound at many points,
  so the excess is where it ends up (1.0003 at z = -5.4: an over-damped mode that grows a
  step at a time). The directions here bound the inscribed polygon, cos(pi / N).
- **Damped: |R| <= 1 - MARGIN, not 1** (or the mode's own decay |e^z| where it decays less
  in a step: a lightly damped mode cannot be damped more without a large error). A
  polynomial optimal for the set touches |R| = 1 at many points along it, and there its
  stability region pinches to the set itself. A cloth's modes are not exactly Rayleigh's
  (the membrane's geometric stiffness is undamped, the pins, the strain), and a mode a
  little off the set where it pinches grows slowly. On issue 53's 64² sheet the undamped
  polynomial diverged at 0.85 and 0.9 of its predicted step after 0.16-0.25 s (one solved
  with the modes damped down to half of Rayleigh's rate at 0.95, not 0.9); bounded by 0.9
  it ran at every step tried up to 0.95 of its prediction and diverged at once at 1.0 (the
  stiff end, where the prediction is tight). Chebyshev methods are damped for the same
  reason (RKC: Sommeijer, Shampine & Verwer, "RKC: an explicit solver for parabolic PDEs",
  J. Comput. Appl. Math. 88, 1998). It costs 3 % of the step at gamma 1.9, 13 % at 0.4.
  Points within |z| <= 1 are left out: there R = 1 + z + z^2/2 + O(z^3) is fixed by the
  order, |R| is 1 - O(|z|^2) on the damped modes and no bound below 1 holds R(0) = 1.
- **No row past gamma = 1.5.** Above it the optimal polynomials are those of the
  over-damped modes' real segment, and their regions hug it. On demos/skirt_walk.toml
  without self-collision (a garment that starts wrapped round its figure, its seams being
  sewn and its waistband attached: modes off the Rayleigh set) the rows of 1.80 and 1.98
  diverged at half their predicted step, the step dt="auto" takes, where the rows up to
  1.47 ran (every row diverged at 0.9). A body past 1.47 takes that row: 2.1x symplectic
  Euler per evaluation at gamma 1.9 instead of 2.6x.

The integrator checks the exact |R| on each body's own spectrum at every step up to the one
it takes (stabilized_rk2.reach); this only proposes polynomials.

    python tools/stability_polynomials.py        # needs scipy (in the base install); ~3 min
"""

import numpy as np
from scipy.optimize import linprog

STAGES = 6
DIRECTIONS = 64
ANGLES = np.exp(1j * np.linspace(0.0, 2.0 * np.pi, DIRECTIONS, endpoint=False))
LARGEST = 1.5       # no row past this damping ratio (module doc)
GAMMAS = np.round(np.geomspace(0.4, 4.0, 24), 4)
GAMMAS = GAMMAS[GAMMAS <= LARGEST]
POINTS = 400
MARGIN = 0.1        # |R| <= max(1 - MARGIN, |e^z|) on the region beyond |z| = 1 (module doc)


def region(gamma: float) -> np.ndarray:
    """lambda / w_max on the boundary of the union over h' <= 1 of h' times the spectrum:
    under-damped to the end (gamma <= 1), the arc of the modes w / w_max in (0, 1] and the
    segment from 0 to its end; else the whole circle |1 + 2 gamma lambda| = 1 and the real
    segment of the over-damped modes out to the stiffest's -(gamma + sqrt(gamma^2 - 1))."""
    if gamma <= 1.0:
        w = np.concatenate([np.geomspace(1e-3, 0.05, 40), np.linspace(0.05, 1.0, POINTS)])
        arc = -gamma * w * w + 1j * w * np.sqrt(1.0 - (gamma * w) ** 2)
        return np.concatenate([arc, np.linspace(0.0, 1.0, POINTS // 2)[1:] * arc[-1]])
    circle = (np.exp(1j * np.linspace(0.0, np.pi, POINTS)) - 1.0) / (2.0 * gamma)
    reach = gamma + np.sqrt(gamma * gamma - 1.0)
    return np.concatenate([circle, -np.linspace(0.0, reach, POINTS // 2)[1:] + 0j])


def feasible(z: np.ndarray):
    """Coefficients a3..a6 with Re(e^{i t} R(z_j)) <= b_j cos(pi / DIRECTIONS) for every
    direction and every point with |z| > 1, b_j = 1 - MARGIN or the mode's own decay
    |e^z_j| if that is more (module doc), or None."""
    z = z[np.abs(z) > 1.0]
    base = 1.0 + z + 0.5 * z * z
    powers = np.stack([z ** k for k in range(3, STAGES + 1)], 1)
    rows = np.concatenate([(a * powers).real for a in ANGLES])
    bound = np.minimum(1.0, np.maximum(1.0 - MARGIN, np.exp(z.real))) * np.cos(np.pi / DIRECTIONS)
    bounds = np.concatenate([bound - (a * base).real for a in ANGLES])
    result = linprog(np.zeros(STAGES - 2), A_ub=rows, b_ub=bounds,
                     bounds=[(None, None)] * (STAGES - 2), method="highs")
    return result.x if result.status == 0 else None


def optimal(gamma: float):
    """(the largest h w_max found, a3..a6 there)."""
    lam = region(gamma)
    low, high, best = 0.0, 2.0 * STAGES * STAGES, None
    for _ in range(32):
        h = 0.5 * (low + high)
        found = feasible(h * lam)
        low, high, best = (h, high, found) if found is not None else (low, h, best)
    return low, best


if __name__ == "__main__":
    from ti_cloth.integrators.stabilized_rk2 import reach, spectrum

    print("POLYNOMIALS = (   # gamma, a3, a4, a5, a6 (tools/stability_polynomials.py)")
    for gamma in GAMMAS:
        a = optimal(float(gamma))[1]
        exact = reach(np.array([1.0, 0.5, *a]), spectrum(1.0, 2.0 * gamma, 0.0))
        print(f"    ({gamma:.4f}, {a[0]:.9e}, {a[1]:.9e}, {a[2]:.9e}, {a[3]:.9e}),"
              f"  # h w_max {exact:.3f}", flush=True)
    print(")")
