"""Presets load and cite their papers; impossible geometry is refused naming the field."""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import pytest

from prsm_health.physics.errors import ParameterError
from prsm_health.physics.geometry import Material, Misalignment
from prsm_health.physics.presets import PRESET_NAMES, load_preset, load_preset_file


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_presets_load_and_cite_source(name: str) -> None:
    preset = load_preset(name)
    assert preset.name == name
    assert "Table" in preset.source
    assert preset.geometry.n_rollers == 10


def test_004_helix_angles_match_table_2() -> None:
    geometry = load_preset("meng2022-misalignment").geometry
    assert geometry.screw_helix_angle_rad == pytest.approx(0.1504, abs=5e-5)
    assert geometry.roller_helix_angle_rad == pytest.approx(0.0907, abs=5e-5)


@pytest.mark.parametrize("flank_deg", [30.0, 40.0, 60.0])
def test_the_contact_normal_is_a_unit_vector_at_the_flank_angle(flank_deg: float) -> None:
    """The contact normal has the axial component sin(beta) cos(lambda_r) (004 eq. 18) and
    the radial component cos(beta) (000 eq. 12), the rest sin(beta) sin(lambda_r) along the
    helix (docs/physics.md): a unit vector whose axial-to-radial ratio is tan(beta)
    cos(lambda_r). The presets all use beta = 45 deg, where sin and cos coincide; a mutation
    review found either projection could swap them unseen."""
    beta = math.radians(flank_deg)
    geometry = dataclasses.replace(
        load_preset("meng2022-misalignment").geometry, flank_angle_rad=beta
    )
    helix = geometry.roller_helix_angle_rad
    along_helix = math.sin(beta) * math.sin(helix)
    assert math.hypot(
        geometry.axial_projection, geometry.radial_projection, along_helix
    ) == pytest.approx(1.0, rel=1e-12)
    assert geometry.axial_projection / geometry.radial_projection == pytest.approx(
        math.tan(beta) * math.cos(helix), rel=1e-12
    )


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("roller_radius_m", 20e-3),
        ("pitch_m", 0.0),
        ("pitch_m", -1e-3),
        ("n_rollers", 30),
        ("flank_angle_rad", 2.0),
        ("nut_radius_m", 12e-3),
        ("screw_starts", 0),
        ("pitch_m", math.nan),
    ],
)
def test_impossible_geometry_is_refused_naming_the_field(field: str, value: float) -> None:
    geometry = load_preset("meng2022-misalignment").geometry
    with pytest.raises(ParameterError) as info:
        dataclasses.replace(geometry, **{field: value})
    assert info.value.field.startswith("geometry.")
    assert field in str(info.value) or info.value.field != ""


def test_roller_larger_than_screw_names_roller_radius() -> None:
    geometry = load_preset("dong2022-downhole").geometry
    with pytest.raises(ParameterError, match=r"geometry\.roller_radius_m"):
        dataclasses.replace(geometry, roller_radius_m=16e-3)


def test_material_refuses_text_and_bad_poisson() -> None:
    with pytest.raises(ParameterError, match=r"material\.youngs_modulus_pa"):
        Material(youngs_modulus_pa="2.12e11")  # type: ignore[arg-type]
    with pytest.raises(ParameterError, match=r"material\.poisson_ratio"):
        Material(poisson_ratio=0.6)


def test_misalignment_limits_and_units() -> None:
    tilt = Misalignment.from_arcmin(1.0, 0.0)
    assert tilt.tilt_x_rad == pytest.approx(math.radians(1 / 60))
    assert not tilt.is_aligned and Misalignment().is_aligned
    with pytest.raises(ParameterError, match=r"misalignment\.tilt_y_rad"):
        Misalignment(tilt_y_rad=0.1)


def test_user_preset_file_in_scientific_notation(tmp_path: Path) -> None:
    bundled = Path(__file__).parents[2] / "prsm_health/physics/presets/meng2022-misalignment.yaml"
    text = bundled.read_text().replace("pitch_m: 2.0e-3", "pitch_m: 2e-3")
    path = tmp_path / "mine.yaml"
    path.write_text(text)
    assert load_preset_file(path).geometry.pitch_m == pytest.approx(2e-3)
    path.write_text(text.replace("pitch_m: 2e-3", "pitch_m: two"))
    with pytest.raises(ParameterError, match=r"geometry\.pitch_m"):
        load_preset_file(path)


