"""The elastic and inertial constants of a rod (:class:`Material`), with the stiffest
modulus a Material accepts and the one an "inextensible" rod stretches with."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import validation

#: Young's modulus [Pa] of the stretching term of an "inextensible" rod: the
#: weight of a 1 m rod of density 1000 kg/m^3 then strains it by about 1e-6.
INEXTENSIBLE_MODULUS = 1e10
#: The stiffest modulus [Pa] a Material accepts: above any material (diamond: 1.2e12 Pa);
#: an implicit step loses positive definiteness near 1e22 Pa.
MAX_MODULUS = 1e13


@dataclass(frozen=True)
class Material:
    """Elastic and inertial constants of a rod with an elliptic (default: circular) section.

    young: Young's modulus E [Pa].
    density: rho [kg/m^3].
    radius: semi-axis a of the section along the first material director m1 [m].
    radius2: semi-axis b along m2 [m]; None for a circle (b = a).
    shear: shear modulus G [Pa]; None to use young / (2 (1 + poisson)).
    poisson: Poisson's ratio nu, used only when shear is None (-1 < nu <= 0.5).
    """

    young: float
    density: float = 1000.0
    radius: float = 0.01
    radius2: float | None = None
    shear: float | None = None
    poisson: float = 0.5

    def __post_init__(self):
        validation.material(self)

    @property
    def b(self) -> float:
        return self.radius if self.radius2 is None else self.radius2

    @property
    def shear_modulus(self) -> float:
        """G [Pa]."""
        return self.shear if self.shear is not None else self.young / (2.0 * (1.0 + self.poisson))

    @property
    def area(self) -> float:
        """Cross-section area A = pi a b [m^2]."""
        return np.pi * self.radius * self.b

    @property
    def second_moments(self) -> tuple[float, float]:
        """(I1, I2) [m^4]: about m1 (bending in the t-m2 plane) and about m2."""
        a, b = self.radius, self.b
        return np.pi * a * b**3 / 4.0, np.pi * a**3 * b / 4.0

    @property
    def bend_stiffness(self) -> tuple[float, float]:
        """(B1, B2) = (E I1, E I2) [N m^2]."""
        i1, i2 = self.second_moments
        return self.young * i1, self.young * i2

    @property
    def alpha(self) -> float:
        """Isotropic bending stiffness E I [N m^2] (the mean of B1 and B2)."""
        return 0.5 * sum(self.bend_stiffness)

    @property
    def beta(self) -> float:
        """Twisting stiffness G J [N m^2], J = pi a^3 b^3 / (a^2 + b^2) (2 I for a circle)."""
        a, b = self.radius, self.b
        return self.shear_modulus * np.pi * a**3 * b**3 / (a**2 + b**2)

    @property
    def isotropic(self) -> bool:
        return self.radius2 is None or self.radius2 == self.radius

    @property
    def stretch_stiffness(self) -> float:
        """E A [N]."""
        return self.young * self.area

    @property
    def line_density(self) -> float:
        """Mass per length rho A [kg/m]."""
        return self.density * self.area
