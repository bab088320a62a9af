"""The input stage: validation, counting, time handling and blocks, whatever the chunking."""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import pytest

from prsm_health.actuator import Actuator
from prsm_health.estimation.estimator import HealthEstimator
from prsm_health.estimation.inputs import (
    LARGEST_STAMP_S,
    MEDIAN_OF_THREE_VARIANCE,
    TIME_RESET_SAMPLES,
    Block,
    RejectReason,
    SampleBlocker,
    merge_blocks,
)
from prsm_health.estimation.noise_history import HISTORY_BLOCKS
from prsm_health.estimation.params import EstimatorParams
from prsm_health.estimation.sample_faults import STUCK_RUN_SAMPLES
from prsm_health.physics.meshing import carrier_speed_rad_s
from prsm_health.physics.presets import load_preset
from prsm_health.signals import MotorSamples
from test.estimation.chunks import fed_in_chunks

PARAMS = EstimatorParams(actuator=Actuator(preset=load_preset("dong2022-downhole")))
RATE_HZ = 1000.0


def run(seconds: float = 2.0, seed: int = 0) -> MotorSamples:
    """A noisy 1 kHz run at constant speed and current."""
    rng = np.random.default_rng(seed)
    n = int(seconds * RATE_HZ)
    t = np.arange(n) / RATE_HZ
    return MotorSamples(
        t + 0.1,
        5.0 + rng.normal(0.0, 0.05, n),
        150.0 + rng.normal(0.0, 0.2, n),
        150.0 * t,
    )


def feed_in_chunks(samples: MotorSamples, size: int) -> tuple[list[Block], SampleBlocker]:
    blocker = SampleBlocker(PARAMS)
    return fed_in_chunks(blocker.feed, samples, size) + blocker.flush(), blocker


def with_values(samples: MotorSamples, **changes: tuple[int, float]) -> MotorSamples:
    """Copy of ``samples`` with single values replaced: field=(index, value)."""
    arrays = {f.name: getattr(samples, f.name).copy() for f in dataclasses.fields(samples)}
    for name, (index, value) in changes.items():
        arrays[name][index] = value
    return MotorSamples(**arrays)


@pytest.mark.parametrize("size", [1, 7, 333])
def test_blocks_do_not_depend_on_the_chunking(size: int) -> None:
    """Four seconds: a hundred blocks, so that the speed noise's measurement (HISTORY_BLOCKS)
    sets the later blocks' acceleration variances too."""
    samples = with_values(run(4.0), current_a=(500, 40.0), speed_rad_s=(900, math.nan))
    samples = with_values(samples, speed_rad_s=(1500, -500.0))
    samples.current_a[1200 : 1200 + 3 * STUCK_RUN_SAMPLES] = 3.3
    reference, ref_blocker = feed_in_chunks(samples, len(samples))
    blocks, blocker = feed_in_chunks(samples, size)
    assert blocks == reference
    assert blocker.counters == ref_blocker.counters
    assert blocker.speed_noise.measured_std is not None


def test_each_block_counts_the_samples_up_to_its_last_one() -> None:
    """A non-finite sample in the second block, a spike in the third, a stamp that does not
    advance in the fourth: each block counts what came up to its own last accepted sample,
    whatever came after it in the same chunk (until 2026-11-27 every block of a chunk had the
    chunk's counts)."""
    samples = with_values(run(1.0), speed_rad_s=(50, math.nan), current_a=(100, 40.0))
    samples.stamp_s[130] = samples.stamp_s[129]
    blocks, blocker = feed_in_chunks(samples, len(samples))
    accepted = np.cumsum([b.samples for b in blocks])
    assert [b.accepted_so_far for b in blocks] == accepted.tolist()
    assert [b.rejected_so_far for b in blocks[:5]] == [0, 1, 2, 3, 3]
    last = blocks[-1]
    assert (last.accepted_so_far, last.rejected_so_far) == (
        blocker.counters.accepted,
        blocker.counters.rejected_total,
    )
    assert blocker.counters.rejected_total == 3


def test_blocks_average_the_samples_of_each_grid_cell() -> None:
    samples = run(1.0)
    blocks, blocker = feed_in_chunks(samples, 100)
    per_block = int(PARAMS.filter.block_duration_s * RATE_HZ)
    assert len(blocks) == len(samples) // per_block
    first = samples[:per_block]
    k_t = PARAMS.actuator.drive_train.torque_constant_nm_per_a
    assert blocks[0].samples == per_block
    assert blocks[0].motor_torque_nm == pytest.approx(k_t * first.current_a.mean(), rel=1e-12)
    ratio = float(carrier_speed_rad_s(PARAMS.actuator.preset.geometry, 1.0))
    angle = first.position_rad * ratio / PARAMS.actuator.drive_train.gear_ratio
    assert blocks[0].carrier_cos == pytest.approx(np.cos(angle).mean(), rel=1e-12)
    assert blocks[0].carrier_sin == pytest.approx(np.sin(angle).mean(), rel=1e-12)
    assert all(b.direction == 1 for b in blocks)
    assert blocks[1].duration_s == pytest.approx(blocks[1].stamp_s - blocks[0].stamp_s)
    assert blocks[1].duration_s == pytest.approx(PARAMS.filter.block_duration_s, rel=0.05)
    assert blocker.counters.accepted == len(samples)


