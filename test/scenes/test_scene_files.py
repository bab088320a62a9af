"""Scene files: every bundled scene validates; bad files are refused naming file and field."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest
import yaml

from prsm_health.physics.errors import ParameterError
from prsm_health.scenes.envelope import SINE_PROFILE, envelope_scenes
from prsm_health.scenes.faults import NonFinite, SensorFaults
from prsm_health.scenes.profiles import DownholeCycle, HoldProfile, SineProfile
from prsm_health.scenes.scene import load_scene, scene_names, varied_scene

BUNDLED = (
    "accelerated-wear",
    "nominal-downhole",
    "radial-misalignment",
    "sensor-faults",
    "stationary-hold",
    "sudden-jam",
)

MINIMAL = {
    "name": "minimal",
    "actuator": {"preset": "dong2022-downhole"},
    "duration_s": 1.0,
    "profile": {"type": "constant", "speed_rpm": 300.0, "axial_load_n": 20000.0},
}


def test_the_bundled_scenes_are_all_there_and_validate() -> None:
    assert scene_names() == BUNDLED
    for name in BUNDLED:
        scene = load_scene(name)
        assert scene.name == name
        assert scene.samples <= 60_000
        assert scene.actuator.preset.name == "dong2022-downhole"


def test_bundled_scene_contents_match_their_descriptions() -> None:
    jam = load_scene("sudden-jam")
    assert [(j.time_s, j.roller) for j in jam.jams] == [(4.5, 4), (25.0, 9)]
    tilted = load_scene("radial-misalignment")
    assert not tilted.actuator.misalignment.is_aligned
    assert isinstance(load_scene("stationary-hold").profile, HoldProfile)
    assert load_scene("accelerated-wear").wear.prior_sigma_ln == 0.5
    faults = load_scene("sensor-faults")
    assert faults.sensor_faults.time_jumps[0].jump_s < 0.0
    assert any(isinstance(f, NonFinite) for f in faults.sensor_faults.nonfinite)
    assert isinstance(load_scene("nominal-downhole").profile, DownholeCycle)


def write(tmp_path: Path, document: dict[str, object]) -> Path:
    path = tmp_path / "scene.yaml"
    path.write_text(yaml.safe_dump(document), encoding="utf-8")
    return path


def with_changes(**changes: object) -> dict[str, object]:
    document = {**MINIMAL}
    document.update(changes)
    return document


@pytest.mark.parametrize(
    ("document", "field"),
    [
        (with_changes(colour="red"), "colour"),
        ({k: v for k, v in MINIMAL.items() if k != "duration_s"}, "duration_s"),
        (with_changes(duration_s=-1.0), "duration_s"),
        (with_changes(rate_hz="fast"), "rate_hz"),
        (with_changes(truth_rate_hz=300.0), "truth_rate_hz"),
        (with_changes(seed=1.5), "seed"),
        (with_changes(actuator={"preset": "no-such-preset"}), "actuator.preset"),
        (with_changes(actuator={"preset": "dong2022-downhole", "gear": 3}), "actuator.gear"),
        (with_changes(profile={"type": "zigzag"}), "profile.type"),
        (with_changes(profile={"type": "constant", "speed": 3.0}), "profile.speed"),
        (
            with_changes(profile={"type": "downhole_cycle", "speed_rpm": [400.0, 100.0]}),
            "profile.speed_rpm",
        ),
        (
            with_changes(profile={"type": "downhole_cycle", "stroke_m": 0.001}),
            "profile.stroke_m",
        ),
        (
            with_changes(radial_load={"type": "wall", "min_n": 5.0, "max_n": 1.0}),
            "radial_load.max_n",
        ),
        (with_changes(load_noise={"relative_std": 0.5}), "load_noise.relative_std"),
        (with_changes(jams=[{"time_s": 1.0, "roller": 11}]), "jams[0].roller"),
        (
            with_changes(jams=[{"time_s": 1.0, "roller": 2}, {"time_s": 2.0, "roller": 2}]),
            "jams[1].roller",
        ),
        (with_changes(jams=[{"time_s": -1.0, "roller": 2}]), "jams[0].time_s"),
        (with_changes(wear={"coefficient_factor": 2.0, "prior_sigma_ln": 0.5}), "wear.prior"),
        (
            with_changes(sensors={"encoder_counts_per_rev": -4}),
            "sensors.encoder_counts_per_rev: must be an integer >= 0, got -4",
        ),
        (
            with_changes(
                sensor_faults={"spikes": [{"time_s": 1.0, "field": "torque", "value": 1}]}
            ),
            "sensor_faults.spikes[0].field",
        ),
        (
            with_changes(
                sensor_faults={"nonfinite": [{"time_s": 1.0, "field": "all", "value": 3.0}]}
            ),
            "sensor_faults.nonfinite[0].value",
        ),
        (with_changes(sensor_faults={"glitches": []}), "sensor_faults.glitches"),
        (with_changes(speed_loop={"bandwidth_hz": 0.0}), "speed_loop.bandwidth_hz"),
        (with_changes(joint_states="yes"), "joint_states"),
        # 400 digits: YAML reads an int that float() refuses with an OverflowError.
        (with_changes(duration_s=10**400), "duration_s"),
    ],
)
def test_bad_scene_files_name_the_file_and_the_field(
    tmp_path: Path, document: dict[str, object], field: str
) -> None:
    path = write(tmp_path, document)
    with pytest.raises(ParameterError, match=re.escape(f"{path}: {field}")):
        load_scene(str(path))


def test_a_valid_scene_file_loads_by_path(tmp_path: Path) -> None:
    scene = load_scene(str(write(tmp_path, MINIMAL)))
    assert scene.samples == 1000
    assert scene.truth_decimation == 10


def test_unknown_scene_names_are_refused(tmp_path: Path) -> None:
    with pytest.raises(ParameterError, match="unknown scene 'nowhere'"):
        load_scene("nowhere")
    # A file that is there but no YAML (a bag given as --scene) was an "unknown scene".
    bag = tmp_path / "run.mcap"
    bag.write_bytes(b"\x89MCAP0\r\n")
    with pytest.raises(ParameterError, match=r"run.mcap: a scene file is YAML \(.yaml or .yml\)"):
        load_scene(str(bag))


def test_a_relative_preset_path_is_taken_from_the_scene_files_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """It was taken from the working directory: the same scene file meant another actuator,
    or none, in every folder it was used from."""
    project = tmp_path / "project"
    bundled = Path(__file__).resolve().parents[2] / "prsm_health/physics/presets"
    (project / "presets").mkdir(parents=True)
    text = (bundled / "dong2022-downhole.yaml").read_text()
    (project / "presets" / "mine.yaml").write_text(
        text.replace("name: dong2022-downhole", "name: mine")
    )
    scene = {**MINIMAL, "actuator": {"preset": "presets/mine.yaml"}}
    (project / "scene.yaml").write_text(yaml.safe_dump(scene))
    monkeypatch.chdir(tmp_path)
    assert load_scene("project/scene.yaml").actuator.preset.name == "mine"
    (tmp_path / "presets").mkdir()  # one beside the working directory is not read
    (tmp_path / "presets" / "mine.yaml").write_text("not: a preset\n")
    assert load_scene(str(project / "scene.yaml")).actuator.preset.name == "mine"


def test_a_varied_scene_merges_sections_of_the_same_type_and_replaces_the_others() -> None:
    """sudden-jam at 100 rpm keeps its cycle's stroke and loads; a sine profile replaces the
    cycle whole (a merge would have left the cycle's keys in it, refused)."""
    base = load_scene("sudden-jam")
    slow = varied_scene("sudden-jam", "slow", "at 100 rpm", profile={"speed_rpm": 100.0})
    assert isinstance(slow.profile, DownholeCycle) and isinstance(base.profile, DownholeCycle)
    assert slow.profile.speed_rpm == (100.0, 100.0)
    assert slow.profile.stroke_m == base.profile.stroke_m
    assert slow.profile.traction_load_n == base.profile.traction_load_n
    assert (slow.name, slow.description, slow.jams) == ("slow", "at 100 rpm", base.jams)
    sine = varied_scene("sudden-jam", "sine", "sine strokes", profile=SINE_PROFILE, jams=[])
    assert isinstance(sine.profile, SineProfile) and sine.jams == ()
    assert sine.radial_load == base.radial_load
    faulty = load_scene("sensor-faults")
    assert faulty.sensor_faults != SensorFaults()
    assert varied_scene("sensor-faults", "clean", "", sensor_faults=None).sensor_faults == (
        SensorFaults()
    )


def test_the_envelope_scenes_build_with_their_own_names_and_descriptions() -> None:
    scenes = envelope_scenes()
    names = [s.name for s in scenes]
    assert len(set(names)) == len(names) and not set(names) & set(scene_names())
    assert all(s.description for s in scenes)
    assert [s.name for s in envelope_scenes()] == names  # the same run to run
    other = {s.name: s.actuator.preset.name for s in scenes}
    assert other["sudden-jam-other-screw"] == "meng2022-misalignment"
    assert other["sudden-jam-650rpm"] == "dong2022-downhole"
    by_name = {s.name: s for s in scenes}
    short, bundled = by_name["sudden-jam-supports-0.3s"], load_scene("sudden-jam")
    assert isinstance(short.profile, DownholeCycle) and isinstance(bundled.profile, DownholeCycle)
    assert short.profile == dataclasses.replace(bundled.profile, support_s=0.3)
    assert (short.jams, short.seed) == (bundled.jams, bundled.seed)
