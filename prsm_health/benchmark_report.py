"""The benchmark's floors and files: ``results.json``, ``results.md``, ``pareto.png``.

:func:`floors` evaluates the floors of issue 6 on a :class:`~prsm_health.benchmark.BenchResults`
(measured value and pass/fail; a floor whose runs were not part of the plan is "not
measured"); :func:`write_results` writes the three files. Nothing here asserts: a failing
floor is reported, and the run still succeeds.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from prsm_health.benchmark import (
    BAG_SCENES,
    CONFIGURATION_NAMES,
    ONSET_CATEGORIES,
    BenchResults,
    JamOnset,
    Run,
    ScoredRun,
    Timing,
    WearRun,
)
from prsm_health.estimation.metrics import CalibrationBin

#: The floors' thresholds (issue 6).
NAIVE_SPEEDUP = 50.0
NAIVE_EXTRA_RMSE_PERCENT = 0.5
MEDIAN_COST_US = 50.0
REPLAY_OVER_DECODE = 2.0
RMSE_PERCENT = 2.0
WEAR_ERROR_PERCENT = 10.0
WEAR_COVERAGE = 0.9
#: Scenes that are not the downhole cycle (outside the load-RMSE floor).
NOT_DOWNHOLE = ("stationary-hold",)
#: What :func:`write_results` writes: every run's numbers, the tables, the time-error plot.
JSON_FILE, MARKDOWN_FILE, PARETO_FILE = FILES = ("results.json", "results.md", "pareto.png")


@dataclass(frozen=True)
class Floor:
    """One floor: what is required, what was measured, and whether it holds (None: not
    measured in this run)."""

    name: str
    requirement: str
    measured: str
    passed: bool | None


#: A Run, or a ToldCountRun, in a floor.
AnyRun = TypeVar("AnyRun", bound=ScoredRun)


def _missing(name: str, requirement: str) -> Floor:
    return Floor(name, requirement, "not measured in this run", None)


def pooled_timing(runs: Iterable[Run]) -> Timing:
    """Per-call statistics over the calls of several runs."""
    return Timing.of(np.concatenate([r.durations_ns for r in runs]))


def pooled_rmse_percent(runs: Iterable[ScoredRun]) -> float:
    """Load RMSE over the moving estimates of several runs, % of the largest paper load."""
    chosen = [r for r in runs if r.metrics.moving_estimates]
    if not chosen:
        return math.nan
    squares = sum(r.metrics.moving_estimates * r.rmse_percent_largest**2 for r in chosen)
    return math.sqrt(squares / sum(r.metrics.moving_estimates for r in chosen))


def pooled_calibration(runs: Iterable[ScoredRun]) -> list[CalibrationBin]:
    """The jam count's calibration bins (Metrics.jam_calibration) summed over several runs."""
    pooled: list[CalibrationBin] = []
    for bins in zip(*(r.metrics.jam_calibration for r in runs), strict=True):
        estimates = sum(b.estimates for b in bins)
        weighted = sum(b.mean_probability * b.estimates for b in bins if b.estimates)
        pooled.append(
            CalibrationBin(
                low=bins[0].low,
                high=bins[0].high,
                estimates=estimates,
                correct=sum(b.correct for b in bins),
                mean_probability=weighted / estimates if estimates else math.nan,
            )
        )
    return pooled


def _mark(passed: bool | None) -> str:
    return {True: "pass", False: "**FAIL**", None: "not measured"}[passed]


def _delay(delay_s: float | None) -> str:
    return "never" if delay_s is None else f"{delay_s:.2f} s"


