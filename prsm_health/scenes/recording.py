"""Recording a simulated run as a rosbag2 MCAP bag (``prsm-health simulate``).

Topics: ``/motor_state`` (prsm_health_msgs/MotorState, the estimator's input; log time = the
simulated receive time), optionally ``/joint_states`` (sensor_msgs/JointState with
effort = motor current [A]; log time from the stamps) and ``/truth/state``
(prsm_health_msgs/GroundTruth at the scene's truth rate). Stamps count from the scene start
(the bag starts at the epoch). The run is written chunk by chunk, so hours-long scenes stream;
the bag bytes depend only on the scene, its seed and the chunk size (fixed here), never on the
machine or the time of day.

The bag's rosbag2 ``custom_data`` records the scene's name (:data:`SCENE_KEY`) and, for a scene
read from a file, its ``actuator`` section (:data:`ACTUATOR_KEY`): the replay and the demo
give the estimator that actuator (the scenes accelerate wear; the estimator must know by how
much), whatever the bag is called later (:func:`bag_actuator`).
"""

from __future__ import annotations

import sys
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple, cast

import numpy as np
import yaml

from prsm_health.actuator import Actuator, actuator_from_mapping, relative_preset_file
from prsm_health.bags.bagfiles import custom_data
from prsm_health.bags.writer import BagWriter, write_joint_states, write_motor_states, write_truth
from prsm_health.physics.errors import ParameterError
from prsm_health.scenes.scene import load_scene, scene_names
from prsm_health.scenes.simulator import DEFAULT_CHUNK_SAMPLES, Simulator
from prsm_health.scenes.validation import prefixed

NS_PER_S = 1_000_000_000
#: custom_data key of the scene's name.
SCENE_KEY = "prsm_health.scene"
#: custom_data key of the scene's actuator section (YAML).
ACTUATOR_KEY = "prsm_health.actuator"


def record(
    simulator: Simulator,
    path: Path,
    *,
    progress: Callable[[int], None] | None = None,
    stop: threading.Event | None = None,
) -> tuple[int, int]:
    """Simulate ``simulator``'s scene into the new bag directory ``path``.

    ``progress`` is called with the number of samples simulated after every chunk. When
    ``stop`` is set, the recording ends after the chunk being written, and the bag is closed
    as a complete (shorter) bag. Returns the numbers of motor and truth messages written.
    """
    scene = simulator.scene
    motor_count = truth_count = 0
    with BagWriter(path) as writer:
        writer.set_custom_data(SCENE_KEY, scene.name)
        if scene.actuator_yaml is not None:
            writer.set_custom_data(ACTUATOR_KEY, _recorded_section(scene.actuator_yaml))
        remaining = scene.samples
        for chunk in simulator.run(DEFAULT_CHUNK_SAMPLES):
            receive_ns = np.round(chunk.receive_time_s * NS_PER_S).astype(np.int64)
            write_motor_states(writer, chunk.motor, receive_time_ns=receive_ns)
            if scene.joint_states:
                write_joint_states(writer, chunk.motor)
            write_truth(writer, chunk.truth)
            motor_count += len(chunk.motor)
            truth_count += len(chunk.truth)
            done = min(DEFAULT_CHUNK_SAMPLES, remaining)
            remaining -= done
            if progress is not None:
                progress(done)
            if stop is not None and stop.is_set():
                break
    return motor_count, truth_count


def _recorded_section(actuator_yaml: str) -> str:
    """The actuator section to record: a preset file named by a relative path made absolute
    (relative to the working directory of the simulation, not of a later replay; a scene
    file's own relative path is already joined to its folder:
    :func:`~prsm_health.actuator.preset_beside_file`)."""
    section = yaml.safe_load(actuator_yaml)
    relative = relative_preset_file(section["preset"])
    if relative is None:
        return actuator_yaml
    return yaml.safe_dump({**section, "preset": str(relative.resolve())}, sort_keys=False)


class SceneActuator(NamedTuple):
    """The actuator of a scene: the section as written (for a params file), the actuator,
    and where it came from (for the operator)."""

    section: dict[str, Any]
    actuator: Actuator
    origin: str


def scene_actuator(scene: str) -> SceneActuator:
    """The actuator of a bundled scene (by name) or a scene file (by path).

    Raises:
        ParameterError: an unknown scene or an invalid file, named.
    """
    loaded = load_scene(scene)
    section = yaml.safe_load(cast(str, loaded.actuator_yaml))  # a scene file's: kept
    return SceneActuator(section, loaded.actuator, f"scene {scene}")


def bag_actuator(bag: Path) -> SceneActuator | None:
    """The actuator ``bag`` was simulated with: recorded in it by :func:`record`, else that of
    the bundled scene it is named after (:func:`bundled_scene_of`: a bag written before the
    record, or a bare ``.mcap`` file cut short, which has lost it), else None.

    Raises:
        BagError: the bag cannot be opened (:func:`~prsm_health.bags.bagfiles.bag_files`).
        ParameterError: the recorded section does not build an actuator (e.g. a preset file
            that is no longer where the scene named it), naming the bag and the field.
    """
    data = custom_data(bag)
    if ACTUATOR_KEY not in data:
        named = bundled_scene_of(bag)
        if named is None:
            return None
        return scene_actuator(named)._replace(origin=f"scene {named} (the bag's name)")
    where = f"{bag}: custom_data {ACTUATOR_KEY}"
    try:
        section = yaml.safe_load(data[ACTUATOR_KEY])
        actuator = actuator_from_mapping(section)
    except yaml.YAMLError as exc:
        raise ParameterError(where, f"not YAML: {exc}") from exc
    except ParameterError as exc:
        raise prefixed(exc, where, separator=": ") from exc
    origin = f"scene {data.get(SCENE_KEY, 'unnamed')} (recorded in the bag)"
    return SceneActuator(section, actuator, origin)


def records_actuator(bag: Path) -> bool:
    """Whether ``bag`` holds the record of its scene's actuator (usable or not; False also
    for a bag whose metadata cannot be read, e.g. an ``.mcap`` cut short)."""
    try:
        return ACTUATOR_KEY in custom_data(bag)
    except ValueError:  # BagError: damaged
        return False


def usable_bag_actuator(bag: Path, instead: Path) -> SceneActuator | None:
    """:func:`bag_actuator`, or None with a warning on stderr when the bag's record cannot
    build an actuator (a preset file no longer where it was): the caller then uses the
    actuator of the parameters file ``instead``, which the warning names.

    Raises:
        BagError: the bag cannot be opened.
    """
    try:
        return bag_actuator(bag)
    except ParameterError as exc:
        print(f"warning: {exc}; the actuator of {instead} is used", file=sys.stderr)
        return None


def bundled_scene_of(bag: Path) -> str | None:
    """The bundled scene a bag is named after: its directory's name (``.`` inside it counts),
    or for an ``.mcap`` file its stem or else its directory's."""
    path = bag.resolve()
    names = [path.stem, path.parent.name] if path.suffix == ".mcap" else [path.name]
    return next((name for name in names if name in scene_names()), None)
