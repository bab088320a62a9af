"""The estimator benchmark (prsm_health/benchmark.py, benchmark_report.py, bench_command.py).

A tiny plan runs end to end (a recorded 8 s bag with a jam, replayed and decoded; a generated
run; a wear-prior run; an excerpt): the files are written and every number in them is the
one measured. The floors are checked for consistency with their thresholds, never for the
estimator's speed or accuracy (the benchmark reports those, docs/performance.md).
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from prsm_health import bench_command, benchmark, benchmark_report
from prsm_health.benchmark import (
    CONFIGURATION_NAMES,
    CONFIGURATIONS,
    BenchResults,
    BenchScene,
    JamOnset,
    Plan,
    base_params,
    cycle_period_s,
    full_plan,
    one_jam_scenes,
    onset_category,
    quick_plan,
    ripple_change,
    ripple_phasor,
    run_benchmark,
    select,
    skipped_configurations,
    told_count,
    two_jam_scenes,
)
from prsm_health.benchmark_report import (
    FILES,
    RMSE_PERCENT,
    Panel,
    configuration_styles,
    floors,
    markdown,
    pooled_calibration,
    pooled_rmse_percent,
    run_label,
    write_results,
)
from prsm_health.cli import main
from prsm_health.estimation.params import EstimatorParams, ModelParams
from prsm_health.physics.presets import load_preset
from prsm_health.physics.roller_table import roller_values
from prsm_health.scenes.envelope import MODEL_SETTINGS, envelope_scenes
from prsm_health.scenes.recording import record
from prsm_health.scenes.scene import Scene, load_scene, scene_from_mapping
from prsm_health.scenes.simulator import Simulator, simulate
from prsm_health.signals import TruthSamples
from test.estimation.test_estimator import downhole

BY_NAME = {c.name: c for c in CONFIGURATIONS}


@pytest.fixture(scope="module")
def results(tmp_path_factory: pytest.TempPathFactory) -> BenchResults:
    jam = [{"time_s": 2.5, "roller": 3}]
    bag_scene = scene_from_mapping(downhole(name="tiny-bag", duration_s=8.0, jams=jam))
    bag = tmp_path_factory.mktemp("bench") / "tiny-bag"
    record(Simulator(bag_scene), bag)
    generated = scene_from_mapping(downhole(name="tiny-run", duration_s=8.0, seed=10))
    wear = scene_from_mapping(
        downhole(name="tiny-wear", duration_s=4.0, wear={"prior_sigma_ln": 0.5})
    )
    envelope = scene_from_mapping(
        downhole(name="tiny-envelope", description="a jam at 2.5 s", duration_s=6.0, jams=jam)
    )
    plan = Plan(
        mode="test",
        scenes=(
            BenchScene("tiny-bag", "bags", bag_scene, bag=bag),
            BenchScene("tiny-run", "two-jam", generated),
        ),
        configs=(BY_NAME["default"], BY_NAME["radial-on"], BY_NAME["radial-off"]),
        timing_samples=300,
        naive_scenes=("tiny-bag",),
        naive_seconds=3.0,
        repeats=2,
        wear_bag=None,
        wear_prior=(wear,),
        envelope=(envelope,),
    )
    return run_benchmark(plan, progress=lambda _: None)


def test_every_planned_run_is_measured_and_scored(results: BenchResults) -> None:
    assert set(results.skipped_configs) == {"radial-on"}
    full = {(r.scene, r.config) for r in results.runs_of()}
    assert full == {(s, c) for s in ("tiny-bag", "tiny-run") for c in ("default", "radial-off")}
    assert {(r.scene, r.config) for r in results.runs_of(kind="excerpt")} == {
        ("tiny-bag", "default"),
        ("tiny-bag", "radial-off"),
    }
    for run in results.runs:
        assert run.timing.calls == len(run.durations_ns)
        assert run.timing.calls == (300 if run.kind == "full" else run.samples)
        assert 0.0 < run.timing.median_us <= run.timing.p99_us <= run.timing.max_us
        assert run.timing.mean_us == pytest.approx(run.durations_ns.mean() / 1e3)
        assert run.metrics.estimates == run.estimates > 0
        assert run.rmse_percent_largest == pytest.approx(100.0 * run.metrics.load_rmse_n / 55_000.0)
    bag_runs = [r for r in results.runs_of() if r.scene == "tiny-bag"]
    assert all(r.decode_s and r.replay_over_decode for r in bag_runs)
    excerpt = results.runs_of(kind="excerpt")[0]
    assert excerpt.samples == 3000 and excerpt.chunked_s is None


def test_jam_onsets_are_categorised_and_timed(results: BenchResults) -> None:
    onsets = [o for o in results.jam_onsets if o.scene == "tiny-bag"]
    assert [o.config for o in onsets] == ["default", "radial-off"]
    for onset in onsets:
        assert onset.onset_s == pytest.approx(2.5, abs=0.01)
        assert onset.count == 1
        assert onset.category == "steady motion"  # mid-stroke: the stroke starts at 1.0 s
        assert onset.cycle_s is not None and onset.within_cycle == (
            onset.delay_s is not None and onset.delay_s <= onset.cycle_s
        )
        assert onset.ripple_after == pytest.approx(1.0) and onset.ripple_turn_deg is None
    # The evidence is measured once, under the default configuration's model: a jam in steady
    # motion with the wall's radial load has far more than a block's prior odds (18 nats).
    assert onsets[0].evidence_nats == onsets[1].evidence_nats
    assert onsets[0].evidence_nats is not None and onsets[0].evidence_nats > 18.0


def test_runs_with_jams_are_run_again_told_the_count(results: BenchResults, tmp_path: Path) -> None:
    """tiny-bag has a jam, tiny-run none: only tiny-bag runs again told the count, and the
    report has its two floors, its table and its JSON."""
    (told,) = results.told_count
    assert told.scene == "tiny-bag" and told.group == "bags"
    (jam,) = told.metrics.jams
    assert jam.delay_s is not None and jam.delay_s <= 0.1  # told at the onset
    assert told.rmse_percent_largest == pytest.approx(100.0 * told.metrics.load_rmse_n / 55_000.0)
    named = {f.name: f for f in floors(results)}
    rmse = named["load RMSE while moving <= 2 %, told the jam count (beyond the issue)"]
    assert rmse.measured.startswith(f"largest {told.rmse_percent_largest:.2f} % (tiny-bag)")
    assert rmse.passed == (told.rmse_percent_largest <= RMSE_PERCENT)
    nees = named["load NEES consistent, told the jam count (beyond the issue)"]
    assert nees.passed == told.metrics.load_nees_consistent
    write_results(results, tmp_path / "out")
    text = (tmp_path / "out" / "results.md").read_text()
    assert "## Told the jam count" in text
    assert f"| tiny-bag | {results.runs_of(config='default')[0].rmse_percent_largest:.2f} |" in text
    document = json.loads((tmp_path / "out" / "results.json").read_text())
    assert document["told_count"][0]["metrics"]["load_rmse_n"] == told.metrics.load_rmse_n


def test_envelope_runs_are_reported_apart_from_the_floors(
    results: BenchResults, tmp_path: Path
) -> None:
    """The envelope's scene runs in the default configuration and told the count, and is in
    its own table and JSON entry only: no floor, onset, told-count or full-run list has it."""
    (run,) = results.envelope
    assert (run.scene, run.description) == ("tiny-envelope", "a jam at 2.5 s")
    (jam,) = run.metrics.jams
    assert jam.onset_s == pytest.approx(2.5, abs=0.01)
    assert run.told is not None and run.told.jams[0].delay_s is not None
    scored_elsewhere = (
        {r.scene for r in results.runs}
        | {o.scene for o in results.jam_onsets}
        | {t.scene for t in results.told_count}
    )
    assert "tiny-envelope" not in scored_elsewhere
    found = write_results(results, tmp_path / "out")
    assert all("tiny-envelope" not in f.measured for f in found)
    text = (tmp_path / "out" / "results.md").read_text()
    (row,) = table_under(text, "## Beyond the downhole scenes")
    told_rmse = 100.0 * run.told.load_rmse_n / 55_000.0
    assert run.told_rmse_percent_largest == pytest.approx(told_rmse)
    assert row == {
        "scene": "tiny-envelope",
        "what differs": "a jam at 2.5 s",
        "RMSE %": f"{run.rmse_percent_largest:.2f}",
        "max err kN": f"{run.metrics.load_max_error_n / 1e3:.2f}",
        "NEES": f"{run.metrics.load_nees_mean:.2f}",
        "jams found after": "never" if jam.delay_s is None else f"{jam.delay_s:.2f} s",
        "false jams": str(run.metrics.false_jam_declarations),
        "RMSE % told": f"{told_rmse:.2f}",
    }
    document = json.loads((tmp_path / "out" / "results.json").read_text())
    (entry,) = document["envelope"]
    assert entry["metrics"]["load_rmse_n"] == run.metrics.load_rmse_n
    assert entry["told_metrics"]["load_rmse_n"] == run.told.load_rmse_n
    assert entry["told_load_rmse_percent_largest"] == run.told_rmse_percent_largest
    assert document["plan"]["envelope"] == [
        {"name": "tiny-envelope", "description": "a jam at 2.5 s", "seed": 5, "model_settings": {}}
    ]
    assert entry["model_settings"] == {}


def test_an_envelope_scene_named_with_settings_runs_with_them(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """A scene of scenes.envelope.MODEL_SETTINGS runs with its ``model:`` settings over the
    benchmark's parameters, and the JSON says which. Here the jam rate set to 0 (the count
    rises only when told): the jam the default finds at once (the envelope test above) is not
    found, and told the count it is."""
    settings = {"jam_rate_per_h": 0.0}
    monkeypatch.setattr(benchmark, "MODEL_SETTINGS", {"tiny-envelope": settings})
    jam = [{"time_s": 2.5, "roller": 3}]
    scene = scene_from_mapping(downhole(name="tiny-envelope", duration_s=6.0, jams=jam))
    plan = Plan("test", (), (), 300, (), 3.0, 1, None, (), envelope=(scene,))
    results = run_benchmark(plan, progress=lambda _: None)
    (run,) = results.envelope
    assert run.model_settings == settings
    assert [j.delay_s for j in run.metrics.jams] == [None]
    assert run.told is not None and run.told.jams[0].delay_s is not None
    write_results(results, tmp_path)
    document = json.loads((tmp_path / "results.json").read_text())
    assert document["envelope"][0]["model_settings"] == settings
    assert document["plan"]["envelope"][0]["model_settings"] == settings


def test_every_envelope_setting_names_an_envelope_scene_and_a_model_parameter() -> None:
    names = {s.name for s in envelope_scenes()}
    fields = {f.name for f in dataclasses.fields(ModelParams)}
    assert MODEL_SETTINGS and set(MODEL_SETTINGS) <= names
    assert all(set(settings) <= fields for settings in MODEL_SETTINGS.values())


def test_told_the_count_the_load_is_right_where_the_count_is_not_identifiable() -> None:
    """The documented limit (a jam at standstill without radial load: the count stays 0 and
    the load reads about 38 % high) vanishes when the estimator is told the count."""
    document = downhole(
        duration_s=18.0,
        radial_load={"type": "constant", "value_n": 0.0},
        jams=[{"time_s": 13.0, "roller": 2}],  # support steps between 11.8 s and 14.5 s
    )
    scene = scene_from_mapping(document)
    result = simulate(scene)
    params = EstimatorParams(actuator=scene.actuator, model=ModelParams(radial_load_ratio=0.0))
    states = told_count(params, result.motor, result.truth)
    truth = result.truth
    after = [s for s in states if s.stamp_s >= 13.05]
    assert after and all(s.jammed_rollers_most_likely == 1 for s in after)
    later = [s for s in after if 16.0 < s.stamp_s < 18.0]
    true_load = np.interp([s.stamp_s for s in later], truth.stamp_s, truth.axial_load_n)
    ratio = np.array([s.axial_load_n for s in later]) / true_load
    assert 0.95 < float(np.median(ratio)) < 1.05


def test_onsets_whose_ripple_cancels_are_named(results: BenchResults, tmp_path: Path) -> None:
    """A second jam of the roller opposite the first leaves no ripple: the floor and the
    onset table say so (its miss is not a failure the motor current could avoid)."""
    cancelled = JamOnset("two-jam-x", "default", 20.0, 2, "standstill", None, 20.0, 0.0, None)
    more = dataclasses.replace(results, jam_onsets=[*results.jam_onsets, cancelled])
    standstill = next(f for f in floors(more) if f.name.endswith(": standstill"))
    assert standstill.measured == "jam 2: 0/1 (1 with the ripple cancelled)"
    assert standstill.passed is False
    write_results(more, tmp_path / "out")
    text = (tmp_path / "out" / "results.md").read_text()
    assert "| two-jam-x | 20.00 | 2 | standstill | 0 (cancelled) | never | 20.0 | **no** |" in text
    assert "| 1.00 (new) |" in text  # tiny-bag's first jam


def test_files_hold_the_measured_numbers(results: BenchResults, tmp_path: Path) -> None:
    found = write_results(results, tmp_path / "out")
    for name in FILES:
        assert (tmp_path / "out" / name).stat().st_size > 0
    assert (tmp_path / "out" / "pareto.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    document = json.loads((tmp_path / "out" / "results.json").read_text())
    assert len(document["runs"]) == len(results.runs)
    for entry, run in zip(document["runs"], results.runs, strict=True):
        assert entry["per_sample"]["median_us"] == run.timing.median_us
        assert entry["metrics"]["load_rmse_n"] == run.metrics.load_rmse_n
    assert [f["name"] for f in document["floors"]] == [f.name for f in found]
    assert document["wear_prior"][0]["true_factor"] == results.wear_prior[0].true_factor
    text = (tmp_path / "out" / "results.md").read_text()
    for floor in found:
        assert floor.name in text
    assert "tiny-bag" in text and "radial-off" in text
    assert "## Jam count's probabilities (default configuration)" in text
    assert re.search(r"\n\| \[0\.99999, 1\] \| \d+ \| 1 - \d\.\de-\d\d \| \d+\.\d\d \|", text)
    (row,) = [
        line for line in text.splitlines() if line.startswith("| precision loss with the true")
    ]
    cells = re.split(r"(?<!\\)\|", row)[1:-1]  # cells between unescaped pipes
    assert len(cells) == 4  # the requirement's |final error| stays in its cell


def test_titles_say_what_ran(
    results: BenchResults, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The titles name the run as its mode says, and the excerpt's "naive too" only when the
    naive configuration ran on it (the fixture's plan has none)."""
    drawn: list[tuple[list[Panel], str]] = []
    monkeypatch.setattr(
        benchmark_report, "plot_pareto", lambda panels, title, _: drawn.append((panels, title))
    )
    restricted = dataclasses.replace(
        results, mode="full, restricted to scenes bags; configurations default"
    )
    write_results(restricted, tmp_path)
    label = "full run, restricted to scenes bags; configurations default"
    text = (tmp_path / "results.md").read_text()
    assert text.startswith(f"# Estimator benchmark ({label})\n")
    assert "## Excerpt: the first 3 s of tiny-bag\n" in text
    ((panels, title),) = drawn
    assert title == f"Estimator configurations: time against error ({label})"
    assert [panel_title for panel_title, _ in panels][1] == "first 3 s of 1 bags"
    naive = dataclasses.replace(results.runs_of(kind="excerpt")[0], config="naive")
    with_naive = dataclasses.replace(restricted, runs=[*results.runs, naive])
    assert "tiny-bag (naive too)\n" in markdown(with_naive, floors(with_naive))
    assert run_label("quick") == "quick run"
    assert run_label("full, held-out seed 7") == "full run, held-out seed 7"