def _naive_floors(results: BenchResults) -> list[Floor]:
    names = (
        f"default >= {NAIVE_SPEEDUP:g}x faster per sample than naive",
        f"default <= {NAIVE_EXTRA_RMSE_PERCENT:g} % extra load RMSE over naive",
        "default detects jams no worse than naive",
    )
    requirements = (
        "mean cost per sample ratio",
        "per scene, % of the largest load",
        "every jam naive finds, as early; no more false declarations",
    )
    naive = {r.scene: r for r in results.runs_of(kind="excerpt", config="naive")}
    default = {r.scene: r for r in results.runs_of(kind="excerpt", config="default")}
    scenes = sorted(set(naive) & set(default))
    if not scenes:
        return [_missing(n, q) for n, q in zip(names, requirements, strict=True)]
    slow = pooled_timing(naive[s] for s in scenes).mean_us
    fast = pooled_timing(default[s] for s in scenes).mean_us
    extra = {s: default[s].rmse_percent_largest - naive[s].rmse_percent_largest for s in scenes}
    worse = []
    detections = []
    for s in scenes:
        for d, n in zip(default[s].metrics.jams, naive[s].metrics.jams, strict=True):
            detections.append(f"{s} {d.onset_s:.2f} s: {_delay(d.delay_s)} vs {_delay(n.delay_s)}")
            if n.delay_s is not None and (d.delay_s is None or d.delay_s > n.delay_s):
                worse.append(s)
        if default[s].metrics.false_jam_declarations > naive[s].metrics.false_jam_declarations:
            worse.append(s)
    seconds = results.plan["naive_seconds"]
    return [
        Floor(
            names[0],
            f">= {NAIVE_SPEEDUP:g}x",
            f"{slow / fast:,.0f}x ({slow:,.0f} vs {fast:.1f} us per sample, first {seconds:g} s "
            f"of {', '.join(scenes)})",
            slow / fast >= NAIVE_SPEEDUP,
        ),
        Floor(
            names[1],
            f"<= {NAIVE_EXTRA_RMSE_PERCENT:g} %",
            ", ".join(f"{s} {v:+.3f} %" for s, v in extra.items()),
            max(extra.values()) <= NAIVE_EXTRA_RMSE_PERCENT,
        ),
        Floor(
            names[2],
            requirements[2],
            "; ".join(detections) or "no jam in the excerpts; false declarations compared",
            not worse,
        ),
    ]


def _jam_floors(onsets: list[JamOnset]) -> list[Floor]:
    floors = []
    for category in ONSET_CATEGORIES:
        name = f"jams identified within one motion cycle: {category}"
        found = [o for o in onsets if o.config == "default" and o.category == category]
        if not found:
            floors.append(_missing(name, "every onset"))
            continue
        parts = []
        for count in sorted({o.count for o in found}):
            group = [o for o in found if o.count == count]
            hits = sum(o.within_cycle for o in group)
            cancelled = sum(o.ripple_cancelled for o in group)
            notes = [f"{cancelled} with the ripple cancelled"] if cancelled else []
            missed = [
                o.evidence_nats for o in group if not o.within_cycle and o.evidence_nats is not None
            ]
            if missed:
                blind = sum(evidence <= 0.0 for evidence in missed)
                notes.append(f"{blind} of the {len(missed)} missed without evidence")
            note = f" ({'; '.join(notes)})" if notes else ""
            parts.append(f"jam {count}: {hits}/{len(group)}{note}")
        delays = [o.delay_s for o in found if o.delay_s is not None]
        median = f", median delay {np.median(delays):.2f} s" if delays else ""
        floors.append(
            Floor(
                name,
                "every onset",
                f"{'; '.join(parts)}{median}",
                all(o.within_cycle for o in found),
            )
        )
    return floors


def _wear_floors(results: BenchResults) -> list[Floor]:
    true_name = f"precision loss with the true wear factor within {WEAR_ERROR_PERCENT:g} %"
    true_requirement = f"|final error| <= {WEAR_ERROR_PERCENT:g} %"
    prior_name = f"precision loss within +-2 sigma >= {100 * WEAR_COVERAGE:g} % (factor from prior)"
    prior_requirement = f">= {100 * WEAR_COVERAGE:g} % of estimates"
    floors = []
    run = results.wear_true_factor
    if run is None:
        floors.append(_missing(true_name, true_requirement))
    else:
        floors.append(
            Floor(
                true_name,
                true_requirement,
                f"{run.final_error_percent:+.2f} % of {run.truth_final_um:.1f} um "
                f"(factor {run.true_factor:.4f})",
                abs(run.final_error_percent) <= WEAR_ERROR_PERCENT,
            )
        )
    prior = results.wear_prior
    if not prior:
        floors.append(_missing(prior_name, prior_requirement))
    else:
        coverage = prior_coverage(prior)
        floors.append(
            Floor(
                prior_name,
                prior_requirement,
                f"{100 * coverage:.1f} % over {len(prior)} runs (lowest run "
                f"{100 * min(r.coverage_2sigma for r in prior):.0f} %)",
                coverage >= WEAR_COVERAGE,
            )
        )
    return floors


def prior_coverage(runs: list[WearRun]) -> float:
    """Fraction of all estimates of the prior runs whose truth is within +-2 sigma."""
    return sum(r.coverage_2sigma * r.estimates for r in runs) / sum(r.estimates for r in runs)


def _floor(
    name: str,
    requirement: str,
    runs: Sequence[AnyRun],
    measure: Callable[[Sequence[AnyRun]], tuple[str, bool]],
) -> Floor:
    """A floor measured on ``runs`` by ``measure`` (text, verdict); "not measured" without."""
    if not runs:
        return _missing(name, requirement)
    measured, passed = measure(runs)
    return Floor(name, requirement, measured, passed)


