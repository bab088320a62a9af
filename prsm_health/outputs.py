"""What the estimator's outputs contain, as plain data: ``HealthEstimate`` fields and diagnostics.

ROS-free, shared by the live node (:mod:`prsm_health.ros`) and the offline replay (which writes
the same content into MCAP through rosbags message classes), so a bag of estimates and the live
topics cannot differ in content.

``HealthEstimate``: :func:`health_estimate_fields` converts a :class:`HealthState` to the
message's fields and units (|axial load| in N, um, um/h, probabilities). A non-finite value can
never be published: it is replaced by a safe value and counted (see the function).

Diagnostics (``diagnostic_msgs/DiagnosticStatus`` as :class:`DiagnosticStatusData`): one status
per concern, with stable names (``STATUS_NAMES``) and key-values that are bare numbers as
strings with the unit in the key, so that PlotJuggler and Foxglove turn them into series.
When the inputs are older than ``stale_timeout_s`` (or never came), every estimator status is
STALE: its message says for how long, its values are the last known ones. The persistence
status (:func:`persistence_status`) is about the node's state file, not about the inputs, and
is never stale.
"""

from __future__ import annotations

import enum
import math
import re
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

from prsm_health.estimation.estimate import S_PER_H, UM_PER_M, EstimateEvent, HealthState
from prsm_health.estimation.inputs import InputMeasures
from prsm_health.estimation.motion_torque import against_motion
from prsm_health.estimation.params import DiagnosticThresholds
from prsm_health.estimation.position_speed import disagreement

#: Input stamps that advance more than this many times faster or slower than the node's clock
#: are a clock in the wrong unit (ms or us read as s, a tick counter), not a bag played fast.
STAMP_RATE_LIMIT = 100.0
#: Seconds during which a divergence recovery, a time reset, a non-finite output or a
#: processing error keeps the filter-consistency status at WARN or ERROR.
RECENT_S = 10.0

AXIAL_LOAD = "prsm_health: axial load"
JAMMED_ROLLERS = "prsm_health: jammed rollers"
PRECISION_LOSS = "prsm_health: precision loss"
FATIGUE = "prsm_health: fatigue"
INPUT_HEALTH = "prsm_health: input health"
FILTER_CONSISTENCY = "prsm_health: filter consistency"
PERSISTENCE = "prsm_health: persistence"
CONFIGURATION = "prsm_health: configuration"
#: Appended to the jammed-rollers message at standstill, where the torque carries no evidence
#: of a jam (docs/estimation.md, "Measurement model").
STANDSTILL_JAM_NOTE = "; at standstill: a new jam cannot show until the screw moves"
#: The diagnostics' hardware_id when none is given (the node's parameter, replay's option).
DEFAULT_HARDWARE_ID = "prsm_actuator"
#: What a hardware_id may be (it names the node's state file too).
HARDWARE_ID_PATTERN = "[A-Za-z0-9_.-]+"


def hardware_id_problem(hardware_id: str) -> str | None:
    """Why ``hardware_id`` cannot be one (None if it can): the node's and replay's check."""
    if re.fullmatch(HARDWARE_ID_PATTERN, hardware_id):
        return None
    return f"must match {HARDWARE_ID_PATTERN}, got {hardware_id!r}"


#: The statuses of the estimate itself (the rest are about the inputs and the filter).
ESTIMATE_STATUS_NAMES = (AXIAL_LOAD, JAMMED_ROLLERS, PRECISION_LOSS, FATIGUE)
#: The estimator statuses, in the order :func:`diagnostic_statuses` returns them.
STATUS_NAMES = (*ESTIMATE_STATUS_NAMES, INPUT_HEALTH, FILTER_CONSISTENCY)

#: Float fields of ``HealthEstimate`` that are standard deviations or values (all replaced by
#: 0.0 when non-finite; see :func:`health_estimate_fields`).
_FLOAT_FIELDS = (
    "axial_load_n",
    "axial_load_std_n",
    "precision_loss_um",
    "precision_loss_std_um",
    "precision_loss_rate_um_per_h",
    "friction_torque_nm",
    "efficiency",
    "fatigue_damage",
    "fatigue_damage_std",
    "screw_speed_rad_s",
    "normalized_innovation_squared",
)


