"""Hertz point contact at the screw-roller and roller-nut interfaces, exact elliptic solution.

Curvatures follow paper 004 eq. 23-25: the roller flank is an arc of radius R = r_r / sin(beta)
(both principal curvatures 1/R), the screw flank is straight in profile and curved
circumferentially, cos(beta) / (r_s + r_r - R cos(beta)); the nut is concave,
-cos(beta) / (r_s + r_r + R cos(beta)). The contact ellipse follows Harris & Kotzalas (Rolling
Bearing Analysis, ch. 6): the ellipticity kappa = a/b solves
F(rho) = ((kappa^2 + 1) E(m) - 2 K(m)) / ((kappa^2 - 1) E(m)), m = 1 - 1/kappa^2, with the
complete elliptic integrals K and E. Everything load-independent is computed once per geometry
(:func:`contact_pair`, cached) and the load-dependent formulas are vectorised over loads.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import brentq
from scipy.special import ellipe, ellipk

from prsm_health.physics.errors import ParameterError
from prsm_health.physics.geometry import Geometry, Material

FloatArray = NDArray[np.float64]


def _curvature_difference(kappa: float) -> float:
    """F(rho) as a function of the ellipticity kappa = a/b >= 1 (Harris eq. 6.26).

    Near kappa = 1 the closed form cancels catastrophically (0/0 at 1); there the series
    F = 3/4 (kappa - 1) is used.
    """
    if kappa - 1.0 < 1e-6:
        return 0.75 * (kappa - 1.0)
    m = 1.0 - 1.0 / kappa**2
    big_k, big_e = float(ellipk(m)), float(ellipe(m))
    return ((kappa**2 + 1.0) * big_e - 2.0 * big_k) / ((kappa**2 - 1.0) * big_e)


def ellipticity(curvature_difference: float) -> float:
    """kappa = a/b for a curvature difference F(rho) in [0, 1) (root of Harris eq. 6.26)."""
    if not 0.0 <= curvature_difference < 1.0:
        raise ParameterError(
            "curvature_difference", f"must be in [0, 1), got {curvature_difference!r}"
        )
    if curvature_difference < 0.75e-6:
        return 1.0 + curvature_difference / 0.75  # the series branch of _curvature_difference
    # F(kappa) rises monotonically from 0 at kappa = 1 towards 1 as kappa -> infinity.
    return float(brentq(lambda k: _curvature_difference(k) - curvature_difference, 1.0 + 1e-6, 1e4))


@dataclass(frozen=True)
class ContactPair:
    """Load-independent Hertz constants of one interface (all SI).

    curvature_sum_per_m: sum of the four principal curvatures, Sum rho.
    curvature_difference: F(rho).
    kappa: ellipticity a/b; a_star, b_star, delta_star: dimensionless Harris coefficients
    (the m_a, m_b of papers 001 eq. 36 and 004 eq. 26 are a_star, b_star; 001 eq. 36 prints
    E_0 where the compliance 1/E_0 belongs, 004 eq. 20 has it right).
    compliance_per_pa: (1 - nu1^2)/E1 + (1 - nu2^2)/E2.
    """

    curvature_sum_per_m: float
    curvature_difference: float
    kappa: float
    elliptic_k: float
    elliptic_e: float
    a_star: float
    b_star: float
    delta_star: float
    compliance_per_pa: float

    @property
    def _size_per_n(self) -> float:
        """(3 eta / (2 Sum rho)), the load-independent factor of the semi-axes cubed (004 eq.
        26, Harris eq. 6.39-6.40)."""
        return 3.0 * self.compliance_per_pa / (2.0 * self.curvature_sum_per_m)

    @property
    def deflection_constant(self) -> float:
        """K_h in delta = K_h Q^(2/3) [m N^-2/3] (Harris eq. 6.43; paper 004 eq. 19-20)."""
        return float(
            self.delta_star * self.curvature_sum_per_m / 2.0 * self._size_per_n ** (2.0 / 3.0)
        )

    def semi_axes_m(self, normal_load_n: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Semi-major and semi-minor axes a, b of the contact ellipse (004 eq. 26)."""
        scale = np.cbrt(np.maximum(np.asarray(normal_load_n, dtype=float), 0.0) * self._size_per_n)
        return self.a_star * scale, self.b_star * scale

    def approach_m(self, normal_load_n: ArrayLike) -> FloatArray:
        """Normal approach delta = K_h Q^(2/3) (004 eq. 19)."""
        load = np.maximum(np.asarray(normal_load_n, dtype=float), 0.0)
        return np.asarray(self.deflection_constant * np.cbrt(load) ** 2, dtype=np.float64)

    def load_n(self, approach_m: ArrayLike) -> FloatArray:
        """Normal load Q = (max(delta, 0) / K_h)^(3/2), 004 eq. 19 inverted: smooth through loss
        of contact."""
        approach = np.maximum(np.asarray(approach_m, dtype=float), 0.0)
        return np.asarray((approach / self.deflection_constant) ** 1.5, dtype=np.float64)

    def max_pressure_pa(self, normal_load_n: ArrayLike) -> FloatArray:
        """p_max = 3 Q / (2 pi a b), the peak of 002 eq. 3's Hertz pressure (the stress of 000
        eq. 29's fatigue ratio); 0 where the contact is unloaded."""
        load = np.maximum(np.asarray(normal_load_n, dtype=float), 0.0)
        a, b = self.semi_axes_m(load)
        area = np.where(load > 0.0, a * b, 1.0)
        return np.where(load > 0.0, 3.0 * load / (2.0 * math.pi * area), 0.0)


