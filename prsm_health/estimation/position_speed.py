"""Whether the motor's position and speed agree: how far the position moves per radian of
travel the speed says, measured in motion.

Each moving block of two samples or more gives the ratio of its position change (first to
last sample, the turns of wrapped positions added: inputs.py) to the travel its speeds say
(their trapezoidal integral over the same samples). The ratio reported is the median of the
last ``noise_history.HISTORY_BLOCKS`` of them: 1 when both are of the motor shaft, in radians.
A position in degrees reads 57.3, in turns 0.159; a position of the screw's reads one over
the gear ratio, a speed of the screw's the gear ratio; a position or speed of the other sign
-1. Nothing else checks such a mistake, and the estimator runs on with it: on the sudden-jam
bag (gear 5:1) a position of the screw's gave 6 false jam declarations and 79 % too little
precision loss (the wear follows the travel, inputs.py), a position in degrees a load NEES of
979, a speed of the other sign a load of the other sign (docs/estimation.md, "Numerical
safety", "Position against speed"). The input-health status says so (outputs.py). (A speed
in rpm is mostly rejected as out of range, which that status says too; a current of the other
sign agrees with position and speed, and motion_torque.py sees it.)
"""

from __future__ import annotations

import numpy as np

from prsm_health.estimation.recent_median import RecentMedian
from prsm_health.signals import BoolArray, FloatArray

#: Position and speed agree within this factor either way (a speed sensor's calibration is
#: good to a few percent; the mistakes this catches are factors of 1.5 and more).
AGREEMENT = 1.1


class PositionPerSpeed:
    """The median of the last HISTORY_BLOCKS blocks' position change per travel of their
    speeds (:class:`~prsm_health.estimation.recent_median.RecentMedian`)."""

    def __init__(self) -> None:
        self._ratios = RecentMedian()

    @property
    def ratio(self) -> float | None:
        """Position change per radian of the speeds' travel (module docstring), None before
        HISTORY_BLOCKS blocks have been measured."""
        return self._ratios.median

    def add(self, moved_rad: FloatArray, travel_rad: FloatArray, measured: BoolArray) -> None:
        """Record a batch of blocks, in order: each one's position change and its speeds'
        travel [rad], and whether it is measured (moving, two samples or more)."""
        usable = measured & (travel_rad != 0.0) & np.isfinite(moved_rad)
        self._ratios.add(moved_rad[usable] / travel_rad[usable])


def disagreement(ratio: float | None) -> str | None:
    """What is wrong when the position moves more than AGREEMENT times as far as the speed
    says, or less than 1/AGREEMENT as far, or the other way (None when it agrees, or is not
    measured yet)."""
    if ratio is None or 1.0 / AGREEMENT <= ratio <= AGREEMENT:
        return None
    return (
        f"the position moves {ratio:.3g} rad per rad the speed says (a unit, a sign, or the "
        "gear ratio between them?)"
    )