def test_a_block_holds_the_spread_of_its_stamps_and_a_merged_block_that_of_all() -> None:
    """stamp_var_s2 is the variance of the block's stamps about its mean stamp (the block's
    load is a mean over them, measurement.TorqueModel.predict). Merged standstill blocks hold
    that of all their stamps about the merged stamp, not the mean of their own."""
    samples = run(1.0)
    blocks, _ = feed_in_chunks(samples, 100)
    per_block = int(PARAMS.filter.block_duration_s * RATE_HZ)
    stamps = samples.stamp_s
    assert blocks[0].stamp_var_s2 == pytest.approx(np.var(stamps[:per_block]), rel=1e-9)
    assert blocks[0].stamp_var_s2 == pytest.approx((per_block**2 - 1) / 12 / RATE_HZ**2, rel=1e-6)
    merged = merge_blocks(blocks[:5])
    assert merged.stamp_s == pytest.approx(stamps[: 5 * per_block].mean(), rel=1e-12)
    assert merged.stamp_var_s2 == pytest.approx(np.var(stamps[: 5 * per_block]), rel=1e-9)


def test_bad_values_are_rejected_and_counted_by_reason() -> None:
    samples = with_values(
        run(1.0),
        current_a=(10, math.inf),
        speed_rad_s=(20, 1e6),
        position_rad=(30, math.nan),
    )
    samples = with_values(samples, current_a=(400, 5.0 + 3.0))  # a spike of 3 A
    samples = with_values(samples, position_rad=(600, 1e308))  # the carrier's phase is lost
    _, blocker = feed_in_chunks(samples, 50)
    rejected = blocker.counters.rejected
    assert rejected[RejectReason.NON_FINITE] == 2
    assert rejected[RejectReason.OUT_OF_RANGE] == 2
    # By the field beyond its range (a non-finite sample counts for none).
    assert blocker.out_of_range == {"stamp": 0, "current": 0, "speed": 1, "position": 1}
    assert rejected[RejectReason.SPIKE] == 1
    assert blocker.counters.accepted + blocker.counters.rejected_total == len(samples)


def test_a_step_in_the_current_is_not_a_spike() -> None:
    samples = run(1.0)
    stepped = MotorSamples(
        samples.stamp_s,
        samples.current_a + np.where(np.arange(len(samples)) >= 500, 2.0, 0.0),
        samples.speed_rad_s,
        samples.position_rad,
    )
    _, blocker = feed_in_chunks(stepped, 64)
    assert blocker.counters.rejected_total == 0


@pytest.mark.parametrize("size", [1, 9, 1000])
def test_a_current_alternating_every_sample_is_no_train_of_spikes(size: int) -> None:
    """+-2 A at the sampling frequency (a ripple aliased there) beside an isolated spike and
    two spikes two samples apart: each ripple sample stood out from two neighbours that
    agreed, and 95 % were rejected as spikes (found by a review session). The ripple's first
    and last two samples are rejected, the spikes (and the sample between the two, which
    stands out from them) as before, in any chunks."""
    samples = run(1.0)
    current = samples.current_a.copy()
    current[200:600] += 2.0 * (-1.0) ** np.arange(400)
    current[[800, 900, 902]] += 10.0
    ripple = MotorSamples(samples.stamp_s, current, samples.speed_rad_s, samples.position_rad)
    _, blocker = feed_in_chunks(ripple, size)
    assert blocker.counters.rejected[RejectReason.SPIKE] == 4 + 1 + 3
    assert blocker.counters.rejected_total == 8


def with_speed_departures(departures_rad_s: dict[int, float]) -> MotorSamples:
    """One second at 150 rad/s (1 kHz) with single speed samples moved by the given amounts."""
    samples = run(1.0)
    speed = samples.speed_rad_s.copy()
    for index, departure in departures_rad_s.items():
        speed[index] += departure
    return MotorSamples(samples.stamp_s, samples.current_a, speed, samples.position_rad)


@pytest.mark.parametrize("size", [1, 9, 1000])
def test_a_speed_sample_the_motor_cannot_reach_is_a_spike(size: int) -> None:
    """One speed sample at -500 rad/s from 150 (the sensor-faults scene's): kept, it made its
    block a reversal, whose load the estimator forgets. A speed the motor cannot reach and
    leave again in a millisecond is rejected as a spike, its block moves forward."""
    samples = with_speed_departures({300: -500.0})
    blocks, blocker = feed_in_chunks(samples, size)
    assert blocker.counters.rejected[RejectReason.SPIKE] == 1
    assert blocker.counters.rejected_total == 1
    assert all(b.direction == 1 and not b.reverses for b in blocks)


