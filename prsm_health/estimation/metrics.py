"""Scoring estimates against a simulated run's ground truth (replay --metrics-json, benchmark).

The truth (``/truth/state``, :class:`~prsm_health.signals.TruthSamples`, decimated) is
interpolated linearly to each estimate's stamp for continuous quantities (load, speed,
precision loss: during a load ramp of 100 kN/s a 10 ms offset would be a 1 kN error); counts
(jammed rollers) are taken from the latest truth sample at or before the time compared (below).
Definitions:

- load errors: over estimates while the screw moves (|w_s| above 1 % of the preset's largest
  speed), signed load estimate minus signed truth; RMSE and max, also as % of the rated load.
  At standstill (the other estimates) the load is hardly observed, the static friction
  taking any share of the holding torque: its RMSE, max and the fraction of those estimates
  whose truth lies within +-2 std, so that a standstill is scored for the honesty of its band;
- NEES: (error / std)^2 of the load while moving with a true load of at least
  NEES_MIN_LOAD_FRACTION of the rated load (below, at the ends of the downhole strokes, the
  radial load is largest in proportion and the angle-averaged model least exact). The test of
  consistency: the estimates are thinned to one per second (they are strongly correlated
  within a second), and the mean NEES of those n values must lie in the two-sided 95 %
  interval of chi^2(n) / n;
- jams: an estimate stands for a block of samples around its stamp and has seen the samples
  up to the block's end, taken as the midpoint to the next estimate's stamp (its own stamp for
  the last one). Its count is compared with the true count at that time: a block in which a
  roller seizes may already report it. For each increase of the true count at time t_j, the
  delay from t_j to the end of the first block that reports the new count as the most likely
  (None if never); an increase after the last estimate's block was not seen and is not scored
  (a replay that ended early: stopped, or a bag damaged before its truth ends); a false
  declaration is each onset of a most likely count above the true one;
- the jam count's probabilities: how often the most likely count is the true one, per bin
  of its probability (CALIBRATION_EDGES): where the probabilities are honest, about as often
  as they say (:class:`CalibrationBin`);
- precision loss: the final error (absolute and relative to the final truth), and the
  fraction of estimates whose truth lies within +-2 std.

Only the estimates inside the truth's span are scored (:func:`within_truth`: to one truth
period beyond its first and last samples): outside it the truth is unknown, not its first or
last value held (a bag cut short whose motor samples outlast its truth was scored against a
load frozen at its last value); how many were left out is reported (with none inside, nothing
is scored).

Estimates are stamped with the sensor's clock. When that clock jumps back (an estimate with
event TIME_RESET) or its stamps skip ahead (estimates further apart than SKIP_SPACINGS times
their usual spacing: a clock that jumped ahead, or missing data), the estimates after it are
put back on the truth's time line by the offset that best matches their screw speed to the
truth's (searched within +-MAX_CLOCK_OFFSET_S of a guess that is kept unless another matches
clearly better: after a skip the offset before it, after a TIME_RESET the one that puts the
estimates after those before it by the time their samples took); the offsets found are
reported, one per jump or skip.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

from prsm_health.estimation.estimate import EstimateEvent, HealthState
from prsm_health.jsonvalues import json_safe
from prsm_health.signals import TruthSamples

FloatArray = NDArray[np.float64]

#: The screw counts as moving above this fraction of the preset's largest speed.
MOVING_FRACTION = 0.01
#: The NEES test covers loads from this fraction of the rated load up.
NEES_MIN_LOAD_FRACTION = 0.05
#: Largest sensor-clock jump that the alignment after a TIME_RESET or a skip searches for [s].
MAX_CLOCK_OFFSET_S = 10.0
#: The search's grid: every COARSE_STEP_S over +-MAX_CLOCK_OFFSET_S, then every FINE_STEP_S
#: within two coarse steps of the best [s].
COARSE_STEP_S = 1e-2
FINE_STEP_S = 1e-3
#: Consecutive estimates further apart than this many times their usual spacing (the median
#: over the run, apart for those in motion and those beside a standstill estimate, which may
#: stand for merged blocks) are a skip: the sensor clock jumped ahead, or data are missing.
#: Shorter skips are not searched, and misalign the estimates after them by at most this.
SKIP_SPACINGS = 2.5
#: After a skip, another offset than the one before it (at least one usual spacing in motion
#: from it) must match the screw speed this many times better (mean squared difference), over
#: a time line of at least MIN_LINE_S, to be taken: a short line matches too many offsets.
#: Both are compared at their best within the fine search (FINE_STEP_S).
SKIP_MATCH_GAIN = 2.0
MIN_LINE_S = 2.0
#: The bins of the most likely jam count's probability whose estimates are counted right and
#: wrong (Metrics.jam_calibration): [0, 0.5), [0.5, 0.9), ..., [0.99999, 1].
CALIBRATION_EDGES = (0.0, 0.5, 0.9, 0.99, 0.999, 0.99999, 1.0)
#: The offset search matches at most this many estimates from the start of a time line (its
#: candidates times these estimates are held at once: an hour's line would take gigabytes).
MATCHED_ESTIMATES = 1000


@dataclass(frozen=True)
class JamDetection:
    """One true jam onset and when the estimator identified it."""

    onset_s: float
    count: int
    delay_s: float | None


@dataclass(frozen=True)
class CalibrationBin:
    """The estimates whose most likely jam count had a probability in [low, high) (the last
    bin includes 1): how many, how many of them had the true count as the most likely, and
    the mean of that probability. Honest probabilities have correct / estimates near it."""

    low: float
    high: float
    estimates: int
    correct: int
    mean_probability: float


@dataclass(frozen=True)
class Metrics:
    """Scores of one run (SI units; percentages of the rated load where named)."""

    estimates: int
    moving_estimates: int
    load_rmse_n: float
    load_rmse_percent_rated: float
    load_max_error_n: float
    load_nees_mean: float
    #: None, as ``load_nees_consistent``, when no estimate was loaded and moving (nothing to
    #: test); the mean is NaN then.
    load_nees_interval: tuple[float, float] | None
    load_nees_consistent: bool | None
    load_standstill_rmse_n: float
    load_standstill_max_error_n: float
    load_standstill_coverage_2sigma: float
    jams: tuple[JamDetection, ...]
    false_jam_declarations: int
    false_jam_seconds: float
    precision_loss_final_m: float
    precision_loss_truth_final_m: float
    precision_loss_error_percent: float
    precision_loss_coverage_2sigma: float
    clock_offsets_s: tuple[float, ...] = ()
    #: Estimates outside the truth's span, not scored (module docstring).
    estimates_beyond_truth: int = 0
    jam_calibration: tuple[CalibrationBin, ...] = ()

    def to_dict(self) -> dict[str, object]:
        """JSON-able form (``--metrics-json``): a value that could not be computed (NaN, e.g. a
        load RMSE without an estimate in motion) is null, which JSON has and NaN is not."""
        data = asdict(self)
        data["jams"] = [asdict(j) for j in self.jams]
        return {key: json_safe(value) for key, value in data.items()}


def _truth_at(truth: TruthSamples, stamps: FloatArray) -> NDArray[np.int64]:
    """Index of the latest truth sample at or before each stamp (the first one before it)."""
    index = np.searchsorted(truth.stamp_s, stamps, side="right") - 1
    return np.asarray(np.clip(index, 0, len(truth) - 1), dtype=np.int64)


def score(
    states: list[HealthState],
    truth: TruthSamples,
    *,
    rated_load_n: float,
    largest_screw_speed_rad_s: float,
) -> Metrics:
    """Score ``states`` against ``truth`` (see the module docstring)."""
    if not states or len(truth) == 0:
        raise ValueError("score: no estimates or no truth to compare")
    offsets = _clock_offsets(states, truth)
    stamps = on_truth_clock(states, offsets)
    inside = within_truth(stamps, truth)
    beyond = len(states) - int(np.count_nonzero(inside))
    if not inside.any():  # e.g. a truth cut at a damage before the first block ended
        return _nothing_scored(beyond, offsets)
    if beyond:
        states = [state for state, kept in zip(states, inside.tolist(), strict=True) if kept]
        stamps = stamps[inside]

    def interpolated(values: FloatArray) -> FloatArray:
        return np.asarray(np.interp(stamps, truth.stamp_s, values), dtype=np.float64)

    load = np.array([s.axial_load_n for s in states])
    load_std = np.array([s.axial_load_std_n for s in states])
    speed = interpolated(truth.screw_speed_rad_s)
    moving = np.abs(speed) > MOVING_FRACTION * largest_screw_speed_rad_s
    true_load = interpolated(truth.axial_load_n)
    error = load - true_load
    moving_error, still_error = error[moving], error[~moving]
    rmse, still_rmse = (
        float(np.sqrt(np.mean(e**2))) if e.size else math.nan for e in (moving_error, still_error)
    )
    loaded = moving & (np.abs(true_load) >= NEES_MIN_LOAD_FRACTION * rated_load_n)
    nees = (error[loaded] / np.maximum(load_std[loaded], 1e-9)) ** 2
    nees_mean, interval, consistent = _nees_test(stamps[loaded], nees)

    estimated_count = np.array([s.jammed_rollers_most_likely for s in states])
    seen_until = np.r_[(stamps[:-1] + stamps[1:]) / 2.0, stamps[-1]]
    true_count = truth.jammed_rollers[_truth_at(truth, seen_until)]
    jams = _jam_detections(truth, seen_until, estimated_count)
    top_probability = np.array([max(s.jam_probabilities) for s in states])
    over = estimated_count > true_count
    onsets = int(np.count_nonzero(over[1:] & ~over[:-1]) + int(over[0]))
    durations = np.diff(stamps, append=stamps[-1])
    loss = np.array([s.precision_loss_m for s in states])
    loss_std = np.array([s.precision_loss_std_m for s in states])
    loss_truth = interpolated(truth.precision_loss_m)
    covered = np.abs(loss - loss_truth) <= 2.0 * loss_std + 1e-15
    final_truth = float(loss_truth[-1])
    return Metrics(
        estimates=len(states),
        moving_estimates=int(np.count_nonzero(moving)),
        load_rmse_n=rmse,
        load_rmse_percent_rated=100.0 * rmse / rated_load_n,
        load_max_error_n=float(np.abs(moving_error).max()) if moving_error.size else math.nan,
        load_nees_mean=nees_mean,
        load_nees_interval=interval,
        load_nees_consistent=consistent,
        load_standstill_rmse_n=still_rmse,
        load_standstill_max_error_n=(
            float(np.abs(still_error).max()) if still_error.size else math.nan
        ),
        load_standstill_coverage_2sigma=(
            float(np.mean(np.abs(still_error) <= 2.0 * load_std[~moving]))
            if still_error.size
            else math.nan
        ),
        jams=tuple(jams),
        false_jam_declarations=onsets,
        false_jam_seconds=float(durations[over].sum()),
        precision_loss_final_m=float(loss[-1]),
        precision_loss_truth_final_m=final_truth,
        precision_loss_error_percent=(
            100.0 * (float(loss[-1]) - final_truth) / final_truth if final_truth > 0 else math.nan
        ),
        precision_loss_coverage_2sigma=float(np.mean(covered)),
        clock_offsets_s=offsets,
        estimates_beyond_truth=beyond,
        jam_calibration=_calibration(top_probability, estimated_count == true_count),
    )


def _calibration(
    top_probability: FloatArray, correct: NDArray[np.bool_]
) -> tuple[CalibrationBin, ...]:
    """The estimates per bin of CALIBRATION_EDGES of their most likely count's probability,
    and how many of them had the true count as the most likely."""
    edges = np.array(CALIBRATION_EDGES)
    bins = np.clip(np.searchsorted(edges, top_probability, side="right") - 1, 0, len(edges) - 2)
    found = []
    for b in range(len(edges) - 1):
        inside = bins == b
        count = int(np.count_nonzero(inside))
        found.append(
            CalibrationBin(
                low=float(edges[b]),
                high=float(edges[b + 1]),
                estimates=count,
                correct=int(np.count_nonzero(correct[inside])),
                mean_probability=float(top_probability[inside].mean()) if count else math.nan,
            )
        )
    return tuple(found)


def _nothing_scored(beyond: int, offsets: tuple[float, ...]) -> Metrics:
    """The metrics of a run none of whose ``beyond`` estimates lies inside the truth's span:
    nothing could be computed (NaN, JSON null), nothing was found or declared."""
    values: dict[str, Any] = {f.name: math.nan for f in fields(Metrics)}
    values.update(
        estimates=0,
        moving_estimates=0,
        load_nees_interval=None,
        load_nees_consistent=None,
        jams=(),
        false_jam_declarations=0,
        false_jam_seconds=0.0,
        clock_offsets_s=offsets,
        estimates_beyond_truth=beyond,
        jam_calibration=(),
    )
    return Metrics(**values)


def within_truth(stamps: FloatArray, truth: TruthSamples) -> NDArray[np.bool_]:
    """Which ``stamps`` (on the truth's clock) the truth covers: from one truth period (its
    median spacing) before its first sample to one after its last."""
    period = float(np.median(np.diff(truth.stamp_s))) if len(truth) > 1 else 0.0
    return np.asarray(
        (stamps >= truth.stamp_s[0] - period) & (stamps <= truth.stamp_s[-1] + period),
        dtype=np.bool_,
    )


def _clock_offsets(states: list[HealthState], truth: TruthSamples) -> tuple[float, ...]:
    """The offset of each time line (:func:`_time_lines`) that best matches its estimates'
    screw speed to the truth's (its first MATCHED_ESTIMATES), searched within
    +-MAX_CLOCK_OFFSET_S of a guess that is kept unless the rules of SKIP_MATCH_GAIN take
    another (a gap in the data, or a standstill where every offset matches alike, keeps it).
    The guess: after a skip, the offset of the line before it; after a TIME_RESET, the offset
    that puts the line after the estimate before it by the time the samples between them
    took (:func:`_times_between`: the data go on while the clock is set back, whatever by; a
    guess of zero matched a motion that repeats a period away alike, and missed a clock set
    back by more than MAX_CLOCK_OFFSET_S)."""
    stamps = np.array([s.stamp_s for s in states])
    speed = np.array([s.screw_speed_rad_s for s in states])
    lines, moving_spacing = _time_lines(states)
    times_between = _times_between(states, stamps, moving_spacing)

    def mismatch(segment: slice, candidates: FloatArray) -> FloatArray:
        matched = slice(segment.start, min(segment.stop, segment.start + MATCHED_ESTIMATES))
        shifted = stamps[matched][None, :] + candidates[:, None]
        truth_speed = np.interp(shifted, truth.stamp_s, truth.screw_speed_rad_s)
        return np.asarray(np.mean((truth_speed - speed[matched][None, :]) ** 2, axis=1))

    def best_near(segment: slice, centre: float, span: float, step: float) -> tuple[float, float]:
        """The offset within +-span of centre (on a grid of step) that matches best, and its
        mismatch; ties go to the nearest."""
        near = np.arange(-span, span + step / 2, step)
        candidates = centre + near[np.argsort(np.abs(near), kind="stable")]
        mismatches = mismatch(segment, candidates)
        best = int(np.argmin(mismatches))
        return float(candidates[best]), float(mismatches[best])

    offsets: list[float] = []
    for segment in lines:
        before = offsets[-1] if offsets else 0.0
        first = segment.start
        if states[first].event == EstimateEvent.TIME_RESET and first > 0:
            last = stamps[first - 1] + before  # on the truth's clock
            before = last + float(times_between[first]) - stamps[first]
        coarse, _ = best_near(segment, before, MAX_CLOCK_OFFSET_S, COARSE_STEP_S)
        best, found = best_near(segment, coarse, COARSE_STEP_S * 2.0, FINE_STEP_S)
        # The guess, compared at its own best within the same fine search: the estimates'
        # speeds are block means that lag their stamps, so any offset found (a motion's
        # period further on, say) matched better than the guess held exactly. Kept, it is
        # kept exactly (the same lag would bias its best by half a block).
        _, kept = best_near(segment, before, COARSE_STEP_S * 2.0, FINE_STEP_S)
        long_enough = stamps[segment.stop - 1] - stamps[segment.start] >= MIN_LINE_S
        jumped = abs(best - before) >= moving_spacing and found * SKIP_MATCH_GAIN < kept
        offsets.append(best if jumped and long_enough else before)
    return tuple(offsets)


def _times_between(
    states: list[HealthState], stamps: FloatArray, moving_spacing: float
) -> FloatArray:
    """[i]: the time from estimate i - 1 to estimate i that their samples took ([0]: none
    before it): the samples the estimator counted between them (accepted and rejected: those
    rejected while it waited for a clock set back to be confirmed took time too) at the
    input's rate, the median of accepted samples per second between estimates that advance;
    the usual spacing in motion where the counters do not tell."""
    counted = np.array([s.samples_accepted + s.samples_rejected for s in states], dtype=float)
    accepted = np.diff([float(s.samples_accepted) for s in states])
    steps = np.diff(stamps)
    advancing = (steps > 0.0) & (accepted > 0.0)
    if not advancing.any():
        return np.full(len(states), moving_spacing)
    rate = float(np.median(accepted[advancing] / steps[advancing]))  # > 0
    samples = np.diff(counted, prepend=counted[:1])
    return np.where(samples > 0.0, samples / rate, moving_spacing)


def on_truth_clock(states: list[HealthState], offsets_s: tuple[float, ...]) -> FloatArray:
    """The stamps of ``states`` with ``offsets_s[i]`` added over their i-th time line after
    the first (:func:`_time_lines`): the time line :func:`score` compares on
    (``Metrics.clock_offsets_s``)."""
    stamps = np.array([s.stamp_s for s in states])
    segments, _ = _time_lines(states)
    if len(offsets_s) != len(segments):
        raise ValueError(
            f"on_truth_clock: {len(offsets_s)} offsets for {len(segments)} sensor clock jumps"
        )
    for segment, offset in zip(segments, offsets_s, strict=True):
        stamps[segment] += offset
    return stamps


def _time_lines(states: list[HealthState]) -> tuple[list[slice], float]:
    """The estimates from each sensor clock jump to the next (or the end): a TIME_RESET, or a
    skip, where the stamps advance by more than SKIP_SPACINGS of their usual spacing: a clock
    that jumped ahead, or a gap in the data (:func:`_clock_offsets` tells them apart). The
    estimates before the first keep their stamps. Also the usual spacing in motion [s].

    The usual spacings are medians over the run, of consecutive estimates in motion and of
    those beside a standstill estimate (which may stand for merged blocks); one stands for
    the other where a run has none of a kind.
    """
    stamps = np.array([s.stamp_s for s in states])
    still = np.array([s.event == EstimateEvent.STANDSTILL for s in states], dtype=bool)
    steps = np.diff(stamps)
    beside = still[1:] | still[:-1]
    forward = steps > 0.0  # not across a time reset
    moving = float(np.median(steps[~beside & forward])) if np.any(~beside & forward) else 0.0
    resting = float(np.median(steps[beside & forward])) if np.any(beside & forward) else 0.0
    moving, resting = moving or resting, max(resting, moving)
    skipped = np.r_[False, steps > SKIP_SPACINGS * np.where(beside, resting, moving)]
    starts = [i for i, s in enumerate(states) if s.event == EstimateEvent.TIME_RESET or skipped[i]]
    lines = [slice(b, e) for b, e in zip(starts, [*starts[1:], len(states)], strict=False)]
    return lines, moving


def _nees_test(
    stamps: FloatArray, nees: FloatArray
) -> tuple[float, tuple[float, float] | None, bool | None]:
    """Mean NEES of one estimate per second, its 95 % chi-square interval and whether it lies
    inside (NaN, None and None without a value to test)."""
    if nees.size == 0:
        return math.nan, None, None
    seconds = np.floor(stamps - stamps[0]).astype(np.int64)
    first = np.flatnonzero(np.r_[True, seconds[1:] != seconds[:-1]])
    thinned = nees[first]
    n = len(thinned)
    interval = (float(chi2.ppf(0.025, n) / n), float(chi2.ppf(0.975, n) / n))
    mean = float(thinned.mean())
    return mean, interval, interval[0] <= mean <= interval[1]


def _jam_detections(
    truth: TruthSamples, seen_until: FloatArray, estimated: NDArray[np.int64]
) -> list[JamDetection]:
    counts = truth.jammed_rollers
    detections = []
    for index in truth.jam_onsets:
        onset = float(truth.stamp_s[index])
        if onset > seen_until[-1]:  # after the last estimate: not seen (module docstring)
            break
        count = int(counts[index])
        after = np.flatnonzero((seen_until >= onset) & (estimated == count))
        delay = float(seen_until[after[0]] - onset) if after.size else None
        detections.append(JamDetection(onset_s=onset, count=count, delay_s=delay))
    return detections
