"""Estimator parameters: defaults, YAML loading, and errors that name the bad key."""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import numpy as np
import pytest

from prsm_health.actuator import DRIVE_TRAIN_RANGES, WEAR_ACCELERATION_RANGE
from prsm_health.estimation.estimator import HealthEstimator
from prsm_health.estimation.params import load_params, params_from_mapping
from prsm_health.physics.errors import ParameterError
from prsm_health.physics.geometry import Misalignment
from prsm_health.physics.meshing import meshing, smallest_misaligned_clearance
from prsm_health.physics.presets import load_preset
from prsm_health.signals import MotorSamples


def test_minimal_document_takes_the_defaults() -> None:
    params = params_from_mapping({"actuator": {"preset": "dong2022-downhole"}})
    assert params.rated_load_n == 55_000.0
    assert params.radial_terms  # the downhole robot's wall contact is expected by default
    assert params.max_motor_speed_rad_s > 0.0


def test_no_radial_load_and_aligned_drops_the_ripple_states() -> None:
    params = params_from_mapping(
        {"actuator": {"preset": "dong2022-downhole"}, "model": {"radial_load_ratio": 0.0}}
    )
    assert not params.radial_terms
    misaligned = params_from_mapping(
        {
            "actuator": {"preset": "meng2022-misalignment", "misalignment_arcmin": [1.0, 0.0]},
            "model": {"radial_load_ratio": 0.0},
        }
    )
    assert misaligned.radial_terms


@pytest.mark.parametrize(
    ("document", "field"),
    [
        ({}, "actuator"),
        ({"actuator": {"preset": "dong2022-downhole"}, "filtre": {}}, "filtre"),
        ({"actuator": {"preset": "dong2022-downhole"}, "filter": {"block_s": 1}}, "filter.block_s"),
        (
            {"actuator": {"preset": "dong2022-downhole"}, "filter": {"block_duration_s": -1}},
            "filter.block_duration_s",
        ),
        (
            {"actuator": {"preset": "dong2022-downhole"}, "noise": {"current_std_a": "high"}},
            "noise.current_std_a",
        ),
        (
            {"actuator": {"preset": "dong2022-downhole"}, "fidelity": {"filter": "pf"}},
            "fidelity.filter",
        ),
        (
            {"actuator": {"preset": "dong2022-downhole", "drive_train": {"gear_ratio": 0}}},
            "drive_train.gear_ratio",
        ),
        (
            {"actuator": {"preset": "dong2022-downhole"}, "model": {"initial_jammed_rollers": 11}},
            "model.initial_jammed_rollers",
        ),
        (
            {"actuator": {"preset": "dong2022-downhole"}, "filter": {"components_per_count": 1.5}},
            "filter.components_per_count",
        ),
        (
            {"actuator": {"preset": "dong2022-downhole"}, "filter": {"components_per_count": 0}},
            "filter.components_per_count",
        ),
        (
            {
                "actuator": {"preset": "dong2022-downhole"},
                "filter": {"min_established_probability": 0.5},
            },
            "filter.min_established_probability",
        ),
        (
            {
                "actuator": {"preset": "dong2022-downhole"},
                "diagnostics": {"load_warn_fraction": 2.0, "load_error_fraction": 1.0},
            },
            "diagnostics.load_warn_fraction",
        ),
        # Repeated stamps would be a new time line after TIME_RESET_SAMPLES of them.
        (
            {"actuator": {"preset": "dong2022-downhole"}, "filter": {"time_reset_after_s": 0}},
            "filter.time_reset_after_s",
        ),
        # A block's wear would be cut to the gap limit.
        (
            {"actuator": {"preset": "dong2022-downhole"}, "filter": {"max_gap_s": 0.01}},
            "filter.max_gap_s",
        ),
        # Ten blocks never fit: the divergence test would never run.
        (
            {"actuator": {"preset": "dong2022-downhole"}, "filter": {"divergence_window_s": 0.2}},
            "filter.divergence_window_s",
        ),
        # kN for N: every block beyond ten times 55 N would be "diverged".
        (
            {"actuator": {"preset": "dong2022-downhole"}, "diagnostics": {"rated_load_n": 55}},
            "diagnostics.rated_load_n",
        ),
    ],
)
def test_invalid_documents_name_the_field(document: dict[str, object], field: str) -> None:
    with pytest.raises(ParameterError, match=field.replace(".", r"\.")):
        params_from_mapping(document)


