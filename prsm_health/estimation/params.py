"""The estimator's configuration: one validated object, loaded from YAML.

The same parameters serve offline replay, the ROS node and the benchmark. A params file::

    actuator:            # see prsm_health.actuator.actuator_from_mapping
      preset: dong2022-downhole
    noise: {...}         # NoiseParams
    model: {...}         # ModelParams
    filter: {...}        # FilterParams
    fidelity: {...}      # Fidelity (the named skips)
    diagnostics: {...}   # DiagnosticThresholds

Every section and key is optional except ``actuator.preset``; unknown keys are refused with
their dotted name. Units are SI except where the name says otherwise.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any, Literal

from prsm_health.actuator import Actuator, actuator_from_mapping, preset_beside_file
from prsm_health.config import build_dataclass, build_each
from prsm_health.physics.errors import ParameterError
from prsm_health.physics.geometry import require, require_integer, require_ranges
from prsm_health.yamlio import YamlError, load_yaml_mapping

#: The NIS divergence test needs at least this many blocks in its window
#: (``filter.divergence_window_s``).
MIN_BLOCKS_FOR_DIVERGENCE = 10
#: A rated load set in the diagnostics must lie within this factor of the preset's largest
#: paper load either way (the statuses and the divergence bound follow it: 55 meant as kN
#: instead of N would make every load an ERROR).
RATED_LOAD_FACTOR = 10.0
#: A load beyond this many times the load scale (or the rated load, if larger) has diverged,
#: whatever its NIS: the motor cannot drive it (at its current limit the default actuator's
#: screw carries about five times its largest paper load). Seen with the UKF, whose spread
#: can straddle F = 0, where a self-locked screw's friction slope changes sign. The estimator
#: re-initialises the load there, and the re-initialisation restarts such a load from zero.
DIVERGED_LOAD_RATIO = 10.0


@dataclass(frozen=True, kw_only=True)
class NoiseParams:
    """What the sensors are like (the simulator's defaults; docs/scenes.md).

    current_std_a: white noise of one current sample. speed_std_rad_s: of one motor speed
    sample, at least: the estimator measures the speed's noise in motion and takes the larger
    (:mod:`prsm_health.estimation.noise_history`). model_error_rel: relative error of the torque
    model (surrogate, unmodelled harmonics, radial load unknown), added to the measurement
    variance of each block.
    model_error_floor_nm: absolute floor of that error, motor side.
    torque_scale_error_rel: standard uncertainty of the torque per newton of load, relative:
    the drive train's calibration (torque constant, gear efficiency) and the friction
    coefficients. Not a noise: one fixed error, the same in every block, which makes every load
    wrong by about that fraction and which the motor signals cannot show (it scales the load).
    It is not filtered but added to each hypothesis' load variance as (error x load)^2 in the
    reported load's uncertainty and the wear and fatigue integration (0: the parameters are
    exact, as in the simulated scenes; docs/estimation.md, "When the parameters are wrong").
    """

    current_std_a: float = 0.05
    speed_std_rad_s: float = 0.2
    model_error_rel: float = 0.0015
    model_error_floor_nm: float = 0.005
    torque_scale_error_rel: float = 0.0

    def __post_init__(self) -> None:
        require_ranges(
            self,
            "noise",
            {
                "current_std_a": (1e-6, 100.0),
                "speed_std_rad_s": (1e-6, 1e3),
                "model_error_rel": (0.0, 1.0),
                "model_error_floor_nm": (1e-9, 1e3),
                "torque_scale_error_rel": (0.0, 0.5),
            },
        )


@dataclass(frozen=True, kw_only=True)
class ModelParams:
    """Prior knowledge about the operation (docs/estimation.md explains each choice).

    radial_load_ratio: typical F_r / F_a (0 = no radial load; the downhole robot's wall
    contact gives about 0.15). radial_load_ratio_std: its uncertainty (enters the wear
    rate's uncertainty). load_jerk_psd_n2_per_s5: how fast the axial load may change in
    steady motion: the white-noise density of its jerk (a constant-acceleration model; a load
    that followed the carrier-frequency ripple would cost tens of nats a second).
    load_jerk_psd_transition_n2_per_s5: the same while a stroke starts (the first
    load_transition_s of a direction of motion, unless it began with a reversal: there the
    load is found again, it does not build up) and at standstill, where the traction load
    builds up: a smooth ramp of the downhole cycle, 45 kN in 0.5 s, costs a few nats, a step in
    one block thousands. load_transition_acceleration_rad_s2: a block whose motor acceleration
    exceeds this in magnitude (a stroke starting or ending) is on the transition density too,
    and is predicted at its mean load, which bends within such a block (0: off). For a load
    released faster than the scenes' 0.5 s, with the transition density raised to match
    (docs/estimation.md, "A load released fast").
    ripple_prior_radial_n: size of the carrier-frequency torque ripple a new jammed roller adds,
    per cosine and sine component, as the radial load that makes it (the physics core's
    ripple per newton of radial load, surrogate.jammed_ripple_nm_per_n, scales it to the
    screw: 4 kN is 0.30 of the load torque at the ripple knee on dong2022-downhole, 0.09 on
    meng2022-misalignment); a first jam starts at twice its variance (docs/estimation.md,
    load model). ripple_walk_radial_n_per_sqrt_s: its drift as the radial load changes,
    likewise: along its phasor (the amplitude follows the wall's radial load), and in every
    direction while its phase is not yet known. ripple_phase_walk_radial_n_per_sqrt_s: its
    drift across the phasor once the phase is known (the phase is set by which rollers are
    jammed; hypotheses.ripple_walk).
    ripple_phase_known_rad: the phase counts as known when its standard deviation is below
    this. ripple_phase_walk_rad_per_sqrt_s: the phase's drift while a stroke starts, where the
    ripple of a hypothesis whose phase is known is updated in polar coordinates
    (estimation/phasor.py). jam_rate_per_h: prior rate of a new jam (0: the count rises
    only when told, estimation/evidence.py). initial_jammed_rollers: jammed count known at
    start (after maintenance, 0).
    wear_coefficient_factor: the actuator's wear coefficient relative to the preset's, when
    calibrated (1 = the preset's). wear_coefficient_sigma_ln: log-normal spread of the true
    coefficient around that value (0.5 is the prior the scenes draw from).
    plausible_load_factor: the axial load never exceeds this many times the preset's largest
    paper load; a hypothesis whose load lies more than three standard deviations beyond it
    is dropped while another lies within (0: no bound; hypotheses.PLAUSIBLE_LOAD_SIGMAS).
    """

    radial_load_ratio: float = 0.15
    radial_load_ratio_std: float = 0.1
    load_jerk_psd_n2_per_s5: float = 5.0e11
    load_jerk_psd_transition_n2_per_s5: float = 5.0e12
    load_transition_s: float = 1.0
    load_transition_acceleration_rad_s2: float = 0.0
    ripple_prior_radial_n: float = 4000.0
    ripple_walk_radial_n_per_sqrt_s: float = 1300.0
    ripple_phase_walk_radial_n_per_sqrt_s: float = 130.0
    ripple_phase_known_rad: float = 0.5
    ripple_phase_walk_rad_per_sqrt_s: float = 0.03
    jam_rate_per_h: float = 1e-3
    initial_jammed_rollers: int = 0
    wear_coefficient_factor: float = 1.0
    wear_coefficient_sigma_ln: float = 0.5
    plausible_load_factor: float = 1.5

    def releases_load(self, motor_acceleration_rad_s2: float) -> bool:
        """Whether a block whose drive accelerates at this rate (either sign) is taken as a load
        being released or built up (``load_transition_acceleration_rad_s2``; never when 0)."""
        return 0.0 < self.load_transition_acceleration_rad_s2 < abs(motor_acceleration_rad_s2)

    def __post_init__(self) -> None:
        require_ranges(
            self,
            "model",
            {
                "radial_load_ratio": (0.0, 0.9),
                "radial_load_ratio_std": (0.0, 1.0),
                "load_jerk_psd_n2_per_s5": (1e-3, 1e24),
                "load_jerk_psd_transition_n2_per_s5": (1e-3, 1e24),
                "load_transition_s": (0.0, 1e3),
                "load_transition_acceleration_rad_s2": (0.0, 1e9),
                "ripple_prior_radial_n": (1e-3, 1e7),
                "ripple_walk_radial_n_per_sqrt_s": (1e-3, 1e7),
                "ripple_phase_walk_radial_n_per_sqrt_s": (1e-3, 1e7),
                "ripple_phase_known_rad": (1e-6, math.pi),
                "ripple_phase_walk_rad_per_sqrt_s": (1e-9, 10.0),
                "jam_rate_per_h": (0.0, 1e6),
                "wear_coefficient_factor": (1e-6, 1e6),
                "wear_coefficient_sigma_ln": (0.0, 5.0),
                "plausible_load_factor": (0.0, 1e3),
            },
        )
        require_integer(self.initial_jammed_rollers, "model.initial_jammed_rollers", 0)


@dataclass(frozen=True, kw_only=True)
class FilterParams:
    """How samples become filter updates, and the numerical-safety thresholds.

    block_duration_s: samples are averaged over blocks of this duration (one filter update
    each). standstill_speed_rad_s: motor speed below which a block is standstill.
    max_gap_s: a longer gap between accepted samples starts a new block grid (the block after
    it is never merged into a standstill), and one block integrates wear and fatigue over at
    most this long. time_reset_after_s: time going backwards is rejected until the
    jumped-back clock has advanced this long on its own (over at least
    inputs.TIME_RESET_SAMPLES samples); then it is followed and the load
    re-initialised (event TIME_RESET). (A silence of more than estimator.HOLE_BLOCKS blocks
    keeps the load but forgets its derivatives.) gate_nis: a block whose
    normalised innovation squared exceeds it in every active hypothesis is rejected as an
    outlier. divergence_nis: mean NIS over divergence_window_s above it means the filter is
    inconsistent; the load is re-initialised (event DIVERGENCE_RECOVERED).
    min_hypothesis_probability: below it a fresh jam hypothesis (a jam in the last block,
    weighed by that block) is pruned; min_established_probability: below it an established
    one is (when pruning is on; hypotheses.py says why the two differ).
    components_per_count: most Gaussians kept per jam count; merge_distance_sigmas: two of one
    count whose loads differ by less than this many standard deviations become one
    (hypotheses.py: a jam that happened unseen and one that starts now are different).
    max_speed_rad_s: motor speeds beyond it are out of range (rejected). Default 0 means
    three times the preset's largest speed. max_acceleration_rad_s2: the motor's speed
    cannot change faster; a speed sample further from both its neighbours than that allows
    is a spike (rejected; sample_faults.py). Default 0 means from the drive train
    (EstimatorParams.max_motor_acceleration_rad_s2).
    """

    block_duration_s: float = 0.04
    standstill_speed_rad_s: float = 1.0
    max_gap_s: float = 0.5
    time_reset_after_s: float = 0.1
    gate_nis: float = 36.0
    divergence_nis: float = 12.0
    divergence_window_s: float = 2.0
    min_hypothesis_probability: float = 1e-9
    min_established_probability: float = 1e-13
    components_per_count: int = 2
    merge_distance_sigmas: float = 3.0
    max_speed_rad_s: float = 0.0
    max_acceleration_rad_s2: float = 0.0

    def __post_init__(self) -> None:
        require_ranges(
            self,
            "filter",
            {
                "block_duration_s": (1e-4, 10.0),
                "standstill_speed_rad_s": (0.0, 1e3),
                "max_gap_s": (1e-3, 1e6),
                "time_reset_after_s": (1e-3, 1e3),
                "gate_nis": (1.0, 1e6),
                "divergence_nis": (1.0, 1e6),
                "divergence_window_s": (1e-3, 1e4),
                "min_hypothesis_probability": (0.0, 0.1),
                "min_established_probability": (0.0, 0.1),
                "merge_distance_sigmas": (0.0, 1e3),
                "max_speed_rad_s": (0.0, 1e5),
                "max_acceleration_rad_s2": (0.0, 1e9),
            },
        )
        require(
            self.max_gap_s >= self.block_duration_s,
            "filter.max_gap_s",
            f"must be at least filter.block_duration_s ({self.block_duration_s:g} s), got "
            f"{self.max_gap_s:g} (a block's wear and fatigue are integrated over at most it)",
        )
        shortest = MIN_BLOCKS_FOR_DIVERGENCE * self.block_duration_s
        require(
            self.divergence_window_s >= shortest,
            "filter.divergence_window_s",
            f"must hold at least {MIN_BLOCKS_FOR_DIVERGENCE} blocks ({shortest:g} s), got "
            f"{self.divergence_window_s:g} (a shorter window never judges divergence)",
        )
        require_integer(self.components_per_count, "filter.components_per_count", 1, 8)


FilterKind = Literal["ekf", "ukf"]


@dataclass(frozen=True, kw_only=True)
class Fidelity:
    """The named skips and model choices (each one switchable for the benchmark).

    surrogate: the physics through tables built once per geometry (False: the full physics
    core at every evaluation, the naive reference). radial_terms: "auto" keeps the
    carrier-harmonic ripple states only when a radial load or a misalignment is configured;
    "on" always; "off" never. skip_standstill: no wear or fatigue integration at standstill
    (the rates are zero there anyway; jam evidence is never used at standstill).
    prune_hypotheses: drop ruled-out jam counts and keep only the next possible jam above the
    plausible ones. merge_standstill_blocks: one filter update per standstill_block_s instead
    of per block while nothing moves. filter: "ekf" or "ukf".
    """

    surrogate: bool = True
    radial_terms: Literal["auto", "on", "off"] = "auto"
    skip_standstill: bool = True
    prune_hypotheses: bool = True
    merge_standstill_blocks: bool = True
    standstill_block_s: float = 0.5
    filter: FilterKind = "ekf"

    def __post_init__(self) -> None:
        for name in ("surrogate", "skip_standstill", "prune_hypotheses", "merge_standstill_blocks"):
            value = getattr(self, name)
            require(
                isinstance(value, bool),
                f"fidelity.{name}",
                f"must be true or false, got {value!r}",
            )
        require(
            self.radial_terms in ("auto", "on", "off"),
            "fidelity.radial_terms",
            f"must be auto, on or off, got {self.radial_terms!r}",
        )
        require(
            self.filter in ("ekf", "ukf"),
            "fidelity.filter",
            f"must be ekf or ukf, got {self.filter!r}",
        )
        require_ranges(self, "fidelity", {"standstill_block_s": (1e-3, 60.0)})


@dataclass(frozen=True, kw_only=True)
class DiagnosticThresholds:
    """Levels of the diagnostics (OK / WARN / ERROR) and input health limits.

    rated_load_n: 0 means the preset's largest paper load; else within RATED_LOAD_FACTOR of it.
    Only the statuses and the divergence bound follow it (EstimatorParams.diverged_load_n), not
    the filter's model. load_warn/error_fraction: of the
    rated load. jam_warn_probability: P(at least one jammed roller) that raises WARN; a most
    likely count >= 1 is ERROR. precision_loss_budget_um: the allowed loss; warn/error
    fractions of it. fatigue_warn/error_damage: Miner damage levels. stale_timeout_s: inputs
    older than this make every status STALE. min_input_rate_hz: below it, input health WARN.
    rejected_warn_fraction: share of rejected samples (last second) that raises WARN.
    """

    rated_load_n: float = 0.0
    load_warn_fraction: float = 0.9
    load_error_fraction: float = 1.1
    jam_warn_probability: float = 0.2
    precision_loss_budget_um: float = 50.0
    precision_loss_warn_fraction: float = 0.7
    precision_loss_error_fraction: float = 1.0
    fatigue_warn_damage: float = 0.5
    fatigue_error_damage: float = 0.9
    stale_timeout_s: float = 1.0
    min_input_rate_hz: float = 100.0
    rejected_warn_fraction: float = 0.05

    def __post_init__(self) -> None:
        require_ranges(
            self,
            "diagnostics",
            {
                "rated_load_n": (0.0, 1e9),
                "load_warn_fraction": (0.0, 10.0),
                "load_error_fraction": (0.0, 10.0),
                "jam_warn_probability": (0.0, 1.0),
                "precision_loss_budget_um": (1e-6, 1e6),
                "precision_loss_warn_fraction": (0.0, 10.0),
                "precision_loss_error_fraction": (0.0, 10.0),
                "fatigue_warn_damage": (0.0, 10.0),
                "fatigue_error_damage": (0.0, 10.0),
                "stale_timeout_s": (1e-3, 1e4),
                "min_input_rate_hz": (0.0, 1e6),
                "rejected_warn_fraction": (0.0, 1.0),
            },
        )
        for low, high in (
            ("load_warn_fraction", "load_error_fraction"),
            ("precision_loss_warn_fraction", "precision_loss_error_fraction"),
            ("fatigue_warn_damage", "fatigue_error_damage"),
        ):
            require(
                getattr(self, low) <= getattr(self, high),
                f"diagnostics.{low}",
                f"must not exceed diagnostics.{high}",
            )


@dataclass(frozen=True, kw_only=True)
class EstimatorParams:
    """Everything the estimator needs: the actuator and the sections above."""

    actuator: Actuator
    noise: NoiseParams = field(default_factory=NoiseParams)
    model: ModelParams = field(default_factory=ModelParams)
    filter: FilterParams = field(default_factory=FilterParams)
    fidelity: Fidelity = field(default_factory=Fidelity)
    diagnostics: DiagnosticThresholds = field(default_factory=DiagnosticThresholds)

    def __post_init__(self) -> None:
        n_rollers = self.actuator.preset.geometry.n_rollers
        require(
            self.model.initial_jammed_rollers <= n_rollers,
            "model.initial_jammed_rollers",
            f"must be <= n_rollers = {n_rollers}",
        )
        rated, largest = self.diagnostics.rated_load_n, self.actuator.preset.largest_axial_load_n
        require(
            rated == 0.0 or largest / RATED_LOAD_FACTOR <= rated <= largest * RATED_LOAD_FACTOR,
            "diagnostics.rated_load_n",
            f"must be 0 (the preset's largest load, {largest:g} N) or within "
            f"{RATED_LOAD_FACTOR:g}x of it, in N; got {rated:g}",
        )

    @property
    def rated_load_n(self) -> float:
        """The load the diagnostics compare against (the preset's largest by default)."""
        rated = self.diagnostics.rated_load_n
        return rated if rated > 0.0 else self.actuator.preset.largest_axial_load_n

    @property
    def load_scale_n(self) -> float:
        """The filter's load scale: the preset's largest paper load (initial variances, the
        ripple's knee, the friction's kink, the size of an update that is checked). A
        property of the screw, not of the diagnostics: setting ``rated_load_n`` as an alarm
        level must not change the estimates."""
        return self.actuator.preset.largest_axial_load_n

    @property
    def diverged_load_n(self) -> float:
        """A likeliest load beyond this has diverged (DIVERGED_LOAD_RATIO of the larger of the
        load scale and the rated load: an actuator rated above its preset's paper loads may
        carry such loads)."""
        return DIVERGED_LOAD_RATIO * max(self.load_scale_n, self.rated_load_n)

    @property
    def max_motor_speed_rad_s(self) -> float:
        """Largest plausible motor speed; faster samples are rejected as out of range."""
        if self.filter.max_speed_rad_s > 0.0:
            return self.filter.max_speed_rad_s
        screw = self.actuator.preset.largest_speed_rpm * 2.0 * math.pi / 60.0
        return 3.0 * screw * self.actuator.drive_train.gear_ratio

    @property
    def max_motor_acceleration_rad_s2(self) -> float:
        """Largest plausible motor acceleration (``filter.max_acceleration_rad_s2``, or else):
        the motor's largest torque (k_t at ``max_current_a``) and the screw torque of the
        largest load (F L / 2 pi through the gear ratio, no efficiency: at most; the load
        bound ``model.plausible_load_factor``, or without one the divergence bound), both the
        same way, over the inertia at the motor. 1.9e5 rad/s^2 for the bundled actuator."""
        if self.filter.max_acceleration_rad_s2 > 0.0:
            return self.filter.max_acceleration_rad_s2
        drive = self.actuator.drive_train
        load_n = self.model.plausible_load_factor * self.load_scale_n
        if load_n == 0.0:  # no load bound
            load_n = self.diverged_load_n
        lead_m = self.actuator.preset.geometry.lead_m
        load_torque_nm = load_n * lead_m / (2.0 * math.pi) / drive.gear_ratio
        motor_torque_nm = drive.max_current_a * drive.torque_constant_nm_per_a
        return (motor_torque_nm + load_torque_nm) / drive.inertia_at_motor_kg_m2

    @property
    def radial_terms(self) -> bool:
        """Whether the carrier-harmonic ripple states are part of the filter."""
        mode = self.fidelity.radial_terms
        if mode == "auto":
            return self.model.radial_load_ratio > 0.0 or not self.actuator.misalignment.is_aligned
        return mode == "on"


_SECTIONS: dict[str, type[Any]] = {
    "noise": NoiseParams,
    "model": ModelParams,
    "filter": FilterParams,
    "fidelity": Fidelity,
    "diagnostics": DiagnosticThresholds,
}


def params_from_mapping(data: dict[str, Any]) -> EstimatorParams:
    """Validate a parsed params document (see the module docstring)."""
    unknown = sorted(set(data) - {"actuator", *_SECTIONS})
    if unknown:
        raise ParameterError(
            unknown[0], f"unknown section; allowed: actuator, {', '.join(_SECTIONS)}"
        )
    if "actuator" not in data:
        raise ParameterError("actuator", "missing (at least actuator.preset is required)")
    # Every section is checked, so that one edit fixes every bad section (every value out of
    # its range is named; the checks of values against each other follow).
    parts: dict[str, Callable[[], Any]] = {
        "actuator": lambda: actuator_from_mapping(data["actuator"])
    }
    for name, cls in _SECTIONS.items():
        parts[name] = partial(build_dataclass, cls, data.get(name), name)
    return EstimatorParams(**build_each(parts))


def load_params_mapping(path: Path) -> dict[str, Any]:
    """A params YAML file parsed, its preset file (if it names one by a relative path) taken
    from the file's folder (:func:`~prsm_health.actuator.preset_beside_file`).

    Raises:
        YamlError: the file cannot be read or parsed, or is no mapping.
    """
    return preset_beside_file(load_yaml_mapping(path), path)


def load_params(path: str | Path, *, actuator_if_none: Any = None) -> EstimatorParams:
    """Load a params YAML file; errors name the file (and the bad key). ``actuator_if_none``:
    the ``actuator:`` section of a file that has none (settings only), if given."""
    path = Path(path)
    try:
        data = load_params_mapping(path)
        if actuator_if_none is not None:
            data = {"actuator": actuator_if_none, **data}
        return params_from_mapping(data)
    except YamlError as exc:
        raise ParameterError("params", str(exc)) from exc
    except ParameterError as exc:
        raise exc.in_file(path) from exc


#: The bundled parameters of the downhole actuator, relative to the package's share directory
#: (installed) or the source tree (editable install, checkout).
BUNDLED_PARAMS = Path("config", "default.yaml")


def bundled_params_file() -> Path:
    """``config/default.yaml``: from the ament index when the package is installed there, else
    from the source tree."""
    try:
        from ament_index_python.packages import get_package_share_directory

        installed = Path(get_package_share_directory("prsm_health")) / BUNDLED_PARAMS
        if installed.is_file():
            return installed
    except (ImportError, LookupError, OSError, ValueError):  # not installed through ament
        pass
    return Path(__file__).resolve().parents[2] / BUNDLED_PARAMS
