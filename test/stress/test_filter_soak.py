"""Filter soak: many updates of random valid and adversarial inputs, numerical invariants.

Two paths share the update budget (``PRSM_SOAK_UPDATES``, default 1e5; docs/stability.md runs
1e7):

- the whole estimator (:class:`HealthEstimator`) on sample streams: random motion, steps and
  reversals at peak load, long standstill, huge and tiny sample spacing, dropouts, time
  jumps, float32 arrays, denormals, NaN/inf bursts. Checked after every ``process`` call:
  every estimate finite, probabilities in [0, 1] summing to 1, precision loss and fatigue
  damage never decreasing, every accepted or rejected sample counted; the hypotheses'
  covariances (from the public snapshot) symmetric positive definite;
- the jam-hypothesis bank (:class:`JamHypotheses` with :class:`TorqueModel`) on blocks
  directly, EKF, UKF and without pruning: random blocks and adversarial ones (dt from 1 ns to
  three years, torques up to 1e6 N m, denormals, float32 rounding, reversals at peak load, load
  re-initialisations). Checked after every step: correlation matrices symmetric to round-off,
  positive definite and with a condition number inside the bounds below, probabilities in
  [0, 1] summing to 1.

Definiteness is judged on the correlation matrix D^-1/2 P D^-1/2: the states are in N, N/s,
N/s^2 and relative units, so the raw eigenvalues span 20 orders of magnitude
(``repair_covariance``). The measured extremes are printed (``pytest -s``).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass, fields

import numpy as np
import pytest

from prsm_health.actuator import Actuator
from prsm_health.estimation.estimate import HealthState
from prsm_health.estimation.estimator import HealthEstimator
from prsm_health.estimation.hypotheses import JamHypotheses
from prsm_health.estimation.inputs import Block
from prsm_health.estimation.measurement import TorqueModel
from prsm_health.estimation.params import EstimatorParams, Fidelity, ModelParams
from prsm_health.physics.presets import load_preset
from prsm_health.signals import MotorSamples

#: Total updates of the soak (blocks through the bank plus estimates of the estimator).
SOAK_UPDATES = int(os.environ.get("PRSM_SOAK_UPDATES", "100000"))
#: Share of the updates per path (the bank without pruning filters 21 hypotheses per block).
SHARES = {"estimator": 0.25, "ekf": 0.62, "ukf": 0.10, "no-prune": 0.03}
#: Every correlation matrix must be numerically far from singular: its condition number
#: times the machine epsilon below 2.3e-3 (about three significant digits left when it is
#: solved). The repair (repair_covariance) clips eigenvalues to CORRELATION_FLOOR only when a
#: Cholesky pivot falls below it, and a pivot bounds the smallest eigenvalue only from above,
#: so the eigenvalues themselves can go lower; measured extremes: docs/stability.md.
MAX_CONDITION = 1e13
#: Asymmetry allowed on the correlation scale: a repaired covariance is rebuilt from its
#: eigenvectors, symmetric to round-off only.
MAX_ASYMMETRY = 1e-12

PRESET = load_preset("dong2022-downhole")
ACTUATOR = Actuator(preset=PRESET)
ARM_M = PRESET.geometry.lead_m / (2.0 * math.pi)
GEAR = ACTUATOR.drive_train.gear_ratio
K_T = ACTUATOR.drive_train.torque_constant_nm_per_a
PEAK_N = PRESET.largest_axial_load_n
MAX_MOTOR_SPEED = PRESET.largest_speed_rpm * 2.0 * math.pi / 60.0 * GEAR


@dataclass
class Extremes:
    """The worst values seen (printed at the end of each test)."""

    checks: int = 0
    min_eigenvalue: float = math.inf
    max_condition: float = 0.0
    max_asymmetry: float = 0.0
    max_probability_error: float = 0.0

    def covariances(self, matrices: list[np.ndarray]) -> None:
        """Check covariances of one size: variances positive, symmetric to round-off and
        positive definite and well conditioned on the correlation scale (NaN or inf fail the
        eigenvalue test). Batched: one LAPACK call for all."""
        p = np.stack(matrices)
        d = 1.0 / np.sqrt(np.diagonal(p, axis1=1, axis2=2))
        correlation = p * d[:, :, None] * d[:, None, :]
        transposed = np.swapaxes(correlation, 1, 2)
        asymmetry = float(np.abs(correlation - transposed).max())
        values = np.linalg.eigvalsh(0.5 * (correlation + transposed))
        condition = values[:, -1] / values[:, 0]
        assert asymmetry <= MAX_ASYMMETRY, asymmetry
        assert np.all(values[:, 0] > 0.0), values  # positive definite, or NaN: fail at once
        self.checks += len(p)
        self.max_asymmetry = max(self.max_asymmetry, asymmetry)
        self.min_eigenvalue = min(self.min_eigenvalue, float(values[:, 0].min()))
        self.max_condition = max(self.max_condition, float(condition.max()))

    def probabilities(self, probabilities: np.ndarray) -> None:
        """Probabilities in [0, 1] summing to 1."""
        assert np.all((probabilities >= 0.0) & (probabilities <= 1.0)), probabilities
        error = abs(float(probabilities.sum()) - 1.0)
        self.max_probability_error = max(self.max_probability_error, error)
        assert error <= 1e-12

    def report(self, label: str, updates: int) -> None:
        """Print the extremes, then require the condition bound (checked at the end, so that
        a long run measures its extremes in full)."""
        print(
            f"\n{label}: {updates} updates, {self.checks} covariance checks; smallest "
            f"correlation eigenvalue {self.min_eigenvalue:.3g}, largest condition number "
            f"{self.max_condition:.3g}, largest asymmetry {self.max_asymmetry:.2g}, "
            f"largest probability-sum error {self.max_probability_error:.2g}"
        )
        assert self.max_condition <= MAX_CONDITION


def _budget(path: str) -> int:
    return max(1, round(SHARES[path] * SOAK_UPDATES))


# --- the bank on blocks -----------------------------------------------------------------------
#: A high jam rate keeps fresh hypotheses alive in the bank, so several filters run and merge.
BANK_JAM_RATE_PER_H = 50.0
#: The bank's longest block: years, as after a drive clock jumps from boot time to the epoch
#: (the filters predict at most hypotheses.LONGEST_PREDICTION_S of it).
MAX_BANK_DT_S = 1e8


def _params(fidelity: Fidelity) -> EstimatorParams:
    return EstimatorParams(
        actuator=ACTUATOR,
        model=ModelParams(jam_rate_per_h=BANK_JAM_RATE_PER_H),
        fidelity=fidelity,
    )


def _motion_block(rng: np.random.Generator, stamp: float, dt: float, speed: float) -> Block:
    """A block moving at ``speed`` (motor side) with a random load and ripple phase."""
    load = rng.uniform(-1.5, 1.5) * PEAK_N
    angle = rng.uniform(0.0, 2.0 * math.pi)
    attenuation = rng.uniform(0.0, 1.0)
    direction = int(np.sign(speed)) if abs(speed) > 1.0 else 0
    torque = load * ARM_M / GEAR + direction * rng.uniform(0.0, 2.0) + rng.normal(0.0, 0.05)
    return Block(
        stamp_s=stamp,
        duration_s=dt,
        samples=int(rng.integers(1, 200)),
        motor_torque_nm=torque,
        motor_speed_rad_s=speed,
        motor_acceleration_rad_s2=rng.normal(0.0, 200.0),
        carrier_cos=attenuation * math.cos(angle),
        carrier_sin=attenuation * math.sin(angle),
        direction=direction,
        current_residual_var_a2=rng.exponential(0.01),
    )


def _adversarial(rng: np.random.Generator, stamp: float, block: Block) -> Block:
    """One of the adversarial variations of ``block``."""
    kind = int(rng.integers(0, 8))
    change: dict[str, float | int] = {}
    if kind == 0:  # huge dt (a long gap)
        change["duration_s"] = 10.0 ** rng.uniform(0.0, math.log10(MAX_BANK_DT_S))
    elif kind == 1:  # tiny dt
        change["duration_s"] = 10.0 ** rng.uniform(-9.0, -4.0)
    elif kind == 2:  # step and reversal at peak load
        direction = -1 if rng.random() < 0.5 else 1
        change.update(
            motor_speed_rad_s=direction * MAX_MOTOR_SPEED,
            direction=direction,
            motor_torque_nm=direction * PEAK_N * ARM_M / GEAR * rng.uniform(1.0, 3.0),
        )
    elif kind == 3:  # far outside anything physical
        change.update(
            motor_torque_nm=rng.choice([-1.0, 1.0]) * 10.0 ** rng.uniform(3.0, 6.0),
            motor_acceleration_rad_s2=rng.normal(0.0, 1e9),
            current_residual_var_a2=10.0 ** rng.uniform(0.0, 12.0),
        )
    elif kind == 4:  # denormal and zero values
        tiny = float(rng.choice([5e-324, 1e-310, 2.2e-308, 0.0]))
        change.update(
            motor_torque_nm=tiny,
            motor_speed_rad_s=tiny,
            motor_acceleration_rad_s2=tiny,
            carrier_cos=tiny,
            carrier_sin=tiny,
            direction=0,
            current_residual_var_a2=tiny,
        )
    elif kind == 5:  # float32 rounding of every value
        change.update(
            {
                f.name: float(np.float32(getattr(block, f.name)))
                for f in fields(Block)
                if isinstance(getattr(block, f.name), float) and f.name != "stamp_s"
            }
        )
    elif kind == 6:  # long standstill, merged (0.5 s) blocks
        change.update(
            duration_s=0.5,
            samples=500,
            motor_speed_rad_s=0.0,
            motor_acceleration_rad_s2=0.0,
            direction=0,
        )
    else:  # one sample per block
        change["samples"] = 1
    values = {f.name: getattr(block, f.name) for f in fields(Block)} | change
    values["stamp_s"] = stamp
    return Block(**values)  # type: ignore[arg-type]


def _soak_bank(fidelity: Fidelity, updates: int, seed: int) -> Extremes:
    params = _params(fidelity)
    bank = JamHypotheses(params, TorqueModel(params))
    rng = np.random.default_rng(seed)
    extremes = Extremes()
    stamp = 0.0
    speed = 200.0
    for step in range(updates):
        if rng.random() < 0.02:  # a new stroke: speed and direction change
            speed = float(rng.choice([-1.0, 1.0]) * rng.uniform(0.0, MAX_MOTOR_SPEED))
        block = _motion_block(rng, stamp, 0.04, speed)
        if rng.random() < 0.3:
            block = _adversarial(rng, stamp, block)
        if rng.random() < 0.005:  # what the estimator does after a time reset or a hole
            bank.reinitialise_load(keep_load=bool(rng.random() < 0.5))
        transition = bool(rng.random() < 0.3)  # a stroke start: polar ripple updates
        result = bank.step(
            block,
            jerk_psd=5e12 if transition else 5e11,
            evidence=bool(rng.random() < 0.95),
            load_transition=transition,
        )
        stamp += block.duration_s
        assert len(result.predictions) == len(bank.hypotheses)
        assert all(math.isfinite(v) and v >= 0.0 for v in result.nis)
        for h in bank.hypotheses:
            assert np.all(np.isfinite(h.filter.x)), (step, h.count, h.filter.x)
        extremes.covariances([h.filter.P for h in bank.hypotheses])
        extremes.probabilities(bank.probabilities())
    return extremes


@pytest.mark.parametrize(
    ("path", "fidelity"),
    [
        ("ekf", Fidelity()),
        ("ukf", Fidelity(filter="ukf")),
        ("no-prune", Fidelity(prune_hypotheses=False)),
    ],
)
def test_bank_soak_keeps_covariances_definite_and_probabilities_normalised(
    path: str, fidelity: Fidelity
) -> None:
    updates = _budget(path)
    extremes = _soak_bank(fidelity, updates, seed=len(path))
    extremes.report(f"bank soak ({path})", updates)
    assert extremes.checks >= updates


# --- the whole estimator on samples -----------------------------------------------------------
#: The streams' clock restarts at 0 (a drive reboot, a time reset) beyond this [s]: stamps
#: beyond 2^31 s are out of range (``inputs.LARGEST_STAMP_S``), and the gaps of the full soak
#: add up to about 2.8e9 s: its last quarter would have had no estimate, and never ended.
CLOCK_RESTART_S = 1e9


class _Stream:
    """Sample streams of the scenarios, continuing in time and motor angle."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.time = 0.0
        self.angle = 0.0

    def _samples(
        self, n: int, speed: np.ndarray, load: np.ndarray, dt: np.ndarray | float
    ) -> MotorSamples:
        rng = self.rng
        if self.time > CLOCK_RESTART_S:
            self.time = 0.0
        steps = np.broadcast_to(np.asarray(dt, dtype=np.float64), (n,))
        stamp = self.time + np.cumsum(steps)
        angle = self.angle + np.cumsum(speed * steps)
        friction = np.sign(speed) * 0.3
        current = (load * ARM_M / GEAR + friction) / K_T + rng.normal(0.0, 0.05, n)
        measured = speed + rng.normal(0.0, 0.2, n)
        self.time, self.angle = float(stamp[-1]), float(angle[-1])
        return MotorSamples(stamp, current, measured, angle)

    def motion(self) -> MotorSamples:
        """Random valid motion: a few strokes with random speed and load."""
        n = int(self.rng.integers(500, 4000))
        speed = np.full(n, self.rng.choice([-1.0, 1.0]) * self.rng.uniform(0.0, MAX_MOTOR_SPEED))
        load = np.full(n, self.rng.uniform(-1.0, 1.0) * PEAK_N)
        return self._samples(n, speed, load, 1e-3)

    def reversals(self) -> MotorSamples:
        """Steps and reversals at peak load every few blocks."""
        n = 2000
        period = int(self.rng.integers(20, 400))
        sign = np.where((np.arange(n) // period) % 2 == 0, 1.0, -1.0)
        return self._samples(n, sign * MAX_MOTOR_SPEED, sign * PEAK_N, 1e-3)

    def standstill(self) -> MotorSamples:
        """A long standstill (sparse samples), holding a large load."""
        n = int(self.rng.integers(200, 2000))
        return self._samples(n, np.zeros(n), np.full(n, 0.8 * PEAK_N), 0.02)

    def spacing(self) -> MotorSamples:
        """Huge and tiny spacing: gaps of up to 11 days, bursts 1 ns apart."""
        n = 400
        dt = np.where(
            self.rng.random(n) < 0.01,
            10.0 ** self.rng.uniform(0.0, 6.0, n),
            10.0 ** self.rng.uniform(-9.0, -3.0, n),
        )
        return self._samples(n, np.full(n, 300.0), np.full(n, 2e4), dt)

    def faults(self) -> MotorSamples:
        """Valid motion with NaN/inf bursts, dropouts, a time jump back and denormals."""
        samples = self.motion()
        n = len(samples)
        values = [a.copy() for a in fields_of(samples)]
        for _ in range(int(self.rng.integers(1, 5))):
            field = int(self.rng.integers(0, 4))
            begin = int(self.rng.integers(0, n))
            bad = self.rng.choice([math.nan, math.inf, -math.inf])
            values[field][begin : begin + int(self.rng.integers(1, 200))] = bad
        if self.rng.random() < 0.5:  # denormal currents and speeds (valid numbers)
            begin = int(self.rng.integers(0, n))
            values[1][begin : begin + 100] = 5e-324
            values[2][begin : begin + 100] = -1e-310
        keep = np.ones(n, dtype=bool)
        begin = int(self.rng.integers(0, n))
        keep[begin : begin + int(self.rng.integers(0, 600))] = False  # a dropout
        if self.rng.random() < 0.3:  # stamps jump back
            values[0][n // 2 :] -= self.rng.uniform(0.0, 2.0)
        return MotorSamples(*(v[keep] for v in values))

    def float32(self) -> MotorSamples:
        """Valid motion delivered as float32 arrays."""
        samples = self.motion()
        return MotorSamples(
            samples.stamp_s,
            samples.current_a.astype(np.float32),  # type: ignore[arg-type]
            samples.speed_rad_s.astype(np.float32),  # type: ignore[arg-type]
            samples.position_rad.astype(np.float32),  # type: ignore[arg-type]
        )

    def scenarios(self) -> Iterator[MotorSamples]:
        """An endless random sequence of the scenarios above."""
        makers: list[Callable[[], MotorSamples]] = [
            self.motion,
            self.reversals,
            self.standstill,
            self.spacing,
            self.faults,
            self.float32,
        ]
        while True:
            yield makers[int(self.rng.integers(0, len(makers)))]()


def fields_of(samples: MotorSamples) -> list[np.ndarray]:
    """The four arrays of ``samples`` in field order."""
    return [getattr(samples, f.name) for f in fields(MotorSamples)]


def _check_state(state: HealthState, extremes: Extremes) -> None:
    for f in fields(HealthState):
        value = getattr(state, f.name)
        if isinstance(value, float):
            assert math.isfinite(value), (f.name, state)
    assert state.axial_load_std_n > 0.0
    assert state.precision_loss_std_m >= 0.0 and state.fatigue_damage_std >= 0.0
    extremes.probabilities(np.asarray(state.jam_probabilities))


def test_estimator_soak_on_adversarial_sample_streams() -> None:
    updates = _budget("estimator")
    estimator = HealthEstimator(EstimatorParams(actuator=ACTUATOR))  # default jam rate
    extremes = Extremes()
    fed = estimates = 0
    loss = damage = 0.0
    stream = _Stream(seed=7)
    for samples in stream.scenarios():
        fed += len(samples)
        states = estimator.process(samples)
        for state in states:
            _check_state(state, extremes)
            assert state.precision_loss_m >= loss and state.fatigue_damage >= damage
            loss, damage = state.precision_loss_m, state.fatigue_damage
        extremes.covariances([np.asarray(h["P"]) for h in estimator.snapshot()["hypotheses"]])
        estimates += len(states)
        if estimates >= updates:
            break
    for state in estimator.finish():
        _check_state(state, extremes)
        assert state.precision_loss_m >= loss
    counters = estimator.counters
    assert counters.accepted + counters.rejected_total == fed
    assert counters.rejected_total > 0 and counters.time_resets > 0 and counters.gaps > 0
    extremes.report(f"estimator soak ({fed} samples)", estimates)