@pytest.mark.parametrize(
    ("warn", "error", "low", "high"),
    [
        ("load_warn_fraction", "load_error_fraction", 2.0, 1.0),
        ("precision_loss_warn_fraction", "precision_loss_error_fraction", 1.5, 1.0),
        ("fatigue_warn_damage", "fatigue_error_damage", 0.95, 0.5),
    ],
)
def test_a_warn_threshold_above_its_error_threshold_is_refused(
    warn: str, error: str, low: float, high: float
) -> None:
    """Pins each diagnostics warn/error pair's order check (warn at or below error; equal is
    accepted): a warn level above the error level is refused naming the warn key. A mutation
    review found the fatigue pair unguarded (its check dropped, warn 0.95 with error 0.5 was
    accepted)."""
    actuator = {"preset": "dong2022-downhole"}
    with pytest.raises(
        ParameterError, match=rf"^diagnostics\.{warn}: must not exceed diagnostics\.{error}$"
    ):
        params_from_mapping({"actuator": actuator, "diagnostics": {warn: low, error: high}})
    equal = params_from_mapping({"actuator": actuator, "diagnostics": {warn: high, error: high}})
    assert getattr(equal.diagnostics, warn) == getattr(equal.diagnostics, error) == high


def test_parameters_at_their_cross_checked_limits_are_accepted() -> None:
    params = params_from_mapping(
        {
            "actuator": {"preset": "dong2022-downhole"},
            "filter": {"block_duration_s": 0.05, "max_gap_s": 0.05, "divergence_window_s": 0.5},
            "diagnostics": {"rated_load_n": 5500.0},
        }
    )
    assert params.rated_load_n == 5500.0


def test_load_params_reads_yaml_and_names_an_unreadable_file(tmp_path: Path) -> None:
    path = tmp_path / "params.yaml"
    path.write_text("actuator:\n  preset: li2020-jamming\nfilter:\n  block_duration_s: 2e-2\n")
    assert load_params(path).filter.block_duration_s == pytest.approx(0.02)
    with pytest.raises(ParameterError, match=r"missing\.yaml"):
        load_params(tmp_path / "missing.yaml")
    path.write_text("actuator: {preset: li2020-jamming}\nfilter: {block_duration_s: -1}\n")
    with pytest.raises(ParameterError, match=rf"^{path}: filter\.block_duration_s: must be"):
        load_params(path)


def _documented_value(text: str) -> object:
    """A default as docs/estimation.md writes it: true/false, a number, or a bare word."""
    if text in ("true", "false"):
        return text == "true"
    try:
        return float(text)
    except ValueError:
        return text


def test_docs_list_every_parameter_with_its_default() -> None:
    """docs/estimation.md "Every parameter": one row per key of every section, its default."""
    docs = Path(__file__).resolve().parents[2] / "docs" / "estimation.md"
    section = docs.read_text(encoding="utf-8").split("## Every parameter", 1)[1]
    rows = dict(re.findall(r"^\| `(\w+\.\w+)` \| ([^|]+?) \|", section, flags=re.MULTILINE))
    params = params_from_mapping({"actuator": {"preset": "dong2022-downhole"}})
    expected = {
        f"{f.name}.{key.name}": getattr(getattr(params, f.name), key.name)
        for f in dataclasses.fields(params)
        if f.name != "actuator"
        for key in dataclasses.fields(getattr(params, f.name))
    }
    assert sorted(rows) == sorted(expected)
    for key, default in expected.items():
        assert _documented_value(rows[key]) == default, key


DOWNHOLE = {"preset": "dong2022-downhole"}
#: An integer no float can hold: YAML reads 400 digits as an int.
HUGE = 10**400


@pytest.mark.parametrize(
    ("document", "field"),
    [
        ({"noise": {"current_std_a": HUGE}}, "noise.current_std_a"),
        ({"model": {"wear_coefficient_factor": -HUGE}}, "model.wear_coefficient_factor"),
        ({"fidelity": {"standstill_block_s": HUGE}}, "fidelity.standstill_block_s"),
        ({"diagnostics": {"rated_load_n": HUGE}}, "diagnostics.rated_load_n"),
        ({"actuator": DOWNHOLE | {"wear_acceleration": HUGE}}, "actuator.wear_acceleration"),
        (
            {"actuator": DOWNHOLE | {"drive_train": {"gear_ratio": HUGE}}},
            "actuator.drive_train.gear_ratio",
        ),
        (
            {"actuator": DOWNHOLE | {"misalignment_arcmin": [HUGE, 0]}},
            "actuator.misalignment_arcmin[0]",
        ),
    ],
)
def test_an_integer_too_large_for_a_float_is_refused_naming_the_key(
    document: dict[str, object], field: str
) -> None:
    """Was an OverflowError ("int too large to convert to float") with a traceback."""
    document = {"actuator": DOWNHOLE} | document
    with pytest.raises(ParameterError, match=rf"^{re.escape(field)}: must be a finite number"):
        params_from_mapping(document)