def test_a_speed_spike_is_what_the_motor_cannot_accelerate_to_and_back() -> None:
    """The bound is the drive's largest acceleration over the sample's interval plus
    SPIKE_SIGMAS speed noise sigmas: a departure of 0.9 times the acceleration's share is
    kept, 1.1 times is a spike, whichever way; so are steps of one encoder count a sample (a
    coarse encoder differenced into the speed: 2 pi / 1024 per ms) and a step of the whole
    speed. filter.max_acceleration_rad_s2 replaces the drive's bound."""
    reach = PARAMS.max_motor_acceleration_rad_s2 / RATE_HZ
    assert reach > 100.0  # the bundled drive: 36 N m of motor torque over 2.4e-4 kg m^2
    encoder_step = 2.0 * math.pi / 1024 * RATE_HZ
    departures = {100: 0.9 * reach, 200: -0.9 * reach, 300: encoder_step, 600: -encoder_step}
    samples = with_speed_departures({**departures, 400: 1.1 * reach, 500: -1.1 * reach})
    samples.speed_rad_s[700:] = 0.0
    _, blocker = feed_in_chunks(samples, 64)
    assert blocker.counters.rejected[RejectReason.SPIKE] == 2
    assert blocker.counters.rejected_total == 2
    tighter = dataclasses.replace(
        PARAMS, filter=dataclasses.replace(PARAMS.filter, max_acceleration_rad_s2=1e4)
    )
    assert tighter.max_motor_acceleration_rad_s2 == 1e4
    told = SampleBlocker(tighter)
    fed_in_chunks(told.feed, samples, 64) + told.flush()
    # 10 rad/s a sample plus 2.4 of noise: the four departures too, the encoder's steps not.
    assert told.counters.rejected[RejectReason.SPIKE] == 4


@pytest.mark.parametrize("size", [1, 7, 1000])
def test_a_current_noisier_than_its_parameter_is_measured_not_taken_for_spikes(size: int) -> None:
    """Ten times the parameter's current noise (0.5 A against 0.05): its tails, 12 of the
    parameter's sigmas but 1.2 of the noise's, were rejected as spikes (9 % of the samples),
    and in the first 0.32 s, before eight blocks were measured, still 28 samples. The noise
    is measured from the first block on, that block judged by its own: only the real spikes
    (25 A), one in the first block and one later, are rejected, in any chunks."""
    samples = run(6.0)
    samples.current_a[:] = 5.0 + np.random.default_rng(4).normal(0.0, 0.5, len(samples))
    samples.current_a[[15, 5020]] += 25.0
    blocks, blocker = feed_in_chunks(samples, size)
    rejected = np.diff([0] + [b.rejected_so_far for b in blocks])  # in each block
    spikes = [
        int(np.argmin(np.abs([b.stamp_s - samples.stamp_s[i] for b in blocks]))) for i in (15, 5020)
    ]
    assert rejected.sum() == 2 and rejected[spikes].tolist() == [1, 1]
    assert blocker.counters.rejected_total == blocker.counters.rejected[RejectReason.SPIKE]
    assert blocker.faults.current_noise.measured_std == pytest.approx(0.5, rel=0.1)


@pytest.mark.parametrize("size", [1, 9, 1000])
def test_a_stuck_current_is_rejected_whole_and_a_shorter_run_is_not(size: int) -> None:
    samples = run(1.0)
    current = samples.current_a.copy()
    current[200:300] = 4.2
    current[500 : 500 + STUCK_RUN_SAMPLES - 1] = 4.3  # one short of stuck
    stuck = MotorSamples(samples.stamp_s, current, samples.speed_rad_s, samples.position_rad)
    _, blocker = feed_in_chunks(stuck, size)
    assert blocker.counters.rejected[RejectReason.STUCK] == 100


@pytest.mark.parametrize("size", [9, 86])
def test_a_stuck_run_is_rejected_whole_wherever_it_starts(size: int) -> None:
    """Blocks close STUCK_RUN_SAMPLES samples late so that a stuck run is seen whole before
    the block holding its first samples is estimated: closed at once, a 60-sample run from
    sample 239 fed in chunks of 86 lost 2 of its samples to the block before (found by a
    mutation review)."""
    samples = run(1.0)
    for start in range(225, 256):
        current = samples.current_a.copy()
        current[start : start + 60] = 4.4
        stuck = MotorSamples(samples.stamp_s, current, samples.speed_rad_s, samples.position_rad)
        _, blocker = feed_in_chunks(stuck, size)
        assert blocker.counters.rejected[RejectReason.STUCK] == 60, start


def test_time_going_backwards_is_rejected_then_followed_as_a_new_time_line() -> None:
    samples = run(2.0)
    stamps = samples.stamp_s.copy()
    stamps[1000:] -= 0.5  # the clock jumps back by 0.5 s at sample 1000
    jumped = MotorSamples(stamps, samples.current_a, samples.speed_rad_s, samples.position_rad)
    blocks, blocker = feed_in_chunks(jumped, 128)
    counters = blocker.counters
    # Stamps that do not advance are rejected until the new line has run time_reset_after_s.
    expected = round(PARAMS.filter.time_reset_after_s * RATE_HZ)
    assert counters.rejected[RejectReason.TIME_BACKWARDS] == expected
    assert counters.time_resets == 1
    resets = [b for b in blocks if b.time_reset]
    assert len(resets) == 1
    assert all(
        b2.stamp_s > b1.stamp_s for b1, b2 in itertools.pairwise(blocks) if not b2.time_reset
    )


