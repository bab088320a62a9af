"""Scores against ground truth: hand-made runs where every metric is known."""

from __future__ import annotations

import dataclasses
import itertools
import math
from typing import Any

import numpy as np
import pytest

from prsm_health.estimation.estimate import EstimateEvent, HealthState
from prsm_health.estimation.metrics import CALIBRATION_EDGES, on_truth_clock, score
from prsm_health.signals import TruthSamples

N_ROLLERS = 10


def truth(seconds: float, jam_at: float | None) -> TruthSamples:
    t = np.arange(0.0, seconds, 0.01)
    jammed = np.zeros((len(t), N_ROLLERS), dtype=bool)
    if jam_at is not None:
        jammed[t >= jam_at, 3] = True
    n = len(t)
    return TruthSamples(
        stamp_s=t,
        axial_load_n=np.full(n, 20e3),
        radial_load_n=np.zeros(n),
        loading_case=np.ones(n, dtype=np.int64),
        roller_jammed=jammed,
        precision_loss_m=1e-6 * t,
        friction_torque_nm=np.ones(n),
        fatigue_damage=np.zeros(n),
        screw_speed_rad_s=np.full(n, 30.0),
        carrier_angle_rad=np.zeros(n),
        wear_coefficient_factor=np.ones(n),
    )


def state(stamp: float, load: float, std: float, count: int, loss: float) -> HealthState:
    probabilities = [0.0] * (N_ROLLERS + 1)
    probabilities[count] = 1.0
    return HealthState(
        stamp_s=stamp,
        axial_load_n=load,
        axial_load_std_n=std,
        jam_probabilities=tuple(probabilities),
        precision_loss_m=loss,
        precision_loss_std_m=0.05e-6,
        precision_loss_rate_m_per_s=1e-6,
        friction_torque_nm=1.0,
        efficiency=0.9,
        fatigue_damage=0.0,
        fatigue_damage_std=0.0,
        screw_speed_rad_s=30.0,
        samples_accepted=0,
        samples_rejected=0,
        nis=1.0,
        event=EstimateEvent.NONE,
    )


def test_known_errors_delays_and_false_declarations() -> None:
    stamps = np.arange(0.02, 20.0, 0.04)
    rng = np.random.default_rng(0)
    states = [
        state(
            float(t),
            20e3 + float(rng.normal(0.0, 100.0)),
            100.0,
            (1 if t >= 10.49 else 0) + (1 if 2.99 <= t < 3.49 else 0),
            1e-6 * float(t) * 1.02,
        )
        for t in stamps
    ]
    metrics = score(states, truth(20.0, 10.0), rated_load_n=55e3, largest_screw_speed_rad_s=73.3)
    assert metrics.load_rmse_n == pytest.approx(100.0, rel=0.15)
    assert metrics.load_rmse_percent_rated == pytest.approx(100 * metrics.load_rmse_n / 55e3)
    assert metrics.load_nees_consistent
    # One NEES a second over 20 s: the 95 % interval of chi2(20) / 20 (tables: 9.591, 34.170).
    assert metrics.load_nees_interval == pytest.approx((0.47954, 1.70851), rel=1e-4)
    (jam,) = metrics.jams
    assert jam.onset_s == pytest.approx(10.0) and jam.count == 1
    assert jam.delay_s == pytest.approx(0.52)  # the block stamped 10.50 has seen up to 10.52
    assert metrics.false_jam_declarations == 1
    assert metrics.false_jam_seconds == pytest.approx(0.5, abs=0.05)
    assert metrics.precision_loss_error_percent == pytest.approx(2.0, rel=0.05)


def test_a_jam_declared_from_the_first_estimate_is_a_false_declaration() -> None:
    """The first estimate already says 1 jammed where the truth has none (a restored state,
    a wrong initial count): one false declaration, lasting until the count falls back."""
    stamps = np.arange(0.02, 20.0, 0.04)
    states = [state(float(t), 20e3, 100.0, int(t < 2.0), 1e-6 * float(t)) for t in stamps]
    metrics = score(states, truth(20.0, None), rated_load_n=55e3, largest_screw_speed_rad_s=73.3)
    assert metrics.false_jam_declarations == 1
    assert metrics.false_jam_seconds == pytest.approx(2.0, abs=0.05)