@pytest.mark.parametrize(
    "tilt",
    [[None, 0], [[1], 0], ["abc", 0], [True, 0], [0, False], [math.nan, 0], [0, math.inf]],
)
def test_misalignment_elements_must_be_finite_numbers(tilt: list[object]) -> None:
    """[null, 0] and [[1], 0] were TypeErrors, [abc, 0] did not name the key, [true, 0] was
    taken as one arc minute."""
    document = {"actuator": DOWNHOLE | {"misalignment_arcmin": tilt}}
    with pytest.raises(ParameterError, match=r"^actuator\.misalignment_arcmin\[[01]\]: must be a"):
        params_from_mapping(document)


def test_a_misalignment_beyond_the_small_angle_limit_names_the_key_in_arc_minutes() -> None:
    document = {"actuator": DOWNHOLE | {"misalignment_arcmin": [90, 0]}}
    with pytest.raises(ParameterError, match=r"^actuator\.misalignment_arcmin: \[90, 0\] arc"):
        params_from_mapping(document)


def test_a_misalignment_that_closes_the_flanks_is_a_bad_parameter() -> None:
    """3 arc minutes on paper 004's screw: accepted, then a DomainError when the estimator
    was built (found by a review session). 1 arc minute stays fine."""
    tilted = {"preset": "meng2022-misalignment", "misalignment_arcmin": [3.0, 0.0]}
    with pytest.raises(
        ParameterError,
        match=r"^actuator\.misalignment_arcmin: \[3\.0, 0\.0\] arc minutes is more than "
        r"meng2022-misalignment's clearances allow: .* the flanks would overlap",
    ):
        params_from_mapping({"actuator": tilted})
    tilted["misalignment_arcmin"] = [1.0, 0.0]
    HealthEstimator(params_from_mapping({"actuator": tilted}))


def test_a_misalignment_just_past_the_clearance_is_refused_at_any_carrier_angle() -> None:
    """The check sampled 64 carrier angles per roller spacing, so a tilt up to about 1e-5 of
    itself past the limit passed where the worst angle fell between two samples, and then
    closed the flanks (a DomainError) where the simulator's carrier reached that angle. Here
    the tilt's direction puts the worst angle half a sample step from the old grid; a
    millionth past the limit is refused, a millionth short is accepted and meshes at its
    worst angle."""
    preset = load_preset("meng2022-misalignment")
    geometry = preset.geometry
    one_arcmin = Misalignment.from_arcmin(1.0, 0.0)
    aligned, _, _ = smallest_misaligned_clearance(geometry, Misalignment())
    tilted, _, worst_angle = smallest_misaligned_clearance(geometry, one_arcmin)
    limit_arcmin = aligned / (aligned - tilted)  # the clearance falls linearly with the tilt
    half_step = math.pi / geometry.n_rollers / 64
    direction = half_step - worst_angle % (2.0 * half_step)  # turns the worst angle with it
    for scale, refused in ((1.0 + 1e-6, True), (1.0 - 1e-6, False)):
        tilt = limit_arcmin * scale * np.array([math.cos(direction), math.sin(direction)])
        document = {
            "actuator": {"preset": preset.name, "misalignment_arcmin": [float(t) for t in tilt]}
        }
        if refused:
            with pytest.raises(ParameterError, match=r"thread \d+ to -0\.000 um .* would overlap"):
                params_from_mapping(document)
            continue
        params = params_from_mapping(document)
        clearance, _, angle = smallest_misaligned_clearance(geometry, params.actuator.misalignment)
        assert angle % (2.0 * half_step) == pytest.approx(half_step, abs=1e-6)
        assert 0.0 <= clearance < 1e-10
        meshing(geometry, params.actuator.misalignment, carrier_angle_rad=angle)