def test_cli_names_the_restriction_in_the_mode(monkeypatch: pytest.MonkeyPatch) -> None:
    """--scenes and --configs restrict the plan, and its mode (the files' titles) says so."""

    class PlannedError(Exception):
        pass

    def planned(plan: Plan) -> BenchResults:
        raise PlannedError(plan.mode)

    monkeypatch.setattr(bench_command, "run_benchmark", planned)
    with pytest.raises(PlannedError, match=r"^quick, restricted to configurations default$"):
        main(["bench", "--quick", "--configs", "default"])
    with pytest.raises(
        PlannedError, match=r"^full, restricted to scenes bags; configurations default$"
    ):
        main(["bench", "--scenes", "bags", "--configs", "default"])
    with pytest.raises(PlannedError, match=r"^quick$"):
        main(["bench", "--quick"])


def test_floors_follow_their_thresholds(results: BenchResults) -> None:
    """Each floor's verdict is its measured value against its threshold: a run made worse
    than the threshold flips the RMSE floor; missing runs are "not measured"."""
    by_name = {f.name: f for f in floors(results)}
    rmse = next(f for name, f in by_name.items() if name.startswith("load RMSE"))
    default = results.runs_of(config="default")
    worst = max(r.rmse_percent_largest for r in default)
    assert rmse.passed == (worst <= RMSE_PERCENT)
    bad = dataclasses.replace(
        default[0],
        metrics=dataclasses.replace(default[0].metrics, load_rmse_n=0.03 * 55_000.0),
    )
    worse = dataclasses.replace(results, runs=[bad, *results.runs[1:]])
    assert next(f for f in floors(worse) if f.name == rmse.name).passed is False
    hour = next(f for name, f in by_name.items() if "one hour" in name)
    naive = next(f for name, f in by_name.items() if "faster per sample than naive" in name)
    assert hour.passed is None and naive.passed is None
    pooled = pooled_calibration(default)
    assert [b.estimates for b in pooled] == [
        sum(r.metrics.jam_calibration[i].estimates for r in default) for i in range(len(pooled))
    ]
    assert sum(b.estimates for b in pooled) == sum(r.metrics.estimates for r in default)
    assert sum(b.correct for b in pooled) <= sum(b.estimates for b in pooled)
    assert pooled_rmse_percent(default) == pytest.approx(
        math.sqrt(
            sum(r.metrics.moving_estimates * r.rmse_percent_largest**2 for r in default)
            / sum(r.metrics.moving_estimates for r in default)
        )
    )


