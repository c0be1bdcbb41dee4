"""Fabric: a cloth's material in the units a textile lab measures, independent of the mesh.

Where a Material gives every spring its own constant (Stuyck ch. 4, which change meaning when
the mesh is refined), a Fabric gives the sheet's moduli, and the elements of energies/ turn
them into forces that converge as the mesh is refined:

  density   surface density [kg/m^2]
  stretch   2-D Young's modulus E h [N/m]: a strip under a tension T per metre of width
            strains T / stretch. A number, or (warp, weft).
  shear     in-plane shear modulus times thickness, G12 h [N/m].
  bending   flexural rigidity [N m] (moment per width per curvature; ASTM D1388's
            G = W c^3, W the weight per area [N/m^2] and c the bending length [m]).
            A number, or (warp, weft).
  bending_curve  a BendingCurve (or its fields as a mapping): rigidities sampled at
            curvatures, the way measured cloth bends (body/bending_curve.py); `bending` and
            `twist` are then its values at zero curvature. None: the rigidities are constant.
  twist     D12 [N m], the twisting rigidity (None: sqrt(warp x weft), an isotropic sheet's
            when they are equal); with it the rigidity along the bias (45 degrees) is
            (warp + weft + 2 twist) / 4, which a bias cantilever measures.
  poisson   nu_12: the weft's contraction per unit strain when stretched along the warp;
            nu_21 = nu_12 E_weft / E_warp (plane-stress orthotropy). Needs
            nu_12 nu_21 < 1 (a positive definite sheet).
  compression  the sheet's stiffness against being shortened along its warp or weft, as a
            fraction of its stiffness in tension, in [0.0001, 1]. 1 (the default): a Saint
            Venant-Kirchhoff sheet, as stiff pushed as pulled. A woven yarn cannot push:
            it buckles, so real cloth gathers and folds at almost no in-plane stress
            (Choi & Ko 2002 model the same buckling on springs); a mesh whose triangles
            are larger than those folds sees the sheet refuse to shorten instead
            (energies/membrane.py). Shear is unchanged. 0.05 lets the implicit solvers'
            large steps converge on mildly compressed cloth (a sheet a few percent short),
            not yet on garments, whose triangles start sheared as well (docs/integrators.md,
            "Compressed cloth").
  damping   stiffness-proportional (Rayleigh) damping time beta [s]: the stress
            C (strain + beta d(strain)/dt), the same for bending; rigid motions are not
            damped, and beta is the same at every resolution.
  hem_mass  extra mass [kg] on each hem particle, as in Material (Stuyck 4.2).

The warp runs along a grid's columns (its first axis); for other meshes along the `warp`
direction Cloth is given, projected into each triangle.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

from ..inputs import limits
from . import material
from .bending_curve import BendingCurve
from ..inputs.validation import finite_number, in_range, keyword_only, require

STRETCH = limits.Range(1e-3, 1e9, "N/m", "fabric stretch and shear moduli")
BENDING = limits.Range(0.0, 1e2, "N m", "fabric flexural rigidity (0 allowed: no bending)")
DAMPING_TIME = limits.Range(0.0, 1.0, "s", "fabric damping time beta")
COMPRESSION = limits.Range(1e-4, 1.0, "", "fabric compressive stiffness as a fraction of the tensile")
_DEFAULT_BENDING = (1e-5, 1e-5)
STANDARD_GRAVITY = 9.80665      # m/s^2: a swatch's weight per area W = density x this


def _pair(name: str, value, allowed: limits.Range) -> tuple[float, float]:
    """(warp, weft) from a number or a pair of numbers, each in `allowed`."""
    if isinstance(value, (tuple, list)):
        require(len(value) == 2, f"Fabric.{name}", value, "a number or a (warp, weft) pair")
        return (in_range(f"Fabric.{name}[0] (warp)", value[0], allowed),
                in_range(f"Fabric.{name}[1] (weft)", value[1], allowed))
    number = in_range(f"Fabric.{name}", value, allowed)
    return number, number


@keyword_only
@dataclass(frozen=True, kw_only=True)
class Fabric:
    """A cloth's material in textile units (module doc). `stretch` and `bending` are kept as
    (warp, weft) pairs."""

    density: float = 0.2
    stretch: tuple = (1e3, 1e3)
    shear: float = 50.0
    bending: tuple = _DEFAULT_BENDING
    twist: float | None = None
    bending_curve: BendingCurve | None = None
    poisson: float = 0.0
    compression: float = 1.0
    damping: float = 1e-4
    hem_mass: float = 0.0

    def __post_init__(self):
        set_ = object.__setattr__
        set_(self, "density", in_range("Fabric.density", self.density, limits.DENSITY))
        set_(self, "stretch", _pair("stretch", self.stretch, STRETCH))
        set_(self, "shear", in_range("Fabric.shear", self.shear, STRETCH))
        set_(self, "bending", _pair("bending", self.bending, BENDING))
        if self.twist is not None:
            set_(self, "twist", in_range("Fabric.twist", self.twist, BENDING))
        if self.bending_curve is not None:
            self._take_curve()
        poisson = finite_number("Fabric.poisson", self.poisson, 0.0)
        warp, weft = self.stretch
        require(poisson * poisson * weft / warp < 1.0, "Fabric.poisson", poisson,
                f"below sqrt(stretch warp / weft) = {(warp / weft) ** 0.5:.4g} (nu_12 nu_21 < 1: "
                "a sheet that resists every stretch)")
        set_(self, "poisson", poisson)
        set_(self, "compression", in_range("Fabric.compression", self.compression, COMPRESSION))
        set_(self, "damping", in_range("Fabric.damping", self.damping, DAMPING_TIME))
        hem_mass = finite_number("Fabric.hem_mass", self.hem_mass, 0.0, unit="kg")
        set_(self, "hem_mass", hem_mass and in_range("Fabric.hem_mass", hem_mass, limits.MASS))

    def _take_curve(self) -> None:
        """bending and twist from bending_curve (a BendingCurve, or a mapping of its fields)."""
        curve = self.bending_curve
        if isinstance(curve, dict):
            known = ("curvature", "warp", "weft", "bias")
            require(set(curve) <= set(known), "Fabric.bending_curve keys", sorted(curve),
                    f"some of {list(known)}")
            curve = BendingCurve(**curve)
        require(isinstance(curve, BendingCurve), "Fabric.bending_curve", curve,
                "None, a BendingCurve or a mapping of its fields (curvature, warp, weft, bias)")
        flat = (curve.warp[0], curve.weft[0])
        given = self.bending
        require(given in (flat, _DEFAULT_BENDING), "Fabric.bending", given,
                f"left out with a bending_curve (its values at zero curvature {flat} are taken)")
        twist = curve.twist[0] if curve.bias is not None else None
        require(self.twist is None or self.twist == twist, "Fabric.twist", self.twist,
                "left out with a bending_curve (its bias row sets the twist)")
        object.__setattr__(self, "bending_curve", curve)
        object.__setattr__(self, "bending", flat)
        object.__setattr__(self, "twist", twist)

    @property
    def membrane(self) -> tuple[float, float, float, float]:
        """(C11, C12, C22, C33) [N/m] of the plane-stress orthotropic law
        S = C (G11, G22, 2 G12) on the Green strain, warp = 1, weft = 2:
        C11 = E1 / (1 - nu12 nu21), C22 = E2 / (1 - nu12 nu21), C12 = nu12 C22, C33 = shear."""
        warp, weft = self.stretch
        nu12 = self.poisson
        nu21 = nu12 * weft / warp
        scale = 1.0 / (1.0 - nu12 * nu21)
        return warp * scale, nu12 * weft * scale, weft * scale, self.shear

    @property
    def flexural(self) -> tuple[float, float, float]:
        """(D11, D22, D12) [N m] of the bending energy 1/2 (D11 k11^2 + D22 k22^2 + 2 D12 k12^2)
        per area, k the change of curvature in the warp/weft frame: D11, D22 the warp and weft
        rigidities, D12 the twist: `twist`, or sqrt(D11 D22) (an isotropic sheet of Poisson
        ratio 0 when they are equal: 1/2 D |k|^2)."""
        warp, weft = self.bending
        return warp, weft, (warp * weft) ** 0.5 if self.twist is None else self.twist

    @property
    def bias_bending(self) -> float:
        """The flexural rigidity [N m] along the bias (45 degrees to the warp): a curvature k
        there bends k11 = k22 = k12 = k / 2, so D = (D11 + D22 + 2 D12) / 4."""
        d11, d22, d12 = self.flexural
        return (d11 + d22 + 2.0 * d12) / 4.0

    @classmethod
    def from_measurements(cls, *, weight: float, bending_length=None, rigidity=None,
                          stretch=None, strip_test=None, shear: float = 50.0,
                          poisson: float = 0.0, compression: float = 1.0,
                          damping: float = 1e-4, hem_mass: float = 0.0) -> "Fabric":
        """The Fabric of a swatch's lab numbers, each by its closed form (exact):

        weight         [g/m^2]: density = weight / 1000 kg/m^2.
        bending_length (warp, weft) or (warp, weft, bias) [m], ASTM D1388's cantilever c:
                       the rigidity G = W c^3, W = density x STANDARD_GRAVITY [N/m^2]; a bias
                       length sets the twist, D12 = 2 G_bias - (G_warp + G_weft) / 2 (the
                       bias rigidity of bias_bending), which must come out >= 0.
        rigidity       the same as flexural rigidities (warp, weft[, bias]) [N m] instead.
        stretch        2-D moduli E h [N/m], a number or (warp, weft); or
        strip_test     (tension per width [N/m], warp strain, weft strain) of a strip test in
                       its linear range: stretch = tension / strain.
        shear, poisson, compression, damping, hem_mass as Fabric's."""
        density = finite_number("weight", weight, 0.0, strict=True, unit="g/m^2") / 1000.0
        in_range("weight", density * 1000.0, limits.Range(limits.DENSITY.low * 1000,
                                                          limits.DENSITY.high * 1000, "g/m^2",
                                                          "fabric weight"))
        require((bending_length is None) != (rigidity is None), "bending_length",
                bending_length, "given, or rigidity instead (one of them)")
        name = "bending_length" if rigidity is None else "rigidity"
        values = bending_length if rigidity is None else rigidity
        require(isinstance(values, (tuple, list)) and len(values) in (2, 3), name, values,
                "(warp, weft) or (warp, weft, bias)")
        unit = "m" if rigidity is None else "N m"
        values = [finite_number(f"{name}[{k}]", v, 0.0, strict=True, unit=unit)
                  for k, v in enumerate(values)]
        weight_force = density * STANDARD_GRAVITY
        rigidities = [weight_force * c ** 3 for c in values] if rigidity is None else values
        twist = None
        if len(rigidities) == 3:
            warp, weft, bias = rigidities
            twist = 2.0 * bias - (warp + weft) / 2.0
            require(twist >= 0.0, f"{name}[2] (bias)", values[2],
                    f"a bias rigidity of at least (warp + weft) / 4 = {(warp + weft) / 4:.4g} N m "
                    f"(this law's least: no twisting rigidity); it gives {bias:.4g} N m")
        require((stretch is None) != (strip_test is None), "stretch", stretch,
                "given, or strip_test instead (one of them)")
        if strip_test is not None:
            require(isinstance(strip_test, (tuple, list)) and len(strip_test) == 3, "strip_test",
                    strip_test, "(tension per width [N/m], warp strain, weft strain)")
            tension = finite_number("strip_test[0] (tension)", strip_test[0], 0.0, strict=True,
                                    unit="N/m")
            stretch = tuple(tension / finite_number(f"strip_test[{k}] (strain)", strip_test[k],
                                                    0.0, strict=True) for k in (1, 2))
        return cls(density=density, stretch=stretch, shear=shear,
                   bending=(rigidities[0], rigidities[1]), twist=twist, poisson=poisson,
                   compression=compression, damping=damping, hem_mass=hem_mass)

    def table(self) -> str:
        """This fabric as a scene file's [bodies.fabric] table (every field, to paste)."""
        def number(value) -> str:
            return repr(float(value))          # the shortest text that reads back exactly

        def pair(values) -> str:
            return f"[{number(values[0])}, {number(values[1])}]"

        rows = ["[bodies.fabric]", f"density = {number(self.density)}                # kg/m^2",
                f"stretch = {pair(self.stretch)}       # N/m, warp and weft",
                f"shear = {number(self.shear)}                # N/m",
                f"bending = {pair(self.bending)}       # N m, warp and weft"]
        if self.bending_curve is not None:
            rows[-1] = f"bending_curve = {self.bending_curve.table()}   # 1/m, N m"
        elif self.twist is not None:
            rows.append(f"twist = {number(self.twist)}                # N m")
        rows.append(f"poisson = {number(self.poisson)}")
        if self.compression != 1.0:
            rows.append(f"compression = {number(self.compression)}")
        rows.append(f"damping = {number(self.damping)}                # s")
        if self.hem_mass:
            rows.append(f"hem_mass = {number(self.hem_mass)}                # kg")
        return "\n".join(rows)

    @classmethod
    def preset(cls, name: str, **overrides) -> "Fabric":
        """A measured fabric (PRESETS, any letter case); keyword arguments replace single
        fields (`bending` or `twist` replaces its bending_curve: constant rigidities;
        bending_curve=None keeps its rigidities at zero curvature)."""
        name = name.lower() if isinstance(name, str) else name
        springs = isinstance(name, str) and (name in material.PRESETS
                                             or name in material.FORMER_NAMES)
        require(isinstance(name, str) and name in PRESETS, "preset", name,
                f"one of {sorted(PRESETS)}" + (f" ({name!r} names Stuyck's springs: "
                                               f"Material.preset({name!r}))" if springs else ""))
        known = {f.name for f in fields(cls)}
        for key in overrides:
            require(key in known, "Fabric field", key, f"one of {sorted(known)}")
        base = dict(PRESETS[name])
        if {"bending", "twist"} & set(overrides) and "bending_curve" not in overrides:
            base.pop("bending_curve")                        # constant rigidities instead
        elif "bending_curve" in overrides and overrides["bending_curve"] is None:
            curve = base.pop("bending_curve")                # its values at zero curvature
            base["bending"] = (curve.warp[0], curve.weft[0])
            base["twist"] = curve.twist[0] if curve.bias is not None else None
        return cls(**{**base, **overrides})


