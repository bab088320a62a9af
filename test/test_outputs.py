"""HealthEstimate fields and diagnostics as plain data (prsm_health.outputs)."""

from __future__ import annotations

import dataclasses
import math
from collections import Counter

import pytest

from prsm_health.estimation.estimate import EstimateEvent, HealthState
from prsm_health.estimation.inputs import InputMeasures
from prsm_health.estimation.params import DiagnosticThresholds
from prsm_health.outputs import (
    AXIAL_LOAD,
    CONFIGURATION,
    FATIGUE,
    FILTER_CONSISTENCY,
    INPUT_HEALTH,
    JAMMED_ROLLERS,
    PERSISTENCE,
    PRECISION_LOSS,
    STANDSTILL_JAM_NOTE,
    STATUS_NAMES,
    FilterEvents,
    InputHealth,
    Level,
    PersistenceHealth,
    configuration_status,
    diagnostic_statuses,
    health_estimate_fields,
    persistence_status,
    restored_statuses,
)

RATED_N = 55_000.0
NOW = 100.0


#: An estimate: 20 kN resisting, almost surely no jam, 2 um lost.
BASE_STATE = {
    "stamp_s": 99.9,
    "axial_load_n": -20_000.0,
    "axial_load_std_n": 150.0,
    "jam_probabilities": (0.99, 0.01, 0.0),
    "precision_loss_m": 2e-6,
    "precision_loss_std_m": 5e-7,
    "precision_loss_rate_m_per_s": 1e-9,
    "friction_torque_nm": 0.8,
    "efficiency": 0.9,
    "fatigue_damage": 0.01,
    "fatigue_damage_std": 0.002,
    "screw_speed_rad_s": 31.4,
    "samples_accepted": 5000,
    "samples_rejected": 3,
    "nis": 1.1,
    "event": EstimateEvent.NONE,
}


def state(**changes: object) -> HealthState:
    return HealthState(**{**BASE_STATE, **changes})  # type: ignore[arg-type]


def inputs(**changes: object) -> InputHealth:
    base = InputHealth(
        rate_hz=1000.0,
        last_sample_s=NOW - 0.01,
        received=5003,
        accepted=5000,
        rejected={"non_finite": 3, "spike": 0},
    )
    return dataclasses.replace(base, **changes)  # type: ignore[arg-type]


def statuses(
    s: HealthState | None = None,
    i: InputHealth | None = None,
    th: DiagnosticThresholds | None = None,
    events: FilterEvents | None = None,
) -> dict[str, tuple[Level, str, dict[str, str]]]:
    result = diagnostic_statuses(
        s if s is not None else state(),
        i if i is not None else inputs(),
        th if th is not None else DiagnosticThresholds(),
        RATED_N,
        "left",
        NOW,
        events,
    )
    assert [r.name for r in result] == list(STATUS_NAMES)
    assert all(r.hardware_id == "left" for r in result)
    return {r.name: (r.level, r.message, dict(r.values)) for r in result}


def test_fields_in_message_units() -> None:
    fields = health_estimate_fields(state())
    assert fields["axial_load_n"] == 20_000.0  # magnitude
    assert fields["precision_loss_um"] == pytest.approx(2.0)
    assert fields["precision_loss_std_um"] == pytest.approx(0.5)
    assert fields["precision_loss_rate_um_per_h"] == pytest.approx(1e-9 * 1e6 * 3600)
    assert fields["jammed_rollers_probability"] == [0.99, 0.01, 0.0]
    assert fields["jammed_rollers_most_likely"] == 0
    assert fields["normalized_innovation_squared"] == 1.1
    assert fields["event"] == 0
    assert (fields["samples_accepted"], fields["samples_rejected"]) == (5000, 3)