@pytest.mark.parametrize(
    ("section", "key"), [("model", "initial_jammed_rollers"), ("filter", "components_per_count")]
)
def test_integer_parameters_refuse_bools(section: str, key: str) -> None:
    """initial_jammed_rollers: true was accepted as 1, and numpy took it as a mask: every jam
    count equally likely."""
    with pytest.raises(ParameterError, match=rf"^{section}\.{key}: must be an integer"):
        params_from_mapping({"actuator": DOWNHOLE, section: {key: True}})


def test_radial_terms_on_and_off_read_as_written(tmp_path: Path) -> None:
    """YAML 1.1 read on/off as booleans, so the listed values were refused as True/False."""
    path = tmp_path / "params.yaml"
    for word in ("on", "off", "auto"):
        path.write_text(
            f"actuator: {{preset: dong2022-downhole}}\nfidelity: {{radial_terms: {word}}}\n"
        )
        assert load_params(path).fidelity.radial_terms == word
    path.write_text("actuator: {preset: dong2022-downhole}\nfidelity: {surrogate: no}\n")
    with pytest.raises(
        ParameterError, match=r"fidelity\.surrogate: must be true or false, got 'no'"
    ):
        load_params(path)
    path.write_text("actuator: {preset: dong2022-downhole}\nfidelity: {surrogate: False}\n")
    assert load_params(path).fidelity.surrogate is False


def test_a_params_file_that_is_not_utf8_is_named(tmp_path: Path) -> None:
    path = tmp_path / "latin1.yaml"
    path.write_bytes(b"# ok\nactuator: {preset: dong\xe9}\n")
    with pytest.raises(ParameterError, match=r"latin1\.yaml, line 2: not UTF-8 text \(byte 0xe9\)"):
        load_params(path)


def test_a_section_given_twice_is_refused_naming_file_key_and_line(tmp_path: Path) -> None:
    """The second noise section silently replaced the first."""
    path = tmp_path / "twice.yaml"
    path.write_text(
        "actuator: {preset: dong2022-downhole}\n"
        "noise: {current_std_a: 0.05}\n"
        "noise: {current_std_a: 99}\n"
    )
    with pytest.raises(
        ParameterError,
        match=r"twice\.yaml, line 3, column 1: duplicate key 'noise' \(first on line 2\)",
    ):
        load_params(path)


# --- the drive train's ranges (adversarial fuzz, 2026-11) ------------------------------------
#: Values that were accepted (finite and > 0), then overflowed the estimator's arithmetic.
OVERFLOWED = [
    ("drive_train.motor_inertia_kg_m2", 1e200),
    ("drive_train.gear_efficiency", 1e-300),
    ("drive_train.torque_constant_nm_per_a", 1e300),
    ("drive_train.gear_ratio", 1e300),
    ("wear_acceleration", 1e200),
]
RANGES = [(f"drive_train.{key}", limits) for key, limits in DRIVE_TRAIN_RANGES.items()]
RANGES.append(("wear_acceleration", WEAR_ACCELERATION_RANGE))


def _actuator_with(key: str, value: float) -> dict[str, object]:
    """The parameter document with ``actuator.<key>`` (``drive_train.x`` for a drive-train
    field) set to ``value``."""
    actuator: dict[str, object] = dict(DOWNHOLE)
    if key.startswith("drive_train."):
        actuator["drive_train"] = {key.split(".", 1)[1]: value}
    else:
        actuator[key] = value
    return {"actuator": actuator}


@pytest.mark.parametrize(
    ("key", "value"),
    OVERFLOWED
    + [(key, low * (1.0 - 1e-9)) for key, (low, _) in RANGES]
    + [(key, high * (1.0 + 1e-9)) for key, (_, high) in RANGES],
)
def test_drive_train_values_beyond_their_range_are_refused_naming_the_key(
    key: str, value: float
) -> None:
    with pytest.raises(ParameterError, match=rf"^actuator\.{re.escape(key)}: must be in \["):
        params_from_mapping(_actuator_with(key, value))