class Level(enum.IntEnum):
    """``diagnostic_msgs/DiagnosticStatus`` levels: OK, WARN, ERROR (the estimate crossed a
    threshold, or the node failed), STALE (no recent input)."""

    OK, WARN, ERROR, STALE = range(4)


#: A status before the name and hardware id are attached: level, message, key-values.
_Part = tuple[Level, str, list[tuple[str, str]]]


@dataclass(frozen=True)
class DiagnosticStatusData:
    """One ``DiagnosticStatus``: values are (key, bare number as a string) pairs."""

    name: str
    level: Level
    message: str
    hardware_id: str
    values: list[tuple[str, str]]


@dataclass(frozen=True)
class InputHealth:
    """How the inputs arrive (the content of the input-health status).

    rate_hz: input messages received per second over the last second. last_sample_s: when the
    last one arrived, on the caller's clock (the node's clock; None before the first).
    received: messages received since start. accepted: samples the estimator accepted since
    start. rejected: samples rejected since start, by reason (the estimator's reasons in lower
    case, plus the caller's own, e.g. ``joint_missing``). recent_rejected_fraction: share of
    the samples judged over the last second that were rejected; recent_rejected: those, by
    reason. topic: the input topic (empty if unknown): the stale message names it while no
    input came (a wrong input_topic shows there). rejecting_since_s: when the first sample
    was rejected that no accepted sample has followed yet, on the same clock (None: none): while
    every sample is rejected (a stuck or dead sensor), the estimates stop. (Not the first message
    received: samples count as accepted when their block closes, which takes longer than the
    stale timeout with long blocks or a slow stream.) stamp_rate: seconds
    by which the accepted samples' stamps advance per second of the caller's clock (the median
    over the last second; -1: not known, e.g. in an offline replay, whose clock is the stamps).
    input_clock_s: the latest accepted sample's stamp (None: not known, as in an offline
    replay). measures: what the estimator has measured of its inputs
    (:attr:`HealthEstimator.input_measures
    <prsm_health.estimation.estimator.HealthEstimator.input_measures>`).
    """

    rate_hz: float
    last_sample_s: float | None
    received: int
    accepted: int
    rejected: Mapping[str, int]
    recent_rejected_fraction: float = 0.0
    recent_rejected: Mapping[str, int] = field(default_factory=dict)
    topic: str = ""
    rejecting_since_s: float | None = None
    stamp_rate: float = -1.0
    input_clock_s: float | None = None
    measures: InputMeasures = field(default_factory=InputMeasures)


@dataclass(frozen=True)
class FilterEvents:
    """What happened to the filter and to the outputs (the filter-consistency status).

    Counts since start: time_resets and gaps (input stage), divergence_recoveries (estimates
    with event DIVERGENCE_RECOVERED), non_finite_outputs (values replaced by
    :func:`health_estimate_fields`), processing_errors (exceptions caught around the
    estimator). last_warning_s / last_error_s: when the last time reset or recovery / the last
    non-finite output or processing error happened (caller's clock), with a short text.
    """

    time_resets: int = 0
    gaps: int = 0
    divergence_recoveries: int = 0
    non_finite_outputs: int = 0
    processing_errors: int = 0
    last_warning_s: float | None = None
    last_warning: str = ""
    last_error_s: float | None = None
    last_error: str = ""


@dataclass(frozen=True)
class PersistenceHealth:
    """The state file: where, when last saved, what happened at restore and at the last save.

    restored: the estimator resumed from the file at configure. kept_aside: where an
    unusable state file was moved aside (None if none was), with the reason in problem; a
    restored file's problem is a part of it not used (its last estimate, or the filters' states
    saved under other drive-train or model parameters).
    save_error: the last save failure (None after a successful save).
    """

    state_file: str
    last_save_s: float | None = None
    saves: int = 0
    restored: bool = False
    kept_aside: str | None = None
    problem: str = ""
    save_error: str | None = None


def _finite(value: float, name: str, replaced: Counter[str] | None) -> float:
    if math.isfinite(value):
        return float(value)
    if replaced is not None:
        replaced[name] += 1
    return 0.0