def _truth(speed: list[float], load: list[float]) -> TruthSamples:
    n = len(speed)
    return TruthSamples(
        stamp_s=0.1 * np.arange(n),
        axial_load_n=np.asarray(load, dtype=np.float64),
        radial_load_n=np.zeros(n),
        loading_case=np.ones(n, dtype=np.int64),
        roller_jammed=np.zeros((n, 10), dtype=bool),
        precision_loss_m=np.zeros(n),
        friction_torque_nm=np.zeros(n),
        fatigue_damage=np.zeros(n),
        screw_speed_rad_s=np.asarray(speed, dtype=np.float64),
        carrier_angle_rad=np.zeros(n),
        wear_coefficient_factor=np.ones(n),
    )


def test_onset_categories_from_the_truth() -> None:
    """Two strokes: loads ramp up and down; the categories follow speed and load."""
    speed = [0, 0, 30, 30, 30, 30, 30, 0, 0, -30, -30, -30, 0]
    load = [0, 0, 2e3, 2e4, 4e4, 4e4, 5e3, 0, 0, -3e4, -3e4, -1e4, 0]
    truth = _truth(speed, load)
    expected = {  # truth sample of the onset: category
        1: "standstill",
        2: "stroke end/low load",  # 2 kN of a 40 kN stroke
        3: "steady motion",  # half of it
        4: "steady motion",
        6: "stroke end/low load",
        8: "standstill",
        9: "steady motion",
        11: "stroke end/low load",  # 10 kN of a 30 kN stroke
    }
    for index, category in expected.items():
        assert onset_category(truth, float(truth.stamp_s[index]), 1.0) == category, index