def _cost(runs: Sequence[Run]) -> tuple[str, bool]:
    timing = pooled_timing(runs)
    chunked_us = 1e6 * sum(r.chunked_s or 0.0 for r in runs) / sum(r.samples for r in runs)
    return (
        f"median {timing.median_us:.1f} us, p99 {timing.p99_us:.0f} us, mean "
        f"{timing.mean_us:.1f} us over {timing.calls:,} calls; chunked {chunked_us:.1f} us",
        timing.median_us <= MEDIAN_COST_US,
    )


def _replay(runs: Sequence[Run]) -> tuple[str, bool]:
    ratios = {r.scene: r.replay_over_decode or 0.0 for r in runs}
    worst = max(ratios, key=ratios.__getitem__)
    return (
        f"{min(ratios.values()):.2f}x to {ratios[worst]:.2f}x ({worst})",
        ratios[worst] <= REPLAY_OVER_DECODE,
    )


def _rmse(runs: Sequence[ScoredRun]) -> tuple[str, bool]:
    worst = max(runs, key=lambda r: r.rmse_percent_largest)
    return (
        f"largest {worst.rmse_percent_largest:.2f} % ({worst.scene}), pooled "
        f"{pooled_rmse_percent(runs):.2f} % over {len(runs)} scenes",
        worst.rmse_percent_largest <= RMSE_PERCENT,
    )


def _false_jams(runs: Sequence[Run]) -> tuple[str, bool]:
    declarations = sum(r.metrics.false_jam_declarations for r in runs)
    seconds = sum(r.metrics.false_jam_seconds for r in runs)
    hours = sum(r.samples for r in runs) / 1000.0 / 3600.0  # the generated runs: 1 kHz
    worst = max(runs, key=lambda r: r.metrics.false_jam_seconds)
    where = f"; longest in {worst.scene}" if declarations else ""
    return (
        f"{declarations} ({seconds:.1f} s declared) over {hours:.2f} h in {len(runs)} "
        f"run{'s' if len(runs) > 1 else ''}{where}",
        declarations == 0,
    )


def _nees(runs: Sequence[ScoredRun]) -> tuple[str, bool]:
    """Consistent on every run; a run with nothing to test (None) is named apart, and is no
    pass either: the floor is not shown there."""
    failed = [r.scene for r in runs if r.metrics.load_nees_consistent is False]
    untested = [r.scene for r in runs if r.metrics.load_nees_consistent is None]
    listed = f"; not: {', '.join(failed)}" if failed else ""
    listed += f"; untested: {', '.join(untested)}" if untested else ""
    consistent = len(runs) - len(failed) - len(untested)
    return f"{consistent}/{len(runs)} consistent{listed}", not failed and not untested


def floors(results: BenchResults) -> list[Floor]:
    """Every floor of issue 6, measured on ``results``."""
    default = results.runs_of(config="default")
    return [
        *_naive_floors(results),
        _floor(
            f"median estimator cost <= {MEDIAN_COST_US:g} us per sample",
            f"<= {MEDIAN_COST_US:g} us (one call per sample)",
            default,
            _cost,
        ),
        _floor(
            f"offline replay <= {REPLAY_OVER_DECODE:g}x the bare decode time",
            f"<= {REPLAY_OVER_DECODE:g}x on every bag",
            [r for r in default if r.replay_over_decode is not None],
            _replay,
        ),
        _floor(
            f"load RMSE while moving <= {RMSE_PERCENT:g} % of the largest paper load",
            f"<= {RMSE_PERCENT:g} % on every downhole scene",
            [r for r in default if r.scene not in NOT_DOWNHOLE],
            _rmse,
        ),
        _floor(
            f"load RMSE while moving <= {RMSE_PERCENT:g} %, told the jam count (beyond the issue)",
            f"<= {RMSE_PERCENT:g} % on every downhole scene with jams",
            [r for r in results.told_count if r.scene not in NOT_DOWNHOLE],
            _rmse,
        ),
        *_jam_floors(results.jam_onsets),
        _floor(
            "no false jam in one hour of nominal cycles",
            "0 false declarations",
            [r for r in default if r.scene == "nominal-1h"],
            _false_jams,
        ),
        _floor(
            "no false second jam after a jam (beyond the issue)",
            "0 false declarations",
            [r for r in default if r.group == "one-jam"],
            _false_jams,
        ),
        *_wear_floors(results),
        _floor("load NEES consistent (95 % chi-square test)", "every scene", default, _nees),
        _floor(
            "load NEES consistent, told the jam count (beyond the issue)",
            "every scene with jams",
            results.told_count,
            _nees,
        ),
    ]