def test_a_jam_after_the_last_estimate_is_not_scored() -> None:
    """Estimates up to 8 s of a truth that jams at 10 s (a replay stopped, or a bag damaged
    before its truth ends): the jam was never seen, so it is not counted as never identified."""
    stamps = np.arange(0.02, 8.0, 0.04)
    states = [state(float(t), 20e3, 100.0, 0, 1e-6 * float(t)) for t in stamps]
    metrics = score(states, truth(20.0, 10.0), rated_load_n=55e3, largest_screw_speed_rad_s=73.3)
    assert metrics.jams == ()
    seen = score(states, truth(20.0, 7.0), rated_load_n=55e3, largest_screw_speed_rad_s=73.3)
    (jam,) = seen.jams
    assert jam.onset_s == pytest.approx(7.0) and jam.delay_s is None


def test_overconfident_load_fails_the_nees_test_and_coverage_counts() -> None:
    stamps = np.arange(0.02, 20.0, 0.04)
    states = [state(float(t), 21e3, 100.0, 0, 1e-6 * float(t) + 3e-7) for t in stamps]
    metrics = score(states, truth(20.0, None), rated_load_n=55e3, largest_screw_speed_rad_s=73.3)
    assert not metrics.load_nees_consistent
    assert metrics.jams == ()
    assert metrics.false_jam_declarations == 0
    assert metrics.precision_loss_coverage_2sigma == 0.0  # 0.3 um off, 2 std = 0.1 um
    wider = [dataclasses.replace(s, precision_loss_std_m=2e-7) for s in states]
    covered = score(wider, truth(20.0, None), rated_load_n=55e3, largest_screw_speed_rad_s=73.3)
    assert covered.precision_loss_coverage_2sigma == 1.0


def test_the_load_at_standstill_is_scored_apart() -> None:
    """The standstill's error was in no metric (the RMSE, max and NEES are of motion)."""
    stopped = truth(20.0, None)
    stopped.screw_speed_rad_s[stopped.stamp_s >= 10.0] = 0.0
    stamps = np.arange(0.02, 20.0, 0.04)
    states = [
        state(float(t), 20e3 + (3e3 if t >= 15.0 else 1e3 if t >= 10.0 else 0.0), 1e3, 0, 0.0)
        for t in stamps
    ]
    metrics = score(states, stopped, rated_load_n=55e3, largest_screw_speed_rad_s=73.3)
    assert metrics.load_rmse_n == pytest.approx(0.0, abs=1e-9)  # motion: exact
    assert metrics.load_standstill_max_error_n == pytest.approx(3e3)
    assert metrics.load_standstill_rmse_n == pytest.approx(np.sqrt((1e3**2 + 3e3**2) / 2), rel=0.01)
    assert metrics.load_standstill_coverage_2sigma == pytest.approx(0.5, abs=0.01)  # 3 kN > 2 std
    moving_only = score(states[:240], stopped, rated_load_n=55e3, largest_screw_speed_rad_s=73.3)
    assert np.isnan(moving_only.load_standstill_rmse_n)
    assert moving_only.to_dict()["load_standstill_coverage_2sigma"] is None


def test_the_block_in_which_a_roller_seizes_may_report_it() -> None:
    """Stamps are block mid-points: the block stamped 9.98 holds samples up to 10.00, and the
    roller seizes at 9.99; reporting it there is an identification, not a false declaration."""
    stamps = np.arange(0.02, 20.0, 0.04)
    states = [state(float(t), 20e3, 100.0, int(t > 9.97), 0.0) for t in stamps]
    metrics = score(states, truth(20.0, 9.985), rated_load_n=55e3, largest_screw_speed_rad_s=73.3)
    (jam,) = metrics.jams
    assert jam.onset_s == pytest.approx(9.99)
    assert jam.delay_s == pytest.approx(0.01)
    assert metrics.false_jam_declarations == 0
    early = [state(float(t), 20e3, 100.0, int(t > 9.93), 0.0) for t in stamps]
    one_block_early = score(
        early, truth(20.0, 9.985), rated_load_n=55e3, largest_screw_speed_rad_s=73.3
    )
    assert one_block_early.false_jam_declarations == 1