@pytest.mark.parametrize("rollers", [(0,), (0, 1), (0, 3), (2, 6), (0, 5), (2, 6, 7)])
def test_ripple_phasor_is_the_physics_core_carrier_harmonic(rollers: tuple[int, ...]) -> None:
    """The first carrier harmonic of the jammed rollers' sliding torque from the physics core
    (000 eq. 8 with 002 eq. 15-16, 30 kN axial, 4 kN radial, 72 carrier angles) is one
    roller's harmonic times ripple_phasor: in size and in phase; opposite rollers cancel."""
    angles = np.linspace(0.0, 2.0 * np.pi, 72, endpoint=False)
    values = roller_values(
        load_preset("dong2022-downhole"), 30e3, radial_load_n=4e3, carrier_angle_rad=angles
    )
    jammed = np.zeros(values.jammed_torque_nm.shape[-1], dtype=bool)
    jammed[list(rollers)] = True
    harmonic = np.exp(-1j * angles) @ values.jammed_torque_nm
    one_roller = harmonic[0]
    assert abs(one_roller) > 1.0  # N m, summed over the angles: a real ripple to compare with
    expected = one_roller * ripple_phasor(jammed)
    assert abs(harmonic[jammed].sum() - expected) < 1e-3 * abs(one_roller)