def with_late_samples(samples: MotorSamples, at: int, stamps: np.ndarray) -> MotorSamples:
    """``samples`` with samples stamped ``stamps`` (the first sample's values) delivered
    before sample ``at``."""
    order = np.r_[np.arange(at), np.zeros(len(stamps), dtype=int), np.arange(at, len(samples))]
    late = samples[order]
    late.stamp_s[at : at + len(stamps)] = stamps
    return late


def test_a_few_late_samples_far_apart_are_rejected_not_a_new_time_line() -> None:
    # Two stale samples from 1 s earlier, 0.15 s apart (more than time_reset_after_s), then
    # TIME_RESET_SAMPLES - 3 more from that old line: too few samples to follow it.
    samples = run(2.0)
    late_count = TIME_RESET_SAMPLES - 1
    late_stamps = samples.stamp_s[1000] - 1.0 + 0.15 * np.arange(late_count) / (late_count - 1)
    assert late_stamps[-1] - late_stamps[0] > PARAMS.filter.time_reset_after_s
    blocks, blocker = feed_in_chunks(with_late_samples(samples, 1000, late_stamps), 128)
    assert blocker.counters.time_resets == 0
    assert blocker.counters.rejected[RejectReason.TIME_BACKWARDS] == late_count
    assert not any(b.time_reset for b in blocks)
    # One more sample on that line, and it is followed.
    followed = with_late_samples(samples, 1000, np.r_[late_stamps, late_stamps[-1] + 0.01])
    _, blocker = feed_in_chunks(followed, 128)
    assert blocker.counters.time_resets == 1


def test_a_gap_in_the_samples_starts_a_new_grid_and_spans_the_prediction() -> None:
    samples = run(2.0)
    keep = np.ones(len(samples), dtype=bool)
    keep[700:1500] = False  # 0.8 s dropout, longer than max_gap_s
    blocks, blocker = feed_in_chunks(samples[keep], 100)
    after = [b for b in blocks if b.after_gap]
    assert len(after) == 1 and blocker.counters.gaps == 1
    assert after[0].duration_s > 0.8


@pytest.mark.parametrize("size", [1, 100, 730, 2000])
def test_a_gap_is_a_gap_whatever_the_chunking(size: int) -> None:
    # 730: the first chunk ends 30 samples after the gap, so the blocks before it are closed
    # and the first pending sample of the next chunk is the first one after the gap.
    samples = run(2.0)
    keep = np.ones(len(samples), dtype=bool)
    keep[700:1500] = False  # 0.8 s dropout, longer than max_gap_s
    blocks, blocker = feed_in_chunks(samples[keep], size)
    assert [b.stamp_s for b in blocks if b.after_gap] == [
        b.stamp_s for b in feed_in_chunks(samples[keep], len(samples))[0] if b.after_gap
    ]
    assert sum(b.after_gap for b in blocks) == 1 and blocker.counters.gaps == 1


@pytest.mark.parametrize("size", [1, 7, 2000])
def test_a_position_re_homed_to_zero_is_a_jump_not_a_wrap(size: int) -> None:
    """Pins the wrap rule's "both positions within one turn of zero": a position re-homed from
    150 rad to 0 (one side only near zero) is a jump, and the travel is measured on after it,
    whatever the chunks; a position wrapped into one turn has none. A mutation review found it
    unguarded ("either position near zero": every travel after the re-homing was NaN)."""
    samples = run(2.0)
    position = samples.position_rad.copy()
    assert position[999] > 100.0
    position[1000:] -= position[1000]  # re-homed: 149.85 rad, then 0
    blocks, _ = feed_in_chunks(dataclasses.replace(samples, position_rad=position), size)
    no_travel = [i for i, b in enumerate(blocks) if not math.isfinite(b.travel_rad)]
    assert no_travel == [0]  # only the first block: no sample before it
    jump = next(i for i, b in enumerate(blocks) if b.travel_rad > 100.0)  # sample 1000's block
    assert blocks[jump - 1].stamp_s < samples.stamp_s[1000] < blocks[jump + 1].stamp_s
    # 150 rad/s at 1 kHz: 0.15 rad a sample, measured from the last sample of the block before.
    after = [b.travel_rad for b in blocks[jump + 1 :]]
    assert after == pytest.approx([0.15 * b.samples for b in blocks[jump + 1 :]], rel=1e-9)
    wrapped = np.mod(samples.position_rad + math.pi, 2.0 * math.pi) - math.pi
    blocks, _ = feed_in_chunks(dataclasses.replace(samples, position_rad=wrapped), size)
    assert all(math.isnan(b.travel_rad) for b in blocks)


@pytest.mark.parametrize("size", [1, 7, 2000])
def test_a_position_wrapped_into_one_turn_gives_the_carrier_angle_of_the_turns(size: int) -> None:
    """A single-turn encoder: the positions wrapped into [-pi, pi) (or [0, 2 pi)) give the
    blocks the carrier angle of the positions counting turns, across a 0.25 s dropout too
    (whole turns from the speeds), whatever the chunks. Taken as they were they made the
    carrier angle meaningless (5 false jam declarations on the sudden-jam bag)."""
    samples = run(2.0)
    keep = np.ones(len(samples), dtype=bool)
    keep[700:950] = False
    samples = samples[keep]
    turns, _ = feed_in_chunks(samples, len(samples))
    for wrapped in (
        np.mod(samples.position_rad + math.pi, 2.0 * math.pi) - math.pi,
        np.mod(samples.position_rad, 2.0 * math.pi),
    ):
        blocks, _ = feed_in_chunks(dataclasses.replace(samples, position_rad=wrapped), size)
        assert len(blocks) == len(turns)
        for field in ("carrier_cos", "carrier_sin"):
            got = [getattr(b, field) for b in blocks]
            assert got == pytest.approx([getattr(b, field) for b in turns], abs=1e-9)
    assert np.ptp([b.carrier_cos for b in turns]) > 1.0  # the carrier turns in the run


