"""Running input and filter statistics behind the diagnostics (prsm_health.tracking)."""

from __future__ import annotations

import dataclasses
from collections import Counter

import pytest

from prsm_health.estimation.estimate import EstimateEvent
from prsm_health.estimation.inputs import InputCounters, RejectReason
from prsm_health.estimation.params import params_from_mapping
from prsm_health.outputs import FILTER_CONSISTENCY, INPUT_HEALTH, STATUS_NAMES, Level
from prsm_health.tracking import DiagnosticsTracker, EventTracker, InputTracker, rejected_by_reason
from test.test_outputs import state


def test_rate_counts_the_last_second_only() -> None:
    tracker = InputTracker()
    for i in range(200):  # 10 messages every 10 ms for 2 s
        tracker.update(i * 0.01, 10, accepted=10 * (i + 1), rejected={"spike": 0})
    health = tracker.health(1.99)
    assert health.rate_hz == pytest.approx(1000.0)
    assert health.received == 2000
    assert health.last_sample_s == pytest.approx(1.99)
    assert tracker.health(5.0).rate_hz == 0.0
    assert tracker.health(5.0).last_sample_s == pytest.approx(1.99)


def test_recent_rejected_fraction() -> None:
    tracker = InputTracker()
    tracker.update(0.0, 100, accepted=100, rejected={"spike": 0})
    tracker.update(0.5, 100, accepted=180, rejected={"spike": 20})
    health = tracker.health(0.9)
    assert health.recent_rejected_fraction == pytest.approx(20 / 200)
    assert health.rejected == {"spike": 20}
    assert tracker.health(1.4).recent_rejected_fraction == pytest.approx(20 / 100)
    assert tracker.health(2.0).recent_rejected_fraction == 0.0


def test_the_reasons_named_are_the_last_seconds() -> None:
    """Non-finite samples at 0.5 s, stamps going back at 2.5 s: the warning at 2.9 s names only
    the second (it named every reason of the run)."""
    tracker = InputTracker()
    tracker.update(0.5, 100, accepted=90, rejected={"non_finite": 10, "time_backwards": 0})
    tracker.update(2.5, 100, accepted=170, rejected={"non_finite": 10, "time_backwards": 20})
    health = tracker.health(2.9)
    assert health.recent_rejected == {"time_backwards": 20}
    assert health.rejected == {"non_finite": 10, "time_backwards": 20}


def test_counts_restored_with_the_state_are_not_this_runs() -> None:
    """After a restart the estimator's totals include the runs before: clean input must not
    show as rejected (it warned '12.5 % rejected' and '400 rejected of 1251 received')."""
    tracker = InputTracker()
    tracker.start_from(5000, {"non_finite": 400})
    tracker.update(0.5, 100, accepted=5100, rejected={"non_finite": 400})
    health = tracker.health(0.9)
    assert health.recent_rejected_fraction == 0.0 and health.recent_rejected == {}
    assert health.accepted == 100 and health.rejected == {"non_finite": 0}


def test_clock_jumping_back_restarts_the_window() -> None:
    tracker = InputTracker()
    tracker.update(10.0, 100, accepted=100, rejected={})
    tracker.update(1.0, 5, accepted=105, rejected={})
    assert tracker.health(1.0).rate_hz == pytest.approx(5.0)