def test_ripple_change_of_a_second_roller() -> None:
    """m positions away: the ripple scales by 2 |cos(pi m / N)| and turns by pi m / N; a
    first jam and a cancelled ripple have no phase to turn."""
    first = np.zeros(10, dtype=bool)
    first[2] = True
    assert ripple_change(0j, ripple_phasor(first)) == (pytest.approx(1.0), None)
    for m in range(1, 10):
        both = first.copy()
        both[(2 + m) % 10] = True
        size, turn = ripple_change(ripple_phasor(first), ripple_phasor(both))
        assert size == pytest.approx(2.0 * abs(math.cos(math.pi * m / 10)), abs=1e-12)
        if m == 5:
            assert turn is None
        else:
            assert turn == pytest.approx(math.degrees(math.pi * min(m, 10 - m) / 10))


def test_two_jam_runs_are_reproducible_and_leave_a_cycle_after_each_jam() -> None:
    scenes = two_jam_scenes(4)
    assert [s.name for s in scenes] == [s.name for s in two_jam_scenes(4)]
    assert [s.jams for s in scenes] == [s.jams for s in two_jam_scenes(4)]
    for scene in scenes:
        assert 40.0 <= scene.duration_s <= 60.0
        first, second = scene.jams
        assert second.time_s - first.time_s >= 2.0
        assert second.time_s <= scene.duration_s - 25.0
        assert first.roller != second.roller


