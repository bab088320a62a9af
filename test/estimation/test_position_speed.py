"""Whether the motor's position and speed agree: the median of the moving blocks' ratios."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from prsm_health.actuator import Actuator
from prsm_health.estimation import HealthEstimator
from prsm_health.estimation.noise_history import HISTORY_BLOCKS
from prsm_health.estimation.params import EstimatorParams
from prsm_health.estimation.position_speed import PositionPerSpeed, disagreement
from prsm_health.physics.presets import load_preset
from prsm_health.signals import MotorSamples
from test.estimation.test_noise_history import moving_run

PARAMS = EstimatorParams(actuator=Actuator(preset=load_preset("dong2022-downhole")))


def test_the_median_of_the_last_blocks_once_there_are_enough() -> None:
    ratios = PositionPerSpeed()
    ones = np.ones(HISTORY_BLOCKS - 1)
    ratios.add(ones, ones, np.ones(HISTORY_BLOCKS - 1, dtype=np.bool_))
    assert ratios.ratio is None
    # Unmeasured blocks, no travel and a non-finite change do not count.
    ratios.add(
        np.array([5.0, 1.0, math.nan, -0.2]),
        np.array([1.0, 0.0, 1.0, -0.1]),
        np.array([False, True, True, True]),
    )
    assert ratios.ratio == 1.0  # 63 ones and a 2
    ratios.add(np.full(HISTORY_BLOCKS, 0.3), np.ones(HISTORY_BLOCKS), np.ones(HISTORY_BLOCKS, bool))
    assert ratios.ratio == pytest.approx(0.3)  # only the last HISTORY_BLOCKS


@pytest.mark.parametrize(
    ("ratio", "agrees"),
    [
        (None, True),
        (1.0, True),
        (1.09, True),
        (0.92, True),
        (1.2, False),
        (0.2, False),
        (57.3, False),
        (-1.0, False),
    ],
)
def test_what_disagrees(ratio: float | None, agrees: bool) -> None:
    said = disagreement(ratio)
    assert (said is None) == agrees
    if not agrees:
        assert said is not None and f"moves {ratio:.3g} rad per rad the speed says" in said


@pytest.mark.parametrize(
    ("position_factor", "wrap", "expected"),
    [
        (1.0, False, 1.0),
        (1.0, True, 1.0),
        (0.2, False, 0.2),
        (180.0 / math.pi, False, 57.3),
        (-1.0, False, -1.0),
        (-1.0, True, -1.0),
    ],
)
def test_the_estimator_measures_how_far_the_position_moves_per_speed(
    position_factor: float, wrap: bool, expected: float
) -> None:
    """A position of the screw's behind a 5:1 gear, in degrees, or counting the other way is
    seen; wrapped into one turn it is not a mistake. The same whatever the chunks."""
    run = moving_run(4.0, 0.5, seed=2)
    position = run.position_rad * position_factor
    if wrap:
        position = np.mod(position + math.pi, 2.0 * math.pi) - math.pi
    run = dataclasses.replace(run, position_rad=position)
    found = []
    for size in (len(run), 37):
        estimator = HealthEstimator(PARAMS)
        for start in range(0, len(run), size):
            estimator.process(run[start : start + size])
        assert estimator.input_measures.position_per_speed is not None
        found.append(estimator.input_measures.position_per_speed)
    assert found[0] == pytest.approx(expected, rel=2e-3)
    assert found[1] == found[0]


def test_nothing_is_said_before_enough_motion() -> None:
    estimator = HealthEstimator(PARAMS)
    estimator.process(moving_run(1.0, 0.5, seed=2))
    assert estimator.input_measures.position_per_speed is None
    standing = MotorSamples(*(np.zeros(4000) for _ in range(4)))
    standing = dataclasses.replace(standing, stamp_s=np.arange(4000) / 1000.0)
    estimator = HealthEstimator(PARAMS)
    estimator.process(standing)
    assert estimator.input_measures.position_per_speed is None
