"""Sample series and small bags for the bag tests (built in tmp_path, never committed)."""

from __future__ import annotations

import shutil
from dataclasses import fields
from pathlib import Path

import numpy as np
import yaml
from mcap.reader import NonSeekingReader
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter

from prsm_health.bags.codecs import encode_motor_states
from prsm_health.bags.stamps import seconds_to_stamps, stamps_to_seconds
from prsm_health.bags.typestore import MOTOR_STATE, typestore
from prsm_health.bags.writer import BagWriter, write_joint_states, write_motor_states, write_truth
from prsm_health.signals import MotorSamples, TruthSamples


def motor_samples(n: int, *, t0: float = 0.0, seed: int = 0, faults: bool = True) -> MotorSamples:
    """``n`` samples at 1 kHz; with ``faults``, NaN/inf/backwards stamps and NaN/inf values."""
    rng = np.random.default_rng(seed)
    stamp = t0 + 1e-3 * np.arange(n)
    current, speed, position = rng.normal(size=(3, n)) * [[5.0], [100.0], [1e3]]
    if faults and n > 12:
        stamp[5], stamp[6], stamp[7] = np.nan, np.inf, -np.inf
        stamp[10] = stamp[9] - 0.5  # backwards
        stamp[11] = -3.25  # negative
        current[3], speed[4], position[8] = np.nan, np.inf, -np.inf
        current[9] = -0.0
    return MotorSamples(stamp, current, speed, position)


def truth_samples(n: int, *, rollers: int = 5, t0: float = 0.0, seed: int = 1) -> TruthSamples:
    """``n`` ground-truth samples at 1 kHz with a random jam pattern."""
    rng = np.random.default_rng(seed)
    values = rng.normal(size=(8, n))
    return TruthSamples(
        stamp_s=t0 + 1e-3 * np.arange(n),
        axial_load_n=values[0] * 1e4,
        radial_load_n=values[1] * 1e3,
        loading_case=rng.integers(1, 3, size=n),
        roller_jammed=rng.random((n, rollers)) < 0.2,
        precision_loss_m=np.abs(values[2]) * 1e-6,
        friction_torque_nm=values[3],
        fatigue_damage=np.abs(values[4]) * 1e-3,
        screw_speed_rad_s=values[5] * 10,
        carrier_angle_rad=values[6],
        wear_coefficient_factor=np.abs(values[7]) + 1,
    )


def quantised(stamp_s: np.ndarray) -> np.ndarray:
    """Stamps as a bag stores them (nanosecond resolution, non-finite kept)."""
    return stamps_to_seconds(*seconds_to_stamps(stamp_s))


def assert_same(actual: object, expected: object) -> None:
    """Field-by-field array equality of two sample containers (NaN equals NaN)."""
    assert type(actual) is type(expected)
    for f in fields(expected):  # type: ignore[arg-type]
        np.testing.assert_array_equal(getattr(actual, f.name), getattr(expected, f.name), f.name)


def with_quantised_stamps(samples: MotorSamples) -> MotorSamples:
    """``samples`` with stamps as read back from a bag."""
    return MotorSamples(
        quantised(samples.stamp_s), samples.current_a, samples.speed_rad_s, samples.position_rad
    )


def write_bag(
    path: Path,
    *,
    motor: MotorSamples | None = None,
    joint: MotorSamples | None = None,
    truth: TruthSamples | None = None,
    compress: bool = True,
) -> Path:
    """A bag at ``path`` with the given series on the default topics; returns ``path``."""
    with BagWriter(path, compress=compress) as writer:
        if motor is not None:
            write_motor_states(writer, motor)
        if joint is not None:
            write_joint_states(writer, joint)
        if truth is not None:
            write_truth(writer, truth)
    return path


def mcap_file(bag: Path) -> Path:
    """The .mcap file inside a bag directory."""
    return bag / f"{bag.name}.mcap"


def split_bag(path: Path, parts: list[Path]) -> Path:
    """A bag directory at ``path`` whose storage files are the .mcap files of ``parts``."""
    path.mkdir()
    names = []
    for part in parts:
        names.append(f"{part.name}.mcap")
        shutil.copyfile(mcap_file(part), path / names[-1])
    meta = yaml.safe_load((parts[0] / "metadata.yaml").read_text())
    meta["rosbag2_bagfile_information"]["relative_file_paths"] = names
    (path / "metadata.yaml").write_text(yaml.safe_dump(meta))
    return path


def streamed_messages(path: Path) -> list[tuple[int, int, tuple[str, int, bytes]]]:
    """(log time, channel id, (topic, log time, payload)) of what the mcap library streams out
    of the .mcap file ``path`` before any damage (the chunks complete before it), in file
    order: an independent count of what a damaged bag still holds."""
    found = []
    with path.open("rb") as stream:
        try:
            for _, channel, message in NonSeekingReader(stream).iter_messages(log_time_order=False):
                found.append(
                    (message.log_time, channel.id, (channel.topic, message.log_time, message.data))
                )
        except Exception:  # noqa: S110 - the damage ends the stream; what came before counts
            pass
    return found


def motor_state_payloads(motor: MotorSamples) -> list[bytes]:
    """Each sample as the CDR payload of a MotorState (frame_id "m")."""
    sec, nanosec = seconds_to_stamps(motor.stamp_s)
    columns = {"sec": sec, "nanosec": nanosec, "current_a": motor.current_a}
    columns |= {"speed_rad_s": motor.speed_rad_s, "position_rad": motor.position_rad}
    return [bytes(p) for p in encode_motor_states(columns, frame_id="m")]


def write_with_mcap_library(
    path: Path, messages: list[tuple[str, int, bytes]], *, chunk_size: int
) -> None:
    """A bare .mcap of MotorState ``(topic, log time [ns], payload)`` messages written by the
    mcap library (uncompressed chunks, which carry a CRC: the rosbags writer stores none)."""
    msgdef, _ = typestore().generate_msgdef(MOTOR_STATE, ros_version=2)
    with path.open("wb") as stream:
        writer = McapWriter(stream, chunk_size=chunk_size, compression=CompressionType.NONE)
        writer.start(profile="ros2", library="test")
        schema = writer.register_schema(MOTOR_STATE, "ros2msg", msgdef.encode())
        channels: dict[str, int] = {}
        for sequence, (topic, log_time, payload) in enumerate(messages):
            if topic not in channels:
                channels[topic] = writer.register_channel(topic, "cdr", schema)
            writer.add_message(channels[topic], log_time, payload, log_time, sequence=sequence)
        writer.finish()
