"""Physics core over the valid domain, beyond test/physics: extreme but valid materials and
model parameters, radial loads up to the contact-loss limit, misalignment with radial load and
elastic errors together, speeds up to 3000 rpm.

test/physics/test_model.py and test_load_distribution.py already sample the presets as
published (finite, non-negative, axial balance of the bare solver). Here every solver must
converge with its residual checked (the load distribution's scaled residual below its
tolerance, the fractal load balance) or raise its typed error; nothing may be NaN or inf
(the fatigue life excepted at standstill or without load, where it is infinite by definition,
and at denormal speeds, where it overflows);
axial and radial equilibrium hold. Example counts stay small: a solve with a new geometry
(new materials) costs 10-30 ms.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import event, example, given, settings
from hypothesis import strategies as st

from prsm_health.physics.errors import ConvergenceError, DomainError
from prsm_health.physics.fractal import (
    LARGEST_TABLE_LOAD_N,
    fractal_surface,
    real_contact_area_m2,
    solve_largest_spot_m2,
)
from prsm_health.physics.geometry import Material, Misalignment
from prsm_health.physics.load_distribution import (
    NEGLIGIBLE_LOAD_N,
    LoadDistribution,
    LoadingCase,
    radial_capacity_ratio,
    solve_load_distribution,
)
from prsm_health.physics.meshing import meshing
from prsm_health.physics.model import OperatingPoint, evaluate
from prsm_health.physics.parameters import FatigueParameters, FrictionParameters, WearParameters
from prsm_health.physics.presets import PRESET_NAMES, Preset, load_preset

RPM = 2.0 * math.pi / 60.0
#: The load distribution's default tolerance on its scaled residual.
TOLERANCE = 1e-11
#: The full-model test samples radial loads up to this share of the radial capacity at the
#: carrier angle (the contact-loss limit), the load-distribution test from it to 99.999 %.
#: The simulator and the estimator stay below half the capacity.
CONVERGED_SHARE = 0.95


def log_uniform(low: float, high: float) -> st.SearchStrategy[float]:
    """Floats spread evenly in log between ``low`` and ``high``."""
    return st.floats(math.log(low), math.log(high)).map(math.exp)


#: Bodies from aluminium bronze (110 GPa) to tungsten carbide (600 GPa), soft to very hard.
materials = st.builds(
    Material,
    youngs_modulus_pa=log_uniform(7e10, 6e11),
    poisson_ratio=st.floats(0.2, 0.35),
    hardness_pa=log_uniform(1e9, 2e10),
    yield_strength_pa=log_uniform(3e8, 4e9),
)
friction_parameters = st.builds(
    FrictionParameters,
    hysteresis_loss_coefficient=log_uniform(1e-4, 0.05),
    sliding_friction_coefficient=st.floats(0.01, 0.5),
    lubricant_viscosity_pa_s=log_uniform(1e-3, 1.0),
    pressure_viscosity_coefficient_per_pa=log_uniform(5e-9, 4e-8),
)
wear_parameters = st.builds(
    WearParameters,
    model=st.sampled_from(["archard", "fractal"]),
    archard_coefficient=log_uniform(1e-9, 1e-5),
    adhesive_wear_coefficient=log_uniform(1e-13, 1e-9),
    surface_roughness_ra_m=log_uniform(5e-8, 1.6e-6),
)
fatigue_parameters = st.builds(
    FatigueParameters,
    reference_cycles=log_uniform(1e6, 1e10),
    stress_exponent=st.floats(3.0, 12.0),
    reference_pressure_pa=log_uniform(1e9, 5e9),
)


@st.composite
def presets(draw: st.DrawFn) -> Preset:
    """A bundled preset with every body's material and the model parameters redrawn."""
    preset = load_preset(draw(st.sampled_from(PRESET_NAMES)))
    geometry = dataclasses.replace(
        preset.geometry, screw=draw(materials), roller=draw(materials), nut=draw(materials)
    )
    return dataclasses.replace(
        preset,
        geometry=geometry,
        friction=draw(friction_parameters),
        wear=draw(wear_parameters),
        fatigue=draw(fatigue_parameters),
    )