def _probabilities(state: HealthState, replaced: Counter[str] | None) -> list[float]:
    probabilities = [float(p) for p in state.jam_probabilities]
    valid = bool(probabilities) and all(math.isfinite(p) and p >= 0.0 for p in probabilities)
    if valid and sum(probabilities) > 0.0:
        return probabilities
    if replaced is not None:
        replaced["jammed_rollers_probability"] += 1
    n = max(len(probabilities), 1)
    return [1.0 / n] * n


def health_estimate_fields(
    state: HealthState, *, replaced: Counter[str] | None = None
) -> dict[str, Any]:
    """``HealthEstimate`` field name -> value in the message's units (header excluded).

    The axial load is the magnitude (the message has no sign), lengths in um, rates in um/h.
    Safe values for what should never happen: a non-finite float becomes 0.0; non-finite or
    negative jam probabilities become the uniform distribution ("unknown"), from which the
    most likely count is taken. Each replacement adds 1 to ``replaced[field name]``, so the
    caller can report it (the node's filter-consistency status turns ERROR).
    """
    probabilities = _probabilities(state, replaced)
    values = {
        "axial_load_n": abs(state.axial_load_n),
        "axial_load_std_n": state.axial_load_std_n,
        "precision_loss_um": state.precision_loss_m * UM_PER_M,
        "precision_loss_std_um": state.precision_loss_std_m * UM_PER_M,
        "precision_loss_rate_um_per_h": state.precision_loss_rate_m_per_s * UM_PER_M * S_PER_H,
        "friction_torque_nm": state.friction_torque_nm,
        "efficiency": state.efficiency,
        "fatigue_damage": state.fatigue_damage,
        "fatigue_damage_std": state.fatigue_damage_std,
        "screw_speed_rad_s": state.screw_speed_rad_s,
        "normalized_innovation_squared": state.nis,
    }
    fields: dict[str, Any] = {name: _finite(values[name], name, replaced) for name in _FLOAT_FIELDS}
    fields["jammed_rollers_probability"] = probabilities
    fields["jammed_rollers_most_likely"] = max(
        range(len(probabilities)), key=probabilities.__getitem__
    )
    fields["samples_accepted"] = max(int(state.samples_accepted), 0)
    fields["samples_rejected"] = max(int(state.samples_rejected), 0)
    fields["event"] = int(state.event)
    return fields


def _num(value: float) -> str:
    """A bare number for a diagnostics value (never NaN or inf: those become 0)."""
    return f"{value:.6g}" if math.isfinite(value) else "0"


def _numbers(values: Mapping[str, float]) -> list[tuple[str, str]]:
    """Key-values of numbers: counts as integers, the rest as :func:`_num` does."""
    return [
        (key, str(value) if isinstance(value, int) else _num(value))
        for key, value in values.items()
    ]


def _picked(fields: Mapping[str, Any], *names: str) -> dict[str, float]:
    """The named fields of a HealthEstimate (as diagnostics values of the same name)."""
    return {name: float(fields[name]) for name in names}


def _level(value: float, warn: float, error: float) -> Level:
    if value >= error:
        return Level.ERROR
    return Level.WARN if value >= warn else Level.OK


def _rollers(count: int) -> str:
    return f"{count} jammed roller{'s' if count != 1 else ''}"


def _axial_load(fields: Mapping[str, Any], th: DiagnosticThresholds, rated_n: float) -> _Part:
    load = float(fields["axial_load_n"])
    fraction = load / rated_n
    level = _level(fraction, th.load_warn_fraction, th.load_error_fraction)
    std = float(fields["axial_load_std_n"])  # over 10 kN at standstill: say it
    message = (
        f"{load / 1e3:.1f} ± {std / 1e3:.2g} kN (1 sigma), {100.0 * fraction:.0f} % of rated "
        f"{rated_n / 1e3:.3g} kN"
    )
    values = _picked(fields, "axial_load_n", "axial_load_std_n")
    values |= {"rated_load_n": rated_n, "load_fraction_of_rated": fraction}
    values |= _picked(fields, "friction_torque_nm", "efficiency", "screw_speed_rad_s")
    return level, message, _numbers(values)