@pytest.mark.parametrize("size", [1, 7, 501, 2000])
def test_one_stamp_far_ahead_is_rejected_not_the_samples_after_it(size: int) -> None:
    """One sample stamped 30 years ahead in a clean stream: it is rejected as out of order,
    whatever the chunks. (It was accepted, and the next 100 good samples were rejected as
    going backwards until a time reset followed them.)"""
    samples = run(2.0)
    stamps = samples.stamp_s.copy()
    stamps[500] += 30 * 365.25 * 86400.0
    faulty = MotorSamples(stamps, samples.current_a, samples.speed_rad_s, samples.position_rad)
    blocks, blocker = feed_in_chunks(faulty, size)
    assert blocker.counters.rejected[RejectReason.TIME_BACKWARDS] == 1
    assert blocker.counters.accepted == len(samples) - 1
    assert blocker.counters.time_resets == 0 and blocker.counters.gaps == 0
    assert not any(b.time_reset or b.after_gap for b in blocks)
    assert max(b.stamp_s for b in blocks) < stamps[-1]


def test_a_clock_that_jumps_ahead_for_good_is_a_gap_whatever_the_chunks() -> None:
    """The same jump kept by every sample after it (a clock set to the epoch): a gap, and no
    sample lost, also when the jump is the last sample of a chunk."""
    samples = run(2.0)
    stamps = samples.stamp_s.copy()
    stamps[500:] += 30 * 365.25 * 86400.0
    jumped = MotorSamples(stamps, samples.current_a, samples.speed_rad_s, samples.position_rad)
    for size in (1, 501, 2000):
        blocks, blocker = feed_in_chunks(jumped, size)
        assert blocker.counters.accepted == len(samples), size
        assert blocker.counters.gaps == 1 and sum(b.after_gap for b in blocks) == 1, size


def test_a_gap_after_a_flush_is_a_gap() -> None:
    # The node flushes when its input has been silent for a while.
    samples = run(2.0)
    blocker = SampleBlocker(PARAMS)
    before = blocker.feed(samples[:700]) + blocker.flush()
    after = blocker.feed(samples[1500:]) + blocker.flush()
    assert not any(b.after_gap for b in before)
    assert after[0].after_gap and not any(b.after_gap for b in after[1:])
    assert blocker.counters.gaps == 1


def test_a_stamp_far_ahead_just_before_a_pause_is_judged_by_what_comes_after_it() -> None:
    """The node flushes when its input goes silent: a sample stamped far ahead just before the
    silence stays held, and the samples after the pause reject it as out of order. (It was
    accepted by the flush, its block estimated at that stamp, and the next 100 good samples
    rejected until a time reset followed them.) At the end of the data it is accepted."""
    samples = run(2.0)
    stamps = samples.stamp_s.copy()
    stamps[699] = LARGEST_STAMP_S - 1.0
    faulty = MotorSamples(stamps, samples.current_a, samples.speed_rad_s, samples.position_rad)
    blocker = SampleBlocker(PARAMS)
    before = blocker.feed(faulty[:700]) + blocker.flush(end_of_data=False)
    after = blocker.feed(faulty[1500:]) + blocker.flush()
    assert blocker.counters.rejected[RejectReason.TIME_BACKWARDS] == 1
    assert blocker.counters.accepted == 699 + 500 and blocker.counters.time_resets == 0
    assert max(b.stamp_s for b in before + after) < stamps[-1]
    assert after[0].after_gap and blocker.counters.gaps == 1
    ended = SampleBlocker(PARAMS)
    last = ended.feed(faulty[:700]) + ended.flush()
    assert last[-1].stamp_s == LARGEST_STAMP_S - 1.0 and ended.counters.accepted == 700


@pytest.mark.parametrize("size", [1, 7, 3333])
def test_stamps_that_hardly_advance_still_make_blocks(size: int) -> None:
    """A clock in the wrong unit, 10 ns a sample: every sample in one 40 ms cell, which never
    ended; the samples pending for it grew without bound. A block holds 10,000 samples at most
    in 40 ms blocks (MAX_SAMPLE_RATE_HZ), split the same whatever the chunks."""
    samples = run(35.0)
    slow = MotorSamples(
        0.1 + 1e-8 * np.arange(len(samples)),
        samples.current_a,
        samples.speed_rad_s,
        samples.position_rad,
    )
    blocker = SampleBlocker(PARAMS)
    assert blocker.block_capacity == 10_000
    blocks = fed_in_chunks(blocker.feed, slow, size)
    assert len(blocker._pending) < blocker.block_capacity + STUCK_RUN_SAMPLES + size
    assert [b.samples for b in blocks] == [10_000] * 3  # the rest pending
    blocks += blocker.flush()
    assert sum(b.samples for b in blocks) == blocker.counters.accepted == len(slow)