def assert_balanced(
    preset: Preset, loads: LoadDistribution, axial: float, radial: float, theta: float
) -> None:
    """Axial balance of both interfaces and radial balance of the screw (000 eq. 12)."""
    geometry = preset.geometry
    q_s, q_n = loads.screw_roller_n, loads.roller_nut_n
    # Below NEGLIGIBLE_LOAD_N of axial load nothing is solved: every force is exactly zero; a
    # radial load below it is none (solve_load_distribution).
    carried = axial if axial > NEGLIGIBLE_LOAD_N else 0.0
    radial = radial if carried and radial > NEGLIGIBLE_LOAD_N else 0.0
    for q in (q_s, q_n):
        assert q.sum() * geometry.axial_projection == pytest.approx(carried, rel=1e-9, abs=1e-9)
    phi = theta + np.asarray(geometry.roller_angles_rad)
    per_roller = q_s.sum(axis=-1) * geometry.radial_projection
    force = np.array([(per_roller * np.cos(phi)).sum(), (per_roller * np.sin(phi)).sum()])
    assert np.allclose(force, [radial, 0.0], rtol=0.0, atol=1e-9 * max(axial, 1.0))


def tilts(arcmin: float) -> st.SearchStrategy[tuple[float, float]]:
    """Screw tilts about x and y up to ``arcmin`` each."""
    return st.tuples(st.floats(-arcmin, arcmin), st.floats(-arcmin, arcmin))


angles = st.floats(0.0, 2.0 * math.pi)
cases = st.sampled_from(list(LoadingCase))


@settings(max_examples=40, deadline=None)
@example(  # found in CI: 0.8 mN of radial load on 6.9 kN, solved as none
    preset=load_preset("dong2022-downhole"),
    fraction=0.125,
    radial_share=1.192092896e-07,
    tilt=(0.0, 0.0),
    speed_rpm=0.0,
    jammed=0,
    case=LoadingCase.SCREW_TENSION_NUT_COMPRESSION,
    theta=0.0,
    elastic_errors=False,
)
@given(
    preset=presets(),
    fraction=st.floats(0.0, 3.0),
    radial_share=st.floats(0.0, CONVERGED_SHARE),
    tilt=tilts(5.0),
    speed_rpm=st.floats(-3000.0, 3000.0),
    jammed=st.integers(0, 10),
    case=cases,
    theta=angles,
    elastic_errors=st.booleans(),
)
def test_full_model_with_extreme_valid_parameters_converges_balanced_and_finite(
    preset: Preset,
    fraction: float,
    radial_share: float,
    tilt: tuple[float, float],
    speed_rpm: float,
    jammed: int,
    case: LoadingCase,
    theta: float,
    elastic_errors: bool,
) -> None:
    axial = fraction * preset.largest_axial_load_n
    radial = radial_share * float(radial_capacity_ratio(preset.geometry, theta)) * axial
    point = OperatingPoint(
        axial_load_n=axial,
        radial_load_n=radial,
        screw_speed_rad_s=speed_rpm * RPM,
        jammed_rollers=min(jammed, preset.geometry.n_rollers),
        misalignment=Misalignment.from_arcmin(*tilt),
        case=case,
        carrier_angle_rad=theta,
        elastic_errors=elastic_errors,
    )
    try:
        result = evaluate(preset, point)
    except DomainError as exc:
        # Below the radial capacity only a tilt that closes a clearance, or F_r > 0 at F_a = 0.
        assert "overlap" in str(exc) or (axial == 0.0 and radial > 0.0)
        event("domain error")
        return
    event("solved")
    assert result.loads.residual <= TOLERANCE
    assert_balanced(preset, result.loads, axial, radial, theta)
    outputs = np.concatenate(
        [
            np.ravel(result.loads.screw_roller_n),
            np.ravel(result.loads.roller_nut_n),
            np.ravel(result.friction.per_roller_nm),
            [float(result.friction.total_nm), result.precision_loss_rate_m_per_s],
        ]
    )
    assert np.all(np.isfinite(outputs)) and outputs.min() >= 0.0
    assert 0.0 <= result.efficiency <= 1.0
    life = result.fatigue_life_h
    assert life > 0.0  # never NaN; infinite without load or motion (or a denormal speed)
    assert math.isfinite(life) or abs(speed_rpm) < 1e-200 or axial <= NEGLIGIBLE_LOAD_N