def test_non_finite_values_are_replaced_and_counted() -> None:
    replaced: Counter[str] = Counter()
    bad = state(
        axial_load_n=math.nan,
        efficiency=math.inf,
        jam_probabilities=(math.nan, 0.5, 0.5),
    )
    fields = health_estimate_fields(bad, replaced=replaced)
    assert fields["axial_load_n"] == 0.0
    assert fields["efficiency"] == 0.0
    assert fields["jammed_rollers_probability"] == pytest.approx([1 / 3] * 3)
    assert replaced == {"axial_load_n": 1, "efficiency": 1, "jammed_rollers_probability": 1}
    floats = [v for v in fields.values() if isinstance(v, float)]
    assert all(math.isfinite(v) for v in floats + fields["jammed_rollers_probability"])
    # A negative probability, or none at all, is no distribution either (a mutation review).
    for probabilities in ((-0.1, 0.6, 0.5), (0.0, 0.0, 0.0)):
        replaced.clear()
        fields = health_estimate_fields(state(jam_probabilities=probabilities), replaced=replaced)
        assert fields["jammed_rollers_probability"] == pytest.approx([1 / 3] * 3)
        assert replaced == {"jammed_rollers_probability": 1}


def test_load_levels_follow_the_rated_fractions() -> None:
    th = DiagnosticThresholds()
    for load, level in ((0.5, Level.OK), (0.95, Level.WARN), (1.2, Level.ERROR)):
        got, message, values = statuses(state(axial_load_n=load * RATED_N), th=th)[AXIAL_LOAD]
        assert got == level, (load, message)
        assert float(values["axial_load_n"]) == pytest.approx(load * RATED_N)
        assert float(values["load_fraction_of_rated"]) == pytest.approx(load)


def test_estimator_statuses_name_the_estimate_they_report() -> None:
    """Each estimator status carries its estimate's stamp to the millisecond, also an epoch
    stamp (a node behind a backlog of samples reports an estimate older than its clock); the
    input and consistency statuses, which are about now, do not."""
    epoch = 1_764_072_000.123
    reported = statuses(state(stamp_s=epoch))
    for name in (AXIAL_LOAD, JAMMED_ROLLERS, PRECISION_LOSS, FATIGUE):
        assert reported[name][2]["estimate_stamp_s"] == "1764072000.123", name
    assert "estimate_stamp_s" not in reported[INPUT_HEALTH][2]


def test_jam_levels_and_message_names_the_count() -> None:
    level, message, values = statuses(state(jam_probabilities=(0.02, 0.98, 0.0)))[JAMMED_ROLLERS]
    assert level == Level.ERROR
    assert message == "1 jammed roller (p = 0.98)"
    assert values["jammed_rollers_most_likely"] == "1"
    assert float(values["jam_probability_1"]) == pytest.approx(0.98)
    assert float(values["jam_probability_any"]) == pytest.approx(0.98)

    level, message, _ = statuses(state(jam_probabilities=(0.1, 0.2, 0.7)))[JAMMED_ROLLERS]
    assert (level, message) == (Level.ERROR, "2 jammed rollers (p = 0.70)")

    level, message, _ = statuses(state(jam_probabilities=(0.7, 0.3, 0.0)))[JAMMED_ROLLERS]
    assert level == Level.WARN
    assert "0.30" in message

    level, _, _ = statuses(state(jam_probabilities=(0.9, 0.1, 0.0)))[JAMMED_ROLLERS]
    assert level == Level.OK


def test_at_standstill_the_jam_status_says_a_new_jam_cannot_show() -> None:
    """A standing screw's torque carries no evidence of a jam: the status says so, at every
    level, and ``jam_observable`` is 0; moving, neither."""
    for probabilities in ((0.999, 0.001, 0.0), (0.7, 0.3, 0.0), (0.02, 0.98, 0.0)):
        standing = statuses(state(jam_probabilities=probabilities, event=EstimateEvent.STANDSTILL))[
            JAMMED_ROLLERS
        ]
        moving = statuses(state(jam_probabilities=probabilities))[JAMMED_ROLLERS]
        assert standing[0] == moving[0]
        assert standing[1] == moving[1] + STANDSTILL_JAM_NOTE
        assert (standing[2]["jam_observable"], moving[2]["jam_observable"]) == ("0", "1")


def test_precision_loss_and_fatigue_levels() -> None:
    th = DiagnosticThresholds(precision_loss_budget_um=10.0)
    level, _, values = statuses(state(precision_loss_m=8e-6), th=th)[PRECISION_LOSS]
    assert level == Level.WARN
    assert float(values["precision_loss_um"]) == pytest.approx(8.0)
    assert statuses(state(precision_loss_m=11e-6), th=th)[PRECISION_LOSS][0] == Level.ERROR
    assert statuses(state(fatigue_damage=0.6))[FATIGUE][0] == Level.WARN
    assert statuses(state(fatigue_damage=0.95))[FATIGUE][0] == Level.ERROR


