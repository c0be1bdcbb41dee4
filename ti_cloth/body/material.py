"""Material parameters: surface density, per-kind spring constants, damping model, hem mass."""

from __future__ import annotations

import enum
import warnings
from dataclasses import dataclass, field

from ..inputs import limits
from ..inputs.validation import finite_number, in_range, keyword_only, require


class SpringKind(enum.IntEnum):
    """The three spring families of Stuyck fig. 4.2."""

    STRETCH = 0  # axis neighbours (green)
    SHEAR = 1    # diagonal neighbours (purple)
    BEND = 2     # 2-ring neighbours along an axis, skipping one particle (yellow)


DAMPING_MODELS = ("axial", "relative")


@dataclass(frozen=True)
class SpringParams:
    """Constants of one spring family.

    k: stiffness [N/m] (Stuyck eq. 4.4), >= 0.
    kd: damping coefficient [kg/s] (Stuyck eq. 4.7), >= 0.
    """

    k: float
    kd: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "k", in_range("SpringParams.k", self.k, limits.STIFFNESS))
        object.__setattr__(self, "kd", in_range("SpringParams.kd", self.kd, limits.DAMPING))


@keyword_only
@dataclass(frozen=True, kw_only=True)
class Material:
    """What the cloth is made of.

    density: surface density [kg/m^2], > 0 (Stuyck 4.2).
    stretch, shear, bend: spring constants per family.
    damping: "axial" damps only the relative velocity along the spring, so rigid rotations
        are free; "relative" is Stuyck eq. 4.7, -kd (v_i - v_j), which also resists rotation.
    hem_mass: extra mass [kg] added to every boundary particle (Stuyck 4.2), >= 0.
    """

    density: float = 0.2
    stretch: SpringParams = field(default_factory=lambda: SpringParams(5e3, 1.0))
    shear: SpringParams = field(default_factory=lambda: SpringParams(5e2, 0.1))
    bend: SpringParams = field(default_factory=lambda: SpringParams(50.0, 0.01))
    damping: str = "axial"
    hem_mass: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "density", in_range("Material.density", self.density,
                                                     limits.DENSITY))
        for name in ("stretch", "shear", "bend"):
            value = getattr(self, name)
            require(isinstance(value, SpringParams), f"Material.{name}", value, "a SpringParams")
        require(self.damping in DAMPING_MODELS, "Material.damping", self.damping,
                f"one of {DAMPING_MODELS}")
        hem_mass = finite_number("Material.hem_mass", self.hem_mass, 0.0, unit="kg")
        object.__setattr__(self, "hem_mass", hem_mass and in_range("Material.hem_mass", hem_mass,
                                                                   limits.MASS))

    def springs(self, kind: SpringKind) -> SpringParams:
        """The constants of one spring family."""
        return (self.stretch, self.shear, self.bend)[SpringKind(kind)]

    @classmethod
    def preset(cls, name: str, **overrides) -> "Material":
        """A named material (PRESETS, any letter case); keyword arguments replace single
        fields."""
        name = preset_name(name)
        require(name in PRESETS, "preset", name, f"one of {sorted(PRESETS)}")
        return cls(**{**PRESETS[name], **overrides})


def preset_name(name):
    """`name` in lower case as PRESETS spells it: a spring preset's former name (before the
    `_springs` ending kept them apart from the measured Fabric presets: "denim" was both)
    gives its new one with a DeprecationWarning."""
    if not isinstance(name, str):
        return name
    name = name.lower()
    if name in FORMER_NAMES:
        warnings.warn(f"the spring Material preset {name!r} is now {FORMER_NAMES[name]!r} "
                      "(spring presets end in _springs, apart from the measured fabrics: "
                      f"Fabric.preset / fabric = {name!r} is another cloth where one exists)",
                      DeprecationWarning, stacklevel=3)
        return FORMER_NAMES[name]
    return name


# Densities are typical fabric weights; stiffnesses are per-spring constants chosen so the
# fabrics look right at 16-64 particles per metre (on a square grid a spring constant is a 2-D
# modulus of the sheet, the same at every resolution for stretch and shear; no bend spring
# gives the sheet a bending stiffness that stays: docs/integrators.md, resolution).
# Named "<cloth>_springs" so that none is taken for a measured Fabric preset (body/fabric.py).
PRESETS: dict[str, dict] = {
    "silk_springs": dict(density=0.06, stretch=SpringParams(2e3, 0.2),
                         shear=SpringParams(50.0, 0.02), bend=SpringParams(0.5, 0.001)),
    "cotton_springs": dict(density=0.15, stretch=SpringParams(5e3, 0.5),
                           shear=SpringParams(2e2, 0.05), bend=SpringParams(5.0, 0.005)),
    "denim_springs": dict(density=0.40, stretch=SpringParams(2e4, 2.0),
                          shear=SpringParams(1e3, 0.2), bend=SpringParams(50.0, 0.02)),
    "rubber_springs": dict(density=1.0, stretch=SpringParams(1e3, 0.5),
                           shear=SpringParams(1e3, 0.5), bend=SpringParams(20.0, 0.02)),
}
FORMER_NAMES = {name.removesuffix("_springs"): name for name in PRESETS}