def test_two_jam_runs_on_another_screw_are_the_same_runs_with_its_screw() -> None:
    for run, other in zip(
        two_jam_scenes(3), two_jam_scenes(3, preset="meng2022-misalignment"), strict=True
    ):
        assert other.name == f"{run.name}-meng2022-misalignment"
        assert other.actuator.preset.name == "meng2022-misalignment"
        assert other.actuator.drive_train == run.actuator.drive_train
        kept = {f.name for f in dataclasses.fields(run)} - {
            "name",
            "description",
            "actuator",
            "actuator_yaml",
        }
        assert all(getattr(other, k) == getattr(run, k) for k in kept)


def test_one_jam_runs_are_reproducible_with_one_jam_in_their_first_minute() -> None:
    scenes = one_jam_scenes(4, 300.0)
    assert [s.jams for s in scenes] == [s.jams for s in one_jam_scenes(4, 300.0)]
    assert len({s.seed for s in scenes}) == 4
    for scene in scenes:
        (jam,) = scene.jams
        assert scene.duration_s == 300.0 and 5.0 <= jam.time_s <= 60.0


def test_false_jams_are_summed_over_the_runs_of_the_floor(results: BenchResults) -> None:
    """The one-jam floor adds up the runs' false declarations; one false run fails it."""
    default = [r for r in results.runs_of(config="default") if r.group == "two-jam"]
    runs = [dataclasses.replace(r, group="one-jam") for r in default]
    clean = dataclasses.replace(results, runs=runs)
    name = "no false second jam after a jam (beyond the issue)"
    assert next(f for f in floors(clean) if f.name == name).passed == all(
        r.metrics.false_jam_declarations == 0 for r in runs
    )
    false = dataclasses.replace(
        runs[0], metrics=dataclasses.replace(runs[0].metrics, false_jam_declarations=2)
    )
    failed = next(f for f in floors(dataclasses.replace(clean, runs=[false])) if f.name == name)
    assert failed.passed is False and failed.measured.startswith("2 (")


def test_cycle_period_of_sudden_jam_is_its_documented_cycle() -> None:
    """bags/README.md: sudden-jam runs at 350 rpm, a cycle of 20.8 s."""
    period = cycle_period_s(load_scene("sudden-jam"))
    assert period == pytest.approx(20.8, abs=0.05)
    assert cycle_period_s(load_scene("stationary-hold")) is None


def test_radial_on_is_skipped_where_auto_resolves_to_it() -> None:
    assert set(skipped_configurations(CONFIGURATIONS)) == {"radial-on"}