def test_input_health_rate_and_rejections() -> None:
    level, _, values = statuses(i=inputs())[INPUT_HEALTH]
    assert level == Level.OK
    assert values["rejected_non_finite"] == "3"
    assert values["received"] == "5003"
    assert values["speed_noise_std_rad_s"] == "-1"  # not measured yet
    level, message, values = statuses(
        i=inputs(measures=InputMeasures(speed_noise_std_rad_s=1.853))
    )[INPUT_HEALTH]
    assert level == Level.OK and message.endswith(" received, speed noise 1.85 rad/s")
    assert values["speed_noise_std_rad_s"] == "1.853"
    assert values["current_noise_std_a"] == "-1"  # not measured yet
    level, message, values = statuses(i=inputs(measures=InputMeasures(current_noise_std_a=0.21)))[
        INPUT_HEALTH
    ]
    assert level == Level.OK and message.endswith(" received, current noise 0.210 A")
    assert values["current_noise_std_a"] == "0.21"
    assert values["position_per_speed"] == "-1"  # not measured yet
    level, message, values = statuses(i=inputs(measures=InputMeasures(position_per_speed=1.04)))[
        INPUT_HEALTH
    ]
    assert level == Level.OK and message.endswith(" received, position per speed 1.04")
    assert values["position_per_speed"] == "1.04"
    # A position of the screw's behind a 5:1 gear (position_speed.py)
    level, message, _ = statuses(i=inputs(measures=InputMeasures(position_per_speed=0.2)))[
        INPUT_HEALTH
    ]
    assert level == Level.WARN
    assert message.startswith("the position moves 0.2 rad per rad the speed says (a unit")
    assert "torque_along_motion_forward_nm" not in values  # signed: absent until measured
    # A current of the other sign: the motor brakes the motion both ways (motion_torque.py).
    level, message, values = statuses(
        i=inputs(measures=InputMeasures(torque_along_motion_nm=(-5.35, -7.01)))
    )[INPUT_HEALTH]
    assert level == Level.WARN
    assert message.startswith("the motor brakes the motion both ways (-5.35 N·m along it forward")
    assert values["torque_along_motion_forward_nm"] == "-5.35"
    assert values["torque_along_motion_reverse_nm"] == "-7.01"
    # A weight lifted and lowered: braking one way only is no mistake.
    level, _, values = statuses(
        i=inputs(measures=InputMeasures(torque_along_motion_nm=(5.35, None)))
    )[INPUT_HEALTH]
    assert level == Level.OK and values["torque_along_motion_forward_nm"] == "5.35"
    assert "torque_along_motion_reverse_nm" not in values
    level, message, _ = statuses(i=inputs(rate_hz=20.0))[INPUT_HEALTH]
    assert level == Level.WARN
    assert "20 Hz" in message
    level, message, _ = statuses(
        i=inputs(recent_rejected_fraction=0.2, recent_rejected={"non_finite": 3})
    )[INPUT_HEALTH]
    assert level == Level.WARN
    assert "non_finite" in message
    # A speed in rpm read as rad/s: out of range, and the field named.
    level, message, values = statuses(
        i=inputs(
            recent_rejected_fraction=0.5,
            recent_rejected={"out_of_range": 500, "spike": 1},
            measures=InputMeasures(
                out_of_range_by_field={"stamp": 0, "current": 0, "speed": 30476, "position": 0}
            ),
        )
    )[INPUT_HEALTH]
    assert level == Level.WARN
    assert message.endswith("50.0 % rejected in the last second (out_of_range: speed, spike)")
    assert values["out_of_range_speed"] == "30476" and values["out_of_range_stamp"] == "0"


