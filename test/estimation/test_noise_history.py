"""The speed noise measured in motion: the median of the moving blocks' speed variances."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from prsm_health.actuator import Actuator
from prsm_health.estimation.inputs import MEDIAN_OF_THREE_VARIANCE, SampleBlocker
from prsm_health.estimation.noise_history import HISTORY_BLOCKS, MIN_SAMPLES, NoiseHistory
from prsm_health.estimation.params import EstimatorParams, NoiseParams
from prsm_health.physics.presets import load_preset
from prsm_health.signals import MotorSamples

PARAMS = EstimatorParams(actuator=Actuator(preset=load_preset("dong2022-downhole")))
#: The span between the middle samples of the first and last three of 40 samples 1 ms apart.
SPAN_S = 0.037


def params_with_speed_std(std: float) -> EstimatorParams:
    return dataclasses.replace(PARAMS, noise=NoiseParams(speed_std_rad_s=std))


def moving_run(seconds: float, speed_std: float, seed: int) -> MotorSamples:
    """1 kHz at 150 rad/s with white speed noise; the position integrates the true speed."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * 1000.0)) / 1000.0
    return MotorSamples(
        t + 0.1,
        5.0 + rng.normal(0.0, 0.05, len(t)),
        150.0 + rng.normal(0.0, speed_std, len(t)),
        150.0 * t,
    )


def test_the_floor_holds_until_the_history_is_full_then_the_median_above_it() -> None:
    noise = NoiseHistory(0.1)
    variances = np.r_[np.full(HISTORY_BLOCKS - 1, 4.0), 9.0, 1e-6]
    used = noise.variances(variances, np.ones(len(variances), dtype=np.bool_))
    assert used[: HISTORY_BLOCKS - 1].tolist() == [pytest.approx(0.01)] * (HISTORY_BLOCKS - 1)
    assert used[HISTORY_BLOCKS - 1] == 4.0  # the median of 63 x 4 and one 9
    assert used[HISTORY_BLOCKS] == 4.0  # the median of 62 x 4, a 9 and a 1e-6
    assert noise.measured_std == 2.0
    quiet = NoiseHistory(3.0)
    assert (
        quiet.variances(np.full(HISTORY_BLOCKS, 4.0), np.ones(HISTORY_BLOCKS, np.bool_))[-1] == 9.0
    )


def test_unmeasured_blocks_neither_count_nor_move_the_median() -> None:
    noise = NoiseHistory(0.1)
    variances = np.r_[np.full(HISTORY_BLOCKS, 4.0), 1e6]
    measured = np.r_[np.ones(HISTORY_BLOCKS, np.bool_), False]
    used = noise.variances(variances, measured)
    assert used[-1] == 4.0 and noise.measured_std == 2.0
    alone = NoiseHistory(0.1)
    assert (
        alone.variances(np.full(HISTORY_BLOCKS, 4.0), np.zeros(HISTORY_BLOCKS, np.bool_)).tolist()
        == [pytest.approx(0.01)] * HISTORY_BLOCKS
    )
    assert alone.measured_std is None


def test_the_result_does_not_depend_on_the_batches() -> None:
    rng = np.random.default_rng(3)
    variances = rng.chisquare(38, 300) / 38.0
    measured = rng.random(300) > 0.3
    whole = NoiseHistory(0.5).variances(variances, measured)
    noise = NoiseHistory(0.5)
    pieces = [noise.variances(variances[i : i + 7], measured[i : i + 7]) for i in range(0, 300, 7)]
    assert np.array_equal(np.concatenate(pieces), whole)
    whole_before, after = NoiseHistory(0.5, first_blocks=8).variances_before(variances, measured)
    noise = NoiseHistory(0.5, first_blocks=8)
    batches = [
        noise.variances_before(variances[i : i + 7], measured[i : i + 7]) for i in range(0, 300, 7)
    ]
    assert np.array_equal(np.concatenate([before for before, _ in batches]), whole_before)
    assert batches[-1][1] == after


def test_before_each_block_and_from_the_first_blocks_on() -> None:
    """variances_before takes the blocks before each one (the current's spike threshold: the
    samples after a batch belong to the next block, which the whole batch comes before);
    first_blocks lets the median of the first measured blocks serve until HISTORY_BLOCKS."""
    noise = NoiseHistory(0.1, first_blocks=3)
    variances = np.array([4.0, 9.0, 1e6, 16.0, 25.0])
    measured = np.array([True, True, False, True, True])
    before, after = noise.variances_before(variances, measured)
    # Block 3 follows 4 and 9 (block 2 is not measured): two, fewer than three.
    assert before.tolist() == [pytest.approx(0.01)] * 4 + [9.0]
    assert after == 12.5  # the median of 4, 9, 16 and 25
    assert noise.measured_std == pytest.approx(math.sqrt(12.5))
    assert NoiseHistory(0.1).variances_before(variances, measured)[1] == pytest.approx(0.01)


