"""Running statistics behind the diagnostics: input rate and rejections, filter events.

ROS-free (the node feeds them on its clock; an offline replay could feed them on bag time).
:class:`InputTracker` gives :class:`~prsm_health.outputs.InputHealth`,
:class:`EventTracker` gives :class:`~prsm_health.outputs.FilterEvents`, and
:class:`DiagnosticsTracker` holds both for one actuator and gives its statuses.
"""

from __future__ import annotations

from collections import Counter, deque
from collections.abc import Iterable, Mapping

import numpy as np

from prsm_health.estimation.estimate import EstimateEvent, HealthState
from prsm_health.estimation.inputs import InputCounters, InputMeasures, RejectReason
from prsm_health.estimation.params import EstimatorParams
from prsm_health.outputs import (
    DiagnosticStatusData,
    FilterEvents,
    InputHealth,
    diagnostic_statuses,
)

#: Window of the input rate and of the recent rejected fraction [s].
WINDOW_S = 1.0
#: Moves of the inputs' clock in the window needed to give the stamps' rate.
STAMP_RATE_MOVES = 10


def rejected_by_reason(counters: InputCounters, extra: Mapping[str, int]) -> dict[str, int]:
    """The estimator's rejections by reason (names in lower case), then the caller's own."""
    rejected = {reason.name.lower(): counters.rejected[reason] for reason in RejectReason}
    rejected.update(extra)
    return rejected


class InputTracker:
    """Messages received and samples judged, over a sliding window of :data:`WINDOW_S`.

    Times are the caller's clock in seconds; if it jumps back (a looped bag's sim time), the
    window starts again, and the last receipt and the first rejection not followed by an
    accepted sample count from the jump (their age is unknown: no older than the jump, so that input
    that stops with it goes stale). Counts are of
    this run: totals an estimator brings from a restored state are its starting point
    (:meth:`start_from`), not samples judged now. ``topic``: where the inputs come from (named
    by the input-health status; empty if unknown). ``measures``: what the estimator has
    measured of its inputs, as the caller last read them
    (:attr:`HealthEstimator.input_measures
    <prsm_health.estimation.estimator.HealthEstimator.input_measures>`).
    """

    def __init__(self) -> None:
        self.topic = ""
        self.measures = InputMeasures()
        self._received_total = 0
        self._last_sample_s: float | None = None
        # When the first sample was rejected since one was last accepted (None: none since).
        self._rejecting_since_s: float | None = None
        self._received: deque[tuple[float, int]] = deque()
        # (time, the inputs' clock) where it moved: how fast the stamps advance
        self._clock: deque[tuple[float, float]] = deque()
        self._input_clock_s: float | None = None  # the latest input_clock_s given
        # time, newly accepted, newly rejected by reason
        self._judged: deque[tuple[float, int, dict[str, int]]] = deque()
        self._accepted = self._start_accepted = 0
        self._rejected: dict[str, int] = {}
        self._start_rejected: dict[str, int] = {}

    def start_from(self, accepted: int, rejected: Mapping[str, int]) -> None:
        """The estimator's totals before this run (restored from a saved state)."""
        self._accepted = self._start_accepted = accepted
        self._rejected, self._start_rejected = dict(rejected), dict(rejected)

    def update(
        self,
        now_s: float,
        received: int,
        accepted: int,
        rejected: Mapping[str, int],
        input_clock_s: float | None = None,
    ) -> None:
        """Record ``received`` new messages and the estimator's totals after processing them
        (and :meth:`judge`'s ``input_clock_s``)."""
        self.receive(now_s, received)
        self.judge(now_s, accepted, rejected, input_clock_s)

    def receive(self, now_s: float, received: int) -> None:
        """Record ``received`` messages that came at ``now_s`` (an offline replay spreads a
        piece's over the bag time it covers)."""
        if self._received and now_s < self._received[-1][0]:
            self._received.clear()
        if received:
            self._received_total += received
            self._last_sample_s = now_s
            if self._received and self._received[-1][0] == now_s:  # one entry per time: a
                received += self._received.pop()[1]  # clock that stands still grew the window
            self._received.append((now_s, received))

    def judge(
        self,
        now_s: float,
        accepted: int,
        rejected: Mapping[str, int],
        input_clock_s: float | None = None,
    ) -> None:
        """Record the estimator's totals at ``now_s``, and where its inputs' clock is then
        (``input_clock_s``, :attr:`HealthEstimator.input_clock_s`; None: not compared, as in an
        offline replay, whose clock is the inputs')."""
        if self._judged and now_s < self._judged[-1][0]:
            self._judged.clear()
        # Where the inputs' clock moves (its samples are accepted so far: the count of accepted
        # samples moves only as blocks close, every 10,000 samples on a clock that hardly moves).
        if input_clock_s is not None:
            self._input_clock_s = input_clock_s
        if input_clock_s is not None and (not self._clock or input_clock_s != self._clock[-1][1]):
            if self._clock and (now_s < self._clock[-1][0] or input_clock_s < self._clock[-1][1]):
                self._clock.clear()  # either clock went back: compare from here
            elif self._clock and now_s == self._clock[-1][0]:
                self._clock.pop()  # one move per time of the caller's (a sim /clock steps)
            self._clock.append((now_s, input_clock_s))
        new_accepted = accepted - self._accepted
        new_rejected = {
            reason: count - self._rejected.get(reason, 0)
            for reason, count in rejected.items()
            if count != self._rejected.get(reason, 0)
        }
        if new_accepted > 0:
            self._rejecting_since_s = None
        elif new_rejected and self._rejecting_since_s is None:
            self._rejecting_since_s = now_s
        if new_accepted or new_rejected:
            if self._judged and self._judged[-1][0] == now_s:  # one entry per time (receive)
                _, before_accepted, before_rejected = self._judged.pop()
                new_accepted += before_accepted
                new_rejected = dict(Counter(before_rejected) + Counter(new_rejected))
            self._judged.append((now_s, new_accepted, new_rejected))
        self._accepted, self._rejected = accepted, dict(rejected)
        self._trim(now_s)

    def _trim(self, now_s: float) -> None:
        while self._received and self._received[0][0] <= now_s - WINDOW_S:
            self._received.popleft()
        while self._judged and self._judged[0][0] <= now_s - WINDOW_S:
            self._judged.popleft()
        while self._clock and self._clock[0][0] <= now_s - WINDOW_S:
            self._clock.popleft()

    def health(self, now_s: float) -> InputHealth:
        """The input health at ``now_s``."""
        if self._last_sample_s is not None and now_s < self._last_sample_s:
            self._last_sample_s = now_s  # the clock went back (class docstring)
        if self._rejecting_since_s is not None and now_s < self._rejecting_since_s:
            self._rejecting_since_s = now_s
        self._trim(now_s)
        accepted = sum(entry[1] for entry in self._judged)
        recent: Counter[str] = Counter()
        for _, _, reasons in self._judged:
            recent.update(reasons)
        judged = accepted + sum(recent.values())
        return InputHealth(
            rate_hz=sum(count for _, count in self._received) / WINDOW_S,
            last_sample_s=self._last_sample_s,
            received=self._received_total,
            accepted=self._accepted - self._start_accepted,
            rejected={
                reason: count - self._start_rejected.get(reason, 0)
                for reason, count in self._rejected.items()
            },
            recent_rejected_fraction=sum(recent.values()) / judged if judged > 0 else 0.0,
            recent_rejected=dict(recent),
            topic=self.topic,
            rejecting_since_s=self._rejecting_since_s,
            stamp_rate=self._stamp_rate(),
            input_clock_s=self._input_clock_s,
            measures=self.measures,
        )

    def _stamp_rate(self) -> float:
        """The median, over the window, of how far the inputs' clock moved per second of the
        caller's between two of its moves (-1 with fewer than STAMP_RATE_MOVES over half the
        window): one jump of the stamps (a pause of the sensor that the caller's clock did not
        share, a clock set ahead) is not a rate."""
        if len(self._clock) <= STAMP_RATE_MOVES or (
            self._clock[-1][0] - self._clock[0][0] < WINDOW_S / 2
        ):
            return -1.0
        times, clocks = np.array(self._clock).T
        elapsed, moved = np.diff(times), np.diff(clocks)
        between = elapsed > 0.0
        if np.count_nonzero(between) < STAMP_RATE_MOVES:
            return -1.0
        return float(np.median(moved[between] / elapsed[between]))


