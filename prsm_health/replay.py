"""Offline replay: a bag's motor samples through the estimator, as fast as it can go.

``prsm-health replay BAG`` (cli.py) runs :func:`replay`: it reads the inputs (MotorState, or
JointState by :class:`~prsm_health.bags.reader.InputTopics`) chunk by chunk, runs one
:class:`~prsm_health.estimation.estimator.HealthEstimator`, and optionally

- writes an MCAP bag (``out``; with the input bag's rosbag2 ``custom_data``, so a simulated
  bag's scene record goes along) with the inputs (as ``/motor_state`` MotorState, also when
  read from JointState), the bag's ``/truth/state`` if it has one, ``/prsm_health/health``
  (HealthEstimate) and
  ``/diagnostics`` (DiagnosticArray, once per second of the inputs' clock and at the end: the
  latest accepted sample's stamp, as a node's run on the time it receives; the estimator's
  counters brought up to date every half second of samples): the content the node
  publishes (both are built by :mod:`prsm_health.outputs`), on the bag's time line;
- scores the estimates against the bag's ``/truth/state`` (:mod:`~prsm_health.estimation.metrics`).

A damaged bag (cut short, a corrupt chunk) is not fatal: everything read before the damage is
estimated and reported, and the damage is returned in :attr:`ReplayResult.damage`. A replay
stopped early (``stop``, Ctrl-C in the command) likewise ends with what was read: the output
bag closed complete, the estimates scored against the truth up to the last of them (a jam
after it is not scored: :mod:`~prsm_health.estimation.metrics`).
"""

from __future__ import annotations

import math
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterator
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np

from prsm_health.bags import (
    DIAGNOSTIC_ARRAY,
    HEALTH_ESTIMATE,
    BagDamagedError,
    BagError,
    BagWriter,
    InputTopics,
    iter_motor_samples,
    read_truth,
    write_motor_states,
    write_truth,
)
from prsm_health.bags.bagfiles import custom_data
from prsm_health.bags.stamps import seconds_to_stamps
from prsm_health.bags.topics import DIAGNOSTICS_TOPIC, HEALTH_TOPIC, TRUTH_TOPIC
from prsm_health.bags.typestore import typestore
from prsm_health.estimation.estimate import HealthState
from prsm_health.estimation.estimator import HealthEstimator
from prsm_health.estimation.inputs import InputCounters, InputMeasures
from prsm_health.estimation.metrics import Metrics, score
from prsm_health.estimation.params import EstimatorParams
from prsm_health.outputs import DEFAULT_HARDWARE_ID, DiagnosticStatusData, health_estimate_fields
from prsm_health.signals import MotorSamples, TruthSamples
from prsm_health.tracking import DiagnosticsTracker, rejected_by_reason

#: Diagnostics are written once per this many seconds of bag time.
DIAGNOSTICS_PERIOD_S = 1.0
#: Samples read per chunk.
CHUNK_SAMPLES = 20_000
#: With an output bag, samples are estimated in pieces of about half DIAGNOSTICS_PERIOD_S (by
#: their usual spacing), at most this many, after each of which the input-health counters are
#: brought up to date and the diagnostics written when due.
OUTPUT_PIECE_SAMPLES = 1000
#: Received messages are spread over the bag time of their piece in bins of this length.
RECEIVED_BIN_S = 0.01


@dataclass(frozen=True)
class ReplayResult:
    """What a replay produced.

    states: every estimate. counters: the estimator's input counters. samples: samples read.
    truth: the bag's ground truth (None without /truth/state). metrics: scores against it.
    damage: the error that ended reading early (the rest of the result covers what was read
    before it), or None; inputs_complete: every input sample was read all the same (the
    damage is in the truth only). stopped: the replay was stopped before the end of the bag
    (the same). elapsed_s: wall time of reading and estimating (without writing ``out`` or
    scoring). measures: what the estimator measured of its inputs
    (:attr:`HealthEstimator.input_measures
    <prsm_health.estimation.estimator.HealthEstimator.input_measures>`).
    """

    states: list[HealthState]
    counters: InputCounters
    samples: int
    truth: TruthSamples | None
    metrics: Metrics | None
    damage: BagError | None
    stopped: bool
    elapsed_s: float
    inputs_complete: bool = True
    measures: InputMeasures = field(default_factory=InputMeasures)


