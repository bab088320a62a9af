"""What the estimator says at each update: the content of ``HealthEstimate`` (SI inside)."""

from __future__ import annotations

import enum
from dataclasses import dataclass

#: Metres to micrometres, and per second to per hour, at the message edge.
UM_PER_M = 1e6
S_PER_H = 3600.0


class EstimateEvent(enum.IntEnum):
    """What happened at this estimate (``HealthEstimate.EVENT_*``).

    One per estimate, the first that applies in this order: TIME_RESET (the estimate starts a
    new time line: its stamp may lie before the previous one's, and the evaluation splits the
    time lines there), DIVERGENCE_RECOVERED (the load was re-initialised; on the block of a
    time reset it is said by the next estimate instead, so that neither is lost: unless the
    input ends there, or a maintenance reset comes first, after which it is no news),
    STANDSTILL, NONE.
    """

    NONE = 0
    STANDSTILL = 1
    TIME_RESET = 2
    DIVERGENCE_RECOVERED = 3


@dataclass(frozen=True)
class HealthState:
    """One health estimate (one filter update).

    axial_load_n: signed load (> 0 resists positive motor rotation); the message carries its
    magnitude. jam_probabilities[k]: probability that k rollers are jammed (sums to 1).
    precision_loss_m and its std, rate [m/s]; friction_torque_nm (magnitude), efficiency
    (paper 002 eq. 19); fatigue_damage (Miner) and its std; screw_speed_rad_s; samples
    accepted and rejected from the start up to the block's last accepted sample, in input
    order (:class:`~prsm_health.estimation.inputs.Block`: the same however the samples were
    chunked); nis: mean normalised innovation squared over the divergence window (about 1
    when the filter is consistent); event.
    """

    stamp_s: float
    axial_load_n: float
    axial_load_std_n: float
    jam_probabilities: tuple[float, ...]
    precision_loss_m: float
    precision_loss_std_m: float
    precision_loss_rate_m_per_s: float
    friction_torque_nm: float
    efficiency: float
    fatigue_damage: float
    fatigue_damage_std: float
    screw_speed_rad_s: float
    samples_accepted: int
    samples_rejected: int
    nis: float
    event: EstimateEvent

    @property
    def jammed_rollers_most_likely(self) -> int:
        """The jam count with the largest probability."""
        return max(range(len(self.jam_probabilities)), key=self.jam_probabilities.__getitem__)