def test_selection_by_name_and_group_and_unknown_names() -> None:
    plan = quick_plan()
    chosen = select(plan, scenes=["two-jam"], configs=["default"])
    assert [s.name for s in chosen.scenes] == ["two-jam-1"]
    assert [c.name for c in chosen.configs] == ["default"]
    assert chosen.wear_bag is None and chosen.wear_prior == () and chosen.envelope == ()
    full = full_plan()
    envelope = select(full, scenes=["envelope"], configs=None)
    assert envelope.scenes == () and envelope.envelope == full.envelope
    names = [s.name for s in full.envelope]
    assert "sine-jam" in names and "two-jam-8-meng2022-misalignment" in names
    one = select(full, scenes=["sine-jam", "two-jam-3"], configs=None)
    assert [s.name for s in one.envelope] == ["sine-jam"]
    assert [s.name for s in one.scenes] == ["two-jam-3"]
    with pytest.raises(ValueError, match="unknown nope"):
        select(plan, scenes=["nope"], configs=None)
    with pytest.raises(ValueError, match="unknown fast"):
        select(plan, scenes=None, configs=["fast"])


def test_held_out_plan_draws_its_generated_runs_from_other_seeds() -> None:
    default, held_out = full_plan(), full_plan(held_out=7777)
    assert held_out.mode == "full, held-out seed 7777"

    def generated(plan: Plan) -> list[Scene]:
        return [s.scene for s in plan.scenes if s.bag is None] + list(plan.wear_prior)

    assert [s.name for s in generated(held_out)] == [s.name for s in generated(default)]
    assert not {s.seed for s in generated(held_out)} & {s.seed for s in generated(default)}
    two_jam = [
        [s.scene.jams for s in p.scenes if s.group == "two-jam"] for p in (default, held_out)
    ]
    assert two_jam[0] != two_jam[1]
    assert [s.bag for s in held_out.scenes if s.bag] == [s.bag for s in default.scenes if s.bag]
    with pytest.raises(ValueError, match=r"two-jam runs \(seeds 2020-2035\) meet the default"):
        full_plan(held_out=2020)
    with pytest.raises(ValueError, match=r"wear-prior runs \(seeds 310-329\) meet the default"):
        full_plan(held_out=110)


def test_cli_refuses_a_held_out_seed_with_the_quick_plan_or_one_that_meets_the_plan(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["bench", "--quick", "--held-out", "7777"]) == 2
    assert "only with the full plan" in capsys.readouterr().err
    assert main(["bench", "--held-out", "2030", "--out", "unused"]) == 2
    assert "meet the default plan's two-jam runs" in capsys.readouterr().err


def test_cli_refuses_unknown_configurations(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "--quick", "--configs", "fast"]) == 2
    assert "unknown fast" in capsys.readouterr().err


def test_a_plan_runs_with_the_parameters_of_its_file(tmp_path: Path) -> None:
    """--params: every run starts from the file's parameters (the scene's actuator kept). The
    wear factor only scales the integrated precision loss, so a file with twice the bundled
    factor doubles it and changes nothing else."""
    scene = scene_from_mapping(downhole(name="tiny-params", duration_s=4.0))
    plan = Plan(
        mode="test",
        scenes=(BenchScene("tiny-params", "two-jam", scene),),
        configs=(BY_NAME["default"],),
        timing_samples=100,
        naive_scenes=(),
        naive_seconds=0.0,
        repeats=1,
        wear_bag=None,
        wear_prior=(),
    )
    params_file = tmp_path / "params.yaml"
    params_file.write_text(
        "actuator: {preset: li2020-jamming}\nmodel: {wear_coefficient_factor: 2.0}\n"
    )
    bundled, doubled = (
        run_benchmark(dataclasses.replace(plan, params_file=path), progress=lambda _: None)
        for path in (None, params_file)
    )
    assert bundled.plan["params_file"].endswith("default.yaml")
    assert doubled.plan["params_file"] == str(params_file)
    (before,), (after,) = bundled.runs_of(), doubled.runs_of()
    assert after.metrics.load_rmse_n == before.metrics.load_rmse_n  # dong2022-downhole both
    assert after.metrics.precision_loss_final_m == pytest.approx(
        2.0 * before.metrics.precision_loss_final_m, rel=1e-9
    )