def test_long_blocks_of_a_normal_stream_are_not_split() -> None:
    """10 s blocks (the longest filter.block_duration_s) of a 1 kHz stream: the cap scales with
    the block (a fixed 10,000 samples made a block of 1 sample after each 10,000)."""
    long = dataclasses.replace(
        PARAMS,
        filter=dataclasses.replace(
            PARAMS.filter, block_duration_s=10.0, max_gap_s=20.0, divergence_window_s=100.0
        ),
    )
    blocker = SampleBlocker(long)
    blocks = blocker.feed(run(35.0)) + blocker.flush()
    assert blocker.block_capacity == 2_500_000
    assert min(b.samples for b in blocks[:-1]) >= 9_999 and len(blocks) == 4


def test_standstill_and_reversal_blocks_have_no_direction() -> None:
    samples = run(1.0)
    speed = np.where(np.arange(len(samples)) < 500, 0.0, -150.0)
    speed[520:540] = np.linspace(-3.0, 3.0, 20)  # a reversal inside one block
    moved = MotorSamples(samples.stamp_s, samples.current_a, speed, samples.position_rad)
    blocks, _ = feed_in_chunks(moved, 1000)
    directions = [b.direction for b in blocks]
    assert directions[0] == 0 and directions[-1] == -1
    assert 0 in directions[12:14]


@pytest.mark.parametrize("size", [1, 7, 1000])
def test_one_wild_speed_sample_inside_a_block_neither_stops_nor_reverses_it(size: int) -> None:
    """In a stroke at -100 rad/s, a sample at +50 rad/s (the motor could reach it: not a
    spike) inside a block, or at 0 rad/s: the block still moves at -1 and does not reverse. At
    a block's first sample the same value does reverse it (only samples inside a block have
    both neighbours there to tell a wild one): where the motion starts or stops the samples
    below the standstill speed are at the block's ends, on the line of the others."""
    samples = run(1.0)
    speed = np.full(len(samples), -100.0) + np.random.default_rng(2).normal(0.0, 0.2, len(samples))
    speed[415] = 50.0  # inside the block of samples 400-439
    speed[615] = 0.0  # inside the block of samples 600-639
    speed[800] = 50.0  # the first sample of the block of samples 800-839
    moved = MotorSamples(samples.stamp_s, samples.current_a, speed, samples.position_rad)
    blocks, blocker = feed_in_chunks(moved, size)
    assert blocker.counters.rejected_total == 0
    by_first = {round((b.stamp_s - 0.1 - 0.0195) * 1000): b for b in blocks}
    assert by_first[400].direction == -1 and not by_first[400].reverses
    assert by_first[600].direction == -1 and not by_first[600].reverses
    assert by_first[800].direction == 0 and by_first[800].reverses
    assert all(b.direction == -1 for first, b in by_first.items() if first not in (800,))


def test_samples_closer_than_a_microsecond_carry_no_acceleration() -> None:
    """A speed step between samples 1e-300 s apart is no acceleration of 1e302 rad/s^2."""
    samples = MotorSamples(
        np.array([1e-300, 2e-300, 0.2]),
        np.array([5.0, 5.0, 5.0]),
        np.array([150.0, 160.0, 150.0]),
        np.array([0.0, 0.0, 15.0]),
    )
    blocks, blocker = feed_in_chunks(samples, 3)
    assert blocker.counters.accepted == 3
    assert blocks[0].samples == 2 and blocks[0].motor_acceleration_rad_s2 == 0.0
    assert blocks[0].motor_acceleration_var_rad2_s4 == 0.0
    assert all(math.isfinite(b.motor_acceleration_rad_s2) for b in blocks)


def test_the_acceleration_variance_is_that_of_a_speed_difference() -> None:
    """The block's acceleration is the speed change over its span, between the medians of
    its END_SAMPLES first and last samples, so its variance is 2 v sigma^2 / span^2 with v
    the variance of a median of three (not a least-squares slope's 12 sigma^2 / (n T^2)):
    measured over 400 noisy blocks of constant speed, whose noise is the parameter's (sigma:
    the parameter until HISTORY_BLOCKS blocks are measured, then the larger of it and the
    measured noise, here within a few per cent of it). A merged block's is that of the
    sample-weighted mean."""
    blocks, _ = feed_in_chunks(run(16.0, seed=4), 500)
    full = [b for b in blocks if b.samples == 40]
    sigma = PARAMS.noise.speed_std_rad_s
    # 40 samples 1 ms apart: the middle samples of the first and last three are 37 ms apart.
    expected = 2.0 * MEDIAN_OF_THREE_VARIANCE * sigma**2 / 0.037**2
    first = full[: HISTORY_BLOCKS - 1]
    assert all(b.motor_acceleration_var_rad2_s4 == pytest.approx(expected) for b in first)
    assert all(
        0.999 * expected < b.motor_acceleration_var_rad2_s4 < 1.1 * expected
        for b in full[HISTORY_BLOCKS:]
    )
    measured = float(np.var([b.motor_acceleration_rad_s2 for b in full]))
    assert measured == pytest.approx(expected, rel=0.2)  # 400 blocks: about 7 % sampling error
    merged = merge_blocks(full[:5])
    assert merged.motor_acceleration_var_rad2_s4 == pytest.approx(expected / 5)


