"""Whether the motor current works with the motion: the motor torque along the motion in each
direction, measured in motion.

Each moving block of two samples or more gives its mean motor torque k_t i times its
direction of motion, d T [N·m] (positive: the motor drives the motion, negative: it brakes
it). The value reported per direction is the median of that direction's last
``noise_history.HISTORY_BLOCKS`` blocks (recent_median.py). The friction of the screw always
resists the motion (002 eq. 12-19), so the motor drives it at least in one direction: a load
that resists the motion (the downhole traction, 000 section 5) makes both positive, one that
keeps its direction (a weight lifted and lowered) one positive and one negative. Both
negative is a load that pushes whichever way the screw moves, or, far more often, a current
of the other sign than the drive's convention (docs/ros.md). The estimator would run on with
it as an assisting load larger than the true one: on the sudden-jam bag a load RMSE of 150 %,
3 false jam declarations and a load NEES of 18,147 (docs/estimation.md, "Numerical safety",
"Position against speed"; this check: "Current against the motion"). The input-health status
says so (outputs.py).
"""

from __future__ import annotations

from prsm_health.estimation.recent_median import RecentMedian
from prsm_health.signals import BoolArray, FloatArray, IntArray


class TorqueAlongMotion:
    """The median of each direction's last HISTORY_BLOCKS moving blocks' torque along the
    motion (module docstring)."""

    def __init__(self) -> None:
        self._forward = RecentMedian()
        self._reverse = RecentMedian()

    @property
    def medians_nm(self) -> tuple[float | None, float | None]:
        """The motor torque along the motion [N·m], forward and reverse; None for a direction
        before HISTORY_BLOCKS of its blocks have been measured."""
        return self._forward.median, self._reverse.median

    def add(self, torque_nm: FloatArray, direction: IntArray, measured: BoolArray) -> None:
        """Record a batch of blocks, in order: each one's mean motor torque [N·m], its
        direction of motion (1, -1, 0) and whether it is measured (moving, two samples or
        more)."""
        self._forward.add(torque_nm[measured & (direction > 0)])
        self._reverse.add(-torque_nm[measured & (direction < 0)])


def against_motion(forward_nm: float | None, reverse_nm: float | None) -> str | None:
    """What is wrong when the motor brakes the motion in both directions (None when it drives
    it in one of them at least, or a direction is not measured yet)."""
    if forward_nm is None or reverse_nm is None or max(forward_nm, reverse_nm) >= 0.0:
        return None
    return (
        f"the motor brakes the motion both ways ({forward_nm:+.2f} N·m along it forward, "
        f"{reverse_nm:+.2f} N·m reverse): a current of the other sign, or a load that pushes "
        "whichever way the screw moves?"
    )
