"""Model parameters beyond geometry: friction/lubrication, wear and fatigue (SI units).

Each dataclass is validated at construction (finite, positive, in range) and names the bad
field in its error. Defaults are the documented standard values of docs/physics.md; presets
override them from their paper's tables.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from prsm_health.physics.geometry import require, require_finite_positive

WearModel = Literal["archard", "fractal"]


@dataclass(frozen=True, kw_only=True)
class FrictionParameters:
    """Friction torque model of paper 002 (eq. 2-14) and its lubricant.

    hysteresis_loss_coefficient: gamma of eq. 2 (002 Table 1 "energy loss coefficient" 0.008).
    sliding_friction_coefficient: f_s of eq. 3, 4, 15 (lubricated steel; 002 uses 0.2 dry in FE).
    lubricant_viscosity_pa_s: eta_0 of eq. 8 (ISO VG 46 mineral oil near 40 C).
    pressure_viscosity_coefficient_per_pa: alpha_p of eq. 7.
    """

    hysteresis_loss_coefficient: float = 0.008
    sliding_friction_coefficient: float = 0.1
    lubricant_viscosity_pa_s: float = 0.04
    pressure_viscosity_coefficient_per_pa: float = 2.2e-8

    def __post_init__(self) -> None:
        require_finite_positive(self, "friction")
        require(
            self.sliding_friction_coefficient < 1.0,
            "friction.sliding_friction_coefficient",
            "must be < 1",
        )


@dataclass(frozen=True, kw_only=True)
class WearParameters:
    """Wear of the screw-roller flanks: modified Archard (paper 004) or fractal (paper 001).

    archard_coefficient: K of 004 section 2.7 (3.3e-7).
    adhesive_wear_coefficient: K_w of 001 eq. 32 (1.69e-11, 001 section 3).
    surface_roughness_ra_m: Ra of 001 eq. 4-5 (Ra 0.3 um in 001 Table 2).
    model: "archard" (004, the precision loss with 004's K) or "fractal" (001, real contact
    area of the rough flanks). Presets choose; "fractal" reproduces 001's published rate.
    """

    model: WearModel = "fractal"
    archard_coefficient: float = 3.3e-7
    adhesive_wear_coefficient: float = 1.69e-11
    surface_roughness_ra_m: float = 0.3e-6

    def __post_init__(self) -> None:
        require_finite_positive(self, "wear")
        require(self.model in ("archard", "fractal"), "wear.model", "must be archard or fractal")


#: Smallest ``reference_cycles`` (N_0) accepted: a reference life of less than one stress
#: cycle has no physical meaning, and near 1e-300 the damage rate overflows.
MIN_REFERENCE_CYCLES = 1.0


@dataclass(frozen=True, kw_only=True)
class FatigueParameters:
    """Stress-life fatigue of paper 000 eq. 29: N_s = k_alpha^m_s N_0.

    reference_cycles: N_0 (000 section 5: 2.5e8).
    stress_exponent: m_s (000 section 5: 6).
    reference_pressure_pa: the Hertz maximum pressure at which a contact survives N_0 cycles;
    the stress ratio is k_alpha = reference_pressure_pa / p_max (our definition, which 000
    leaves open; see docs/physics.md). 2.69 GPa makes 000's case 1 at F_a = 20 kN,
    F_r = 4 kN, 300 rpm (peak screw-roller p_max 2.418 GPa) last the published ~7,000 h.
    """

    reference_cycles: float = 2.5e8
    stress_exponent: float = 6.0
    reference_pressure_pa: float = 2.69e9

    def __post_init__(self) -> None:
        require_finite_positive(self, "fatigue")
        require(
            self.reference_cycles >= MIN_REFERENCE_CYCLES,
            "fatigue.reference_cycles",
            f"must be at least {MIN_REFERENCE_CYCLES:g} (a life of less than one stress cycle "
            f"means nothing, and the damage rate divides by it), got {self.reference_cycles!r}",
        )