# --- results.json -----------------------------------------------------------------------------
def _finite(value: Any) -> Any:
    """JSON-safe: non-finite floats become None, tuples lists, recursively."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


def _run_json(run: Run) -> dict[str, Any]:
    return {
        "scene": run.scene,
        "group": run.group,
        "config": run.config,
        "kind": run.kind,
        "samples": run.samples,
        "estimates": run.estimates,
        "chunked_s": run.chunked_s,
        "samples_per_s": run.samples_per_s,
        "decode_s": run.decode_s,
        "replay_over_decode": run.replay_over_decode,
        "per_sample": dataclasses.asdict(run.timing),
        "load_rmse_percent_largest": run.rmse_percent_largest,
        "largest_load_n": run.largest_load_n,
        "metrics": run.metrics.to_dict(),
    }


def results_json(results: BenchResults, found: list[Floor]) -> dict[str, Any]:
    """Every number of the run, JSON-able."""
    document: dict[str, Any] = _finite(
        {
            "mode": results.mode,
            "elapsed_s": results.elapsed_s,
            "machine": results.machine,
            "plan": results.plan,
            "skipped_configs": results.skipped_configs,
            "floors": [dataclasses.asdict(f) for f in found],
            "runs": [_run_json(r) for r in results.runs],
            "jam_onsets": [
                {**dataclasses.asdict(o), "within_cycle": o.within_cycle}
                for o in results.jam_onsets
            ],
            "wear_true_factor": (
                dataclasses.asdict(results.wear_true_factor)
                if results.wear_true_factor is not None
                else None
            ),
            "wear_prior": [dataclasses.asdict(w) for w in results.wear_prior],
            "wear_prior_coverage": prior_coverage(results.wear_prior)
            if results.wear_prior
            else None,
            "told_count": [
                {
                    "scene": r.scene,
                    "group": r.group,
                    "load_rmse_percent_largest": r.rmse_percent_largest,
                    "largest_load_n": r.largest_load_n,
                    "metrics": r.metrics.to_dict(),
                }
                for r in results.told_count
            ],
            "envelope": [
                {
                    "scene": r.scene,
                    "description": r.description,
                    "load_rmse_percent_largest": r.rmse_percent_largest,
                    "told_load_rmse_percent_largest": r.told_rmse_percent_largest,
                    "largest_load_n": r.largest_load_n,
                    "metrics": r.metrics.to_dict(),
                    "told_metrics": None if r.told is None else r.told.to_dict(),
                    "model_settings": r.model_settings,
                }
                for r in results.envelope
            ],
        }
    )
    return document


# --- results.md -------------------------------------------------------------------------------
def _table(header: list[str], rows: list[list[str]]) -> list[str]:
    """A Markdown table; a "|" inside a cell is escaped so that it stays in its cell."""

    def line(cells: list[str]) -> str:
        return "| " + " | ".join(cell.replace("|", r"\|") for cell in cells) + " |"

    return [line(header), "|" + "---|" * len(header), *(line(row) for row in rows)]


def _number(value: float | None, spec: str) -> str:
    if value is None or not math.isfinite(value):
        return "-"
    return format(value, spec)


def _columns(runs: list[Run]) -> list[str]:
    """Scene columns: each scene, the two-jam runs as one column."""
    names: list[str] = []
    for run in runs:
        column = "two-jam" if run.group == "two-jam" else run.scene
        if column not in names:
            names.append(column)
    return names


def _in_column(run: Run, column: str) -> bool:
    return (run.group == "two-jam") if column == "two-jam" else run.scene == column


def _matrices(results: BenchResults, configs: list[str]) -> list[str]:
    runs = results.runs_of()
    columns = _columns(runs)
    header = [
        "configuration",
        *[c if c != "two-jam" else f"two-jam (x{_count(runs)})" for c in columns],
    ]
    time_rows, error_rows = [], []
    for config in configs:
        mine = [r for r in runs if r.config == config]
        time_row, error_row = [config], [config]
        for column in columns:
            cell = [r for r in mine if _in_column(r, column)]
            if not cell:
                time_row.append("")
                error_row.append("")
                continue
            timing = pooled_timing(cell)
            time_row.append(
                f"{timing.mean_us:,.1f} ({timing.median_us:.0f} / {timing.p99_us:,.0f})"
            )
            error_row.append(f"{pooled_rmse_percent(cell):.2f}")
        time_rows.append(time_row)
        error_rows.append(error_row)
    return [
        "### Time per sample [us]: mean (median / p99), one `process` call per sample",
        "",
        *_table(header, time_rows),
        "",
        "### Load RMSE while moving [% of the largest paper load, 55 kN]",
        "",
        *_table(header, error_rows),
    ]


def _count(runs: list[Run]) -> int:
    return len({r.scene for r in runs if r.group == "two-jam"})


def common_runs(results: BenchResults, kind: str) -> dict[str, list[Run]]:
    """Per configuration, its runs of ``kind`` on the scenes that every configuration ran
    (the one-hour run is the default's only), so that pooled numbers compare."""
    by_config: dict[str, list[Run]] = {}
    for run in results.runs_of(kind=kind):
        by_config.setdefault(run.config, []).append(run)
    if not by_config:
        return {}
    shared = set.intersection(*({r.scene for r in runs} for runs in by_config.values()))
    return {c: [r for r in runs if r.scene in shared] for c, runs in by_config.items()}


def _summary(results: BenchResults, common: dict[str, list[Run]]) -> list[str]:
    rows = []
    for config, runs in common.items():
        timing = pooled_timing(runs)
        samples = sum(r.samples for r in runs)
        chunked = sum(r.chunked_s or 0.0 for r in runs)
        scenes = {r.scene for r in runs}
        onsets = [o for o in results.jam_onsets if o.config == config and o.scene in scenes]
        metrics = [r.metrics for r in runs]
        rows.append(
            [
                config,
                str(len(runs)),
                f"{samples / 1e6:.2f} M",
                f"{timing.median_us:.1f}",
                f"{timing.p99_us:,.0f}",
                f"{timing.mean_us:,.1f}",
                f"{1e6 * chunked / samples:,.1f}",
                f"{pooled_rmse_percent(runs):.2f}",
                f"{max(m.load_max_error_n for m in metrics) / 1e3:.1f}",
                f"{sum(m.load_nees_consistent is True for m in metrics)}/{len(metrics)}",
                f"{sum(o.within_cycle for o in onsets)}/{len(onsets)}",
                str(sum(m.false_jam_declarations for m in metrics)),
                f"{np.nanmean([abs(m.precision_loss_error_percent) for m in metrics]):.1f}",
            ]
        )
    header = [
        "configuration",
        "scenes",
        "samples",
        "median us",
        "p99 us",
        "mean us",
        "chunked us",
        "RMSE %",
        "max err kN",
        "NEES ok",
        "jams in 1 cycle",
        "false jams",
        "mean abs PL err %",
    ]
    return _table(header, rows)


#: Columns of the per-run tables: header and cell of a run.
RUN_COLUMNS: dict[str, Callable[[Run], str]] = {
    "scene": lambda r: r.scene,
    "config": lambda r: r.config,
    "samples": lambda r: f"{r.samples:,}",
    "samples/s": lambda r: _number(r.samples_per_s, ",.0f"),
    "replay/decode": lambda r: _number(r.replay_over_decode, ".2f"),
    "median us": lambda r: f"{r.timing.median_us:.1f}",
    "p99 us": lambda r: f"{r.timing.p99_us:,.0f}",
    "mean us": lambda r: f"{r.timing.mean_us:,.1f}",
    "RMSE %": lambda r: f"{r.rmse_percent_largest:.3f}",
    "max err kN": lambda r: f"{r.metrics.load_max_error_n / 1e3:.2f}",
    "NEES": lambda r: (
        f"{r.metrics.load_nees_mean:.2f}{'' if r.metrics.load_nees_consistent is True else ' (x)'}"
    ),
    "jam delays": lambda r: ", ".join(_delay(j.delay_s) for j in r.metrics.jams) or "-",
    "false jams": lambda r: str(r.metrics.false_jam_declarations),
    "PL err %": lambda r: _number(r.metrics.precision_loss_error_percent, "+.1f"),
    "PL 2s cov %": lambda r: f"{100 * r.metrics.precision_loss_coverage_2sigma:.0f}",
}
DETAIL_COLUMNS = tuple(RUN_COLUMNS)
EXCERPT_COLUMNS = (
    "scene",
    "config",
    "samples",
    "mean us",
    "median us",
    "p99 us",
    "RMSE %",
    "max err kN",
    "jam delays",
    "false jams",
)


def _runs_table(runs: list[Run], columns: tuple[str, ...]) -> list[str]:
    return _table(list(columns), [[RUN_COLUMNS[c](run) for c in columns] for run in runs])


def _decode(results: BenchResults) -> list[str]:
    rows = []
    for scene in BAG_SCENES:
        runs = [r for r in results.runs_of() if r.scene == scene]
        if not runs or runs[0].decode_s is None:
            continue
        decode = runs[0].decode_s
        cells = [f"{r.config} {r.replay_over_decode:.2f}x" for r in runs if r.replay_over_decode]
        rows.append([scene, f"{decode * 1e3:.0f} ms", "; ".join(cells)])
    return _table(["bag", "rosbags decode", "replay time / decode time"], rows)


def _ripple(onset: JamOnset) -> str:
    """The jammed rollers' ripple after the onset, in units of one roller's, and how far the
    onset turned it (benchmark.ripple_change)."""
    if onset.ripple_cancelled:
        return "0 (cancelled)"
    if onset.ripple_turn_deg is None:
        return f"{onset.ripple_after:.2f} (new)"
    return f"{onset.ripple_after:.2f} ({onset.ripple_turn_deg:.0f} deg)"


def _onsets(results: BenchResults) -> list[str]:
    rows = []
    for o in results.jam_onsets:
        if o.config != "default":
            continue
        rows.append(
            [
                o.scene,
                f"{o.onset_s:.2f}",
                str(o.count),
                o.category,
                _ripple(o),
                _delay(o.delay_s),
                _number(o.cycle_s, ".1f"),
                "yes" if o.within_cycle else "**no**",
                _number(o.evidence_nats, ".1f"),
            ]
        )
    header = [
        "scene",
        "onset s",
        "jam",
        "category",
        "ripple after (turn)",
        "identified after",
        "cycle s",
        "in 1 cycle",
        "evidence nats",
    ]
    return _table(header, rows)


def _told(results: BenchResults) -> list[str]:
    """Each run with jams: the default's load RMSE and NEES beside the same told the count."""
    default = {r.scene: r for r in results.runs_of(config="default")}
    rows = []
    for told in results.told_count:
        run = default[told.scene]
        interval = told.metrics.load_nees_interval
        rows.append(
            [
                told.scene,
                f"{run.rmse_percent_largest:.2f}",
                f"{told.rmse_percent_largest:.2f}",
                f"{run.metrics.load_nees_mean:.2f}",
                f"{told.metrics.load_nees_mean:.2f}",
                "-" if interval is None else f"{interval[0]:.2f}-{interval[1]:.2f}",
                str(told.metrics.false_jam_declarations),
            ]
        )
    header = [
        "scene",
        "RMSE %",
        "RMSE % told",
        "NEES",
        "NEES told",
        "95 % interval",
        "false jams told",
    ]
    return _table(header, rows)


def _envelope(results: BenchResults) -> list[str]:
    """Each scene of the envelope: the default's load RMSE, its largest error and NEES, the
    jams found (delay per onset) and false declarations, and the RMSE told the count."""
    rows = []
    for run in results.envelope:
        m, told = run.metrics, run.told_rmse_percent_largest
        rows.append(
            [
                run.scene,
                run.description,
                f"{run.rmse_percent_largest:.2f}",
                f"{m.load_max_error_n / 1e3:.2f}",
                f"{m.load_nees_mean:.2f}",
                ", ".join(_delay(j.delay_s) for j in m.jams) or "-",
                str(m.false_jam_declarations),
                "-" if told is None else f"{told:.2f}",
            ]
        )
    header = [
        "scene",
        "what differs",
        "RMSE %",
        "max err kN",
        "NEES",
        "jams found after",
        "false jams",
        "RMSE % told",
    ]
    return _table(header, rows)


def _probability(p: float) -> str:
    """A probability; near 1 as 1 minus its complement, which ``.6f`` rounds away."""
    if not math.isfinite(p):
        return "-"
    return f"1 - {1.0 - p:.1e}" if p > 0.999 else f"{p:.3f}"


def _calibration(results: BenchResults) -> list[str]:
    """The jam count's probabilities against how often the most likely count was right,
    pooled over the default's full runs, those with jams and those without."""
    runs = results.runs_of(config="default")
    groups = {
        "with jams": [r for r in runs if r.metrics.jams],
        "without": [r for r in runs if not r.metrics.jams],
    }
    pooled = {name: pooled_calibration(chosen) for name, chosen in groups.items() if chosen}
    rows = []
    for i, first in enumerate(next(iter(pooled.values()), [])):
        closed = "]" if first.high == 1.0 else ")"
        row = [f"[{first.low:g}, {first.high:g}{closed}"]
        for bins in pooled.values():
            b = bins[i]
            right = f"{100.0 * b.correct / b.estimates:.2f}" if b.estimates else "-"
            row += [str(b.estimates), _probability(b.mean_probability), right]
        rows.append(row)
    header = ["p of the most likely count"]
    for name, chosen in groups.items():
        if name in pooled:
            header += [f"{name} ({len(chosen)} runs)", "mean p", "right %"]
    return _table(header, rows)


def _wear(results: BenchResults) -> list[str]:
    rows = [
        [
            w.scene,
            f"{w.true_factor:.3f}",
            f"{w.estimator_factor:.3f}",
            f"{w.truth_final_um:.2f}",
            f"{w.final_error_percent:+.1f}",
            f"{100 * w.coverage_2sigma:.0f}",
        ]
        for w in ([results.wear_true_factor] if results.wear_true_factor else [])
        + results.wear_prior
    ]
    header = ["run", "true factor", "estimator's factor", "truth um", "final error %", "2s cov %"]
    return _table(header, rows)


def run_label(mode: str) -> str:
    """The run as the titles name it: the plan's name, "run", then the qualifiers the mode
    adds after a comma (``full run``, ``full run, held-out seed 7``, ``quick run, restricted
    to scenes bags; configurations default``)."""
    plan, comma, qualifiers = mode.partition(",")
    return f"{plan} run{comma}{qualifiers}"


def _naive_too(results: BenchResults) -> str:
    """The excerpt's note that the naive configuration ran on it, empty if it did not."""
    return " (naive too)" if results.runs_of(kind="excerpt", config="naive") else ""


def markdown(results: BenchResults, found: list[Floor]) -> str:
    """``results.md``: the floors, then the tables."""
    configs = list(dict.fromkeys(r.config for r in results.runs))
    machine = results.machine
    lines = [
        f"# Estimator benchmark ({run_label(results.mode)})",
        "",
        f"{machine['cpus']} CPUs ({machine['processor'] or machine['machine']}), Python "
        f"{machine['python']}, load average {machine['load_average_1min_at_start']:.2f} at "
        f"the start; the run took {results.elapsed_s / 60:.1f} min. Per-sample timings: the "
        f"first {results.plan['timing_samples']:,} samples of each run, one `process` call "
        "each.",
        "",
        "## Floors",
        "",
        *_table(
            ["floor", "requirement", "measured", "result"],
            [[f.name, f.requirement, f.measured, _mark(f.passed)] for f in found],
        ),
        "",
        "## Configurations x scenes",
        "",
    ]
    if results.skipped_configs:
        lines += [
            "Not run: " + "; ".join(f"`{k}` {v}" for k, v in results.skipped_configs.items()) + ".",
            "",
        ]
    lines += _matrices(results, [c for c in configs if results.runs_of(config=c)])
    common = common_runs(results, "full")
    shared = sorted({r.scene for runs in common.values() for r in runs})
    left_out = sorted({r.scene for r in results.runs_of()} - set(shared))
    lines += [
        "",
        f"### Summary per configuration ({len(shared)} scenes that every configuration ran"
        + (f"; not {', '.join(left_out)}" if left_out else "")
        + ")",
        "",
        *_summary(results, common),
    ]
    lines += ["", "## Bags: replay against rosbags' bare decode", "", *_decode(results)]
    if results.runs_of(kind="excerpt"):
        lines += [
            "",
            f"## Excerpt: the first {results.plan['naive_seconds']:g} s of "
            f"{', '.join(results.plan['naive_scenes'])}{_naive_too(results)}",
            "",
            *_runs_table(results.runs_of(kind="excerpt"), EXCERPT_COLUMNS),
        ]
    lines += ["", "## Jam onsets (default configuration)", "", *_onsets(results)]
    if results.told_count:
        lines += [
            "",
            "## Told the jam count (default configuration, runs with jams)",
            "",
            "The same runs with the estimator told the true count at each onset (a maintenance",
            "reset, `benchmark.told_count`): the load error left once the count is right.",
            "",
            *_told(results),
        ]
    lines += [
        "",
        "## Jam count's probabilities (default configuration)",
        "",
        "The estimates per bin of their most likely count's probability, the bin's mean",
        "probability, and how often that count was the true one (metrics.CalibrationBin):",
        "honest probabilities are right about as often as they say.",
        "",
        *_calibration(results),
    ]
    lines += ["", "## Precision loss (default configuration)", "", *_wear(results)]
    if results.envelope:
        lines += [
            "",
            "## Beyond the downhole scenes (default configuration; not scored by the floors)",
            "",
            "The envelope's scenes (`scenes/envelope.py`): one thing of a bundled scene changed.",
            "RMSE in % of the preset's largest paper load; told: the count told at each onset.",
            "",
            *_envelope(results),
        ]
    lines += ["", "## Every full run", "", *_runs_table(results.runs_of(), DETAIL_COLUMNS), ""]
    return "\n".join(lines)


# --- pareto.png -------------------------------------------------------------------------------
#: Marker shapes of the Pareto plot, one per configuration (with a colour of its own).
MARKERS = "osD^v<>phX*"


def configuration_styles(names: Iterable[str]) -> dict[str, tuple[str, str]]:
    """(colour, marker) per configuration name, in CONFIGURATION_NAMES' order and fixed by
    its place there (names it lacks follow, alphabetically): the same in both panels and in
    every run, and different for every configuration, so that points which nearly coincide
    (default and no-skip-standstill do) are told apart in the legend instead of by labels
    printed over each other."""
    wanted = set(names)
    rank = {name: i for i, name in enumerate(CONFIGURATION_NAMES)}
    for name in sorted(wanted - rank.keys()):
        rank[name] = len(rank)
    return {
        name: (f"C{rank[name] % 10}", MARKERS[rank[name] % len(MARKERS)])
        for name in sorted(wanted, key=rank.__getitem__)
    }


#: A panel of the Pareto plot: its title and its points (mean us per sample, RMSE %, config).
Panel = tuple[str, list[tuple[float, float, str]]]


def pareto(results: BenchResults, path: Path) -> None:
    """Mean cost per sample (log x) against load RMSE, one point per configuration: on the
    full runs, and on the naive excerpt (where every configuration ran, naive too if it was
    one of them)."""
    titles = {
        "full": "full runs: scenes every configuration ran",
        "excerpt": f"first {results.plan['naive_seconds']:g} s of "
        f"{len(results.plan['naive_scenes'])} bags{_naive_too(results)}",
    }
    panels = [
        (
            title,
            [
                (pooled_timing(runs).mean_us, pooled_rmse_percent(runs), config)
                for config, runs in by_config.items()
            ],
        )
        for kind, title in titles.items()
        if (by_config := common_runs(results, kind))
    ]
    title = f"Estimator configurations: time against error ({run_label(results.mode)})"
    plot_pareto(panels, title, path)


def plot_pareto(panels: list[Panel], title: str, path: Path) -> None:
    """Draw the panels side by side on log axes, one legend for the configurations."""
    import matplotlib  # only when plotting: the CLI starts without it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.ticker import FuncFormatter, NullFormatter

    if not panels:  # e.g. --scenes wear-prior: no configuration timed on a scene
        figure = plt.figure(figsize=(6.0, 2.0))
        figure.text(0.5, 0.5, f"{title}:\nno configuration ran on a scene", ha="center")
        figure.savefig(path, dpi=100)
        plt.close(figure)
        return
    styles = configuration_styles(name for _, points in panels for _, _, name in points)
    width_in = 4.6 * len(panels) + 1.6  # the legend's column included
    figure, axes = plt.subplots(1, len(panels), figsize=(width_in, 4.5), squeeze=False)
    for axis, (panel_title, points) in zip(axes[0], panels, strict=True):
        axis.set_xscale("log")
        axis.set_yscale("log")
        for x, y, name in points:  # hollow markers: coinciding points show both shapes
            colour, marker = styles[name]
            axis.scatter([x], [y], marker=marker, s=48, facecolors="none", edgecolors=colour)
        for scale, values in (
            (axis.xaxis, [p[0] for p in points]),
            (axis.yaxis, [p[1] for p in points]),
        ):
            # Whole decades around the points: labelled major ticks, no crowded minor labels.
            low, high = math.floor(math.log10(min(values))), math.ceil(math.log10(max(values)))
            scale.set_view_interval(10.0**low, 10.0 ** max(high, low + 1))
            scale.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
            scale.set_minor_formatter(NullFormatter())
        axis.set_title(panel_title, fontsize=9)
        axis.set_xlabel("mean cost per sample [us], one process call per sample")
        axis.grid(True, which="both", alpha=0.3)
    axes[0][0].set_ylabel("load RMSE while moving [% of 55 kN]")
    handles = [
        Line2D([], [], linestyle="", marker=marker, color=colour, fillstyle="none", label=name)
        for name, (colour, marker) in styles.items()
    ]
    figure.legend(handles=handles, loc="center right", fontsize=8, title="configuration")
    figure.suptitle(title)
    figure.tight_layout(rect=(0.0, 0.0, 1.0 - 1.5 / width_in, 1.0))
    figure.savefig(path, dpi=100)
    plt.close(figure)


def write_results(results: BenchResults, out: Path) -> list[Floor]:
    """Write FILES into ``out`` (created if needed); returns the floors."""
    out.mkdir(parents=True, exist_ok=True)
    found = floors(results)
    (out / JSON_FILE).write_text(json.dumps(results_json(results, found), indent=2) + "\n")
    (out / MARKDOWN_FILE).write_text(markdown(results, found))
    pareto(results, out / PARETO_FILE)
    return found