# Measured fabrics. Source: H. Wang, J. F. O'Brien, R. Ramamoorthi, "Data-driven elastic models
# for cloth: modeling and measurement", ACM Trans. Graph. 30(4), 2011 (SIGGRAPH), as the
# database is distributed with ArcSim (materials/<name>.json; its README gives each sample's
# use and fibres, quoted below). From each sample: its density [kg/m^2]; the lowest-strain row
# (c11, c12, c22, c33) of its piecewise-linear stretching table [N/m] read as this law's
# (C11, C12, C22, C33) (Fabric.membrane): stretch = (c11 - c12^2 / c22, c22 - c12^2 / c11),
# poisson = c12 / c22 (0 where the fit gave c12 < 0), shear = c33: the small-strain moduli,
# which is what a drape and a cantilever test probe. Bending: the whole table, its 0, 45 and 90
# degree rows (warp = the sample's first axis, bias, weft) at half-curvatures 0, 5, 10, 15 and
# 20 1/m, as BendingCurve.wang reads them (bending_curve.py). ArcSim itself doubles the stretching rows and bends
# with k l^2 theta^2 / (8 (A1 + A2)) per edge (a flexural rigidity of k / 4): the paper's own
# units could not be checked here, and these presets read the tables as the moduli
# (docs/fabrics.md).
PRESETS: dict[str, dict] = {
    # "11oz-black-denim": jeans, 99% cotton 1% spandex, 324 g/m^2
    "denim": dict(density=0.324, stretch=(205.25, 1013.38), shear=53.39, poisson=0.01009,
                  bending_curve=BendingCurve.wang((
            (64.196457e-6, 60.286175e-6, 60.943428e-6, 62.433697e-6, 19.824701e-6),
            (73.384567e-6, 59.671982e-6, 61.080757e-6, 68.242569e-6, 36.033474e-6),
            (96.951576e-6, 107.848228e-6, 113.060738e-6, 120.56974e-6, 79.781021e-6)))),
    # "royal-target": pants, 65% cotton 35% polyester, 220 g/m^2
    "royal_target": dict(density=0.220, stretch=(2016.51, 2034.93), shear=104.76,
                         poisson=0.004506, bending_curve=BendingCurve.wang((
            (125.409805e-6, 167.284561e-6, 215.41275e-6, 215.09079e-6, 223.861038e-6),
            (107.997696e-6, 120.583267e-6, 144.141678e-6, 140.606689e-6, 153.048309e-6),
            (125.409805e-6, 167.284561e-6, 215.41275e-6, 215.09079e-6, 227.861038e-6)))),
    # "white-dots-on-blk": tablecloth, 100% polyester, 128 g/m^2
    "dots": dict(density=0.128, stretch=(2002.09, 2027.49), shear=19.19, poisson=0.0001705,
                 bending_curve=BendingCurve.wang((
            (51.713814e-6, 36.506981e-6, 66.360748e-6, 52.729267e-6, 15.221714e-6),
            (40.65947e-6, 10.401686e-6, 20.84782e-6, 30.993469e-6, 12.726685e-6),
            (31.282822e-6, 22.910311e-6, 26.350384e-6, 30.637762e-6, 16.726685e-6)))),
    # "pink-ribbon-brown": blanket, 100% polyester, 228 g/m^2
    "ribbon": dict(density=0.228, stretch=(105.59, 170.63), shear=30.25, poisson=0.4331,
                   bending_curve=BendingCurve.wang((
            (117.070122e-6, 202.682922e-6, 298.615936e-6, 244.588867e-6, 238.43782e-6),
            (87.509773e-6, 36.396919e-6, 103.628098e-6, 91.630119e-6, 97.175949e-6),
            (59.774277e-6, 59.260632e-6, 64.199661e-6, 55.017326e-6, 59.221714e-6)))),
    # "tango-red-jet-set": jacket, 100% polyester, 113 g/m^2
    "jet_set": dict(density=0.113, stretch=(25.82, 102.78), shear=14.31, poisson=0.3172,
                    bending_curve=BendingCurve.wang((
            (14.293814e-6, 8.949391e-6, 30.011126e-6, 36.08149e-6, 18.363136e-6),
            (21.9517e-6, 22.446325e-6, 18.408735e-6, 19.598495e-6, 12.071854e-6),
            (20.345654e-6, 22.69688e-6, 15.698071e-6, 13.466827e-6, 7.556618e-6)))),
    # "gray-interlock": t-shirt, an interlock knit, 60% cotton 40% polyester, 187 g/m^2
    "interlock": dict(density=0.187, stretch=(16.59, 34.48), shear=36.86, poisson=0.0,
                      bending_curve=BendingCurve.wang((
            (23.191698e-6, 32.932217e-6, 34.406498e-6, 39.01442e-6, 23.382786e-6),
            (24.749964e-6, 18.651314e-6, 16.370552e-6, 25.095791e-6, 8.860165e-6),
            (14.267624e-6, 7.052906e-6, 14.515154e-6, 24.665127e-6, 19.383726e-6)))),
    # "ivory-rib-knit": underwear, 95% cotton 5% spandex, 276 g/m^2
    "rib_knit": dict(density=0.276, stretch=(42.87, 65.17), shear=83.18, poisson=0.0,
                     bending_curve=BendingCurve.wang((
            (46.237591e-6, 63.086697e-6, 83.192772e-6, 97.574425e-6, 80.726685e-6),
            (30.01593e-6, 30.097424e-6, 30.172081e-6, 30.6483e-6, 24.726685e-6),
            (32.243889e-6, 37.341282e-6, 38.817448e-6, 39.812527e-6, 30.43782e-6)))),
    # "navy-sparkle-sweat": sweater, 96% polyester 4% spandex, 224 g/m^2
    "sweat": dict(density=0.224, stretch=(12.49, 3.27), shear=17.62, poisson=0.0,
                  bending_curve=BendingCurve.wang((
            (59.469658e-6, 37.500004e-6, 35.787308e-6, 35.737106e-6, 21.033506e-6),
            (40.072277e-6, 37.446949e-6, 35.206612e-6, 24.871773e-6, 9.033506e-6),
            (45.625023e-6, 39.520981e-6, 30.734119e-6, 23.301662e-6, 13.033506e-6)))),
    # "camel-ponte-roma": jacket, 60% polyester 40% rayon, 284 g/m^2
    "ponte_roma": dict(density=0.284, stretch=(31.15, 44.03), shear=31.90, poisson=0.0,
                       bending_curve=BendingCurve.wang((
            (36.348366e-6, 49.585537e-6, 45.74408e-6, 47.413387e-6, 20.726685e-6),
            (33.013252e-6, 29.744385e-6, 35.103642e-6, 34.041019e-6, 14.439938e-6),
            (37.157593e-6, 34.107452e-6, 33.229435e-6, 34.685535e-6, 10.439938e-6)))),
    # "white-swim-solid": swimsuit, 87% nylon 13% spandex, 204 g/m^2
    "swim": dict(density=0.204, stretch=(47.52, 103.64), shear=60.77, poisson=0.06533,
                 bending_curve=BendingCurve.wang((
            (60.237942e-6, 56.357208e-6, 69.698593e-6, 55.305969e-6, 34.705532e-6),
            (58.803211e-6, 63.121964e-6, 61.379181e-6, 47.971302e-6, 19.383726e-6),
            (51.018833e-6, 50.741455e-6, 50.570576e-6, 50.006001e-6, 24.556618e-6)))),
}
