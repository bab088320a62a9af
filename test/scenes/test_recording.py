"""A simulated bag records the actuator of its scene; replay and demo find it by any name."""

from __future__ import annotations

import dataclasses
import re
import shutil
from pathlib import Path

import pytest
import yaml

from prsm_health.bags.bagfiles import custom_data
from prsm_health.cli import main
from prsm_health.estimation.params import bundled_params_file, load_params
from prsm_health.node_params import accelerated_wear_note
from prsm_health.physics.errors import ParameterError
from prsm_health.ros.demo import DemoError, bag_duration_s, demo_params
from prsm_health.scenes.recording import ACTUATOR_KEY, SCENE_KEY, bag_actuator, bundled_scene_of
from prsm_health.scenes.scene import load_scene

ROOT = Path(__file__).resolve().parents[2]
BUNDLED_BAGS = ROOT / "bags"


@pytest.fixture(scope="module")
def renamed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Five seconds of sudden-jam (wear x 1e5) simulated into a bag of another name."""
    out = tmp_path_factory.mktemp("recording") / "mission-7"
    assert main(["simulate", "--scene", "sudden-jam", "--duration", "5", "--out", str(out)]) == 0
    return out


def copy_recording(bag: Path, copy: Path, actuator_section: str) -> Path:
    """A copy of ``bag`` whose metadata.yaml records ``actuator_section`` instead."""
    shutil.copytree(bag, copy)
    meta = copy / "metadata.yaml"
    info = yaml.safe_load(meta.read_text())
    info["rosbag2_bagfile_information"]["custom_data"][ACTUATOR_KEY] = actuator_section
    meta.write_text(yaml.safe_dump(info))
    return copy


def without_record(bag: Path, copy: Path) -> Path:
    """A copy of ``bag`` whose metadata.yaml records nothing (not named after a scene)."""
    shutil.copytree(bag, copy)
    meta = copy / "metadata.yaml"
    info = yaml.safe_load(meta.read_text())
    del info["rosbag2_bagfile_information"]["custom_data"]
    meta.write_text(yaml.safe_dump(info))
    return copy


def test_the_bag_records_its_scene_and_actuator_section(renamed: Path) -> None:
    data = custom_data(renamed)
    assert data[SCENE_KEY] == "sudden-jam"
    assert yaml.safe_load(data[ACTUATOR_KEY]) == {
        "preset": "dong2022-downhole",
        "wear_acceleration": 1.0e5,
    }
    # The bare .mcap holds the same record (rosbag2's metadata record, in its summary).
    assert custom_data(renamed / "mission-7.mcap") == data


def test_a_renamed_or_bare_bag_gives_its_scenes_actuator(
    renamed: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    expected = load_scene("sudden-jam").actuator
    for bag in (renamed, renamed / "mission-7.mcap"):
        found = bag_actuator(bag)
        assert found is not None and found.actuator == expected
        assert found.origin == "scene sudden-jam (recorded in the bag)"
    # A copy cut short has lost the record (it is written when the bag is closed) ...
    data = (renamed / "mission-7.mcap").read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    assert custom_data(cut) == {} and bag_actuator(cut) is None
    # Replayed, such a bag says so: its truth shows it was simulated (it fell back silently).
    trunc = tmp_path / "trunc.mcap"
    trunc.write_bytes((BUNDLED_BAGS / "sudden-jam/sudden-jam.mcap").read_bytes()[:1_300_000])
    assert main(["replay", str(trunc)]) == 1  # damaged
    assert "has a ground truth but no record of its scene's actuator" in capsys.readouterr().out
    # ... but one named after a bundled scene still gives that scene's.
    named = tmp_path / "sudden-jam.mcap"
    shutil.copy(cut, named)
    found = bag_actuator(named)
    assert found is not None and found.actuator == expected
    assert found.origin == "scene sudden-jam (the bag's name)"


def test_replay_takes_the_recorded_actuator_over_the_params_files(
    renamed: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """With the default file given as --params, the replay ran on its actuator (wear x 1) and
    reported a precision loss of 0 against the truth's (error -100 %)."""
    default = ROOT / "config" / "default.yaml"
    assert main(["replay", str(renamed), "--params", str(default)]) == 0
    out = capsys.readouterr().out
    assert "actuator of scene sudden-jam (recorded in the bag) instead of the file's" in out
    error = float(out.split("precision loss error ")[1].split(" %")[0])
    assert abs(error) < 10.0, out
    # --scene still chooses another (the wear x 1 of an actuator written for it).
    other = renamed.parent / "wear1.yaml"
    scene = yaml.safe_load(
        (ROOT / "prsm_health" / "scenes" / "data" / "sudden-jam.yaml").read_text()
    )
    scene["actuator"]["wear_acceleration"] = 1.0
    other.write_text(yaml.safe_dump(scene))
    assert main(["replay", str(renamed), "--scene", str(other)]) == 0
    out = capsys.readouterr().out
    assert f"actuator of scene {other}" in out
    assert float(out.split("precision loss error ")[1].split(" %")[0]) < -99.0


