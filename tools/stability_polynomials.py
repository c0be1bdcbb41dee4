"""Print integrators/stabilized_rk2.py's POLYNOMIALS: for each damping ratio gamma of a
grid, the stability polynomial R(z) = 1 + z + z^2/2 + a3 z^3 + ... + a6 z^6 (six stages,
order 2) whose region holds the spectrum of Rayleigh-damped modes (x'' = -w^2 x - beta w^2 x',
0 < w <= w_max, gamma = beta w_max / 2) at the largest h w_max.

For a fixed step the conditions |R(h lambda_j)| <= 1 are convex in the coefficients, so the
largest step is found by bisection, each step a linear feasibility problem (|.| <= 1 as
Re(e^{i t} R) <= 1 over ANGLES directions t): Ketcheson & Ahmadia, "Optimal stability
polynomials for numerical integration of initial value problems", CAMCoS 7(2), 2012. The
integrator checks the exact |R| on each body's own spectrum; this only proposes polynomials.

    python tools/stability_polynomials.py        # needs scipy (in the base install)
"""

import numpy as np
from scipy.optimize import linprog

STAGES = 6
ANGLES = np.exp(1j * np.linspace(0.0, 2.0 * np.pi, 64, endpoint=False))
GAMMAS = np.round(np.geomspace(0.4, 4.0, 16), 4)


def spectrum(gamma: float, count: int = 300) -> np.ndarray:
    """lambda / w_max of the modes w / w_max in (0, 1], both roots of l^2 + 2 gamma w^2 l + w^2."""
    w = np.concatenate([np.geomspace(1e-3, 0.05, 40), np.linspace(0.05, 1.0, count)])
    disc = np.sqrt((2.0 * gamma * w * w) ** 2 - 4.0 * w * w + 0j)
    return np.concatenate([(-2.0 * gamma * w * w + disc) / 2, (-2.0 * gamma * w * w - disc) / 2])


def feasible(z: np.ndarray):
    """Coefficients a3..a6 with Re(e^{i t} R(z_j)) <= 1 for every direction and point, or None."""
    base = 1.0 + z + 0.5 * z * z
    powers = np.stack([z ** k for k in range(3, STAGES + 1)], 1)
    rows = np.concatenate([(a * powers).real for a in ANGLES])
    bounds = np.concatenate([1.0 - (a * base).real for a in ANGLES])
    result = linprog(np.zeros(STAGES - 2), A_ub=rows, b_ub=bounds,
                     bounds=[(None, None)] * (STAGES - 2), method="highs")
    return result.x if result.status == 0 else None


def optimal(gamma: float):
    lam = spectrum(gamma)
    low, high, best = 0.0, 2.0 * STAGES * STAGES, None
    for _ in range(40):
        h = 0.5 * (low + high)
        found = feasible(h * lam)
        low, high, best = (h, high, found) if found is not None else (low, h, best)
    return low, best


if __name__ == "__main__":
    print("POLYNOMIALS = (   # gamma, a3, a4, a5, a6 (tools/stability_polynomials.py)")
    for gamma in GAMMAS:
        reach, a = optimal(float(gamma))
        print(f"    ({gamma:.4f}, {a[0]:.9e}, {a[1]:.9e}, {a[2]:.9e}, {a[3]:.9e}),"
              f"  # h w_max {reach:.3f}")
    print(")")
