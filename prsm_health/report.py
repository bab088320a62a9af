"""The replay's report: PNG plots of the estimates against the truth, and an index page.

``prsm-health replay BAG --report DIR`` writes ``load.png`` (axial load with +-2 std and the
truth, the axis spanning the estimate and the truth: the band, tens of kN wide where the load
is hardly observed, is cut off; with the truth, a second panel of the error, estimate minus
truth, inside its own +-2 std: readable where an hour of strokes makes the first one a solid
block), ``jams.png`` (probability of each jam count over time, the true count on top),
``precision_loss.png`` (estimate +-2 std, cut at zero, and the truth) and ``index.html`` (the
three plots and the metrics). The truth is drawn wide, dashed and pale under the estimate's
line, so that both show where they coincide. Sensor time resets and divergence recoveries are
marked by vertical lines on every plot. After a sensor time reset the estimates are
drawn on the truth's clock, shifted by the offsets the metrics found (the x label says by how
much), also after a clock that jumped ahead. matplotlib's Agg backend: no display needed.
"""

from __future__ import annotations

import html
import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.artist import Artist
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.ticker import MaxNLocator
from numpy.typing import NDArray

from prsm_health.estimation.estimate import UM_PER_M, EstimateEvent, HealthState
from prsm_health.estimation.metrics import Metrics, on_truth_clock, within_truth
from prsm_health.signals import TruthSamples

FloatArray = NDArray[np.float64]
PLOTS = ("load.png", "jams.png", "precision_loss.png")
#: The load error panel's axis: this quantile of |error| while moving, times the margin (a few
#: blocks beyond it are cut off rather than flatten the rest), at least the smallest [kN].
ERROR_AXIS_QUANTILE = 0.99
ERROR_AXIS_MARGIN = 2.0
SMALLEST_ERROR_AXIS_KN = 0.01
#: The load panel's axis: the range of the estimate and the truth, widened by this fraction
#: of it (of the smallest span at least) on either side [-, kN].
LOAD_AXIS_MARGIN = 0.1
SMALLEST_LOAD_SPAN_KN = 1.0
#: The jam plot shows the counts whose probability exceeds this somewhere.
SHOWN_PROBABILITY = 1e-3


@dataclass(frozen=True)
class _Series:
    stamp_s: FloatArray
    load_kn: FloatArray
    load_std_kn: FloatArray
    jams: FloatArray  # (estimates, counts)
    loss_um: FloatArray
    loss_std_um: FloatArray
    moving: NDArray[np.bool_]  # not a standstill block of the estimator
    events: NDArray[np.int64]  # EstimateEvent of each estimate


def _series(states: list[HealthState], clock_offsets_s: tuple[float, ...] | None) -> _Series:
    """The estimates to plot. With ``clock_offsets_s`` (the metrics', one per sensor clock
    jump or skip) on the truth's clock, shifted as the scoring did; without, on the
    sensor's."""
    stamps = np.array([s.stamp_s for s in states])
    return _Series(
        stamp_s=stamps if clock_offsets_s is None else on_truth_clock(states, clock_offsets_s),
        load_kn=np.array([s.axial_load_n for s in states]) / 1e3,
        load_std_kn=np.array([s.axial_load_std_n for s in states]) / 1e3,
        jams=np.array([s.jam_probabilities for s in states]),
        loss_um=np.array([s.precision_loss_m for s in states]) * UM_PER_M,
        loss_std_um=np.array([s.precision_loss_std_m for s in states]) * UM_PER_M,
        moving=np.array([s.event != EstimateEvent.STANDSTILL for s in states], dtype=bool),
        events=np.array([s.event for s in states], dtype=np.int64),
    )


#: The estimates' events marked on every plot, with their line styles.
MARKED_EVENTS = {
    EstimateEvent.TIME_RESET: ("sensor time reset", "tab:red", ":"),
    EstimateEvent.DIVERGENCE_RECOVERED: ("load re-initialised (divergence)", "tab:purple", "-."),
}


def _time_label(clock_offsets_s: tuple[float, ...] | None) -> str:
    """The plots' x label: the time, and the shifts of the estimates after each sensor clock
    jump (an offset that differs from the one before it; the first from 0). The same offset
    again (a gap in the data keeps the offset before it) is not named."""
    found = clock_offsets_s or ()
    changes = [b for a, b in zip((0.0, *found), found, strict=False) if b != a]
    if not changes:
        return "time [s]"
    shifts = ", ".join(f"{offset:+.3f} s" for offset in changes)
    return f"time [s] (estimates after a sensor clock jump shifted by {shifts}, as scored)"


