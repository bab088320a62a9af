"""Test data for the node: synthetic motor samples, short simulated scenes, small bags.

The samples are the estimator's kind of input: a constant-speed run of the dong2022-downhole
actuator under a 30 kN load; optionally, from ``jam_at_s`` on, the current steps up by 35 %
and a carrier-frequency ripple appears (the signature of one jammed roller, see
docs/estimation.md). Bags are written with :mod:`prsm_health.bags` (log time = stamp).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from prsm_health.actuator import DriveTrain, load_torque_nm
from prsm_health.bags.writer import BagWriter, write_motor_states
from prsm_health.physics.meshing import carrier_speed_rad_s
from prsm_health.physics.presets import load_preset
from prsm_health.scenes.recording import record
from prsm_health.scenes.scene import Scene, load_scene
from prsm_health.scenes.simulator import Simulator
from prsm_health.signals import MotorSamples

RATE_HZ = 1000.0
LOAD_N = 30_000.0
SCREW_RPM = 300.0
#: Stamp of the first sample of a run from rest [s].
ORIGIN_S = 1000.0


def worn_params(tmp: Path) -> Path:
    """Parameters whose wear is a million times faster, so that seconds show a loss."""
    path = tmp / "params.yaml"
    path.write_text("actuator: {preset: dong2022-downhole, wear_acceleration: 1.0e6}\n")
    return path


def synthetic_run(
    duration_s: float,
    *,
    start_s: float = ORIGIN_S,
    from_rest: bool = True,
    jam_at_s: float | None = None,
    seed: int = 0,
) -> MotorSamples:
    """1 kHz samples stamped from ``start_s`` on, for ``duration_s``.

    from_rest: speed and load ramp up first (else the run is already at speed and load, its
    position continuing from a run that started at ``ORIGIN_S``). jam_at_s: the stamp from
    which one roller is jammed (None: never).
    """
    preset = load_preset("dong2022-downhole")
    drive = DriveTrain()
    rng = np.random.default_rng(seed)
    elapsed = np.arange(round(duration_s * RATE_HZ)) / RATE_HZ
    stamps = start_s + elapsed
    speed_ramp = np.clip(elapsed / 0.2, 0.0, 1.0) if from_rest else np.ones_like(elapsed)
    load_ramp = np.clip((elapsed - 0.3) / 0.5, 0.0, 1.0) if from_rest else speed_ramp
    screw = SCREW_RPM * math.pi / 30.0 * speed_ramp
    motor = screw * drive.gear_ratio
    offset = 0.0 if from_rest else float(motor[0]) * (start_s - ORIGIN_S)
    position = offset + np.cumsum(motor) / RATE_HZ
    torque = load_torque_nm(preset, LOAD_N * load_ramp) * 1.08  # with ~8 % friction
    current = drive.current_a(torque, screw, np.gradient(motor, 1.0 / RATE_HZ))
    if jam_at_s is not None:
        carrier = position * float(carrier_speed_rad_s(preset.geometry, 1.0 / drive.gear_ratio))
        current = np.where(stamps >= jam_at_s, 1.35 * current + 0.4 * np.sin(carrier), current)
    current = current + rng.normal(0.0, 0.05, len(elapsed))
    speed = motor + rng.normal(0.0, 0.2, len(elapsed))
    return MotorSamples(stamps, current, speed, position)


def write_bag(path: Path, samples: MotorSamples) -> Path:
    """A rosbag2 (MCAP) directory with one MotorState per sample on /motor_state."""
    with BagWriter(path) as writer:
        write_motor_states(writer, samples)
    return path


def short_jam_scene(duration_s: float) -> Scene:
    """The first ``duration_s`` of the bundled sudden-jam scene, with its first jam only
    (roller 4 at 4.5 s, in the first forward stroke)."""
    scene = load_scene("sudden-jam")
    return dataclasses.replace(scene, duration_s=duration_s, jams=scene.jams[:1])


def simulated_bag(path: Path, scene: Scene) -> Path:
    """The truth simulator's bag of ``scene`` (/motor_state and /truth/state)."""
    record(Simulator(scene), path)
    return path