@pytest.mark.parametrize(
    ("stamp_rate", "warned"),
    [(-1.0, False), (1.0, False), (20.0, False), (1e-5, True), (1e3, True)],
)
def test_input_stamps_on_another_clock_than_the_nodes_are_named(
    stamp_rate: float, warned: bool
) -> None:
    """Stamps that advance 1e-5 s per second received (a tick counter read as seconds): no
    block ever completed and input health read OK; 1 s a sample at 1 kHz: every sample a gap,
    OK. A bag played 20 times as fast is no clock error; -1 is not known (an offline replay)."""
    level, message, values = statuses(i=inputs(stamp_rate=stamp_rate))[INPUT_HEALTH]
    assert values["stamp_rate"] == f"{stamp_rate:g}"
    assert (level == Level.WARN) == warned
    if warned:
        assert f"stamps advance {stamp_rate:.3g} s per second received" in message


@pytest.mark.parametrize(("input_clock_s", "warned"), [(None, False), (0.0, False), (-497.0, True)])
def test_input_stamps_before_1970_are_named(input_clock_s: float | None, warned: bool) -> None:
    """Stamps from -500 s: every estimate went out stamped 0 (a ROS time cannot be negative)
    and every status read OK (found by a review session). None: not known (a replay)."""
    level, message, _ = statuses(i=inputs(input_clock_s=input_clock_s))[INPUT_HEALTH]
    assert (level == Level.WARN) == warned
    assert ("stamps before 1970 (negative): the estimates go out stamped 0" in message) == warned


def test_filter_consistency_reports_recent_problems() -> None:
    level, _, values = statuses()[FILTER_CONSISTENCY]
    assert level == Level.OK
    assert float(values["normalized_innovation_squared"]) == pytest.approx(1.1)
    recent = FilterEvents(divergence_recoveries=1, last_warning_s=NOW - 2.0, last_warning="x")
    assert statuses(events=recent)[FILTER_CONSISTENCY][:2] == (Level.WARN, "x")
    old = dataclasses.replace(recent, last_warning_s=NOW - 60.0)
    assert statuses(events=old)[FILTER_CONSISTENCY][0] == Level.OK
    error = FilterEvents(non_finite_outputs=2, last_error_s=NOW, last_error="non-finite")
    assert statuses(events=error)[FILTER_CONSISTENCY][0] == Level.ERROR
    # Stamped after now: the clock went back (a looped bag with its clock), an old time line.
    future = dataclasses.replace(error, last_error_s=NOW + 30.0)
    assert statuses(events=future)[FILTER_CONSISTENCY][0] == Level.OK


def test_every_status_is_stale_without_recent_input() -> None:
    th = DiagnosticThresholds(stale_timeout_s=0.5)
    result = statuses(i=inputs(last_sample_s=NOW - 2.0), th=th)
    assert {level for level, _, _ in result.values()} == {Level.STALE}
    assert all(message.startswith("stale: no input for 2.0 s") for _, message, _ in result.values())
    never = statuses(i=inputs(last_sample_s=None), th=th)
    assert {level for level, _, _ in never.values()} == {Level.STALE}
    # A wrong input_topic shows here: the statuses name the topic listened to.
    named = statuses(i=inputs(last_sample_s=None, topic="/left/motor_state"), th=th)
    assert all(
        m.startswith("stale: no input yet on /left/motor_state;") for _, m, _ in named.values()
    )
    assert statuses(i=inputs(last_sample_s=NOW - 0.4), th=th)[AXIAL_LOAD][0] == Level.OK


def test_estimates_go_stale_while_every_sample_is_rejected() -> None:
    """Messages keep coming but none is accepted (a stuck sensor): the estimate statuses say
    their estimate is old; the input health says why (it stayed OK, frozen, for ever)."""
    th = DiagnosticThresholds(stale_timeout_s=0.5)
    rejecting = inputs(
        rejecting_since_s=NOW - 6.0, recent_rejected_fraction=1.0, recent_rejected={"stuck": 1000}
    )
    result = statuses(i=rejecting, th=th)
    for name, (level, message, _) in result.items():
        if name == INPUT_HEALTH:
            assert level == Level.WARN and "100.0 % rejected in the last second (stuck)" in message
        else:
            assert level == Level.STALE, name
            assert message.startswith("stale: every sample rejected for 6.0 s; last: "), name
    accepting = statuses(i=inputs(rejecting_since_s=NOW - 0.4), th=th)
    assert {level for level, _, _ in accepting.values()} == {Level.OK}


