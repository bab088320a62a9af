"""Whether the motor current works with the motion: each direction's median torque along it."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from prsm_health.estimation import HealthEstimator
from prsm_health.estimation.motion_torque import TorqueAlongMotion, against_motion
from prsm_health.estimation.noise_history import HISTORY_BLOCKS
from prsm_health.signals import MotorSamples
from test.estimation.test_noise_history import moving_run
from test.estimation.test_position_speed import PARAMS


def test_each_direction_has_the_median_of_its_last_blocks() -> None:
    torques = TorqueAlongMotion()
    n = HISTORY_BLOCKS
    forward, reverse = np.ones(n, dtype=np.int64), -np.ones(n, dtype=np.int64)
    everything = np.ones(n, dtype=np.bool_)
    torques.add(np.full(n, 3.0), forward, everything)
    assert torques.medians_nm == (3.0, None)
    # Standing and unmeasured blocks do not count; a reverse block's torque along the
    # motion is minus its torque.
    torques.add(
        np.r_[np.full(n, -2.0), 50.0, -50.0, 9.0],
        np.r_[reverse, 0, -1, 1],
        np.r_[everything, True, False, False],
    )
    assert torques.medians_nm == (3.0, 2.0)
    torques.add(np.full(n, -4.0), forward, everything)
    assert torques.medians_nm == (-4.0, 2.0)  # only the last HISTORY_BLOCKS


@pytest.mark.parametrize(
    ("forward", "reverse", "wrong"),
    [
        (None, None, False),
        (-5.0, None, False),
        (5.0, 7.0, False),
        (5.0, -1.0, False),  # a weight lifted, then lowered
        (-0.5, 0.0, False),
        (-5.35, -7.01, True),  # a current of the other sign
    ],
)
def test_what_brakes_the_motion_both_ways(
    forward: float | None, reverse: float | None, wrong: bool
) -> None:
    said = against_motion(forward, reverse)
    assert (said is not None) == wrong
    if wrong:
        assert said == (
            "the motor brakes the motion both ways (-5.35 N·m along it forward, -7.01 N·m "
            "reverse): a current of the other sign, or a load that pushes whichever way the "
            "screw moves?"
        )


def there_and_back(forward_current_a: float, reverse_current_a: float) -> MotorSamples:
    """4 s forward at 150 rad/s, then 4 s back, with these (noisy) currents."""
    there = moving_run(4.0, 0.5, seed=2)
    back = moving_run(4.0, 0.5, seed=3)
    back = MotorSamples(
        back.stamp_s + 4.0,
        back.current_a - 5.0 + reverse_current_a,
        -back.speed_rad_s,
        there.position_rad[-1] - back.position_rad,
    )
    there = dataclasses.replace(there, current_a=there.current_a - 5.0 + forward_current_a)
    return MotorSamples.concatenate([there, back])


@pytest.mark.parametrize(
    ("forward_a", "reverse_a", "wrong"),
    [(5.0, -5.0, False), (5.0, 2.0, False), (-5.0, 5.0, True)],
)
def test_the_estimator_measures_the_torque_along_the_motion(
    forward_a: float, reverse_a: float, wrong: bool
) -> None:
    """A load resisting both ways, one that keeps its direction (braked on the way back), and
    the first with the current of the other sign. The same whatever the chunks."""
    run = there_and_back(forward_a, reverse_a)
    torque_constant = PARAMS.actuator.drive_train.torque_constant_nm_per_a
    found = []
    for size in (len(run), 37):
        estimator = HealthEstimator(PARAMS)
        for start in range(0, len(run), size):
            estimator.process(run[start : start + size])
        found.append(estimator.input_measures.torque_along_motion_nm)
    forward, reverse = found[0]
    assert forward == pytest.approx(torque_constant * forward_a, rel=0.01)
    assert reverse == pytest.approx(-torque_constant * reverse_a, rel=0.01)
    assert found[1] == found[0]
    assert (against_motion(forward, reverse) is not None) == wrong
