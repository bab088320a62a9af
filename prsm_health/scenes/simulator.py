"""The truth simulator: a scene's actuator, sample by sample, in chunks.

Per sample (vectorised over a chunk; docs/scenes.md has the whole model):

1. Profile -> screw speed reference, signed axial load F (times 1 + the coloured load noise),
   radial load F_r (clamped to rho_max |F|, the roller table's largest ratio), direction and
   loading case.
2. Speed loop -> screw speed omega_s, acceleration, screw angle; carrier angle
   theta = r_s / (2 (r_s + r_r)) x screw angle (004 eq. 30); roller i at phi_i = theta +
   2 pi (i - 1) / N from the radial-load direction (000 eq. 8).
3. Every roller's physics at its own angle: :class:`~prsm_health.physics.roller_table.RollerTable`
   lookups, or in exact mode :func:`~prsm_health.physics.roller_table.roller_values` (the
   physics core for every sample). Jammed rollers (scene ``jams``) take their sliding torque
   and jammed wear rate.
4. Screw torque: in motion T = F L / 2 pi + sign(omega_s) M(omega_s) with M the friction summed
   over the rollers (002 eq. 12-18); at rest the stiction model of
   :mod:`prsm_health.scenes.drive`. Motor current: :meth:`DriveTrain.current_a` with the motor
   acceleration G x the screw's.
5. Truth: precision loss integrates the rollers' wear rates x wear-coefficient factor x the
   actuator's wear acceleration; fatigue damage integrates 000 eq. 29 at the largest contact
   force (not accelerated).
6. Sensors and faults (:mod:`prsm_health.scenes.sensors`, :mod:`prsm_health.scenes.faults`).

Chunks carry every state (filters, integrals, stiction torque, sensor memories) to the next,
and all noise is indexed by sample, so table-mode results are identical whatever the chunk
size. (Exact mode solves each chunk as one batch, whose Newton iterations depend on the batch;
its results agree to the solver tolerance.)
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import NDArray
from scipy.signal import lfilter

from prsm_health.actuator import load_torque_nm
from prsm_health.physics.errors import DomainError
from prsm_health.physics.fatigue import damage_rate_from_peak_per_s
from prsm_health.physics.load_distribution import LoadingCase
from prsm_health.physics.meshing import carrier_speed_rad_s
from prsm_health.physics.roller_table import (
    RollerTable,
    RollerValues,
    TableGrid,
    roller_table,
    roller_values,
)
from prsm_health.scenes.drive import Drive, MotionState, clamp_recursion
from prsm_health.scenes.faults import FaultInjector
from prsm_health.scenes.noise import NormalStream, Stream, scene_generator
from prsm_health.scenes.profiles import DownholeCycle, HoldProfile, Reference
from prsm_health.scenes.scene import Scene
from prsm_health.scenes.sensors import SensorModel, SensorState
from prsm_health.signals import MotorSamples, TruthSamples

FloatArray = NDArray[np.float64]

#: Samples per chunk unless the caller chooses (about 10 s at 1 kHz, a few tens of MB).
DEFAULT_CHUNK_SAMPLES = 10_000


@dataclass(frozen=True)
class SimulationChunk:
    """One chunk of a run: the published motor samples, their receive times, the truth."""

    motor: MotorSamples
    receive_time_s: FloatArray
    truth: TruthSamples

    @classmethod
    def concatenate(cls, parts: list[SimulationChunk]) -> SimulationChunk:
        """A whole run from its chunks."""
        truth = TruthSamples(
            *(
                np.concatenate([getattr(p.truth, f.name) for p in parts])
                for f in fields(TruthSamples)
            )
        )
        return cls(
            MotorSamples.concatenate([p.motor for p in parts]),
            np.concatenate([p.receive_time_s for p in parts]),
            truth,
        )


@dataclass(frozen=True)
class _State:
    motion: MotionState
    load_noise: FloatArray
    drive_torque_nm: float
    precision_loss_m: float
    fatigue_damage: float
    sensors: SensorState


def _cumulative(initial: float, increments: FloatArray) -> FloatArray:
    """initial + running sum, added in sample order (the same whatever the chunking)."""
    return np.cumsum(np.concatenate(([initial], increments)))[1:]


class Simulator:
    """Runs a :class:`Scene`; ``exact`` overrides the scene's choice of the physics path."""

    def __init__(self, scene: Scene, *, exact: bool | None = None) -> None:
        self.scene = scene
        self.exact = scene.exact if exact is None else exact
        actuator = scene.actuator
        self._geometry = actuator.preset.geometry
        self._period_s = 1.0 / scene.rate_hz
        self._drive = Drive(scene.speed_loop, self._period_s)
        self._sensor_model = SensorModel(scene.sensors, self._period_s, scene.seed)
        self._carrier_ratio = float(carrier_speed_rad_s(self._geometry, 1.0))
        self._max_ratio = TableGrid().max_radial_ratio(self._geometry)
        self._radial = scene.radial_load.peak_n > 0.0
        n_rollers = self._geometry.n_rollers
        self._roller_offsets = 2.0 * math.pi * np.arange(n_rollers) / n_rollers
        self._jam_times = np.full(n_rollers, np.inf)
        for jam in scene.jams:
            self._jam_times[jam.roller - 1] = jam.time_s
        self.wear_coefficient_factor = scene.wear.factor(scene.seed)
        profile = scene.profile
        if isinstance(profile, DownholeCycle):
            segments = profile.segments(scene.duration_s, self._geometry.lead_m, scene.seed)
            self._reference = segments.reference
        elif isinstance(profile, HoldProfile):
            self._reference = profile.segments().reference
        else:
            self._reference = profile.reference
        noise = scene.load_noise
        smoothing = math.exp(-2.0 * math.pi * noise.bandwidth_hz * self._period_s)
        self._noise_b = np.array([noise.relative_std * math.sqrt(1.0 - smoothing**2)])
        self._noise_a = np.array([1.0, -smoothing])
        self._load_noise = NormalStream(scene.seed, Stream.LOAD_NOISE)

    def reference(self, time_s: FloatArray) -> Reference:
        """The profile at ``time_s`` (speed reference, signed load before noise, direction)."""
        return self._reference(time_s)

    def _table(self, case: LoadingCase) -> RollerTable:
        actuator = self.scene.actuator
        return roller_table(actuator.preset, actuator.misalignment, case, radial=self._radial)

    def _initial_state(self) -> _State:
        speed = float(self.reference(np.zeros(1)).speed_rad_s[0])
        # Stationary start of the AR(1) load noise: its state before sample 0.
        start = scene_generator(self.scene.seed, Stream.LOAD_NOISE).standard_normal()
        noise = -self._noise_a[1:] * self.scene.load_noise.relative_std * float(start)
        gear = self.scene.actuator.drive_train.gear_ratio
        return _State(
            motion=self._drive.initial_state(speed),
            load_noise=noise,
            drive_torque_nm=0.0,
            precision_loss_m=0.0,
            fatigue_damage=0.0,
            sensors=self._sensor_model.initial_state(0.0, gear * speed),
        )

    def _rollers(
        self,
        load_n: FloatArray,
        radial_n: FloatArray,
        carrier_rad: FloatArray,
        case: NDArray[np.int64],
    ) -> RollerValues:
        """Every roller's values, shape (samples, n_rollers), per loading case."""
        actuator = self.scene.actuator
        shape = (len(load_n), self._geometry.n_rollers)
        columns = {f.name: np.zeros(shape) for f in fields(RollerValues)}
        for value in np.unique(case):
            members = case == value
            loads = load_n[members]
            if self.exact:
                part = roller_values(
                    actuator.preset,
                    loads,
                    radial_load_n=radial_n[members],
                    carrier_angle_rad=carrier_rad[members],
                    misalignment=actuator.misalignment,
                    case=LoadingCase(int(value)),
                )
            else:
                table = self._table(LoadingCase(int(value)))
                safe = np.where(loads > 0.0, loads, 1.0)
                ratio = np.minimum(
                    np.where(loads > 0.0, radial_n[members] / safe, 0.0), table.max_radial_ratio
                )
                angles = carrier_rad[members, np.newaxis] + self._roller_offsets
                part = table.lookup(loads[:, np.newaxis], ratio[:, np.newaxis], angles)
            for name, column in columns.items():
                column[members] = getattr(part, name)
        return RollerValues(**columns)

    def run(self, chunk_samples: int = DEFAULT_CHUNK_SAMPLES) -> Iterator[SimulationChunk]:
        """The run as consecutive chunks of ``chunk_samples`` motor samples."""
        if chunk_samples < 1:
            raise ValueError(f"chunk_samples must be >= 1, got {chunk_samples}")
        state = self._initial_state()
        faults = FaultInjector(self.scene.sensor_faults, self.scene.rate_hz)
        total = self.scene.samples
        for first in range(0, total, chunk_samples):
            chunk, state = self._chunk(first, min(first + chunk_samples, total), state, faults)
            yield chunk

    def _chunk(
        self, first: int, stop: int, state: _State, faults: FaultInjector
    ) -> tuple[SimulationChunk, _State]:
        scene, actuator = self.scene, self.scene.actuator
        drive_train = actuator.drive_train
        index = np.arange(first, stop)
        time_s = index / scene.rate_hz
        reference = self.reference(time_s)
        motion, motion_state = self._drive.run(reference.speed_rad_s, state.motion)
        speed = motion.speed_rad_s

        white = self._load_noise.take(first, stop)
        noise, noise_state = lfilter(self._noise_b, self._noise_a, white, zi=state.load_noise)
        axial = reference.axial_load_n * (1.0 + noise)
        load = np.abs(axial)
        radial = np.minimum(scene.radial_load.values(time_s, scene.seed), self._max_ratio * load)
        case = np.where(
            reference.direction < 0, int(actuator.case_reverse), int(actuator.case_forward)
        ).astype(np.int64)
        carrier = self._carrier_ratio * motion.screw_angle_rad
        jammed = self._jam_times[np.newaxis, :] <= time_s[:, np.newaxis]
        rollers = self._rollers(load, radial, carrier, case)

        kinetic = rollers.friction_torque_nm(speed[:, np.newaxis], jammed).sum(axis=-1)
        static = rollers.friction_torque_nm(0.0, jammed).sum(axis=-1)
        load_torque = load_torque_nm(actuator.preset, axial)
        moving = speed != 0.0
        in_motion = load_torque + np.sign(speed) * kinetic
        drive_torque = clamp_recursion(
            np.where(moving, in_motion, load_torque - static),
            np.where(moving, in_motion, load_torque + static),
            state.drive_torque_nm,
        )
        current = drive_train.current_a(
            drive_torque, speed, drive_train.gear_ratio * motion.acceleration_rad_s2
        )
        over = np.abs(current) > drive_train.max_current_a
        if np.any(over):
            at = float(time_s[np.argmax(over)])
            raise DomainError(
                f"scene {scene.name}: the motor current exceeds drive_train.max_current_a = "
                f"{drive_train.max_current_a:g} A at t = {at:.3f} s"
            )

        wear_rate = rollers.wear_rate_m_per_s(speed[:, np.newaxis], jammed).sum(axis=-1)
        wear_scale = self.wear_coefficient_factor * actuator.wear_acceleration * self._period_s
        loss = _cumulative(state.precision_loss_m, wear_rate * wear_scale)
        damage_rate = damage_rate_from_peak_per_s(
            self._geometry,
            actuator.preset.fatigue,
            rollers.peak_contact_force_n.max(axis=-1),
            speed,
        )
        damage = _cumulative(state.fatigue_damage, damage_rate * self._period_s)

        gear = drive_train.gear_ratio
        measured, receive, sensor_state = self._sensor_model.measure(
            first,
            time_s,
            current,
            gear * speed,
            gear * motion.screw_angle_rad,
            state.sensors,
        )
        measured, receive = faults.apply(first, measured, receive)

        kept = index % scene.truth_decimation == 0
        truth = TruthSamples(
            stamp_s=time_s[kept],
            axial_load_n=axial[kept],
            radial_load_n=radial[kept],
            loading_case=case[kept],
            roller_jammed=jammed[kept],
            precision_loss_m=loss[kept],
            friction_torque_nm=(drive_torque - load_torque)[kept],
            fatigue_damage=damage[kept],
            screw_speed_rad_s=speed[kept],
            carrier_angle_rad=np.mod(carrier[kept], 2.0 * math.pi),
            wear_coefficient_factor=np.full(int(kept.sum()), self.wear_coefficient_factor),
        )
        next_state = _State(
            motion=motion_state,
            load_noise=noise_state,
            drive_torque_nm=float(drive_torque[-1]),
            precision_loss_m=float(loss[-1]),
            fatigue_damage=float(damage[-1]),
            sensors=sensor_state,
        )
        return SimulationChunk(measured, receive, truth), next_state


def simulate(
    scene: Scene, *, exact: bool | None = None, chunk_samples: int = DEFAULT_CHUNK_SAMPLES
) -> SimulationChunk:
    """A whole run in memory (for tests and short scenes; the CLI streams :meth:`Simulator.run`)."""
    return SimulationChunk.concatenate(list(Simulator(scene, exact=exact).run(chunk_samples)))