def test_a_block_of_one_sample_takes_its_acceleration_from_the_sample_before() -> None:
    """At 50 Hz with jittered stamps, one 40 ms cell in eight holds a single sample. Its
    acceleration was taken as zero with no variance: at a stroke start (about 790 rad/s^2)
    the inertia torque went unexplained, and on the radial-misalignment scene at 50 Hz count
    1 explained it: a false jam and 5.2 % load RMSE (0.4 % since). It is now the speed change
    from the last sample before it, with that difference's variance."""
    rng = np.random.default_rng(7)
    t = np.arange(0.0, 2.0, 0.02) + rng.uniform(-0.006, 0.006, 100) + 0.1
    acceleration = 500.0
    sigma = PARAMS.noise.speed_std_rad_s
    samples = MotorSamples(
        t,
        5.0 + rng.normal(0.0, 0.05, 100),
        20.0 + acceleration * t + rng.normal(0.0, sigma, 100),
        20.0 * t + 0.5 * acceleration * t**2,
    )
    blocks, _ = feed_in_chunks(samples, 7)
    single = [b for b in blocks[1:] if b.samples == 1]
    assert len(single) >= 5
    for block in blocks[1:]:
        std = math.sqrt(block.motor_acceleration_var_rad2_s4)
        assert 0.0 < std < 0.1 * acceleration
        assert abs(block.motor_acceleration_rad_s2 - acceleration) < 5.0 * std


def test_a_block_in_which_the_motion_reverses_says_so() -> None:
    """A block whose samples move both ways faster than the standstill speed reverses (the
    estimator forgets the load there); one that only enters or leaves the standstill band does
    not; a merged block reverses if any of its blocks does."""
    t = np.arange(0.0, 0.16, 0.001) + 0.1
    speed = 100.0 * np.sin(2.0 * math.pi * t / 0.16 + 0.3)  # crosses zero twice
    current = 5.0 + np.random.default_rng(3).normal(0.0, 0.05, len(t))  # not stuck
    samples = MotorSamples(t, current, speed, np.cumsum(speed) * 0.001)
    blocks, _ = feed_in_chunks(samples, 13)
    threshold = PARAMS.filter.standstill_speed_rad_s
    expected = []
    for block in blocks:
        inside = np.abs(t - block.stamp_s) < 0.02  # a 40 ms grid cell about its mean stamp
        moving = speed[inside]
        expected.append(bool(moving.min() < -threshold and moving.max() > threshold))
    assert [b.reverses for b in blocks] == expected and sum(expected) == 2
    assert all(b.direction == 0 for b in blocks if b.reverses)
    assert merge_blocks(blocks[:2]).reverses == (blocks[0].reverses or blocks[1].reverses)
    assert not merge_blocks([b for b in blocks if not b.reverses]).reverses


def test_a_block_of_one_sample_takes_no_acceleration_across_a_gap_or_a_microsecond() -> None:
    """The sample before must be on the same time line (not before a gap, where the speed
    may have changed any way) and at least SHORTEST_SLOPE_SPAN_S earlier (a speed step over
    2e-11 s is no acceleration of 5e12 rad/s^2): else the block has none, as before."""
    gap = MotorSamples(
        np.array([0.0, 0.02, 1.02]),  # a silence of 1 s, beyond filter.max_gap_s
        np.array([5.0, 5.1, 5.2]),
        np.array([100.0, 100.0, 200.0]),
        np.array([0.0, 2.0, 150.0]),
    )
    close = MotorSamples(
        np.array([0.0, 0.0399999999, 0.04000000001]),  # the last alone in the next cell
        np.array([5.0, 5.1, 5.2]),
        np.array([100.0, 100.0, 200.0]),
        np.array([0.0, 4.0, 4.0]),
    )
    for samples in (gap, close):
        blocks, _ = feed_in_chunks(samples, 3)
        assert [b.samples for b in blocks] == [2, 1]
        assert blocks[1].motor_acceleration_rad_s2 == 0.0
        assert blocks[1].motor_acceleration_var_rad2_s4 == 0.0
    assert feed_in_chunks(gap, 3)[0][1].after_gap


# --- what numpy arrays can hold (adversarial fuzz, 2026-11) -----------------------------------
def test_motor_samples_hold_float64_without_copying_float64_columns() -> None:
    """Built for every few samples in the node: float64 columns are kept as they are."""
    samples = run(0.01)
    again = MotorSamples(
        samples.stamp_s, samples.current_a, samples.speed_rad_s, samples.position_rad
    )
    assert again.stamp_s is samples.stamp_s and again.position_rad is samples.position_rad
    converted = MotorSamples(
        samples.stamp_s.astype(np.float32),
        np.arange(len(samples), dtype=np.int8),
        np.arange(len(samples), dtype=np.uint64),
        samples.position_rad.astype(">f8"),  # float64, but not in the machine's byte order
    )
    for name in ("stamp_s", "current_a", "speed_rad_s", "position_rad"):
        column = getattr(converted, name)
        assert type(column) is np.ndarray and column.dtype == np.float64, name
        assert column.dtype.isnative, name