def test_the_demo_gives_the_node_the_recorded_actuator(renamed: Path, tmp_path: Path) -> None:
    path, line = demo_params(renamed, tmp_path)
    params = yaml.safe_load(path.read_text())
    assert params["actuator"] == {"preset": "dong2022-downhole", "wear_acceleration": 1.0e5}
    assert line.endswith("the actuator of scene sudden-jam (recorded in the bag), wear x 100000")


def test_the_demo_names_the_commands_that_read_a_damaged_bag(renamed: Path, tmp_path: Path) -> None:
    cut = tmp_path / "cut.mcap"
    cut.write_bytes((renamed / "mission-7.mcap").read_bytes()[:50_000])
    with pytest.raises(DemoError, match="replay and play read a damaged one up to its damage"):
        bag_duration_s(cut)
    assert bag_duration_s(renamed) == pytest.approx(5.0, abs=0.01)


def test_a_preset_file_is_recorded_by_its_absolute_path(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A scene naming its preset file relative to where it is simulated: the bag was not
    replayable from another directory (not even with --params: the record wins)."""
    project = tmp_path / "project"
    project.mkdir()
    shutil.copy(ROOT / "prsm_health/physics/presets/dong2022-downhole.yaml", project / "mine.yaml")
    scene = yaml.safe_load((ROOT / "prsm_health/scenes/data/sudden-jam.yaml").read_text())
    scene["actuator"]["preset"] = "mine.yaml"
    (project / "scene.yaml").write_text(yaml.safe_dump(scene))
    monkeypatch.chdir(project)
    assert main(["simulate", "--scene", "scene.yaml", "--duration", "1", "--out", "bag"]) == 0
    monkeypatch.chdir(tmp_path)
    found = bag_actuator(project / "bag")
    assert found is not None and found.section["preset"] == str(project / "mine.yaml")
    assert found.actuator == load_scene(str(project / "scene.yaml")).actuator


def test_replay_warns_and_goes_on_when_the_record_cannot_be_used(
    renamed: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A preset file that is no longer there: the actuator of the parameters file, said."""
    bag = copy_recording(renamed, tmp_path / "bag", "preset: /gone/p.yaml\n")
    assert main(["replay", str(bag)]) == 0
    captured = capsys.readouterr()
    assert f"warning: {bag}: custom_data {ACTUATOR_KEY}: preset: " in captured.err
    assert "default.yaml is used" in captured.err
    assert "actuator of" not in captured.out
    assert "no record" not in captured.out  # it has one (the note contradicted the warning)


def test_replays_output_bag_keeps_the_record(renamed: Path, tmp_path: Path) -> None:
    """So that it too replays with the scene's actuator (it had custom_data: null)."""
    out = tmp_path / "out"
    assert main(["replay", str(renamed), "--out", str(out)]) == 0
    assert custom_data(out) == custom_data(renamed)


def test_an_invalid_recorded_actuator_names_the_bag_and_the_field(
    renamed: Path, tmp_path: Path
) -> None:
    bag = copy_recording(renamed, tmp_path / "bag", "preset: no-such-preset\n")
    where = re.escape(f"{bag}: custom_data {ACTUATOR_KEY}: preset: unknown preset")
    with pytest.raises(ParameterError, match=where):
        bag_actuator(bag)


def test_a_scene_whose_actuator_was_replaced_must_drop_the_files_section() -> None:
    """Else its bags would record an actuator they were not simulated with."""
    scene = load_scene("sudden-jam")
    other = load_scene("accelerated-wear").actuator
    assert other != scene.actuator
    with pytest.raises(ParameterError, match="actuator: does not match the section"):
        dataclasses.replace(scene, actuator=other)
    assert dataclasses.replace(scene, actuator=other, actuator_yaml=None).actuator == other


def test_a_bag_named_after_a_bundled_scene_is_found_by_its_name(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """By its directory, its .mcap file or ``.`` inside it; a bag of another name is not."""
    directory = BUNDLED_BAGS / "sudden-jam"
    assert bundled_scene_of(directory) == "sudden-jam"
    assert bundled_scene_of(directory / "sudden-jam.mcap") == "sudden-jam"
    monkeypatch.chdir(directory)
    assert bundled_scene_of(Path(".")) == "sudden-jam"
    assert bundled_scene_of(BUNDLED_BAGS) is None


def test_node_params_writes_the_bundled_parameters_with_the_bags_actuator(
    renamed: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Fed from a scene bag as the README said, with the bundled parameters, a node reported a
    precision loss 1e5 times too small (the scene's wear acceleration)."""
    out = tmp_path / "node.yaml"
    assert main(["node-params", str(renamed), "--out", str(out)]) == 0
    assert f"-p params_file:={out}" in capsys.readouterr().out
    written = yaml.safe_load(out.read_text())
    bundled = yaml.safe_load(bundled_params_file().read_text())
    section = {"preset": "dong2022-downhole", "wear_acceleration": 1.0e5}
    assert written == {**bundled, "actuator": section}
    assert load_params(out).actuator == load_scene("sudden-jam").actuator
    assert main(["node-params", str(renamed), "--out", str(out)]) == 2  # not overwritten
    assert capsys.readouterr().err == f"prsm-health: error: --out: {out} exists\n"
    nested = tmp_path / "new" / "folder" / "node.yaml"  # it said [Errno 2]
    assert main(["node-params", str(renamed), "--out", str(nested)]) == 0
    assert load_params(nested).actuator == load_scene("sudden-jam").actuator


def test_node_params_refuses_what_the_node_would_refuse(
    renamed: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A params file with an unknown key was written out, and the node then failed to
    configure with it (found by a review session)."""
    bad = tmp_path / "bad.yaml"
    bad.write_text("filter:\n  gate_nys: 3\n")
    out = tmp_path / "node" / "node.yaml"
    assert main(["node-params", str(renamed), "--out", str(out), "--params", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"prsm-health: error: --params: {bad}: filter.gate_nys: unknown key")
    assert err.count("\n") == 1 and not out.parent.exists()


def test_node_params_refuses_a_mistake_in_the_actuator_it_replaces(
    renamed: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The file's own actuator section gives way to the bag's, but a mistake in it is refused
    as replay refuses it (node-params alone wrote the file out with the mistake dropped)."""
    bad = tmp_path / "bad.yaml"
    bad.write_text("actuator:\n  preset: dong2022-downhole\n  case_forwrad: 2\n")
    out = tmp_path / "node.yaml"
    assert main(["node-params", str(renamed), "--out", str(out), "--params", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"prsm-health: error: --params: {bad}: actuator")
    assert "case_forwrad" in err and not out.exists()
    assert main(["replay", str(renamed), "--params", str(bad)]) == 2
    assert "case_forwrad" in capsys.readouterr().err


def test_a_bag_without_a_record_gets_no_node_params_and_no_play_note(
    renamed: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    note = accelerated_wear_note(renamed)
    assert note is not None and "accelerates wear x100000" in note
    assert f"prsm-health node-params {renamed} --out FILE" in note
    unrecorded = without_record(renamed, tmp_path / "field-run")
    assert accelerated_wear_note(unrecorded) is None
    out = tmp_path / "node.yaml"
    assert main(["node-params", str(unrecorded), "--out", str(out)]) == 2
    assert "records no actuator" in capsys.readouterr().err and not out.exists()


def test_play_has_no_wear_note_for_a_bag_whose_actuator_wears_at_its_own_rate(
    renamed: Path, tmp_path: Path
) -> None:
    """Pins that play's note is for accelerated wear only: a bag recording an actuator without
    wear_acceleration (x1, what the bundled parameters assume) gets none. A mutation review
    found it unguarded (every recorded bag got "accelerates wear x1")."""
    real_wear = copy_recording(renamed, tmp_path / "real-wear", "preset: dong2022-downhole\n")
    scene = bag_actuator(real_wear)
    assert scene is not None and scene.actuator.wear_acceleration == 1.0
    assert accelerated_wear_note(real_wear) is None


def test_node_params_names_a_record_that_builds_no_actuator(
    renamed: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """It warned that the default actuator was used, then said the bag recorded none."""
    bag = copy_recording(renamed, tmp_path / "bag", "preset: /gone/p.yaml\n")
    out = tmp_path / "node.yaml"
    assert main(["node-params", str(bag), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"prsm-health: error: {bag}: custom_data {ACTUATOR_KEY}: preset: ")
    assert err.count("\n") == 1 and not out.exists()


def test_replay_params_of_settings_only_take_the_bags_actuator(
    renamed: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A tuning file without an actuator: section was refused ("actuator: missing") although
    the bag's record gives the actuator."""
    settings = tmp_path / "settings.yaml"
    settings.write_text("noise: {model_error_rel: 0.002}\n")
    assert main(["replay", str(renamed), "--params", str(settings)]) == 0
    out = capsys.readouterr().out
    assert (
        f"parameters: {settings}, actuator of scene sudden-jam (recorded in the bag) (the " in out
    )
    unrecorded = without_record(renamed, tmp_path / "field-run")
    assert main(["replay", str(unrecorded), "--params", str(settings)]) == 2
    assert "actuator: missing" in capsys.readouterr().err
