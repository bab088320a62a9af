"""The precision loss and fatigue damage integrated from the hypotheses' rates, and their
uncertainty (estimation/degradation.py), on numbers worked out by hand; and the load mixture
the estimates report (law of total variance). Until a mutation review, the wear coefficient's
variance could stand for its standard deviation, and the jam-count spread and the mixture's
spread term be dropped, without a test failing."""

from __future__ import annotations

import math

import numpy as np
import pytest

from prsm_health.estimation.degradation import DegradationIntegrator
from prsm_health.estimation.estimator import _mixed
from prsm_health.estimation.measurement import Prediction


def prediction(rate_m_per_s: float, slope: float = 0.0, damage_per_s: float = 0.0) -> Prediction:
    """A hypothesis' prediction with only the degradation fields that matter here."""
    return Prediction(
        motor_torque_nm=0.0,
        jacobian=np.zeros(1),
        variance_nm2=1.0,
        friction_torque_nm=0.0,
        precision_loss_rate_m_per_s=rate_m_per_s,
        precision_loss_rate_slope=slope,
        fatigue_rate_per_s=damage_per_s,
        fatigue_rate_slope=0.0,
    )


def test_the_wear_coefficient_adds_its_log_normal_spread_to_the_loss() -> None:
    """One hypothesis, a certain load: the only uncertainty is the wear coefficient's, a
    log-normal factor of median 1 and sigma_ln 0.5, whose standard deviation is
    sqrt((e^s^2 - 1) e^s^2) = 0.6039 of the loss."""
    integrator = DegradationIntegrator(wear_coefficient_sigma_ln=0.5, radial_relative_sensitivity=0)
    integrator.add(2.0, [1.0], [prediction(3e-9)], [0.0])
    loss = integrator.state.precision_loss_m
    assert loss == pytest.approx(6e-9, rel=1e-12, abs=0.0)
    assert integrator.precision_loss_std_m == pytest.approx(0.60394 * loss, rel=1e-4, abs=0.0)


def test_an_undecided_jam_count_adds_the_spread_of_the_rates() -> None:
    """Two counts at 0.5 each, rates 1 and 3 nm/s for 2 s: the loss is their mean, 4 nm, and
    the jam term their standard deviation, 1 nm/s, times 2 s; the load term adds |slope| x
    sigma_F per hypothesis, linearly (0.5 x 1e-12 x 1000 x 2 s per hypothesis)."""
    integrator = DegradationIntegrator(wear_coefficient_sigma_ln=0.0, radial_relative_sensitivity=0)
    rates = [prediction(1e-9, slope=1e-12), prediction(3e-9, slope=-1e-12)]
    integrator.add(2.0, [0.5, 0.5], rates, [1000.0, 1000.0])
    state = integrator.state
    assert state.precision_loss_m == pytest.approx(4e-9, rel=1e-12, abs=0.0)
    assert state.jam_error_m == pytest.approx(2e-9, rel=1e-12, abs=0.0)
    assert state.load_error_m == pytest.approx(2e-9, rel=1e-12, abs=0.0)
    assert integrator.precision_loss_std_m == pytest.approx(4e-9, rel=1e-12, abs=0.0)  # linear sum


def test_nothing_accrues_at_standstill_and_a_reset_keeps_what_was_not_replaced() -> None:
    integrator = DegradationIntegrator(wear_coefficient_sigma_ln=0.3, radial_relative_sensitivity=0)
    integrator.add(1.0, [1.0], [prediction(1e-9, damage_per_s=1e-6)], [0.0])
    integrator.stop()
    assert integrator.state.rate_m_per_s == 0.0
    assert integrator.state.precision_loss_m == pytest.approx(1e-9, rel=1e-12, abs=0.0)
    integrator.reset(precision_loss=True, fatigue_damage=False)
    assert integrator.precision_loss_std_m == integrator.state.precision_loss_m == 0.0
    assert integrator.state.fatigue_damage == pytest.approx(1e-6, rel=1e-12, abs=0.0)


def test_the_load_mixture_carries_the_spread_between_the_counts() -> None:
    """Two counts at 0.5 with loads 0 and 1000 N, each of variance 1 N^2: the mixture's
    variance is the mean variance plus the loads' spread, 1 + 500^2."""
    load, variance = _mixed([0.5, 0.5], [0.0, 1000.0], [1.0, 1.0])
    assert load == 500.0
    assert variance == 250001.0
    assert math.isclose(_mixed([1.0], [7.0], [4.0])[1], 4.0)