class EventTracker:
    """Counts time resets, gaps, divergence recoveries, non-finite outputs and errors."""

    def __init__(self) -> None:
        self._divergences = 0
        self._non_finite: Counter[str] = Counter()
        self._errors = 0
        self._time_resets = 0
        self._gaps = 0
        self._warning: tuple[float, str] | None = None
        self._error: tuple[float, str] | None = None

    def observe(self, now_s: float, states: Iterable[HealthState], counters: InputCounters) -> None:
        """Take note of new estimates and of the estimator's input counters."""
        for state in states:
            if state.event == EstimateEvent.DIVERGENCE_RECOVERED:
                self._divergences += 1
                self._warning = (now_s, "filter diverged (NIS) and was re-initialised")
        if counters.time_resets > self._time_resets:
            self._warning = (now_s, "input time jumped back: load re-initialised")
        self._time_resets, self._gaps = counters.time_resets, counters.gaps

    def non_finite(self, now_s: float, replaced: Counter[str]) -> None:
        """Output values replaced because they were not finite (field name -> count)."""
        if replaced:
            self._non_finite.update(replaced)
            names = ", ".join(sorted(replaced))
            self._error = (now_s, f"non-finite estimate replaced by safe values ({names})")

    def error(self, now_s: float, text: str) -> None:
        """An exception caught while processing inputs or publishing outputs."""
        self._errors += 1
        self._error = (now_s, f"processing error: {text}")

    @property
    def processing_errors(self) -> int:
        """Exceptions caught so far."""
        return self._errors

    def events(self) -> FilterEvents:
        """The counts and the last warning and error."""
        return FilterEvents(
            time_resets=self._time_resets,
            gaps=self._gaps,
            divergence_recoveries=self._divergences,
            non_finite_outputs=sum(self._non_finite.values()),
            processing_errors=self._errors,
            last_warning_s=self._warning[0] if self._warning else None,
            last_warning=self._warning[1] if self._warning else "",
            last_error_s=self._error[0] if self._error else None,
            last_error=self._error[1] if self._error else "",
        )


class DiagnosticsTracker:
    """The input and event trackers of one actuator, and the diagnostics they give.

    For the node and the offline replay alike: feed ``inputs`` and ``events`` as samples are
    processed; :meth:`statuses` gives the estimator statuses at ``now_s``.
    """

    def __init__(self) -> None:
        self.inputs = InputTracker()
        self.events = EventTracker()

    def statuses(
        self,
        state: HealthState | None,
        params: EstimatorParams,
        hardware_id: str,
        now_s: float,
    ) -> list[DiagnosticStatusData]:
        """:func:`~prsm_health.outputs.diagnostic_statuses` for the latest ``state``, with the
        thresholds and rated load of ``params``."""
        return diagnostic_statuses(
            state,
            self.inputs.health(now_s),
            params.diagnostics,
            params.rated_load_n,
            hardware_id,
            now_s,
            self.events.events(),
        )
