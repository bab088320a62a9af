"""Accumulated precision loss and fatigue damage, with their uncertainty.

Neither is observable in motor current: both are integrated from the physics core's rates at
the estimated load, speed and jam count (the surrogate's wear rates, 001 eq. 30-38 / 004
eq. 32-35, and Miner damage from 000 eq. 29), weighted by the jam probabilities:

    loss += sum_k mu_k rate_k(F_k, w) dt

The uncertainty has four parts, each accumulated as a fully correlated (linear) sum because
their errors persist over time (a load error or a wrong jam count does not average out over
consecutive blocks): the load uncertainty, sum_k mu_k |d rate_k/dF| sigma_F,k dt; the jam
count, the spread of rate_k over the hypotheses; the radial load, a relative sensitivity of
the wear rate to the radial-ratio uncertainty; and the wear coefficient, a log-normal factor
with median 1 and spread ``wear_coefficient_sigma_ln`` on the whole loss. The first three add
linearly (conservative), the coefficient in quadrature.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from prsm_health.estimation.measurement import Prediction


@dataclass
class Degradation:
    """Accumulated state (SI): loss [m] and its correlated error terms, damage and error."""

    precision_loss_m: float = 0.0
    load_error_m: float = 0.0
    jam_error_m: float = 0.0
    radial_error_m: float = 0.0
    fatigue_damage: float = 0.0
    fatigue_error: float = 0.0
    rate_m_per_s: float = 0.0

    def to_dict(self) -> dict[str, float]:
        """Plain numbers for persistence."""
        return asdict(self)


class DegradationIntegrator:
    """Integrates :class:`Degradation` block by block (see the module docstring)."""

    def __init__(
        self,
        *,
        wear_coefficient_sigma_ln: float,
        radial_relative_sensitivity: float,
    ) -> None:
        sigma = wear_coefficient_sigma_ln
        # Standard deviation of a log-normal factor with median 1.
        self._factor_std = math.sqrt(math.expm1(sigma**2) * math.exp(sigma**2))
        self._radial = radial_relative_sensitivity
        self.state = Degradation()

    def add(
        self,
        duration_s: float,
        weights: list[float],
        predictions: list[Prediction],
        load_std_n: list[float],
    ) -> None:
        """Integrate one block of ``duration_s`` under the hypotheses' predictions (the
        lists are aligned: probability, prediction and load std of each hypothesis)."""
        parts = list(zip(weights, predictions, load_std_n, strict=True))
        rate = sum(mu * p.precision_loss_rate_m_per_s for mu, p, _ in parts)
        spread = math.sqrt(
            sum(mu * (p.precision_loss_rate_m_per_s - rate) ** 2 for mu, p, _ in parts)
        )
        load_rate_error = sum(mu * abs(p.precision_loss_rate_slope) * std for mu, p, std in parts)
        damage_rate = sum(mu * p.fatigue_rate_per_s for mu, p, _ in parts)
        damage_error = sum(
            mu * abs(p.fatigue_rate_slope) * std for mu, p, std in parts
        ) + math.sqrt(sum(mu * (p.fatigue_rate_per_s - damage_rate) ** 2 for mu, p, _ in parts))
        s = self.state
        s.rate_m_per_s = rate
        s.precision_loss_m += rate * duration_s
        s.load_error_m += load_rate_error * duration_s
        s.jam_error_m += spread * duration_s
        s.radial_error_m += self._radial * rate * duration_s
        s.fatigue_damage += damage_rate * duration_s
        s.fatigue_error += damage_error * duration_s

    def stop(self) -> None:
        """No motion: the rate is zero (nothing is integrated at standstill)."""
        self.state.rate_m_per_s = 0.0

    def reset(self, *, precision_loss: bool, fatigue_damage: bool) -> None:
        """Parts replaced: the precision loss (with its error terms) and/or the fatigue damage
        (with its error) start again from zero."""
        s = self.state
        if precision_loss:
            s.precision_loss_m = s.load_error_m = s.jam_error_m = s.radial_error_m = 0.0
        if fatigue_damage:
            s.fatigue_damage = s.fatigue_error = 0.0

    @property
    def precision_loss_std_m(self) -> float:
        """Standard deviation of the accumulated precision loss."""
        s = self.state
        correlated = s.load_error_m + s.jam_error_m + s.radial_error_m
        return math.hypot(self._factor_std * s.precision_loss_m, correlated)

    @property
    def fatigue_damage_std(self) -> float:
        """Standard deviation of the Miner damage (load and jam uncertainty)."""
        return self.state.fatigue_error
