"""BendingCurve: a fabric's flexural rigidity as it changes with curvature, the way measured
cloth bends (issue 57). Wang, O'Brien & Ramamoorthi, "Data-driven elastic models for cloth:
modeling and measurement", ACM TOG 30(4), 2011, measured each fabric's rigidity at five
curvatures along the warp, the bias and the weft: 11 oz denim softens about 3x across them,
a ribbon stiffens about 2x, and one number matches only the first sample.

The law. A triangle's change of curvature k = (k11, k22, k12) in its warp/weft frame (the
mid-edge operator of energies/bending.py) has the size rho = sqrt(k11^2 + k22^2 + 2 k12^2)
(the tensor's Frobenius norm: a bend of curvature kappa in any one direction, warp, weft or
bias, has rho = kappa) and the share w_d = c_d k_d^2 / rho^2 in each direction, c = (1, 1, 2).
Its energy per area is

    psi(k) = sum_d c_d k_d^2 g_d(rho),   g_d = F_d(rho) / rho^2,   F_d(rho) = int_0^rho D_d(s) s ds,

D_d = (D11, D22, D12) the warp, weft and twisting rigidities [N m], piecewise linear in the
curvature between the samples and constant past the last. With constant rigidities
psi = 1/2 sum_d c_d D_d k_d^2, the Fabric's own law (Fabric.flexural). A bend in one
direction stores F(kappa) per area, its moment dF/dkappa = D(kappa) kappa: D is the secant
rigidity M / kappa a cantilever measures at that curvature (ASTM D1388; Wang et al. 2011), the
warp's along the warp, the weft's along the weft; along the bias k11 = k22 = k12 = kappa / 2,
w = (1/4, 1/4, 1/2), so the bias rigidity is (D11 + D22 + 2 D12) / 4 at every curvature
(Fabric.bias_bending) and a measured bias row sets D12 = 2 G_bias - (G_warp + G_weft) / 2 at
each sample (twist). A sample where that comes out below 0 (a bias softer than a quarter of
warp and weft, which no sheet with a positive energy has; three of Wang's fabrics have one) is
raised to 0.

The moments: dpsi/dk_d = c_d S_d k_d with the secant rigidities (g' = (D - 2 g) / rho)

    S_d = 2 g_d(rho) + sum_e w_e (D_e(rho) - 2 g_e(rho)),

which equal D_d when the rigidities are constant. Every solver uses S in place of D
(energies/bending_law.py): its moments are the energy's exact gradient, and the secant matrix
B(k) = A sum_d c_d S_d b_d b_d^T, whose product with a triangle's hinge tangents is its
moment, is the implicit solvers' Gauss-Newton Hessian and XPBD's stiffness, with S_d clamped at
0 there to keep them positive semi-definite (S_d < 0 only where one direction softens far
below another's mean). stable_dt takes each direction's stiffest tangent, the largest
d(D kappa)/dkappa = D + kappa dD/dkappa over the table (stiffest; where the moment falls as
the curvature grows, as denim's warp past 30 1/m, the sheet creases there, and no step is
limited by it).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from itertools import pairwise

import numpy as np

from ..inputs import limits
from ..inputs.validation import in_range, keyword_only, require

CURVATURE = limits.Range(0.0, 1e4, "1/m", "bending curvature sample")
RIGIDITY = limits.Range(0.0, 1e2, "N m", "fabric flexural rigidity (0 allowed: no bending)")
WEIGHTS = np.array([1.0, 1.0, 2.0])          # c_d: k12 counts twice in the tensor's norm
WANG_HALF_CURVATURES = (0.0, 5.0, 10.0, 15.0, 20.0)   # 1/m: Wang et al.'s samples (ArcSim's
# bending_stiffness reads them at half the curvature theta l / (A1 + A2), "per 0.05 cm^-1")


def _samples(name: str, values, count: int | None, allowed: limits.Range) -> tuple:
    require(isinstance(values, (tuple, list, np.ndarray)) and len(values) >= 2
            and (count is None or len(values) == count), f"BendingCurve.{name}", values,
            f"a list of {count if count is not None else 'two or more'} numbers"
            + (" (one per curvature)" if count is not None else ""))
    return tuple(in_range(f"BendingCurve.{name}[{k}]", v, allowed) for k, v in enumerate(values))


@keyword_only
@dataclass(frozen=True, kw_only=True)
class BendingCurve:
    """Flexural rigidities [N m] sampled at curvatures [1/m] (module doc): `curvature`
    starts at 0 and increases; `warp`, `weft` and `bias` (None: the twist is sqrt(warp x weft)
    at each sample, as Fabric's default) have one rigidity per curvature."""

    curvature: tuple
    warp: tuple
    weft: tuple
    bias: tuple | None = None

    def __post_init__(self):
        set_ = object.__setattr__
        curvature = _samples("curvature", self.curvature, None, CURVATURE)
        require(curvature[0] == 0.0, "BendingCurve.curvature[0]", curvature[0],
                "0 (the table starts at the flat sheet)")
        require(all(b > a for a, b in pairwise(curvature)), "BendingCurve.curvature",
                list(curvature), "increasing")
        set_(self, "curvature", curvature)
        for name in ("warp", "weft") + (("bias",) if self.bias is not None else ()):
            set_(self, name, _samples(name, getattr(self, name), len(curvature), RIGIDITY))

    @classmethod
    def wang(cls, rows) -> BendingCurve:
        """The curve of a Wang et al. 2011 bending table as ArcSim distributes it: three rows
        (0, 45 and 90 degrees: warp, bias, weft) of five rigidities at half-curvatures
        WANG_HALF_CURVATURES, i.e. at curvatures twice those."""
        warp, bias, weft = rows
        return cls(curvature=tuple(2.0 * h for h in WANG_HALF_CURVATURES), warp=tuple(warp),
                   weft=tuple(weft), bias=tuple(bias))

    @cached_property
    def twist(self) -> tuple:
        """D12 at each sample [N m] (module doc)."""
        warp, weft = np.array(self.warp), np.array(self.weft)
        if self.bias is None:
            return tuple(np.sqrt(warp * weft).tolist())
        return tuple(np.maximum(2.0 * np.array(self.bias) - 0.5 * (warp + weft), 0.0).tolist())

    @cached_property
    def rigidities(self) -> np.ndarray:
        """(N, 3): D11, D22, D12 at each sample."""
        return np.stack([self.warp, self.weft, self.twist], axis=1)

    @cached_property
    def slopes(self) -> np.ndarray:
        """(N, 3): dD/dkappa on the segment starting at each sample, 0 past the last."""
        d, s = self.rigidities, np.array(self.curvature)
        return np.concatenate([np.diff(d, axis=0) / np.diff(s)[:, None], np.zeros((1, 3))])

    @cached_property
    def integrals(self) -> np.ndarray:
        """(N, 3): F_d at each sample [J/m^2] (module doc; segment_integral)."""
        d, m, s = self.rigidities, self.slopes, np.array(self.curvature)
        pieces = segment_integral(d[:-1], m[:-1], s[:-1, None], s[1:, None])
        return np.concatenate([np.zeros((1, 3)), np.cumsum(pieces, axis=0)])

    @cached_property
    def stiffest(self) -> np.ndarray:
        """(3,): each direction's largest tangent d(D kappa)/dkappa over the table [N m]."""
        d, m, s = self.rigidities, self.slopes, np.array(self.curvature)[:, None]
        ends = np.concatenate([d + m * s, d[1:] + m[:-1] * s[1:]])
        return ends.max(axis=0)         # >= D(0) >= 0; a softening tangent limits no step

    def _segments(self, rho: np.ndarray):
        s = np.array(self.curvature)
        j = np.searchsorted(s, rho, side="right") - 1
        return s[j][..., None], self.rigidities[j], self.slopes[j], self.integrals[j]

    def rigidity(self, rho) -> np.ndarray:
        """D_d(rho) (..., 3) at curvatures rho (...)."""
        rho = np.asarray(rho, np.float64)
        s, d, m, _ = self._segments(rho)
        return d + m * (rho[..., None] - s)

    def mean_rigidity(self, rho) -> np.ndarray:
        """2 g_d(rho) = 2 F_d(rho) / rho^2 (..., 3), D_d(0) at rho = 0."""
        rho = np.asarray(rho, np.float64)
        s, d, m, f = self._segments(rho)
        total = f + segment_integral(d, m, s, rho[..., None])
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(rho[..., None] > 0, 2.0 * total / rho[..., None] ** 2,
                            self.rigidities[0])

    def secants(self, k) -> np.ndarray:
        """S_d (..., 3) at changes of curvature k (..., 3) = (k11, k22, k12) (module doc)."""
        k = np.asarray(k, np.float64)
        rho2 = (WEIGHTS * k * k).sum(-1)
        rho = np.sqrt(rho2)
        mean, d = self.mean_rigidity(rho), self.rigidity(rho)
        with np.errstate(divide="ignore", invalid="ignore"):
            share = np.where(rho2[..., None] > 0, WEIGHTS * k * k / rho2[..., None], 0.0)
        return mean + (share * (d - mean)).sum(-1, keepdims=True)

    def density(self, k) -> np.ndarray:
        """psi(k) [J/m^2] (...) at changes of curvature k (..., 3)."""
        k = np.asarray(k, np.float64)
        rho = np.sqrt((WEIGHTS * k * k).sum(-1))
        return 0.5 * (WEIGHTS * k * k * self.mean_rigidity(rho)).sum(-1)

    def table(self) -> str:
        """This curve as a scene file's inline table."""
        def values(v) -> str:
            return "[" + ", ".join(repr(float(x)) for x in v) + "]"
        parts = [f"curvature = {values(self.curvature)}", f"warp = {values(self.warp)}",
                 f"weft = {values(self.weft)}"]
        if self.bias is not None:
            parts.append(f"bias = {values(self.bias)}")
        return "{ " + ", ".join(parts) + " }"


def segment_integral(d, m, s, rho):
    """int_s^rho (d + m (x - s)) x dx = d u (rho + s) / 2 + m u^2 (2 rho + s) / 6, u = rho - s:
    the energy per area a segment of the law adds between curvatures s and rho (the form has
    no cancellation at small rho, and is exact at s = 0)."""
    u = rho - s
    return d * u * (rho + s) / 2.0 + m * u * u * (2.0 * rho + s) / 6.0


def curve_tables(curves, count: int) -> tuple:
    """(samples (C, count), rigidities, slopes, integrals (C, count, 3)) of `curves` for the
    kernels (energies/bending_law.py), each padded to `count` samples past its last at
    1 1/m apart, where the law goes on at its last rigidity (slope 0)."""
    shape = (max(len(curves), 1), count)
    samples, tables = np.zeros(shape), [np.zeros(shape + (3,)) for _ in range(3)]
    for c, curve in enumerate(curves):
        s = np.array(curve.curvature)
        extra = s[-1] + np.arange(1, count - len(s) + 1)
        padded = BendingCurve(curvature=tuple(np.concatenate([s, extra]).tolist()),
                              warp=curve.warp + (curve.warp[-1],) * len(extra),
                              weft=curve.weft + (curve.weft[-1],) * len(extra),
                              bias=None if curve.bias is None
                              else curve.bias + (curve.bias[-1],) * len(extra))
        samples[c] = padded.curvature
        for table, values in zip(tables, (padded.rigidities, padded.slopes, padded.integrals)):
            table[c] = values
    return (samples, *tables)