def test_no_estimate_yet() -> None:
    result = diagnostic_statuses(None, inputs(), DiagnosticThresholds(), RATED_N, "left", NOW, None)
    assert [s.level for s in result[:4]] == [Level.OK] * 4
    assert all(s.message == "no estimate yet" for s in result[:4])


def test_values_are_bare_numbers() -> None:
    for name, (_, _, values) in statuses().items():
        for key, value in values.items():
            assert float(value) == float(value), (name, key)  # parses, not NaN
            assert math.isfinite(float(value)), (name, key)


def test_persistence_status() -> None:
    fresh = persistence_status(PersistenceHealth(state_file="/s.json"), "left", NOW)
    assert (fresh.name, fresh.level) == (PERSISTENCE, Level.OK)
    kept = PersistenceHealth(
        state_file="/s.json", kept_aside="/s.json.corrupt-x", problem="unusable state file"
    )
    status = persistence_status(kept, "left", NOW)
    assert status.level == Level.WARN
    assert "/s.json.corrupt-x" in status.message
    assert ("kept_aside", "/s.json.corrupt-x") in status.values
    failing = PersistenceHealth(state_file="/s.json", save_error="disk full")
    assert persistence_status(failing, "left", NOW).level == Level.ERROR
    saved = PersistenceHealth(state_file="/s.json", saves=1, last_save_s=NOW - 4.0)
    assert ("last_save_age_s", "4") in persistence_status(saved, "left", NOW).values
    later = dataclasses.replace(saved, last_save_s=NOW + 30.0)  # the clock went back
    assert ("last_save_age_s", "0") in persistence_status(later, "left", NOW).values


def test_restored_statuses_say_so() -> None:
    """A restored jam stays what it is (STALE until input comes, its level after), named with
    the sensor time of its estimate."""
    jammed = state(jam_probabilities=(0.0, 0.0, 1.0))
    never = inputs(last_sample_s=None)
    plain = diagnostic_statuses(jammed, never, DiagnosticThresholds(), RATED_N, "left", NOW)
    marked = {s.name: s for s in restored_statuses(plain, jammed.stamp_s)}
    jam = marked[JAMMED_ROLLERS]
    assert jam.level == Level.STALE
    assert jam.message == (
        "stale: no input yet; last: 2 jammed rollers (p = 1.00)"
        " (restored, estimate at sensor time 99.900 s)"
    )
    assert ("estimate_stamp_s", "99.900") in jam.values
    for before in plain:
        after = marked[before.name]
        assert (after.level, after.values) == (before.level, before.values)
        restored = after.message.endswith("(restored, estimate at sensor time 99.900 s)")
        assert restored == (before.name in STATUS_NAMES[:4])
    live = diagnostic_statuses(jammed, inputs(), DiagnosticThresholds(), RATED_N, "left", NOW)
    assert restored_statuses(live, jammed.stamp_s)[1].level == Level.ERROR  # input came


def test_configuration_status() -> None:
    status = configuration_status("parameter input_type: must be one of a, b", "left")
    assert (status.name, status.level, status.hardware_id) == (CONFIGURATION, Level.ERROR, "left")
    assert status.message == "configure failed: parameter input_type: must be one of a, b"


#: 2**-17 m is 15625 / 2048 um, exact in binary: the precision-loss fractions below are exact.
LOSS_M = 2.0**-17
LOSS_UM = LOSS_M * 1e6