def _counts_shown(jam_probabilities: FloatArray) -> list[int]:
    """The jam counts the jam plot stacks and names: those whose probability (a column per
    count) exceeds SHOWN_PROBABILITY somewhere; eleven entries in the legend would hide it."""
    return [int(k) for k in np.flatnonzero(jam_probabilities.max(axis=0) > SHOWN_PROBABILITY)]


def _mark_events(axis: Axes, series: _Series) -> list[Line2D]:
    """A vertical line at each estimate that starts a new time line or re-initialised the
    load: what the curves do there is no estimate of the plant. Returns the first line of
    each kind (the legend's entries)."""
    first = []
    for event, (label, colour, style) in MARKED_EVENTS.items():
        for i, time_s in enumerate(series.stamp_s[series.events == event]):
            # One legend entry per kind: matplotlib leaves out labels starting with "_".
            shown = label if i == 0 else f"_{label}"
            line = axis.axvline(time_s, color=colour, ls=style, lw=1.0, label=shown)
            if i == 0:
                first.append(line)
    return first


def _band(
    axis: Axes,
    t: FloatArray,
    mean: FloatArray,
    std: FloatArray,
    label: str,
    *,
    non_negative: bool = False,
) -> None:
    """The estimate and its +-2 std band; a quantity that cannot be negative (precision loss)
    has the band cut at zero, and says so."""
    low = np.maximum(mean - 2 * std, 0.0) if non_negative else mean - 2 * std
    band = f"{label} +-2 std" + (", cut at 0" if non_negative else "")
    axis.fill_between(t, low, mean + 2 * std, alpha=0.3, label=band)
    axis.plot(t, mean, lw=1.0, label=label)


def _truth(axis: Axes, t: FloatArray, values: FloatArray) -> None:
    """The truth beside an estimate: wide, dashed and pale, under the estimate's line, so that
    both show where they coincide."""
    axis.plot(t, values, "k--", lw=2.5, alpha=0.4, zorder=1.5, label="truth")


def _load_figure(series: _Series, truth: TruthSamples | None, *, xlabel: str, title: str) -> Figure:
    """The axial load with its band and the truth; with the truth, below it the error
    (estimate minus the truth interpolated to each estimate, as the metrics score it) inside
    +-2 std."""
    t = series.stamp_s
    if truth is None:
        figure, axis = plt.subplots(figsize=(10, 4))
        axis.set_xlabel(xlabel)
    else:
        figure, (axis, error_axis) = plt.subplots(
            2, 1, figsize=(10, 6), sharex=True, height_ratios=(2, 1)
        )
        # Beyond the truth's span the truth is unknown: no error is drawn there.
        error_kn = np.where(
            within_truth(t, truth),
            series.load_kn - np.interp(t, truth.stamp_s, truth.axial_load_n / 1e3),
            np.nan,
        )
        two_std = 2.0 * series.load_std_kn
        error_axis.fill_between(t, -two_std, two_std, alpha=0.3, label="+-2 std")
        error_axis.plot(t, error_kn, lw=0.8, label="estimate - truth")
        error_axis.set(xlabel=xlabel, ylabel="load error [kN]")
        if series.moving.any():
            # Scaled to the errors in motion: at standstill and at the stroke ends the load
            # is hardly observed (its band spans tens of kN) and would flatten them.
            size = np.abs(error_kn[series.moving])
            size = size[np.isfinite(size)]
            limit = (
                ERROR_AXIS_MARGIN * float(np.quantile(size, ERROR_AXIS_QUANTILE))
                if size.size
                else SMALLEST_ERROR_AXIS_KN
            )
            error_axis.set_ylim(
                -max(limit, SMALLEST_ERROR_AXIS_KN), max(limit, SMALLEST_ERROR_AXIS_KN)
            )
            error_axis.set_title(
                "scaled to the errors in motion (wider bands cut off)", fontsize=9, loc="left"
            )
        # Above the axes, beside the title: inside, every place is covered on a long run.
        error_axis.legend(
            loc="lower right", bbox_to_anchor=(1.0, 1.0), ncols=2, fontsize=8, frameon=False
        )
    _band(axis, t, series.load_kn, series.load_std_kn, "estimate")
    _mark_events(axis, series)
    shown = series.load_kn
    if truth is not None:
        _truth(axis, truth.stamp_s, truth.axial_load_n / 1e3)
        # The truth over the estimates' span only (a replay stopped early: its axis).
        during = (truth.stamp_s >= np.nanmin(t)) & (truth.stamp_s <= np.nanmax(t))
        shown = np.concatenate([shown, truth.axial_load_n[during] / 1e3])
    shown = shown[np.isfinite(shown)]
    if shown.size:  # the loads set the axis, not the band
        low, high = float(shown.min()), float(shown.max())
        margin = LOAD_AXIS_MARGIN * max(high - low, SMALLEST_LOAD_SPAN_KN)
        axis.set_ylim(low - margin, high + margin)
    axis.set_ylabel("axial load [kN]")
    # The legend above the axes, right of the title: inside, it covers strokes on a long run.
    axis.set_title(f"{title}: axial load", loc="left")
    axis.legend(loc="lower right", bbox_to_anchor=(1.0, 1.0), ncols=6, fontsize=8, frameon=False)
    return figure