def test_unknown_preset_lists_the_choices() -> None:
    with pytest.raises(ParameterError, match=r"dong2022-downhole"):
        load_preset("nope")


def test_a_missing_preset_file_is_named_as_a_file() -> None:
    with pytest.raises(ParameterError, match=r"no such preset file '/nonexistent/p.yaml'"):
        load_preset("/nonexistent/p.yaml")


def _preset_file(tmp_path: Path, old: str, new: str) -> Path:
    """The dong2022-downhole preset file with one line changed, under a fresh name (load_preset
    caches by path)."""
    bundled = Path(__file__).parents[2] / "prsm_health/physics/presets/dong2022-downhole.yaml"
    text = bundled.read_text()
    assert old in text
    path = tmp_path / f"{new.split(':')[0].strip()}.yaml"
    path.write_text(text.replace(old, new))
    return path


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        # A ZeroDivisionError mid-replay: the load tables and the filter scale by this load.
        (
            "largest_axial_load_n: 55000.0",
            "largest_axial_load_n: 1.0e-300",
            r"largest_axial_load_n: must be at least 1 N .*got 1e-300",
        ),
        # An OverflowError mid-replay: the damage rate divides by N_0.
        (
            "reference_cycles: 2.5e8",
            "reference_cycles: 1.0e-300",
            r"fatigue\.reference_cycles: must be at least 1 \(.*got 1e-300",
        ),
        # An OverflowError (int too large to convert to float) with a traceback.
        (
            "largest_axial_load_n: 55000.0",
            f"largest_axial_load_n: {10**400}",
            r"largest_axial_load_n: must be a finite number, got an integer of about 401 digits",
        ),
        ("largest_speed_rpm: 700.0", "largest_speed_rpm: .inf", r"largest_speed_rpm: must be a"),
        ("largest_speed_rpm: 700.0", "largest_speed_rpm: true", r"largest_speed_rpm: must be a"),
        # true counted as one roller (bool is an int).
        (
            "n_rollers: 10",
            "n_rollers: true",
            r"geometry\.n_rollers: must be an integer in \[1, 100\]",
        ),
        # An OverflowError in the roller-overlap check.
        ("n_rollers: 10", f"n_rollers: {10**400}", r"geometry\.n_rollers: must be an integer"),
        # An OverflowError in the lead (starts times pitch), later.
        ("screw_starts: 5", f"screw_starts: {10**400}", r"geometry\.screw_starts: must be an"),
        (
            "n_threads: 24",
            "n_threads: 100000",
            r"geometry\.n_threads: must be an integer in \[1, 1",
        ),
        ("geometry:\n", "geometry: 3\nignored:\n", r"geometry: must be a mapping, got int"),
    ],
)
def test_absurd_preset_values_are_refused_naming_file_and_key(
    tmp_path: Path, old: str, new: str, message: str
) -> None:
    path = _preset_file(tmp_path, old, new)
    with pytest.raises(ParameterError, match=rf"^{re.escape(str(path))}: {message}"):
        load_preset_file(path)


def test_the_preset_bounds_admit_their_limits(tmp_path: Path) -> None:
    path = _preset_file(tmp_path, "largest_axial_load_n: 55000.0", "largest_axial_load_n: 1")
    assert load_preset_file(path).largest_axial_load_n == 1.0
    path = _preset_file(tmp_path, "reference_cycles: 2.5e8", "reference_cycles: 1")
    assert load_preset_file(path).fatigue.reference_cycles == 1.0


def test_misalignment_refuses_what_is_no_finite_number() -> None:
    for value in (None, True, "0.001", 10**400, math.inf):
        with pytest.raises(ParameterError, match=r"^misalignment\.tilt_x_rad: must be a"):
            Misalignment(tilt_x_rad=value)  # type: ignore[arg-type]