def test_the_stamps_rate_against_the_callers_clock() -> None:
    """Accepted samples whose stamps advance 1e-5 s per second: the rate over the last second;
    unknown without the inputs' clock, with too short a span, or once either clock went back
    (compared afresh from there)."""
    tracker = InputTracker()
    for i in range(101):  # every 10 ms, 10 samples accepted
        tracker.update(i * 0.01, 10, 10 * (i + 1), {}, input_clock_s=5.0 + i * 1e-7)
    assert tracker.health(1.0).stamp_rate == pytest.approx(1e-5)
    tracker.update(1.01, 10, 1020, {}, input_clock_s=1.0)  # a time reset of the inputs
    assert tracker.health(1.01).stamp_rate == -1.0
    steady = InputTracker()  # on the caller's clock, with one jump of the stamps (a pause)
    for i in range(101):
        stamp = 5.0 + i * 0.01 + (30.0 if i >= 50 else 0.0)
        steady.update(i * 0.01, 10, 10 * (i + 1), {}, input_clock_s=stamp)
    assert steady.health(1.0).stamp_rate == pytest.approx(1.0)
    stepped = InputTracker()  # a sim /clock of 20 Hz, the node's batches every 5 ms between
    for i in range(400):
        now = 0.05 * (i // 10)
        stepped.update(now, 5, 5 * (i + 1), {}, input_clock_s=5.0 + 0.005 * i)
    assert stepped.health(0.05 * 39).stamp_rate == pytest.approx(1.0)
    silent = InputTracker()
    silent.update(0.0, 10, 10, {})
    silent.update(0.9, 10, 20, {})
    assert silent.health(0.9).stamp_rate == -1.0
    assert silent.health(0.9).input_clock_s is None  # never given
    assert stepped.health(0.05 * 39).input_clock_s == 5.0 + 0.005 * 399  # the latest


def test_input_that_stops_as_the_clock_jumps_back_goes_stale() -> None:
    """The last input came at 10 s, then the clock reads 1 s (sim time looped back) and no
    input comes: it counts as received at the jump, not 9 s in the future (its statuses read
    OK, age -9 s, until the clock caught up)."""
    tracker = DiagnosticsTracker()
    params = params_from_mapping({"actuator": {"preset": "dong2022-downhole"}})
    tracker.inputs.update(10.0, 100, accepted=100, rejected={})
    assert tracker.inputs.health(1.0).last_sample_s == 1.0
    timeout = params.diagnostics.stale_timeout_s
    later = tracker.statuses(state(), params, "left", 1.0 + timeout + 0.5)
    assert all(s.level == Level.STALE for s in later), [(s.name, s.message) for s in later]
    assert tracker.statuses(state(), params, "left", 1.0 + timeout / 2)[0].level == Level.OK


def test_rejections_that_no_accepted_sample_follows() -> None:
    """Samples count as accepted when their block closes, seconds after they came with long
    blocks or a slow stream: messages not judged yet are no stuck sensor (counted from the
    first message, the estimates went STALE at a stream's start and, with 2 s blocks, half the
    time). Rejections that no accepted sample follows are, from the first of them on."""
    tracker = InputTracker()
    tracker.update(0.0, 40, accepted=40, rejected={"stuck": 0})
    tracker.update(4.0, 5, accepted=40, rejected={"stuck": 0})  # a new stream, no block yet
    tracker.update(6.0, 2000, accepted=40, rejected={"stuck": 0})  # its 2 s block still open
    assert tracker.health(6.0).rejecting_since_s is None
    tracker.update(6.06, 60, accepted=2080, rejected={"stuck": 0})  # the block closed
    for k in range(1, 60):  # then only rejections
        tracker.update(6.06 + 0.1 * k, 100, accepted=2080, rejected={"stuck": 100 * k})
    assert tracker.health(12.0).rejecting_since_s == pytest.approx(6.16)
    tracker.update(12.1, 100, accepted=2180, rejected={"stuck": 5900})
    assert tracker.health(12.1).rejecting_since_s is None


def test_a_clock_that_stands_still_does_not_grow_the_window() -> None:
    """use_sim_time with no /clock while input flows: every batch at the same time. The window
    kept one entry per batch, never trimmed (200 a second, for ever); one per time now, with
    the same counts."""
    tracker = InputTracker()
    for i in range(1000):
        tracker.update(7.0, 5, accepted=4 * (i + 1), rejected={"spike": i + 1}, input_clock_s=i)
    assert len(tracker._received) == len(tracker._judged) == len(tracker._clock) == 1
    health = tracker.health(7.0)
    assert health.rate_hz == pytest.approx(5000.0) and health.received == 5000
    assert health.recent_rejected_fraction == pytest.approx(0.2)


def test_rejections_by_reason_include_the_callers_own() -> None:
    counters = InputCounters()
    counters.rejected[RejectReason.TIME_BACKWARDS] = 4
    rejected = rejected_by_reason(counters, Counter(joint_missing=2))
    assert rejected["time_backwards"] == 4
    assert rejected["joint_missing"] == 2
    assert set(rejected) >= {r.name.lower() for r in RejectReason}


def test_event_tracker() -> None:
    tracker = EventTracker()
    counters = InputCounters(time_resets=0, gaps=1)
    recovered = dataclasses.replace(state(), event=EstimateEvent.DIVERGENCE_RECOVERED)
    tracker.observe(5.0, [state(), recovered], counters)
    events = tracker.events()
    assert (events.divergence_recoveries, events.gaps, events.last_warning_s) == (1, 1, 5.0)
    tracker.observe(6.0, [], InputCounters(time_resets=1))
    assert tracker.events().time_resets == 1
    assert tracker.events().last_warning_s == 6.0
    tracker.non_finite(7.0, Counter(efficiency=2))
    tracker.error(8.0, "boom")
    events = tracker.events()
    assert (events.non_finite_outputs, events.processing_errors) == (2, 1)
    assert (events.last_error_s, events.last_error) == (8.0, "processing error: boom")


def test_one_time_reset_warns_for_the_recent_window_only() -> None:
    """Pins that a time reset warns once, when the count of resets grows: the same count seen
    again later is no new reset, and the filter-consistency WARN clears after the window. A
    mutation review found it unguarded (">=": every later observation renewed the warning and
    kept the status at WARN forever after one reset)."""
    params = params_from_mapping({"actuator": {"preset": "dong2022-downhole"}})
    tracker = DiagnosticsTracker()
    counters = InputCounters(time_resets=1)

    def consistency(now_s: float) -> tuple[Level, str]:
        tracker.inputs.update(now_s, 100, accepted=100, rejected={})  # input keeps coming
        by_name = {s.name: s for s in tracker.statuses(state(), params, "left", now_s)}
        return by_name[FILTER_CONSISTENCY].level, by_name[FILTER_CONSISTENCY].message

    tracker.events.observe(10.0, [], counters)
    assert consistency(10.0) == (Level.WARN, "input time jumped back: load re-initialised")
    tracker.events.observe(110.0, [], counters)
    level, message = consistency(110.0)
    assert level == Level.OK and message.startswith("consistent")
    events = tracker.events.events()
    assert (events.time_resets, events.last_warning_s) == (1, 10.0)


def test_diagnostics_tracker_gives_the_statuses() -> None:
    params = params_from_mapping({"actuator": {"preset": "dong2022-downhole"}})
    tracker = DiagnosticsTracker()
    tracker.inputs.update(10.0, 100, accepted=95, rejected={"spike": 5})
    tracker.events.error(10.0, "boom")
    statuses = tracker.statuses(state(), params, "left", 10.2)
    assert [s.name for s in statuses] == list(STATUS_NAMES)
    by_name = {s.name: s for s in statuses}
    assert ("rated_load_n", "55000") in by_name[STATUS_NAMES[0]].values
    assert ("rejected_spike", "5") in by_name[INPUT_HEALTH].values
    assert by_name[FILTER_CONSISTENCY].message == "processing error: boom"


def test_rejections_a_window_old_are_out_of_it() -> None:
    """Pins that the rejected fraction covers the rate's window, (now - 1 s, now]: samples
    judged exactly 1 s ago are out of both. A mutation review found it unguarded (kept, they
    made the fraction 50 % where none of the last second's samples was rejected)."""
    tracker = InputTracker()
    tracker.update(0.0, 100, accepted=0, rejected={"spike": 100})
    tracker.update(0.5, 100, accepted=100, rejected={"spike": 100})
    health = tracker.health(1.0)
    assert health.rate_hz == pytest.approx(100.0)
    assert (health.recent_rejected_fraction, health.recent_rejected) == (0.0, {})


def stamps_every_10_ms(tracker: InputTracker, moves: int) -> None:
    """``moves`` updates 10 ms apart on both clocks, 10 samples accepted each."""
    for i in range(moves):
        tracker.update(i / 100, 10, 10 * (i + 1), {}, input_clock_s=5.0 + i / 100)


def test_a_burst_of_moves_shorter_than_half_the_window_gives_no_stamp_rate() -> None:
    """Pins that the stamps' rate needs its moves to span half the window: 20 moves over
    0.19 s are no rate yet, 61 over 0.6 s are. A mutation review found the span check
    unguarded (dropped, a burst after a start or a reset gave a rate from 0.19 s)."""
    burst = InputTracker()
    stamps_every_10_ms(burst, 20)
    assert burst.health(0.19).stamp_rate == -1.0
    longer = InputTracker()
    stamps_every_10_ms(longer, 61)
    assert longer.health(0.6).stamp_rate == pytest.approx(1.0)