def test_the_true_count_at_a_truth_stamp_is_that_samples_own() -> None:
    """Counts come from the latest truth sample at or before the time compared: an estimate
    that has seen up to exactly the stamp of the truth sample where the jam starts compares
    with that sample's count (1), so its count 1 is no false declaration. A mutation review
    found this unguarded: looked up with side="left", the sample before (count 0) was taken
    and one false declaration counted."""
    jams = truth(3.0, jam_at=1.0)
    onset = float(jams.stamp_s[100])
    assert jams.jammed_rollers[99] == 0 and jams.jammed_rollers[100] == 1
    # The first has seen up to the midpoint, 0.75 s (count 0); the last up to its own stamp.
    states = [state(0.5, 20e3, 100.0, 0, 0.0), state(onset, 20e3, 100.0, 1, 0.0)]
    metrics = score(states, jams, rated_load_n=55e3, largest_screw_speed_rad_s=73.3)
    assert metrics.clock_offsets_s == ()  # compared at their own stamps, no clock jump
    assert metrics.false_jam_declarations == 0
    (jam,) = metrics.jams
    assert jam.onset_s == onset and jam.count == 1 and jam.delay_s == 0.0


def test_on_truth_clock_shifts_each_time_line_by_its_own_offset() -> None:
    """Each offset applies from its TIME_RESET to the next; the estimates before the first
    reset keep their stamps; offsets that do not match the resets are refused by name."""
    stamps = (1.0, 1.04, 1.08, 0.5, 0.54, 0.1)
    states = [state(t, 20e3, 100.0, 0, 0.0) for t in stamps]
    states[3] = dataclasses.replace(states[3], event=EstimateEvent.TIME_RESET)
    states[5] = dataclasses.replace(states[5], event=EstimateEvent.TIME_RESET)
    shifted = on_truth_clock(states, (2.0, -5.0))
    np.testing.assert_allclose(shifted, [1.0, 1.04, 1.08, 2.5, 2.54, -4.9])
    with pytest.raises(ValueError, match="1 offsets for 2 sensor clock jumps"):
        on_truth_clock(states, (2.0,))


def _swaying(seconds: float) -> TruthSamples:
    """A truth whose screw speed changes all the time and never repeats (a chirp), so that a
    time offset shows and only the right one matches."""
    run = truth(seconds, None)
    t = run.stamp_s
    run.screw_speed_rad_s[:] = 30.0 * np.sin(2.0 * np.pi * (0.1 * t + 0.01 * t**2)) + 5.0
    run.axial_load_n[:] = 20e3 + 10e3 * np.sin(2.0 * np.pi * run.stamp_s / 3.0)
    return run


@pytest.mark.parametrize(
    ("clock", "offsets"),
    [
        # jumps ahead by 3 s at 10 s: scored 3 s late, the load RMSE was 11 % of rated
        (lambda t: t + 3.0 * (t >= 10.0), (-3.0,)),
        # no samples from 10 to 11 s: a gap, the clock unchanged
        (lambda t: np.where((t >= 10.0) & (t < 11.0), np.nan, t), (0.0,)),
        # ahead by 3 s at 10 s, then back by 10 s at 20 s (a TIME_RESET)
        (lambda t: t + 3.0 * (t >= 10.0) - 10.0 * (t >= 20.0), (-3.0, 7.0)),
        # back by 40 s at 20 s, beyond MAX_CLOCK_OFFSET_S: the search about zero missed it
        (lambda t: t - 40.0 * (t >= 20.0), (40.0,)),
    ],
)
def test_a_clock_that_jumps_ahead_is_put_back_on_the_truths_time_line(
    clock: Any, offsets: tuple[float, ...]
) -> None:
    run = _swaying(30.0)
    times = np.arange(0.02, 30.0, 0.04)
    stamps = clock(times)
    states = []
    for t, stamp in zip(times, stamps, strict=True):
        if np.isnan(stamp):
            continue
        load = float(np.interp(t, run.stamp_s, run.axial_load_n))
        speed = float(np.interp(t, run.stamp_s, run.screw_speed_rad_s))
        event = EstimateEvent.TIME_RESET if states and stamp < states[-1].stamp_s else 0
        states.append(
            dataclasses.replace(
                state(float(stamp), load, 100.0, 0, 0.0), screw_speed_rad_s=speed, event=event
            )
        )
    metrics = score(states, run, rated_load_n=55e3, largest_screw_speed_rad_s=73.3)
    assert metrics.clock_offsets_s == pytest.approx(offsets, abs=1e-3)
    assert metrics.load_rmse_n < 1.0  # every estimate compared at its own time