def test_cli_names_an_invalid_parameter_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("actuator: {preset: dong2022-downhole}\nmodel: {jam_rate_per_h: -1}\n")
    assert main(["bench", "--params", str(bad), "--scenes", "two-jam-1", "--out", "unused"]) == 2
    error = capsys.readouterr().err
    assert f"--params: {bad}: model.jam_rate_per_h" in error and error.count(str(bad)) == 1
    assert not Path("unused").exists()
    # A file of settings only, as replay takes it (it was refused: 'actuator: missing'), and
    # its bad key named rather than the missing actuator.
    settings = tmp_path / "settings.yaml"
    settings.write_text("model: {jam_rate_per_h: 0.01}\n")
    assert base_params(settings).model.jam_rate_per_h == 0.01
    settings.write_text("filter: {gate_nys: 3}\n")
    assert main(["bench", "--params", str(settings), "--scenes", "two-jam-1"]) == 2
    assert f"--params: {settings}: filter.gate_nys: unknown key" in capsys.readouterr().err


def test_cli_refuses_an_out_it_cannot_write_before_the_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--out names a file: refused at once (it failed with a traceback after the whole run,
    its results lost; found by a review session)."""
    a_file = tmp_path / "results"
    a_file.write_text("mine")
    assert main(["bench", "--quick", "--out", str(a_file)]) == 2
    captured = capsys.readouterr()
    assert f"--out: cannot make the folder {a_file}" in captured.err
    assert "bench:" not in captured.err, "nothing ran"
    assert a_file.read_text() == "mine"


def test_every_configuration_has_its_own_pareto_style() -> None:
    """Points that nearly coincide (default and no-skip-standstill) are told apart by colour
    and marker in the legend, so no two configurations may share both."""
    styles = configuration_styles([*reversed(CONFIGURATION_NAMES), "default", "extra"])
    assert list(styles) == [*CONFIGURATION_NAMES, "extra"]
    assert len(set(styles.values())) == len(styles)
    assert configuration_styles(["ukf", "default"])["ukf"] == styles["ukf"]


def test_a_plan_without_scene_runs_still_draws_its_pareto(tmp_path: Path) -> None:
    """``bench --scenes wear-prior`` ran its 20 runs and then failed on the plot ("Number of
    columns must be a positive integer, not 0") with no results written."""
    path = tmp_path / "pareto.png"
    benchmark_report.plot_pareto([], "Estimator configurations", path)
    assert path.stat().st_size > 0


def table_under(text: str, heading: str) -> list[dict[str, str]]:
    """The rows, by column, of the first Markdown table after the line starting with
    ``heading``."""
    after = text.split("\n" + heading, 1)[1].split("\n\n")[1:]
    lines = next(p for p in after if p.startswith("|")).splitlines()
    cells = [[c.strip() for c in re.split(r"(?<!\\)\|", line)[1:-1]] for line in lines]
    header, _, *rows = cells
    return [dict(zip(header, row, strict=True)) for row in rows]


def test_the_tables_give_each_number_in_its_columns_unit(results: BenchResults) -> None:
    """Pins the units of results.md: every run an hour at 1 kHz with a largest load error of
    2.5 kN reads 3,600,000 samples and 2.50 kN per run, 3.6 M samples per scene and 2.5 kN
    per configuration, and the false-jam floor counts its hours. A mutation review found
    these unguarded (kN as N / 100, M samples as thousands, hours as minutes passed)."""
    hour = 3_600_000
    runs = [
        dataclasses.replace(
            r,
            group="one-jam",
            samples=hour,
            metrics=dataclasses.replace(r.metrics, load_max_error_n=2_500.0),
        )
        for r in results.runs
    ]
    timed = dataclasses.replace(results, runs=runs)
    text = markdown(timed, floors(timed))
    every_run = table_under(text, "## Every full run")
    assert len(every_run) == len(timed.runs_of())
    for row in every_run:
        assert (row["samples"], row["max err kN"]) == ("3,600,000", "2.50"), row
    summary = table_under(text, "### Summary per configuration")
    assert len(summary) == len({r.config for r in timed.runs_of()})
    for row in summary:
        assert row["samples"] == f"{3.6 * int(row['scenes']):.2f} M", row
        assert row["max err kN"] == "2.5", row
    default = len(timed.runs_of(config="default"))
    (floor,) = [f for f in floors(timed) if f.name.startswith("no false second jam")]
    assert f" over {default:.2f} h in {default} runs" in floor.measured