@pytest.mark.parametrize(("key", "limits"), RANGES)
def test_drive_trains_at_the_edges_of_their_ranges_give_finite_estimates(
    key: str, limits: tuple[float, float]
) -> None:
    """Each parameter at either end of its range, the others at their defaults: samples the
    drive can deliver (half its current limit, a tenth of the largest speed) are estimated,
    nothing raises and no estimate is non-finite."""
    n = 400
    t = 1.0 + np.arange(n) * 1e-3
    noise = np.random.default_rng(0).normal(0.0, 1e-3, n)
    for value in limits:
        params = params_from_mapping(_actuator_with(key, value))
        current = 0.5 * params.actuator.drive_train.max_current_a * (1.0 + noise)
        speed = np.full(n, 0.1 * params.max_motor_speed_rad_s)
        estimator = HealthEstimator(params)
        states = estimator.process(MotorSamples(t, current, speed, speed * t)) + estimator.finish()
        assert states, (key, value)
        for state in states:
            numbers = [v for v in dataclasses.astuple(state) if isinstance(v, float)]
            assert all(math.isfinite(v) for v in numbers), (key, value, state)


def test_a_relative_preset_path_is_taken_from_the_params_files_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """As in a scene file: not from the working directory (the node's is wherever it was
    launched)."""
    bundled = Path(__file__).resolve().parents[2] / "prsm_health/physics/presets"
    (tmp_path / "robot" / "presets").mkdir(parents=True)
    text = (bundled / "dong2022-downhole.yaml").read_text()
    preset = tmp_path / "robot" / "presets" / "mine.yaml"
    preset.write_text(text.replace("name: dong2022-downhole", "name: mine"))
    (tmp_path / "robot" / "params.yaml").write_text("actuator: {preset: presets/mine.yaml}\n")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    assert load_params(Path("../robot/params.yaml")).actuator.preset.name == "mine"
    preset.unlink()
    with pytest.raises(ParameterError, match=re.escape(f"no such preset file '{preset.parent}")):
        load_params(tmp_path / "robot" / "params.yaml")


def test_every_bad_section_is_named_at_once() -> None:
    """Only the first bad section was named: one edit per run to find the next."""
    document = {
        "actuator": {"preset": "dong2022-downhole", "wear_acceleration": -1.0},
        "filter": {"gate_nis": -1.0},
        "noise": {"model_error_rel": -2.0},
    }
    with pytest.raises(ParameterError) as info:
        params_from_mapping(document)
    assert info.value.field == "actuator.wear_acceleration"
    for named in ("actuator.wear_acceleration", "filter.gate_nis", "noise.model_error_rel"):
        assert str(info.value).count(named) == 1


def test_every_bad_value_and_unknown_key_of_a_section_is_named_at_once() -> None:
    """Within a section only the first value out of range (or the first unknown key) was
    named: three typos in one section took three runs to find."""
    values = {"filter": {"gate_nis": -1.0, "max_gap_s": 0.0, "block_duration_s": "fast"}}
    with pytest.raises(ParameterError) as info:
        params_from_mapping({"actuator": {"preset": "dong2022-downhole"}, **values})
    for named in ("filter.gate_nis", "filter.max_gap_s", "filter.block_duration_s"):
        assert str(info.value).count(named) == 1, info.value
    keys = {"noise": {"curent_std_a": 0.1, "sped_std_rad_s": 0.1, "current_std_a": 0.1}}
    with pytest.raises(ParameterError) as info:
        params_from_mapping({"actuator": {"preset": "dong2022-downhole"}, **keys})
    assert info.value.field == "noise.curent_std_a"
    assert "noise.sped_std_rad_s: unknown key" in str(info.value)
    assert "noise.current_std_a:" not in str(info.value)
    # An unknown key hid the section's bad values.
    both = {"filter": {"gate_nis": -1.0, "typo": 1}, "actuator": {"prest": "x"}}
    with pytest.raises(ParameterError) as info:
        params_from_mapping(both)
    for named in ("filter.typo", "filter.gate_nis", "actuator.prest", "actuator.preset: missing"):
        assert str(info.value).count(named) == 1, info.value
    actuator = {
        "preset": "dong2022-downhole",
        "drive_train": {"gear_ratio": 0.5, "gear_efficiency": 2.0},
        "case_forward": 3,
        "misalignment_arcmin": [0.0, "x"],
    }
    with pytest.raises(ParameterError) as info:
        params_from_mapping({"actuator": actuator})
    for named in (
        "actuator.drive_train.gear_ratio",
        "actuator.drive_train.gear_efficiency",
        "actuator.case_forward",
        "actuator.misalignment_arcmin[1]",
    ):
        assert str(info.value).count(named) == 1, info.value
