"""The whole model chain over the valid domain: finite, non-negative, or a typed domain error."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from prsm_health.physics.errors import DomainError
from prsm_health.physics.geometry import Misalignment
from prsm_health.physics.load_distribution import LoadingCase
from prsm_health.physics.model import OperatingPoint, evaluate
from prsm_health.physics.presets import PRESET_NAMES, load_preset

RPM = 2.0 * math.pi / 60.0


@settings(max_examples=60, deadline=None)
@given(
    name=st.sampled_from(PRESET_NAMES),
    fraction=st.floats(0.0, 3.0),
    radial_ratio=st.floats(0.0, 0.95),
    tilt=st.tuples(st.floats(-5.0, 5.0), st.floats(-5.0, 5.0)),
    speed_rpm=st.floats(-3000.0, 3000.0),
    jammed=st.integers(0, 10),
    case=st.sampled_from(list(LoadingCase)),
    theta=st.floats(0.0, 2.0 * math.pi),
)
# Found by hypothesis in CI: a radial load of 7.8e-10 N on 6.6 mN of axial load with a tilt
# stalled the load distribution's Newton (radial loads below 1 mN are now none).
@example(
    name="dong2022-downhole",
    fraction=1.192092896e-07,
    radial_ratio=1.192092896e-07,
    tilt=(1.0, 0.0),
    speed_rpm=0.0,
    jammed=0,
    case=LoadingCase.SCREW_TENSION_NUT_COMPRESSION,
    theta=1.0,
)
def test_model_outputs_are_finite_and_nonnegative_or_a_domain_error(
    name: str,
    fraction: float,
    radial_ratio: float,
    tilt: tuple[float, float],
    speed_rpm: float,
    jammed: int,
    case: LoadingCase,
    theta: float,
) -> None:
    preset = load_preset(name)
    axial = fraction * preset.largest_axial_load_n
    point = OperatingPoint(
        axial_load_n=axial,
        radial_load_n=radial_ratio * axial,
        screw_speed_rad_s=speed_rpm * RPM,
        jammed_rollers=jammed,
        misalignment=Misalignment.from_arcmin(*tilt),
        case=case,
        carrier_angle_rad=theta,
    )
    try:
        result = evaluate(preset, point)
    except DomainError as exc:
        # Only a misalignment that closes a clearance, or F_r > 0 at F_a = 0, may leave it.
        assert "overlap" in str(exc) or axial == 0.0
        return
    for array in (result.loads.screw_roller_n, result.loads.roller_nut_n):
        assert np.all(np.isfinite(array)) and np.all(array >= 0.0)
    torque = float(result.friction.total_nm)
    assert math.isfinite(torque) and torque >= 0.0
    assert 0.0 <= result.efficiency <= 1.0
    assert math.isfinite(result.precision_loss_rate_m_per_s)
    assert result.precision_loss_rate_m_per_s >= 0.0
    assert result.fatigue_life_h > 0.0  # may be inf at standstill or zero load


def test_small_tilts_keep_the_clearances_open_and_jams_cost_efficiency() -> None:
    preset = load_preset("meng2022-misalignment")
    base = OperatingPoint(
        axial_load_n=30e3,
        screw_speed_rad_s=300 * RPM,
        misalignment=Misalignment.from_arcmin(1.0, -1.0),
    )
    healthy = evaluate(preset, base)
    jammed = evaluate(preset, OperatingPoint(**{**base.__dict__, "jammed_rollers": 2}))
    assert jammed.efficiency < healthy.efficiency
    assert jammed.precision_loss_rate_m_per_s > healthy.precision_loss_rate_m_per_s
    assert float(jammed.friction.total_nm) > float(healthy.friction.total_nm)


def test_standstill_means_no_wear_and_infinite_life() -> None:
    preset = load_preset("meng2021-fractal")
    result = evaluate(preset, OperatingPoint(axial_load_n=20e3))
    assert result.precision_loss_rate_m_per_s == 0.0
    assert result.fatigue_life_h == pytest.approx(math.inf)