def _estimates_span(figure: Figure, stamps_s: FloatArray) -> None:
    """Every time axis of ``figure`` over the estimates' span (1 % margin): the truth of a
    replay stopped or damaged early runs on beyond it, and squeezed the estimates."""
    first, last = float(np.nanmin(stamps_s)), float(np.nanmax(stamps_s))
    margin = 0.01 * ((last - first) or 1.0)
    for axis in figure.axes:
        axis.set_xlim(first - margin, last + margin)


def write_report(
    directory: Path,
    states: list[HealthState],
    truth: TruthSamples | None,
    metrics: Metrics | None,
    *,
    title: str,
    scores: Mapping[str, object] | None = None,
) -> list[Path]:
    """Write the plots and ``index.html`` into ``directory`` (created); returns the files.

    ``scores``: what the index page lists (the replay's metrics JSON, with what it adds to
    ``metrics``); by default ``metrics`` itself."""
    if not states:
        raise ValueError("report: no estimates to plot")
    directory.mkdir(parents=True, exist_ok=True)
    offsets = metrics.clock_offsets_s if metrics is not None else None
    series = _series(states, offsets)
    t = series.stamp_s
    xlabel = _time_label(offsets)
    figures = []

    figures.append(_load_figure(series, truth, xlabel=xlabel, title=title))

    figure, axis = plt.subplots(figsize=(10, 4))
    shown = _counts_shown(series.jams)
    handles: list[Artist] = list(
        axis.stackplot(t, series.jams[:, shown].T, labels=[f"P({k} jammed)" for k in shown])
    )
    if truth is not None:
        axis2 = axis.twinx()
        handles += axis2.step(
            truth.stamp_s, truth.jammed_rollers, "k--", lw=1.6, where="post", label="true count"
        )
        axis2.set_ylabel("true jammed rollers")
        # Half a count of margin: a count of 0 on the axis' edge was hard to see.
        axis2.set_ylim(-0.5, max(2, int(truth.jammed_rollers.max()) + 1) + 0.5)
        axis2.yaxis.set_major_locator(MaxNLocator(integer=True))
    handles += _mark_events(axis, series)
    axis.set(xlabel=xlabel, ylabel="probability", ylim=(0, 1), title=f"{title}: jams")
    # Below the axes: inside, it would cover the probabilities it names.
    axis.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.15), ncols=6)
    figures.append(figure)

    figure, axis = plt.subplots(figsize=(10, 4))
    _band(axis, t, series.loss_um, series.loss_std_um, "estimate", non_negative=True)
    _mark_events(axis, series)
    if truth is not None:
        _truth(axis, truth.stamp_s, truth.precision_loss_m * UM_PER_M)
    axis.set(xlabel=xlabel, ylabel="precision loss [µm]", title=f"{title}: precision loss")
    axis.legend(loc="best")
    figures.append(figure)

    for figure in figures:
        _estimates_span(figure, t)
    files = []
    for name, figure in zip(PLOTS, figures, strict=True):
        path = directory / name
        figure.tight_layout()
        figure.savefig(path, dpi=100)
        plt.close(figure)
        files.append(path)
    index = directory / "index.html"
    if scores is None and metrics is not None:
        scores = metrics.to_dict()
    index.write_text(_index_html(title, scores), encoding="utf-8")
    files.append(index)
    return files


def _index_html(title: str, scores: Mapping[str, object] | None) -> str:
    listed = (
        f"<pre>{html.escape(json.dumps(scores, indent=2))}</pre>"
        if scores is not None
        else "<p>The bag has no ground truth (/truth/state): no metrics.</p>"
    )
    images = "\n".join(f'<p><img src="{name}" alt="{name}"></p>' for name in PLOTS)
    return (
        f"<!doctype html>\n<html><head><meta charset='utf-8'><title>{html.escape(title)}"
        f"</title></head>\n<body><h1>{html.escape(title)}</h1>\n{images}\n"
        f"<h2>Metrics</h2>\n{listed}\n</body></html>\n"
    )