def make_contact_pair(
    curvatures_body1: tuple[float, float],
    curvatures_body2: tuple[float, float],
    material1: Material,
    material2: Material,
) -> ContactPair:
    """Hertz constants for two bodies given their principal curvatures (convex positive): the
    curvature sum and difference of 004 eq. 23-25, the ellipticity and the coefficients a*,
    b*, delta* of 004 eq. 20 and 26 (Harris eq. 6.26-6.43), the compliance of 001 eq. 9."""
    (r11, r12), (r21, r22) = curvatures_body1, curvatures_body2
    total = r11 + r12 + r21 + r22
    if not total > 0.0:
        raise ParameterError("curvature", f"curvature sum must be > 0, got {total!r}")
    difference = abs((r11 - r12) + (r21 - r22)) / total
    kappa = ellipticity(difference)
    m = 1.0 - 1.0 / kappa**2
    big_k, big_e = float(ellipk(m)), float(ellipe(m))
    return ContactPair(
        curvature_sum_per_m=total,
        curvature_difference=difference,
        kappa=kappa,
        elliptic_k=big_k,
        elliptic_e=big_e,
        a_star=(2.0 * kappa**2 * big_e / math.pi) ** (1.0 / 3.0),
        b_star=(2.0 * big_e / (math.pi * kappa)) ** (1.0 / 3.0),
        delta_star=2.0 * big_k / math.pi * (math.pi / (2.0 * kappa**2 * big_e)) ** (1.0 / 3.0),
        compliance_per_pa=material1.compliance_per_pa + material2.compliance_per_pa,
    )


@dataclass(frozen=True)
class ThreadContacts:
    """The two Hertz interfaces of a PRSM thread: screw-roller and roller-nut."""

    screw_roller: ContactPair
    roller_nut: ContactPair


@cache
def thread_contacts(geometry: Geometry) -> ThreadContacts:
    """Hertz constants of both interfaces, computed once per geometry (004 eq. 23-26)."""
    cos_beta = math.cos(geometry.flank_angle_rad)
    ball = geometry.effective_ball_radius_m
    roller = (1.0 / ball, 1.0 / ball)
    centre = geometry.carrier_radius_m
    screw = (0.0, cos_beta / (centre - ball * cos_beta))
    nut = (0.0, -cos_beta / (centre + ball * cos_beta))
    return ThreadContacts(
        screw_roller=make_contact_pair(roller, screw, geometry.roller, geometry.screw),
        roller_nut=make_contact_pair(roller, nut, geometry.roller, geometry.nut),
    )