def _chunks(bag: Path, topics: InputTopics, damage: list[BagError]) -> Iterator[MotorSamples]:
    """The bag's samples; damage found on the way ends the iteration and is kept."""
    try:
        yield from iter_motor_samples(bag, topics, chunk_size=CHUNK_SAMPLES)
    except BagDamagedError as exc:
        damage.append(exc)


def replay(
    bag: Path,
    params: EstimatorParams,
    *,
    topics: InputTopics | None = None,
    out: Path | None = None,
    hardware_id: str = DEFAULT_HARDWARE_ID,
    progress: Callable[[int], None] | None = None,
    stop: threading.Event | None = None,
) -> ReplayResult:
    """Run the estimator over ``bag`` (see the module docstring).

    ``progress`` is called with the number of samples of each chunk read; once ``stop`` is
    set, the replay ends after the chunk being estimated. Raises BagError when the bag cannot
    be read at all (no such file, no input topic); damage after the start is returned in the
    result instead.
    """
    topics = topics or InputTopics()
    estimator = HealthEstimator(params)
    states: list[HealthState] = []
    damage: list[BagError] = []
    samples = 0
    stopped = False
    elapsed = 0.0
    with ExitStack() as stack:
        output = (
            stack.enter_context(_Output(out, params, hardware_id, custom_data(bag)))
            if out
            else None
        )
        started = time.perf_counter()
        for chunk in _chunks(bag, topics, damage):
            # With an output bag, the diagnostics need the input counters once a second.
            spacing = _usual_spacing(chunk) if output is not None else 0.0
            step = _piece_samples(spacing) if output is not None else len(chunk)
            for begin in range(0, len(chunk), step):
                piece = chunk[begin : begin + step]
                new = estimator.process(piece)
                elapsed += time.perf_counter() - started
                states += new
                if output is not None:
                    output.add(piece, new, estimator, spacing_s=spacing)
                started = time.perf_counter()
            samples += len(chunk)
            if progress is not None:
                progress(len(chunk))
            started = time.perf_counter()
            if stop is not None and stop.is_set():
                stopped = True
                break
        last = estimator.finish()
        elapsed += time.perf_counter() - started
        states += last
        if output is not None:
            output.add(None, last, estimator)
        inputs_complete = not damage and not stopped
        truth = _truth(bag, damage)
        if output is not None and truth is not None and len(truth):
            write_truth(output.writer, truth)  # beside the estimates, for a viewer
    metrics = None
    if truth is not None and states and len(truth):
        preset = params.actuator.preset
        metrics = score(
            states,
            truth,
            rated_load_n=params.rated_load_n,
            largest_screw_speed_rad_s=preset.largest_speed_rpm * 2.0 * np.pi / 60.0,
        )
    return ReplayResult(
        states=states,
        counters=estimator.counters,
        samples=samples,
        truth=truth,
        metrics=metrics,
        damage=damage[0] if damage else None,
        stopped=stopped,
        elapsed_s=elapsed,
        inputs_complete=inputs_complete,
        measures=estimator.input_measures,
    )


def _truth(bag: Path, damage: list[BagError]) -> TruthSamples | None:
    """The bag's truth, or None; a damaged truth topic gives what was read before it, and so
    does a truth sample with a non-finite value or a stamp that does not advance (the bag is
    damaged there as well: the metrics look the truth up by its stamps, and stamps that went
    back 2 s scored a load RMSE of 17.7 % for 0.8 %, found by a review session)."""
    try:
        truth, error = read_truth(bag, partial_ok=True)
    except BagError:
        return None
    if error is not None and not damage:
        damage.append(error)
    if truth is None:
        return None
    # The first message that is not finite or not stamped after the one before it: the
    # truth is scored up to it (whichever comes first, named).
    finite = truth.finite()
    usable = finite & np.r_[True, np.diff(truth.stamp_s) > 0.0]
    if not usable.all():
        first = int(np.argmin(usable))
        if not damage:
            why = (
                "holds a non-finite value"
                if not finite[first]
                else f"is stamped {truth.stamp_s[first]:.9g} s, not after the one before it "
                f"({truth.stamp_s[first - 1]:.9g} s)"
            )
            damage.append(BagError(bag, f"{TRUTH_TOPIC}: message {first} {why}"))
        truth = truth[:first]
    return truth