def _jammed(fields: Mapping[str, Any], th: DiagnosticThresholds) -> _Part:
    probabilities: list[float] = fields["jammed_rollers_probability"]
    count = int(fields["jammed_rollers_most_likely"])
    p_jam = 1.0 - probabilities[0]
    if count >= 1:
        level, message = Level.ERROR, f"{_rollers(count)} (p = {probabilities[count]:.2f})"
    elif p_jam >= th.jam_warn_probability:
        level, message = Level.WARN, f"possible jammed roller (p = {p_jam:.2f})"
    else:
        level, message = Level.OK, f"no jammed roller (p(jam) = {p_jam:.2g})"
    # At standstill the torque holds any load within the stiction band and carries no evidence
    # of a jam (docs/estimation.md, "Measurement model"): the count can only be the one from
    # before, whatever happens now. Say so rather than let "no jammed roller" read as seen.
    standing = fields["event"] == EstimateEvent.STANDSTILL
    if standing:
        message += STANDSTILL_JAM_NOTE
    values = {
        "jam_probability_any": p_jam,
        "jam_warn_probability": th.jam_warn_probability,
        "jam_observable": 0 if standing else 1,
    }
    values.update({f"jam_probability_{k}": p for k, p in enumerate(probabilities)})
    return level, message, [("jammed_rollers_most_likely", str(count)), *_numbers(values)]


def _precision(fields: Mapping[str, Any], th: DiagnosticThresholds) -> _Part:
    loss = float(fields["precision_loss_um"])
    budget = th.precision_loss_budget_um
    fraction = loss / budget
    rate = float(fields["precision_loss_rate_um_per_h"])
    level = _level(fraction, th.precision_loss_warn_fraction, th.precision_loss_error_fraction)
    message = f"{loss:.3g} um of the {budget:g} um budget ({rate:.3g} um/h)"
    values = _picked(
        fields, "precision_loss_um", "precision_loss_std_um", "precision_loss_rate_um_per_h"
    )
    values |= {"precision_loss_budget_um": budget, "budget_fraction": fraction}
    return level, message, _numbers(values)


def _fatigue(fields: Mapping[str, Any], th: DiagnosticThresholds) -> _Part:
    damage = float(fields["fatigue_damage"])
    level = _level(damage, th.fatigue_warn_damage, th.fatigue_error_damage)
    message = (
        f"Miner damage {damage:.3g} (warn {th.fatigue_warn_damage:g},"
        f" error {th.fatigue_error_damage:g})"
    )
    return level, message, _numbers(_picked(fields, "fatigue_damage", "fatigue_damage_std"))


def _inputs(inputs: InputHealth, th: DiagnosticThresholds, now_s: float) -> _Part:
    age = now_s - inputs.last_sample_s if inputs.last_sample_s is not None else math.inf
    problems = []
    if inputs.rate_hz < th.min_input_rate_hz:
        problems.append(f"rate {inputs.rate_hz:.0f} Hz below {th.min_input_rate_hz:g} Hz")
    rate = inputs.stamp_rate
    if rate >= 0.0 and not 1.0 / STAMP_RATE_LIMIT <= rate <= STAMP_RATE_LIMIT:
        problems.append(
            f"stamps advance {rate:.3g} s per second received (a clock in the wrong unit?)"
        )
    if inputs.input_clock_s is not None and inputs.input_clock_s < 0.0:
        problems.append(
            "stamps before 1970 (negative): the estimates go out stamped 0, as a ROS time"
            " cannot be negative (estimate_stamp_s has their own)"
        )
    measures = inputs.measures
    noise, ratio = measures.speed_noise_std_rad_s, measures.position_per_speed
    current = measures.current_noise_std_a
    if (wrong := disagreement(ratio)) is not None:
        problems.append(wrong)
    forward, reverse = measures.torque_along_motion_nm
    if (wrong := against_motion(forward, reverse)) is not None:
        problems.append(wrong)
    fraction = inputs.recent_rejected_fraction
    if fraction > 0.0 and fraction >= th.rejected_warn_fraction:
        reasons = ", ".join(
            out_of_range_reason(measures.out_of_range_by_field) if k == "out_of_range" else k
            for k, v in inputs.recent_rejected.items()
            if v
        )
        problems.append(f"{100.0 * fraction:.1f} % rejected in the last second ({reasons})")
    rejected_total = sum(inputs.rejected.values())
    message = "; ".join(problems) or (
        f"{inputs.rate_hz:.0f} Hz, {rejected_total} rejected of {inputs.received} received"
        + ("" if noise is None else f", speed noise {noise:.2f} rad/s")
        + ("" if ratio is None else f", position per speed {ratio:.2f}")
        + ("" if current is None else f", current noise {current:.3f} A")
    )
    values = {
        "rate_hz": inputs.rate_hz,
        "min_rate_hz": th.min_input_rate_hz,
        "input_age_s": age if math.isfinite(age) else -1.0,
        "received": inputs.received,
        "accepted": inputs.accepted,
        "rejected": rejected_total,
        "recent_rejected_fraction": inputs.recent_rejected_fraction,
        "stamp_rate": inputs.stamp_rate,
        "speed_noise_std_rad_s": -1.0 if noise is None else noise,
        "position_per_speed": -1.0 if ratio is None else ratio,
        "current_noise_std_a": -1.0 if current is None else current,
    }
    for name, torque in (("forward", forward), ("reverse", reverse)):
        if torque is not None:  # signed: no value can say "not yet"
            values[f"torque_along_motion_{name}_nm"] = torque
    values.update({f"rejected_{reason}": count for reason, count in inputs.rejected.items()})
    values.update({f"out_of_range_{name}": n for name, n in measures.out_of_range_by_field.items()})
    return (Level.WARN if problems else Level.OK), message, _numbers(values)