def test_integer_columns_are_checked_as_the_values_they_hold() -> None:
    """uint64 stamps going back wrapped around in a difference (taken as advancing: negative
    block durations, then a math domain error in the filter); abs(int8 -128) and abs(int64
    min) are negative, so -128 A and -9.2e18 rad/s passed the range check."""
    blocker = SampleBlocker(PARAMS)
    n = 200
    stamps = np.r_[1000, 999, 1000 + np.arange(1, n - 1)].astype(np.uint64)
    current = np.where(np.arange(n) % 4 >= 2, -128, 5).astype(np.int8)
    speed = np.full(n, 150, dtype=np.int64)
    speed[3::5] = np.iinfo(np.int64).min
    integers = MotorSamples(stamps, current, speed, np.zeros(n))  # type: ignore[arg-type]
    blocks = blocker.feed(integers) + blocker.flush()
    counters = blocker.counters
    # The first stamp goes back: the one before it is out of order (it jumped from nothing).
    assert counters.rejected[RejectReason.TIME_BACKWARDS] == 1
    out_of_range = (current == -128) | (speed == np.iinfo(np.int64).min)
    assert counters.rejected[RejectReason.OUT_OF_RANGE] == int(np.count_nonzero(out_of_range))
    assert counters.accepted + counters.rejected_total == n
    assert all(b.duration_s > 0.0 for b in blocks)
    assert all(b.motor_torque_nm > 0.0 and b.motor_speed_rad_s == 150.0 for b in blocks)


def test_masked_entries_are_rejected_as_non_finite() -> None:
    """A numpy masked array passed MotorSamples' checks with whatever lay under its mask, then
    raised TypeError in the input stage. Masked entries are invalid values: NaN, rejected and
    counted like any other, and the chunk's other samples are kept."""
    samples = run(0.2)
    masked = np.zeros(len(samples), dtype=bool)
    masked[[0, 50, 51]] = True
    stamps = np.ma.masked_array(samples.stamp_s.astype(np.float32), mask=masked)
    current = np.ma.masked_array(samples.current_a, mask=np.roll(masked, 100))
    speed, position = samples.speed_rad_s, samples.position_rad
    faulty = MotorSamples(stamps, current, speed, position)  # type: ignore[arg-type]
    assert type(faulty.stamp_s) is np.ndarray and np.isnan(faulty.stamp_s[masked]).all()
    _, blocker = feed_in_chunks(faulty, 7)
    assert blocker.counters.rejected[RejectReason.NON_FINITE] == 6
    assert blocker.counters.accepted == len(samples) - 6


@pytest.mark.parametrize("size", [1, 30, 2000])
def test_a_stamp_beyond_what_a_ros_time_carries_is_out_of_range(size: int) -> None:
    """A finite stamp of -1e308 crashed the block grid (OverflowError in a floor). Stamps
    beyond +-2^31 s, the int32 seconds of builtin_interfaces/Time, are out of range; inside
    that range, a clock jumping from one end to the other is a gap."""
    samples = run(2.0)
    stamps = samples.stamp_s.copy()
    stamps[0] = -1e308
    stamps[10] = -LARGEST_STAMP_S * (1.0 + 1e-15)
    stamps[20] = LARGEST_STAMP_S * (1.0 + 1e-15)
    stamps[500:1000] += -LARGEST_STAMP_S  # the oldest stamp a message can carry
    stamps[1000:] += LARGEST_STAMP_S - 3.0  # to the newest, less a second to spare
    faulty = MotorSamples(stamps, samples.current_a, samples.speed_rad_s, samples.position_rad)
    blocks, blocker = feed_in_chunks(faulty, size)
    counters = blocker.counters
    assert counters.rejected[RejectReason.OUT_OF_RANGE] == 3
    # The jump to the oldest stamps goes back: followed after time_reset_after_s.
    assert counters.time_resets == 1 and counters.gaps == 1
    assert counters.accepted + counters.rejected_total == len(samples)
    assert all(math.isfinite(b.stamp_s) and b.duration_s > 0.0 for b in blocks)


def test_a_maintenance_reset_in_a_pause_leaves_a_far_ahead_stamp_to_what_follows() -> None:
    """As the node's silence flush (above): the reset closes the pending block but a last
    sample stamped far ahead stays held. (Accepted by the reset, it made 100 good samples
    after the pause rejected and a time reset; a review found it.)"""
    samples = run(2.0)
    stamps = samples.stamp_s.copy()
    stamps[699] = LARGEST_STAMP_S - 1.0
    faulty = MotorSamples(stamps, samples.current_a, samples.speed_rad_s, samples.position_rad)
    estimator = HealthEstimator(PARAMS)
    states = estimator.process(faulty[:700])
    states += estimator.reset_after_maintenance(
        0, reset_precision_loss=False, reset_fatigue_damage=False
    )
    states += estimator.process(faulty[1500:]) + estimator.finish()
    counters = estimator.counters
    assert counters.rejected[RejectReason.TIME_BACKWARDS] == 1 and counters.time_resets == 0
    assert max(s.stamp_s for s in states) < stamps[-1]
