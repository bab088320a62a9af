"""The IMM over jam counts: filterpy's mixing equations, SPD covariances, probabilities."""

from __future__ import annotations

import math

import numpy as np
import pytest
from filterpy.kalman import IMMEstimator, KalmanFilter

from prsm_health.actuator import Actuator
from prsm_health.estimation.hypotheses import JamHypotheses, repair_covariance, safe_sqrt
from prsm_health.estimation.inputs import Block
from prsm_health.estimation.measurement import TorqueModel
from prsm_health.estimation.params import EstimatorParams, Fidelity, ModelParams
from prsm_health.physics.presets import load_preset

PRESET = load_preset("dong2022-downhole")


def params(**fidelity: object) -> EstimatorParams:
    return EstimatorParams(
        actuator=Actuator(preset=PRESET),
        model=ModelParams(radial_load_ratio=0.0, jam_rate_per_h=3600.0),
        fidelity=Fidelity(**fidelity),  # type: ignore[arg-type]
    )


def test_mixing_equals_filterpy_imm_estimator() -> None:
    """Without pruning and without ripple states, our mixing is filterpy's IMM mixing."""
    p = params(prune_hypotheses=False)
    bank = JamHypotheses(p, TorqueModel(p))
    rng = np.random.default_rng(3)
    n = bank.n_rollers + 1
    mu = rng.dirichlet(np.ones(n))
    reference = []
    for k in range(n):
        x = rng.normal(0.0, 1e3, bank.filters[k].dim_x)
        a = rng.normal(0.0, 1.0, (len(x), len(x)))
        cov = a @ a.T + np.eye(len(x))
        bank.filters[k].x, bank.filters[k].P = x.copy(), cov.copy()
        bank.log_prob[k] = math.log(mu[k])
        kf = KalmanFilter(dim_x=len(x), dim_z=1)
        kf.x, kf.P, kf.Q = x.copy(), cov.copy(), np.zeros_like(cov)
        reference.append(kf)
    dt = 0.04
    p_jump = -math.expm1(-1.0 * dt)  # jam_rate_per_h = 3600 -> 1 per second
    transition = np.eye(n) * (1.0 - p_jump) + np.eye(n, k=1) * p_jump
    transition[-1, -1] = 1.0
    imm = IMMEstimator(reference, mu, transition)
    imm.predict()  # mixes, then F = I, Q = 0 predicts leave the mixed states unchanged
    bank._mix(dt)
    for k in range(n):
        assert bank.filters[k].x == pytest.approx(reference[k].x, rel=1e-12, abs=1e-9)
        assert pytest.approx(reference[k].P, rel=1e-12, abs=1e-9) == bank.filters[k].P
        assert math.exp(bank.log_prob[k]) == pytest.approx(imm.cbar[k], rel=1e-12)


def moving_block(torque_nm: float, rng: np.random.Generator) -> Block:
    angle = rng.uniform(0.0, 2.0 * math.pi)
    return Block(
        stamp_s=0.0,
        duration_s=float(rng.choice([1e-6, 0.04, 30.0])),
        samples=40,
        motor_torque_nm=torque_nm,
        motor_speed_rad_s=float(rng.choice([-150.0, 150.0, 0.0])),
        motor_acceleration_rad_s2=0.0,
        carrier_cos=math.cos(angle),
        carrier_sin=math.sin(angle),
        direction=int(rng.choice([-1, 0, 1])),
    )


@pytest.mark.parametrize("kind", ["ekf", "ukf"])
def test_random_blocks_keep_covariances_spd_and_probabilities_normalised(kind: str) -> None:
    p = EstimatorParams(actuator=Actuator(preset=PRESET), fidelity=Fidelity(filter=kind))  # type: ignore[arg-type]
    bank = JamHypotheses(p, TorqueModel(p))
    rng = np.random.default_rng(11)
    for _ in range(300):
        torque = float(rng.choice([0.0, 1e-300, 3.0, -7.0, 50.0, 1e4]))
        bank.step(moving_block(torque, rng))
        probs = bank.probabilities()
        assert probs.sum() == pytest.approx(1.0, abs=1e-12)
        assert np.all(probs >= 0.0)
        for kf in bank.filters.values():
            assert np.all(np.isfinite(kf.x))
            np.testing.assert_array_equal(kf.P, kf.P.T)
            scale = np.sqrt(np.diagonal(kf.P))
            correlation = kf.P / np.outer(scale, scale)  # unit-free: states are N, N/s^2, ...
            assert np.linalg.eigvalsh(correlation).min() > 0.0
            np.linalg.cholesky(kf.P)


def test_safe_sqrt_repairs_a_matrix_that_lost_definiteness() -> None:
    broken = np.array([[1.0, 1.0], [1.0, 1.0 - 1e-12]])  # indefinite by round-off
    root = safe_sqrt(broken)
    assert np.all(np.isfinite(root))
    assert root.T @ root == pytest.approx(broken, abs=1e-9)
    assert np.linalg.eigvalsh(repair_covariance(broken)).min() > 0.0
    units = np.diag([1e5, 1e-3]) @ np.array([[1.0, 1.0], [1.0, 1.0]]) @ np.diag([1e5, 1e-3])
    repaired = repair_covariance(units)  # singular, with a condition number of 1e16 in SI
    np.linalg.cholesky(repaired)
    assert np.diagonal(repaired) == pytest.approx(np.diagonal(units))


def test_pruning_keeps_the_likely_counts_and_the_next_one() -> None:
    p = params(prune_hypotheses=True)
    bank = JamHypotheses(p, TorqueModel(p))
    assert sorted(bank.filters) == [0]
    rng = np.random.default_rng(5)
    bank.step(moving_block(4.0, rng))
    assert sorted(bank.filters)[0] == 0
    assert len(bank.filters) <= 3