def test_the_first_block_measured_takes_its_own_variance_from_one_block_on() -> None:
    """With first_blocks 1 (the current's), the first block measured has none before it and
    takes its own variance instead of the floor: the floor alone rejected the tails of a
    current noisier than the parameter in the first block. The blocks after it take those
    before them; a history resumed from a saved state leaves no block its own."""
    variances = np.array([1e6, 4.0, 9.0, 16.0])
    measured = np.array([False, True, True, True])
    before, after = NoiseHistory(0.1, first_blocks=1).variances_before(variances, measured)
    assert before.tolist() == [pytest.approx(0.01), 4.0, 4.0, 6.5]
    assert after == 9.0
    resumed = NoiseHistory(0.1, first_blocks=1)
    resumed.resume([4.0])
    assert resumed.variances_before(np.array([1e6]), np.array([True]))[0].tolist() == [4.0]


def test_a_coarse_encoders_speed_noise_is_measured_not_taken_from_the_parameter() -> None:
    """A drive that differences a 1024-count encoder has about 2 rad/s of speed noise, ten
    times the parameter's 0.2 (docs/performance.md, "The drive's sensors"). After
    HISTORY_BLOCKS moving blocks, each block's acceleration variance is that of the measured
    noise, 2 v sigma^2 / span^2 (v: a median of three's, the block's ends), and matches the
    spread of the blocks' accelerations. (The median
    of 64 variances of 38 degrees of freedom scatters by about 4 %: each block's within 15 %
    of the final one's.)"""
    blocker = SampleBlocker(PARAMS)
    blocks = blocker.feed(moving_run(12.0, 2.0, seed=5)) + blocker.flush()
    full = [b for b in blocks if b.samples == 40][HISTORY_BLOCKS:]
    measured = blocker.speed_noise.measured_std
    assert measured == pytest.approx(2.0, rel=0.05)
    expected = 2.0 * MEDIAN_OF_THREE_VARIANCE * measured**2 / SPAN_S**2
    assert all(b.motor_acceleration_var_rad2_s4 == pytest.approx(expected, rel=0.15) for b in full)
    spread = float(np.var([b.motor_acceleration_rad_s2 for b in full]))
    assert spread == pytest.approx(expected, rel=0.2)  # 236 blocks: about 9 % sampling error


def test_curving_speed_at_stroke_starts_is_not_taken_for_noise() -> None:
    """A quarter of the time the speed curves within its blocks (a 2 Hz swing of 60 rad/s,
    up to 750 rad/s^2: the acceleration changes inside a block as where a stroke starts). Its
    variance about a straight line is the curve's, not noise: the median leaves it out, where
    a mean would read about 1.6 rad/s instead of 0.5."""
    samples = moving_run(12.0, 0.5, seed=6)
    t = samples.stamp_s - 0.1
    curving = (t % 2.0) < 0.5
    samples.speed_rad_s[curving] += 60.0 * np.sin(2.0 * math.pi * 2.0 * t[curving])
    blocker = SampleBlocker(params_with_speed_std(0.01))
    blocker.feed(samples)
    assert blocker.speed_noise.measured_std == pytest.approx(0.5, rel=0.1)


def test_standstill_and_sparse_blocks_are_not_measured() -> None:
    """At standstill the speed's noise is the same sensor's, but a block that reverses or
    stands is not 'moving' (its direction is 0) and is left out; so is a block of fewer than
    MIN_SAMPLES samples (at 100 Hz, four)."""
    still = moving_run(4.0, 0.5, seed=7)
    still = MotorSamples(
        still.stamp_s, still.current_a, still.speed_rad_s - 150.0, np.zeros(len(still))
    )
    blocker = SampleBlocker(params_with_speed_std(0.01))
    blocker.feed(still)
    assert blocker.speed_noise.measured_std is None
    sparse = moving_run(40.0, 0.5, seed=8)[:: (40 // (MIN_SAMPLES - 1)) + 1]
    blocker = SampleBlocker(params_with_speed_std(0.01))
    blocks = blocker.feed(sparse)
    assert len(blocks) > HISTORY_BLOCKS and max(b.samples for b in blocks) < MIN_SAMPLES
    assert blocker.speed_noise.measured_std is None