@pytest.mark.parametrize(
    ("spacing_s", "dropped", "speed_noise"),
    [
        (0.12, None, 0.0),  # longer blocks: each estimate was taken for a skip of its own
        (0.04, (0.3, 0.12), 0.3),  # 0.12 s dropouts every 0.3 s: 90 of 99 lines shifted
    ],
)
def test_gaps_and_longer_blocks_are_no_clock_jumps(
    spacing_s: float, dropped: tuple[float, float] | None, speed_noise: float
) -> None:
    """Found by review: the offsets wandered up to 24.5 s, a load RMSE of 9 kN for exact
    loads."""
    run = _swaying(60.0)
    times = np.arange(spacing_s / 2, 60.0, spacing_s)
    if dropped is not None:
        period, length = dropped
        times = times[(times % period) > length]
    rng = np.random.default_rng(3)
    states = [
        dataclasses.replace(
            state(float(t), float(np.interp(t, run.stamp_s, run.axial_load_n)), 100.0, 0, 0.0),
            screw_speed_rad_s=float(np.interp(t, run.stamp_s, run.screw_speed_rad_s))
            + float(rng.normal(0.0, speed_noise)),
        )
        for t in times
    ]
    metrics = score(states, run, rated_load_n=55e3, largest_screw_speed_rad_s=73.3)
    assert all(offset == 0.0 for offset in metrics.clock_offsets_s)
    assert metrics.load_rmse_n < 1.0


def test_a_periodic_motion_after_a_gap_keeps_its_offset() -> None:
    """Found by a sine stroke's sensor-fault scene: after a 0.25 s dropout the offset moved
    to two periods of the stroke (7.98 s), whose speeds repeat; the estimates' speeds are
    means over their blocks, which lag their stamps, and the offset found further on was
    compared with the one before held exactly, not at its own best (a load RMSE of 358 N
    against 0, NEES 6.4 on the scene)."""
    run = truth(60.0, None)
    t = run.stamp_s
    run.screw_speed_rad_s[:] = 30.0 * np.sin(2.0 * np.pi * t / 4.0)
    run.axial_load_n[:] = 20e3 + 300.0 * np.sin(2.0 * np.pi * t / 13.0)
    block_s = 0.04
    ends = np.arange(block_s, 60.0, block_s)
    ends = ends[(ends < 9.0) | (ends > 9.25)]
    states = [
        dataclasses.replace(
            state(float(end), float(np.interp(end, t, run.axial_load_n)), 100.0, 0, 0.0),
            screw_speed_rad_s=float(
                np.mean(np.interp(np.linspace(end - block_s, end, 9), t, run.screw_speed_rad_s))
            ),
        )
        for end in ends
    ]
    metrics = score(states, run, rated_load_n=55e3, largest_screw_speed_rad_s=73.3)
    assert metrics.clock_offsets_s == (0.0,)
    assert metrics.load_rmse_n < 1.0


@pytest.mark.parametrize("waited_s", [0.0, 0.1])
def test_a_periodic_motion_whose_clock_is_set_back_by_its_period_goes_on(waited_s: float) -> None:
    """A clock set back by one period of a sine stroke at 20 s: every offset a period apart
    matches the speed alike, and the search about zero took zero (the estimates after the
    reset compared with the load 4 s before). The data go on at the reset, so the offset
    that puts them after the estimate before by the time their samples took is kept; with
    ``waited_s`` of samples rejected before the reset was confirmed (the estimator's wait,
    0.1 s on the sensor-fault scenes) counted in that time. Counters of 1 kHz samples."""
    run = truth(60.0, None)
    t = run.stamp_s
    run.screw_speed_rad_s[:] = 30.0 * np.sin(2.0 * np.pi * t / 4.0)
    run.axial_load_n[:] = 20e3 + 300.0 * np.sin(2.0 * np.pi * t / 13.0)
    block_s = 0.04
    states: list[HealthState] = []
    for end in np.arange(block_s, 60.0, block_s):
        if 20.0 < end <= 20.0 + waited_s + 1e-9:
            continue  # rejected, counted below
        stamp = end - 4.0 * (end > 20.0)
        event = EstimateEvent.TIME_RESET if states and stamp < states[-1].stamp_s else 0
        speed = np.mean(np.interp(np.linspace(end - block_s, end, 9), t, run.screw_speed_rad_s))
        load = float(np.interp(end, t, run.axial_load_n))
        waited = round(1000 * waited_s) if end > 20.0 else 0
        states.append(
            dataclasses.replace(
                state(float(stamp), load, 100.0, 0, 0.0),
                screw_speed_rad_s=float(speed),
                event=event,
                samples_accepted=round(1000 * end) - waited,
                samples_rejected=waited,
            )
        )
    metrics = score(states, run, rated_load_n=55e3, largest_screw_speed_rad_s=73.3)
    assert metrics.clock_offsets_s == pytest.approx((4.0,), abs=1e-3)
    assert metrics.load_rmse_n < 1.0