def out_of_range_reason(by_field: Mapping[str, int]) -> str:
    """The reason ``out_of_range``, with the fields beyond their range so far, e.g.
    ``out_of_range: speed`` (a speed in rpm read as rad/s)."""
    fields = [name for name, count in by_field.items() if count]
    return "out_of_range" + (f": {', '.join(fields)}" if fields else "")


def _recent(at_s: float | None, now_s: float) -> bool:
    """Within RECENT_S before now; an event stamped after now (the clock went back, e.g. a
    bag played in a loop with its clock) belongs to the old time line and is not recent."""
    return at_s is not None and 0.0 <= now_s - at_s <= RECENT_S


def _consistency(fields: Mapping[str, Any] | None, events: FilterEvents, now_s: float) -> _Part:
    nis = float(fields["normalized_innovation_squared"]) if fields is not None else 0.0
    if _recent(events.last_error_s, now_s):
        level, message = Level.ERROR, events.last_error
    elif _recent(events.last_warning_s, now_s):
        level, message = Level.WARN, events.last_warning
    else:
        level, message = Level.OK, f"consistent (mean NIS {nis:.2g})"
    values = {
        "normalized_innovation_squared": nis,
        "time_resets": events.time_resets,
        "gaps": events.gaps,
        "divergence_recoveries": events.divergence_recoveries,
        "non_finite_outputs": events.non_finite_outputs,
        "processing_errors": events.processing_errors,
    }
    return level, message, _numbers(values)