@pytest.mark.parametrize(
    ("name", "state_changes", "input_changes", "th", "events", "level"),
    [
        (AXIAL_LOAD, {"axial_load_n": 49_500.0}, {}, {}, None, Level.WARN),  # 0.9 of rated
        (AXIAL_LOAD, {"axial_load_n": 60_500.0}, {}, {}, None, Level.ERROR),  # 1.1 of rated
        (
            JAMMED_ROLLERS,
            {"jam_probabilities": (0.75, 0.25, 0.0)},
            {},
            {"jam_warn_probability": 0.25},
            None,
            Level.WARN,
        ),
        (
            PRECISION_LOSS,
            {"precision_loss_m": LOSS_M},
            {},
            {"precision_loss_budget_um": 2 * LOSS_UM, "precision_loss_warn_fraction": 0.5},
            None,
            Level.WARN,
        ),
        (
            PRECISION_LOSS,
            {"precision_loss_m": LOSS_M},
            {},
            {"precision_loss_budget_um": LOSS_UM},
            None,
            Level.ERROR,
        ),
        (FATIGUE, {"fatigue_damage": 0.5}, {}, {}, None, Level.WARN),
        (FATIGUE, {"fatigue_damage": 0.9}, {}, {}, None, Level.ERROR),
        (INPUT_HEALTH, {}, {"rate_hz": 100.0}, {}, None, Level.OK),  # not below the minimum
        (
            INPUT_HEALTH,
            {},
            {"recent_rejected_fraction": 0.05, "recent_rejected": {"spike": 5}},
            {},
            None,
            Level.WARN,
        ),
        (INPUT_HEALTH, {}, {}, {"rejected_warn_fraction": 0.0}, None, Level.OK),  # none rejected
        (INPUT_HEALTH, {}, {"stamp_rate": 100.0}, {}, None, Level.OK),
        (INPUT_HEALTH, {}, {"stamp_rate": 0.01}, {}, None, Level.OK),
        (INPUT_HEALTH, {}, {"stamp_rate": 0.0}, {}, None, Level.WARN),  # stamps standing still
        (
            FILTER_CONSISTENCY,
            {},
            {},
            {},
            FilterEvents(last_warning_s=NOW - 10.0, last_warning="w"),
            Level.WARN,
        ),
        (FATIGUE, {}, {"last_sample_s": NOW - 1.0}, {}, None, Level.OK),  # as old as the timeout
        (FATIGUE, {}, {"rejecting_since_s": NOW - 1.0}, {}, None, Level.OK),
    ],
    ids=[
        "load-warn",
        "load-error",
        "jam-warn",
        "precision-warn",
        "precision-error",
        "fatigue-warn",
        "fatigue-error",
        "min-rate",
        "rejected-warn",
        "rejected-none",
        "stamp-rate-high",
        "stamp-rate-low",
        "stamp-rate-zero",
        "recent-warning",
        "stale-timeout",
        "rejecting-timeout",
    ],
)
def test_each_threshold_is_met_at_its_value(
    name: str,
    state_changes: dict[str, object],
    input_changes: dict[str, object],
    th: dict[str, float],
    events: FilterEvents | None,
    level: Level,
) -> None:
    """Pins each documented limit at its exact value (levels at or above a threshold, rates
    below the minimum, stamp rates outside [0.01, 100] per second, 10 s of recent events, STALE
    older than the timeout): a mutation review found every one of these edges unguarded."""
    got = statuses(
        state(**state_changes), inputs(**input_changes), DiagnosticThresholds(**th), events
    )
    assert got[name][0] == level, got[name][1]


def test_messages_state_the_values_in_their_units() -> None:
    """Pins the load in kN, the precision loss in um and its rate in um per hour, the damage
    and its levels, as the status messages word them: a mutation review found them
    unguarded (the load in tenths of a kN and the rate per second passed)."""
    got = statuses()
    assert got[AXIAL_LOAD][1] == "20.0 ± 0.15 kN (1 sigma), 36 % of rated 55 kN"
    assert got[PRECISION_LOSS][1] == "2 um of the 50 um budget (3.6 um/h)"
    assert got[PRECISION_LOSS][2]["precision_loss_rate_um_per_h"] == "3.6"
    assert got[FATIGUE][1] == "Miner damage 0.01 (warn 0.5, error 0.9)"


def test_counts_are_published_whole() -> None:
    """Pins that counts go out as integers, all their digits, beyond the six significant
    digits that other values get: a mutation review found it unguarded (12345678 received
    went out as 1.23457e+07)."""
    many = inputs(received=12_345_678, accepted=12_345_670, rejected={"spike": 8})
    events = FilterEvents(gaps=1_000_001)
    got = statuses(i=many, events=events)
    assert got[INPUT_HEALTH][2]["received"] == "12345678"
    assert got[INPUT_HEALTH][2]["accepted"] == "12345670"
    assert got[FILTER_CONSISTENCY][2]["gaps"] == "1000001"
    assert got[INPUT_HEALTH][2]["rate_hz"] == "1000"