@settings(max_examples=30, deadline=None)
@given(
    presets(),
    st.floats(0.01, 3.0),
    st.floats(CONVERGED_SHARE, 0.99999),
    tilts(2.0),
    angles,
    cases,
    st.booleans(),
)
def test_load_distribution_up_to_the_contact_loss_limit(
    preset: Preset,
    fraction: float,
    share: float,
    tilt: tuple[float, float],
    theta: float,
    case: LoadingCase,
    elastic_errors: bool,
) -> None:
    """Between 95 % and 99.999 % of the radial capacity at the carrier angle most rollers
    float and the load piles onto a few (with a misalignment the clearances differ as well):
    the solver still converges and balances the loads."""
    geometry = preset.geometry
    axial = fraction * preset.largest_axial_load_n
    radial = share * float(radial_capacity_ratio(geometry, theta)) * axial
    try:
        mesh = meshing(geometry, Misalignment.from_arcmin(*tilt), carrier_angle_rad=theta)
    except DomainError as exc:
        assert "overlap" in str(exc)
        event("domain error")
        return
    loads = solve_load_distribution(
        geometry,
        axial,
        radial_load_n=radial,
        carrier_angle_rad=theta,
        clearance_screw_roller_m=mesh.axial_clearance_screw_roller_m,
        clearance_roller_nut_m=mesh.axial_clearance_roller_nut_m,
        case=case,
        elastic_errors=elastic_errors,
    )
    event("solved")
    assert loads.residual <= TOLERANCE
    assert np.all(np.isfinite(loads.screw_roller_n)) and np.all(loads.screw_roller_n >= 0.0)
    assert np.all(np.isfinite(loads.axial_offset_m)) and np.all(np.isfinite(loads.radial_offset_m))
    assert_balanced(preset, loads, axial, radial, theta)


@settings(max_examples=25, deadline=None)
@given(
    name=st.sampled_from(PRESET_NAMES),
    fraction=st.floats(1e-6, 3.0),
    excess=st.floats(1.0, 10.0),
    theta=angles,
)
def test_beyond_the_contact_loss_limit_is_a_domain_error(
    name: str, fraction: float, excess: float, theta: float
) -> None:
    geometry = load_preset(name).geometry
    axial = fraction * load_preset(name).largest_axial_load_n
    radial = excess * float(radial_capacity_ratio(geometry, theta)) * axial
    with pytest.raises(DomainError, match="opposite flank"):
        solve_load_distribution(geometry, axial, radial_load_n=radial, carrier_angle_rad=theta)


@settings(max_examples=30, deadline=None)
@given(
    screw=materials,
    roller=materials,
    ra_m=log_uniform(5e-8, 1.6e-6),
    loads=st.lists(st.floats(0.0, LARGEST_TABLE_LOAD_N), min_size=1, max_size=6),
)
def test_fractal_contact_solves_or_raises_and_grows_with_load(
    screw: Material, roller: Material, ra_m: float, loads: list[float]
) -> None:
    """001 eq. 22: the reference root solve balances the load to 1e-9 (checked inside, and
    again here), and the vectorised real area is finite, non-negative and non-decreasing."""
    surface = fractal_surface(screw, roller, ra_m)
    for load in loads:
        try:
            spot = solve_largest_spot_m2(surface, load)
        except ConvergenceError as exc:
            assert "residual" in str(exc)
            event("convergence error")
            continue
        assert math.isfinite(spot) and spot >= 0.0
        if load > 0.0 and spot >= surface.plastic_area_m2:
            assert float(surface.load_n(spot)) == pytest.approx(load, rel=1e-9)
    ordered = np.sort(np.asarray(loads))
    area = real_contact_area_m2(surface, ordered)
    assert np.all(np.isfinite(area)) and np.all(area >= 0.0)
    assert np.all(np.diff(area) >= 0.0)