def diagnostic_statuses(
    state: HealthState | None,
    inputs: InputHealth,
    thresholds: DiagnosticThresholds,
    rated_load_n: float,
    hardware_id: str,
    now_s: float,
    events: FilterEvents | None = None,
) -> list[DiagnosticStatusData]:
    """The estimator statuses, one per concern, in the order of ``STATUS_NAMES``.

    ``state``: the latest estimate (None before the first). ``inputs``, ``events``: see their
    classes. ``now_s``: the caller's clock, the same as ``inputs.last_sample_s``. Every status
    is STALE when the last input is older than ``thresholds.stale_timeout_s`` or never came;
    every status but the input health's (which says why) when every sample has been rejected
    for longer than that (``inputs.rejecting_since_s``) while input comes.
    """
    events = events if events is not None else FilterEvents()
    fields: dict[str, Any] | None = None
    parts: list[tuple[str, _Part]]
    if state is None:
        parts = [(name, (Level.OK, "no estimate yet", [])) for name in ESTIMATE_STATUS_NAMES]
    else:
        fields = health_estimate_fields(state)
        # Each estimator status says which estimate it reports (the sensor's stamp of its
        # block, to the millisecond: epoch stamps need more than _num's six digits); behind a
        # backlog of samples the node's clock runs ahead of it.
        stamp = ("estimate_stamp_s", f"{state.stamp_s:.3f}")
        parts = [
            (name, (level, message, [*values, stamp]))
            for name, (level, message, values) in (
                (AXIAL_LOAD, _axial_load(fields, thresholds, rated_load_n)),
                (JAMMED_ROLLERS, _jammed(fields, thresholds)),
                (PRECISION_LOSS, _precision(fields, thresholds)),
                (FATIGUE, _fatigue(fields, thresholds)),
            )
        ]
    parts.append((INPUT_HEALTH, _inputs(inputs, thresholds, now_s)))
    parts.append((FILTER_CONSISTENCY, _consistency(fields, events, now_s)))

    stale = None
    timeout = thresholds.stale_timeout_s
    if inputs.last_sample_s is None:  # a wrong topic shows here: say which one is listened to
        stale = f"stale: no input yet on {inputs.topic}" if inputs.topic else "stale: no input yet"
    elif now_s - inputs.last_sample_s > timeout:
        stale = f"stale: no input for {now_s - inputs.last_sample_s:.1f} s"
    since = inputs.rejecting_since_s
    rejecting_s = now_s - since if since is not None else 0.0
    rejecting = stale is None and rejecting_s > timeout
    if rejecting:
        stale = f"stale: every sample rejected for {rejecting_s:.1f} s"
    statuses = []
    for name, (level, message, values) in parts:
        if stale is not None and not (rejecting and name == INPUT_HEALTH):
            level, message = Level.STALE, f"{stale}; last: {message}"
        statuses.append(DiagnosticStatusData(name, level, message, hardware_id, values))
    return statuses


def persistence_status(
    health: PersistenceHealth, hardware_id: str, now_s: float
) -> DiagnosticStatusData:
    """The state file's status: ERROR when saving fails, WARN while an unusable file was kept
    aside at restore (until the node is cleaned up), else OK."""
    # -1: never saved; a save stamped after now (the clock went back) is 0 s old.
    age = max(now_s - health.last_save_s, 0.0) if health.last_save_s is not None else -1.0
    if health.save_error is not None:
        level, message = Level.ERROR, f"cannot save the state: {health.save_error}"
    elif health.kept_aside is not None:
        level = Level.WARN
        message = f"{health.problem}; kept as {health.kept_aside}, started fresh"
    elif health.last_save_s is not None:
        level, message = Level.OK, f"saved {age:.0f} s ago"
    elif health.restored:
        level = Level.OK
        message = "; ".join(filter(None, ("resumed from the state file", health.problem)))
    else:
        level, message = Level.OK, "not saved yet"
    numbers = {"saves": health.saves, "last_save_age_s": age, "restored": int(health.restored)}
    values = [*_numbers(numbers), ("state_file", health.state_file)]
    if health.kept_aside is not None:
        values.append(("kept_aside", health.kept_aside))
    return DiagnosticStatusData(PERSISTENCE, level, message, hardware_id, values)


def restored_statuses(
    statuses: list[DiagnosticStatusData], stamp_s: float
) -> list[DiagnosticStatusData]:
    """``statuses`` of an estimate restored with the state file, not made in this run (the
    node's, until its first new one), marked as such: the message of each estimate status ends
    with ``(restored, estimate at sensor time 1009.980 s)``, ``stamp_s`` being the estimate's
    stamp. Levels and values are unchanged: STALE until input comes (``stale: no input yet;
    last: 2 jammed rollers (p = 1.00) (restored, ...)``), then the estimate's own."""
    marker = f" (restored, estimate at sensor time {stamp_s:.3f} s)"
    return [
        replace(s, message=s.message + marker) if s.name in ESTIMATE_STATUS_NAMES else s
        for s in statuses
    ]


def configuration_status(reason: str, hardware_id: str) -> DiagnosticStatusData:
    """The status of a node whose configure failed (``reason``: the problem, as its log line
    says it): ERROR, so that a monitor or dashboard shows why the node publishes nothing else
    (it stays unconfigured until the parameters are fixed and configure is called again)."""
    return DiagnosticStatusData(
        CONFIGURATION, Level.ERROR, f"configure failed: {reason}", hardware_id, []
    )