def test_the_jam_counts_probabilities_are_scored_per_bin() -> None:
    """Per bin of the most likely count's probability: how many estimates, how many of them
    right. A jam at 5 s: before it two estimates at p 0.6 (one says 1: wrong), after it
    three at p 1 - 1e-9 that say 0 (wrong) and two that say 1 at p 0.95 (right)."""

    def at(stamp: float, count: int, p: float) -> HealthState:
        probabilities = [0.0] * (N_ROLLERS + 1)
        probabilities[count], probabilities[1 - count] = p, 1.0 - p
        return dataclasses.replace(
            state(stamp, 20e3, 100.0, count, 0.0), jam_probabilities=tuple(probabilities)
        )

    states = [at(1.0, 0, 0.6), at(2.0, 1, 0.6)]
    states += [at(t, 0, 1.0 - 1e-9) for t in (6.0, 7.0, 8.0)] + [at(9.0, 1, 0.95), at(9.5, 1, 0.95)]
    metrics = score(states, truth(10.0, 5.0), rated_load_n=55e3, largest_screw_speed_rad_s=73.3)
    bins = {(b.low, b.high): b for b in metrics.jam_calibration}
    assert [(b.low, b.high) for b in metrics.jam_calibration] == list(
        itertools.pairwise(CALIBRATION_EDGES)
    )
    assert (bins[0.5, 0.9].estimates, bins[0.5, 0.9].correct) == (2, 1)
    assert bins[0.5, 0.9].mean_probability == pytest.approx(0.6)
    assert (bins[0.9, 0.99].estimates, bins[0.9, 0.99].correct) == (2, 2)
    assert (bins[0.99999, 1.0].estimates, bins[0.99999, 1.0].correct) == (3, 0)
    assert sum(b.estimates for b in metrics.jam_calibration) == len(states)
    assert math.isnan(bins[0.0, 0.5].mean_probability)
    assert metrics.to_dict()["jam_calibration"][0]["mean_probability"] is None


def test_estimates_beyond_the_truths_end_are_not_scored() -> None:
    """A bag cut short whose motor samples outlast its truth: the estimates after the truth's
    last sample were scored against its last values held (a load RMSE of 15.8 kN at
    standstill on a truncated nominal-downhole bag whose estimates are right)."""
    true = truth(10.0, None)  # 20 kN until 9.99 s
    stamps = np.arange(0.02, 13.0, 0.04)
    # After the truth ends the load falls to zero, which nothing can score.
    states = [state(float(t), 20e3 if t < 10.0 else 0.0, 100.0, 0, 1e-6 * t) for t in stamps]
    metrics = score(states, true, rated_load_n=55e3, largest_screw_speed_rad_s=73.3)
    assert metrics.estimates_beyond_truth == int(np.count_nonzero(stamps > 10.0))
    assert metrics.estimates == len(stamps) - metrics.estimates_beyond_truth
    assert metrics.load_max_error_n == pytest.approx(0.0, abs=1e-9)
    assert metrics.precision_loss_error_percent == pytest.approx(0.0, abs=0.5)
    # None inside (a truth cut at a damage before the first block): nothing scored, no error
    # (it raised, and the replay lost its DAMAGED summary with it).
    outside = score(states[-5:], true, rated_load_n=55e3, largest_screw_speed_rad_s=73.3)
    assert (outside.estimates, outside.estimates_beyond_truth, outside.jams) == (0, 5, ())
    assert math.isnan(outside.load_rmse_n) and outside.to_dict()["load_rmse_n"] is None
    assert outside.load_nees_consistent is None


def test_a_run_without_load_in_motion_has_no_nees_verdict() -> None:
    """Moving at 20 kN scored against a rated load of 500 kN: below the NEES test's 5 %, so
    the load is scored but its NEES is not tested (None, null in JSON), not failed."""
    stamps = np.arange(0.02, 20.0, 0.04)
    states = [state(float(t), 20e3, 100.0, 0, 1e-6 * float(t)) for t in stamps]
    metrics = score(states, truth(20.0, None), rated_load_n=500e3, largest_screw_speed_rad_s=73.3)
    assert metrics.load_rmse_n == pytest.approx(0.0, abs=1e-9)
    assert math.isnan(metrics.load_nees_mean) and metrics.load_nees_consistent is None
    assert metrics.to_dict()["load_nees_consistent"] is None