def _usual_spacing(samples: MotorSamples) -> float:
    """The median positive spacing of the samples' finite stamps [s] (0 if there is none)."""
    spacing = np.diff(samples.stamp_s)
    spacing = spacing[np.isfinite(spacing) & (spacing > 0.0)]
    return float(np.median(spacing)) if spacing.size else 0.0


def _piece_samples(spacing_s: float) -> int:
    """How many samples at the usual ``spacing_s`` make about half DIAGNOSTICS_PERIOD_S (at most
    OUTPUT_PIECE_SAMPLES), so that the diagnostics are written about once per period whatever
    the input rate."""
    if spacing_s <= 0.0:
        return OUTPUT_PIECE_SAMPLES
    return int(min(max(0.5 * DIAGNOSTICS_PERIOD_S / spacing_s, 1.0), OUTPUT_PIECE_SAMPLES))


class _Output:
    """The replay's output bag: inputs, health estimates, diagnostics once per second
    (``writer``: the bag, for the truth the replay copies into it at the end)."""

    def __init__(
        self, path: Path, params: EstimatorParams, hardware_id: str, custom: dict[str, str]
    ) -> None:
        self.writer = BagWriter(path)
        for key, value in custom.items():  # what a simulated input bag records of its scene
            self.writer.set_custom_data(key, value)
        self._params = params
        self._hardware_id = hardware_id
        self._diagnostics = DiagnosticsTracker()
        self._latest: HealthState | None = None
        self._diagnostics_due_s: float | None = None
        self._diagnostics_written_s: float | None = None
        self._received_until_s: float | None = None
        self._unplaced = 0
        types = typestore().types
        self._health_type = types[HEALTH_ESTIMATE]
        self._header = types["std_msgs/msg/Header"]
        self._time = types["builtin_interfaces/msg/Time"]
        self._array = types[DIAGNOSTIC_ARRAY]
        self._status = types["diagnostic_msgs/msg/DiagnosticStatus"]
        self._key_value = types["diagnostic_msgs/msg/KeyValue"]

    def __enter__(self) -> _Output:
        self.writer.__enter__()
        self.writer.add_topic(HEALTH_TOPIC, HEALTH_ESTIMATE)
        self.writer.add_topic(DIAGNOSTICS_TOPIC, DIAGNOSTIC_ARRAY)
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self.writer.__exit__(kind, error, trace)

    def _stamp(self, seconds: float) -> Any:
        sec, nanosec = seconds_to_stamps([seconds])
        return self._time(sec=int(sec[0]), nanosec=int(nanosec[0]))

    def add(
        self,
        samples: MotorSamples | None,
        states: list[HealthState],
        estimator: HealthEstimator,
        *,
        spacing_s: float = 0.0,
    ) -> None:
        """Write a piece's inputs and the estimates it led to, and the diagnostics when due
        (``samples`` None: the end, after the estimator's ``finish``; ``spacing_s``: the
        samples' usual spacing, :func:`_usual_spacing` of their chunk).

        The diagnostics run on the inputs' clock (:attr:`HealthEstimator.input_clock_s`, the
        latest accepted sample's stamp, which a broken stamp does not move), as a node's run on
        the time it receives them; they describe the latest estimate. A piece's messages are
        received spread over the time its samples advanced that clock."""
        if samples is not None and len(samples):
            write_motor_states(self.writer, samples)
        replaced: Counter[str] = Counter()
        for state in states:
            fields = health_estimate_fields(state, replaced=replaced)
            header = self._header(stamp=self._stamp(state.stamp_s), frame_id=self._hardware_id)
            message = self._health_type(header=header, **_typed(fields))
            log_time = self.writer.log_times_after(HEALTH_TOPIC, _log_time_ns(state.stamp_s))
            self.writer.write(HEALTH_TOPIC, int(log_time[0]), message)
        if states:
            self._latest = states[-1]
        self._unplaced += len(samples) if samples is not None else 0
        now = estimator.input_clock_s
        if now is None or self._latest is None:
            return  # nothing accepted or estimated yet: counted when there is
        counters = estimator.counters
        self._receive(now, self._unplaced, spacing_s)
        self._unplaced = 0
        self._diagnostics.inputs.judge(now, counters.accepted, rejected_by_reason(counters, {}))
        self._diagnostics.events.observe(now, states, counters)
        self._diagnostics.events.non_finite(now, replaced)
        due, written = self._diagnostics_due_s, self._diagnostics_written_s
        if due is None or (written is not None and now < written):
            # The first, or the inputs' clock went back (a time reset: accepted stamps only
            # go back there): a schedule on the new time line. (Tested against the schedule
            # instead, a write up to a quarter period early looked like one, and was repeated
            # by the next piece: pairs 0.1 s apart at 10 kHz, twice the last at the end.)
            due = now
        # A piece that ends less than half a piece before the grid's time is due writes (else
        # it waited a piece more: 1.5 s between two where a piece is half a period; at most a
        # quarter period early, where pieces are shorter, as at 10 kHz).
        piece_s = spacing_s * (len(samples) if samples is not None else 0)
        early = min(0.5 * piece_s, 0.25 * DIAGNOSTICS_PERIOD_S)
        if now >= due - early or (samples is None and written is not None and now > written):
            # Due (once per period of bag time on a fixed grid), or the end.
            self._diagnostics.inputs.measures = estimator.input_measures
            self._write_diagnostics(now)
            self._diagnostics_written_s = now
            due += DIAGNOSTICS_PERIOD_S * (
                math.floor((now + early - due) / DIAGNOSTICS_PERIOD_S) + 1
            )
        self._diagnostics_due_s = due

    def _receive(self, now_s: float, count: int, spacing_s: float) -> None:
        """The input tracker receives ``count`` messages spread evenly over the time the inputs'
        clock advanced since it last received (at most their number at the usual spacing
        ``spacing_s`` back; all at ``now_s`` if the clock did not move), in RECEIVED_BIN_S bins: the
        rate over the last second then counts what came in it."""
        previous, self._received_until_s = self._received_until_s, now_s
        if not count:
            return
        span = spacing_s * count
        start = now_s - span
        if previous is not None and previous <= now_s:
            start = max(previous, start)
        bins = max(1, math.ceil((now_s - start) / RECEIVED_BIN_S))
        cumulative = np.round(np.linspace(0.0, count, bins + 1)).astype(np.int64)
        ends = np.linspace(start, now_s, bins + 1)[1:]
        for end, part in zip(ends.tolist(), np.diff(cumulative).tolist(), strict=True):
            if part:
                self._diagnostics.inputs.receive(end, part)

    def _write_diagnostics(self, now_s: float) -> None:
        statuses = self._diagnostics.statuses(self._latest, self._params, self._hardware_id, now_s)
        message = self._array(
            header=self._header(stamp=self._stamp(now_s), frame_id=""),
            status=[self._status_message(s) for s in statuses],
        )
        log_time = self.writer.log_times_after(DIAGNOSTICS_TOPIC, _log_time_ns(now_s))
        self.writer.write(DIAGNOSTICS_TOPIC, int(log_time[0]), message)

    def _status_message(self, status: DiagnosticStatusData) -> Any:
        return self._status(
            level=int(status.level),
            name=status.name,
            message=status.message,
            hardware_id=status.hardware_id,
            values=[self._key_value(key=k, value=v) for k, v in status.values],
        )


def _typed(fields: dict[str, Any]) -> dict[str, Any]:
    """Message field values as the rosbags classes want them (float64[] as a numpy array)."""
    typed = dict(fields)
    typed["jammed_rollers_probability"] = np.asarray(
        fields["jammed_rollers_probability"], dtype=np.float64
    )
    return typed


def _log_time_ns(stamp_s: float) -> int:
    """A log time for an output message at a (finite) estimate stamp, never negative."""
    return max(round(stamp_s * 1e9), 0)
