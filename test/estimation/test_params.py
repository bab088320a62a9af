"""Estimator parameters: defaults, YAML loading, and errors that name the bad key."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest

from prsm_health.estimation.params import load_params, params_from_mapping
from prsm_health.physics.errors import ParameterError


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
