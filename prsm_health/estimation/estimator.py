"""The health estimator: motor samples in, :class:`HealthState` estimates out.

One object serves offline replay (chunks of thousands of samples), the ROS node (one sample at
a time) and the benchmark; results do not depend on the chunking (but for the sample counters
an estimate carries, which count every sample judged when it was made). The pipeline per block:
:class:`~prsm_health.estimation.inputs.SampleBlocker` (validation, blocks) ->
:class:`~prsm_health.estimation.hypotheses.JamHypotheses` (IMM of filterpy filters over the
jam count, measurement model of :mod:`~prsm_health.estimation.measurement`) ->
:class:`~prsm_health.estimation.degradation.DegradationIntegrator` (precision loss, fatigue).
docs/estimation.md explains the model, what is observable and each option.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from typing import Any

import numpy as np

from prsm_health.estimation.degradation import DegradationIntegrator
from prsm_health.estimation.estimate import EstimateEvent, HealthState
from prsm_health.estimation.hypotheses import JamHypotheses, StepResult
from prsm_health.estimation.inputs import (
    Block,
    InputCounters,
    InputMeasures,
    SampleBlocker,
    merge_blocks,
)
from prsm_health.estimation.measurement import LOAD, TorqueModel
from prsm_health.estimation.noise_history import NoiseHistory
from prsm_health.estimation.params import MIN_BLOCKS_FOR_DIVERGENCE, EstimatorParams
from prsm_health.estimation.snapshot import (
    NOISE_KEYS,
    SNAPSHOT_FORMAT,
    actuator_fingerprint,
    actuator_parts,
    read_snapshot,
    screw_fingerprint,
)
from prsm_health.estimation.surrogate import physics_averages
from prsm_health.physics.friction import efficiency
from prsm_health.physics.geometry import require_integer
from prsm_health.physics.load_distribution import radial_capacity_ratio
from prsm_health.signals import MotorSamples

#: Consecutive gated blocks after which the load is re-initialised (a lasting change that no
#: hypothesis explains, e.g. a load step far beyond the load model).
GATED_BLOCKS_BEFORE_RESET = 5
#: A block whose first sample comes more than this many block periods after the previous
#: block's last one follows a hole in the data (dropouts, rejected samples): the load may
#: have moved on unseen.
HOLE_BLOCKS = 3.0
#: After a hole, jam evidence is not used for this long, while the load is found again: a
#: load that changed inside the hole would otherwise look like a jam.
REACQUIRE_S = 0.25
#: A block that moves against the last moving block less than this long after it reverses
#: the motion through zero (HealthEstimator._reverses): the load had no time to go, it may
#: have stepped. After a longer stop the load builds up again as a stroke starts (the downhole
#: cycle's supports last 0.5 s and more), and forgetting it there loses what the standstill
#: showed: on the benchmark's 24 generated runs, pooled load RMSE 5.61 % instead of 5.43 %
#: and the load NEES consistent on 3 of them instead of 7 (docs/estimation.md, "Reversals").
REVERSAL_WITHIN_S = 0.5


class HealthEstimator:
    """Estimates load, jammed rollers, precision loss and fatigue from motor samples."""

    def __init__(self, params: EstimatorParams) -> None:
        self.params = params
        self._blocker = SampleBlocker(params)
        self._model = TorqueModel(params)
        self._bank = JamHypotheses(params, self._model)
        self._torque_scale_error_rel = params.noise.torque_scale_error_rel
        self._degradation = DegradationIntegrator(
            wear_coefficient_sigma_ln=params.model.wear_coefficient_sigma_ln,
            radial_relative_sensitivity=_radial_sensitivity(params),
        )
        self._standstill: list[Block] = []
        self._nis: deque[tuple[float, float]] = deque()
        self._gated_run = 0
        self._blind_until_s = -math.inf
        self._direction = 0
        self._direction_since_s = -math.inf
        self._moving_direction = 0  # the last moving block's direction
        self._moving_s = -math.inf  # and its stamp
        self._resumed = False
        self._divergence_unsaid = False  # on a time reset's block: said by the next estimate
        self._last: HealthState | None = None

    @property
    def counters(self) -> InputCounters:
        """Samples accepted and rejected (by reason) so far."""
        return self._blocker.counters

    @property
    def input_clock_s(self) -> float | None:
        """The stamp of the latest accepted input sample (:attr:`SampleBlocker.input_clock_s`):
        the offline replay's clock for the diagnostics, as a node's is the time it receives."""
        return self._blocker.input_clock_s

    @property
    def input_measures(self) -> InputMeasures:
        """What the input stage has measured of the inputs so far (:class:`InputMeasures`; its
        noises are used where larger than ``noise.speed_std_rad_s`` and
        ``noise.current_std_a``)."""
        return self._blocker.measures()

    @property
    def log_evidence(self) -> float:
        """log p(y) of the blocks that weighed the jam counts so far, under the filter bank's
        model (the sum of the log normalisers of the counts' probabilities)."""
        return self._bank.log_evidence

    def assume_jam_onset(self, jammed_rollers: int) -> list[HealthState]:
        """Diagnostics (estimation/evidence.py): the samples fed so far are estimated (their
        estimates are returned, as by :meth:`finish`); from now on ``jammed_rollers`` are
        jammed for certain, as if the extra jams had just been born in the filter (the likeliest
        state and ripple, a new roller's ripple prior each; :meth:`JamHypotheses.assume_onset`).

        Raises:
            ValueError: not an integer within 0..N (nothing is changed then); fewer jammed
                rollers than the likeliest hypothesis has (nothing is changed then but the
                pending estimates).
        """
        count = self._count(jammed_rollers)
        before = self.finish(end_of_data=False)
        self._bank.assume_onset(count)
        return before

    def _count(self, jammed_rollers: object) -> int:
        """``jammed_rollers`` as an int, refused unless an integer within 0..N (N: the
        preset's rollers; :func:`require_integer`, which also refuses a bool: it indexed every
        hypothesis at once). A numpy integer is a count like an int."""
        count = int(jammed_rollers) if isinstance(jammed_rollers, np.integer) else jammed_rollers
        return require_integer(count, "jammed_rollers", 0, self._bank.n_rollers)

    # --- persistence --------------------------------------------------------------------
    def snapshot(self) -> dict[str, Any]:
        """Everything needed to resume after a restart, as plain JSON-able data.

        The hypotheses' filter states, ripple axes and probabilities, the accumulated
        degradation, the input counters, the noises the input stage measured (the speed's
        in motion, the current's), and fingerprints
        of the screw and of the rest of the actuator (:meth:`restore` says what it does with
        them).
        """
        bank = self._bank
        return {
            "format": SNAPSHOT_FORMAT,
            "screw": screw_fingerprint(self.params),
            "actuator": actuator_fingerprint(self.params),
            "parts": actuator_parts(self.params),
            "hypotheses": [
                {
                    "count": h.count,
                    "fresh": h.fresh,
                    # JSON has no -inf: None is a count ruled out (unpruned banks keep them).
                    "log_probability": h.log_prob if math.isfinite(h.log_prob) else None,
                    "x": h.filter.x.tolist(),
                    "P": h.filter.P.tolist(),
                    "ripple_axis": None if h.ripple_axis is None else h.ripple_axis.tolist(),
                }
                for h in bank.hypotheses
            ],
            "degradation": self._degradation.state.to_dict(),
            "samples_accepted": self.counters.accepted,
            "samples_rejected": self.counters.rejected,
            **{key: noise.saved() for key, noise in self._blocker_noises()},
        }

    def restore(self, snapshot: dict[str, Any]) -> tuple[str, ...]:
        """Resume from :meth:`snapshot`. The first block after it follows a hole of unknown
        length.

        A snapshot of the same screw whose drive train, misalignment or ripple states differ
        (the parameters were changed between the save and now, e.g. a recalibrated torque
        constant) resumes what belongs to the screw, the accumulated degradation and the
        jam-count probabilities, and starts the filters' states (load, ripple) afresh: they
        were estimated through the old parameters.

        Returns:
            What differs from the saved state's parameters, by name ("drive train",
            "misalignment", "ripple states"; SOME_PART for a state saved before it said): empty
            when the filters' states were resumed too, else only the screw's part was.

        Raises:
            SnapshotError: the snapshot is malformed or of another screw, named by
                :func:`~prsm_health.estimation.snapshot.read_snapshot` (nothing is changed
                then).
        """
        saved = read_snapshot(
            snapshot,
            self.params,
            state_dim=self._model.dim,
            n_rollers=self._bank.n_rollers,
            rejection_reasons=len(self.counters.rejected),
        )
        if saved.changed_parts:
            self._bank.restart_filters(
                [(h.jammed_rollers, h.log_probability) for h in saved.hypotheses]
            )
        else:
            self._bank.restore(saved.hypotheses)
        self._degradation.state = saved.degradation
        self.counters.accepted = saved.samples_accepted
        self.counters.rejected = saved.samples_rejected
        for key, noise in self._blocker_noises():
            noise.resume(saved.noise_variances[key])
        self._resumed = True
        self._last = None
        return saved.changed_parts

    def _blocker_noises(self) -> zip[tuple[str, NoiseHistory]]:
        """The noises the input stage measures, with their snapshot keys."""
        blocker = self._blocker
        return zip(NOISE_KEYS, (blocker.speed_noise, blocker.faults.current_noise), strict=True)

    def reset_after_maintenance(
        self, jammed_rollers: int, *, reset_precision_loss: bool, reset_fatigue_damage: bool
    ) -> list[HealthState]:
        """Maintenance: the jammed-roller count is known again, replaced parts are unworn.

        The filter's jams only ever increase (docs/estimation.md); maintenance is the one way
        back. The samples fed before the call belong to before the maintenance: their pending
        block is closed and estimated first, as in a pause (:meth:`finish` with
        ``end_of_data`` False: a last sample that jumped far ahead waits for what follows), and
        those estimates are returned. Then ``jammed_rollers`` (0..N, usually 0 once the
        jammed rollers were freed or replaced) becomes certain, with the likeliest
        hypothesis' load and an unknown ripple (:meth:`JamHypotheses.reset_count`).
        ``reset_precision_loss``: the worn parts were replaced, so the precision loss and its
        uncertainty start again from zero; ``reset_fatigue_damage`` likewise for the Miner
        damage.

        Raises:
            ValueError: ``jammed_rollers`` not an integer within 0..N (N: the preset's
                rollers), or a flag not a bool (the string "no" is true, and would reset what
                was kept); nothing is done then.
        """
        count = self._count(jammed_rollers)
        flags = {
            "reset_precision_loss": reset_precision_loss,
            "reset_fatigue_damage": reset_fatigue_damage,
        }
        for name, flag in flags.items():
            if not isinstance(flag, bool):
                raise ValueError(f"{name}: must be a bool, got {flag!r}")
        before = self.finish(end_of_data=False)  # more samples follow the maintenance
        self._bank.reset_count(count)
        self._nis.clear()  # the consistency before the maintenance says nothing about after
        self._gated_run = 0
        self._divergence_unsaid = False  # a recovery before it is no news after it
        self._degradation.reset(
            precision_loss=reset_precision_loss, fatigue_damage=reset_fatigue_damage
        )
        return before

    def current_state(self, saved: HealthState | None = None) -> HealthState | None:
        """The latest estimate brought up to the state now, e.g. after
        :meth:`reset_after_maintenance`: jam probabilities, degradation, sample counters and
        mean NIS (0 while its window is empty) as they are now; the stamp, load, friction,
        efficiency and speed of the last estimated block, which no later sample has changed;
        event NONE (no new block). Before the first estimate (also after a restore) the same
        of ``saved``, an estimate saved with a restored state (the node keeps one), with the
        load and its standard deviation the filters' now (after a restore under other
        parameters they start afresh: the saved load no longer holds), or None."""
        counters = self._blocker.counters
        now = self._standing_fields(counters.accepted, counters.rejected_total)
        if self._last is not None:
            return dataclasses.replace(self._last, event=EstimateEvent.NONE, **now)
        if saved is None:
            return None
        weights = [math.exp(h.log_prob) for h in self._bank.hypotheses]  # normalised
        loads, variances = self._load_moments()
        load, load_var = _mixed(weights, loads, variances)
        return dataclasses.replace(
            saved,
            axial_load_n=load,
            axial_load_std_n=math.sqrt(load_var),
            event=EstimateEvent.NONE,
            **now,
        )

    def process(self, samples: MotorSamples) -> list[HealthState]:
        """Feed samples (any number); returns the estimates of the blocks they complete.

        Raises:
            TypeError: ``samples`` is not a :class:`~prsm_health.signals.MotorSamples`.
        """
        if not isinstance(samples, MotorSamples):
            raise TypeError(
                "process: samples must be a prsm_health.signals.MotorSamples (stamp_s, "
                f"current_a, speed_rad_s, position_rad columns), got {type(samples).__name__}"
            )
        return self._run(self._blocker.feed(samples))

    def finish(self, *, end_of_data: bool = True) -> list[HealthState]:
        """Estimates of the samples still pending (call at the end of a bag). ``end_of_data``
        False: a pause (the node's input went silent), after which more may come; a last
        sample that jumped far ahead then waits for it to be judged (a wrong stamp just before
        a pause was accepted, and the good samples after it rejected until a time reset)."""
        states = self._run(self._blocker.flush(end_of_data=end_of_data))
        if self._standstill:
            states.append(self._update(merge_blocks(self._standstill)))
            self._standstill.clear()
        return states

    def _run(self, blocks: list[Block]) -> list[HealthState]:
        states = []
        fidelity = self.params.fidelity
        for block in blocks:
            quiet = (
                block.direction == 0
                and not block.time_reset
                and not block.after_gap
                and not self._after_hole(block)
            )
            if fidelity.merge_standstill_blocks and quiet:
                self._standstill.append(block)
                span = block.stamp_s - self._standstill[0].stamp_s
                if span + self.params.filter.block_duration_s >= fidelity.standstill_block_s:
                    states.append(self._update(merge_blocks(self._standstill)))
                    self._standstill.clear()
                continue
            if self._standstill:
                states.append(self._update(merge_blocks(self._standstill)))
                self._standstill.clear()
            states.append(self._update(block))
        return states

    def _update(self, block: Block) -> HealthState:
        """Estimate ``block``. Its event is the first that applies of TIME_RESET,
        DIVERGENCE_RECOVERED, STANDSTILL, NONE (:class:`EstimateEvent`); a divergence on the
        block of a time reset is said by the next estimate."""
        diverged = self._divergence_unsaid
        if block.time_reset:
            # A new time line: the load and the consistency tests start again.
            self._bank.reinitialise_load()
            self._nis.clear()
            self._gated_run = 0
        # After a restore the time since the saved state is unknown (the input stage's clock is
        # not saved): the first block follows a hole of unknown length.
        hole = self._resumed or self._after_hole(block)
        self._resumed = False
        if hole and not block.time_reset:
            self._bank.reinitialise_load(keep_load=True)
        reverses = self._reverses(block)
        if reverses:
            self._bank.reinitialise_load()
        if block.time_reset or hole:
            self._blind_until_s = block.stamp_s + REACQUIRE_S
        transition = self._load_transition(block, reverses=reverses)
        model = self.params.model
        step = self._bank.step(
            block,
            jerk_psd=model.load_jerk_psd_transition_n2_per_s5
            if transition
            else model.load_jerk_psd_n2_per_s5,
            evidence=block.stamp_s > self._blind_until_s,
            load_transition=transition,
        )
        if self._diverged(block, step):
            self._bank.reinitialise_load()
            self._nis.clear()
            self._gated_run = 0
            diverged = True
        self._divergence_unsaid = diverged and block.time_reset
        if block.time_reset:
            event = EstimateEvent.TIME_RESET
        elif diverged:
            event = EstimateEvent.DIVERGENCE_RECOVERED
        else:
            event = EstimateEvent.STANDSTILL if block.direction == 0 else EstimateEvent.NONE
        hypotheses = self._bank.hypotheses
        weights = [math.exp(h.log_prob) for h in hypotheses]
        loads, variances = self._load_moments()
        moving = block.direction != 0
        if moving or not self.params.fidelity.skip_standstill:
            duration = self._wear_duration_s(block)
            load_std = [math.sqrt(v) for v in variances]
            self._degradation.add(duration, weights, step.predictions, load_std)
        else:
            self._degradation.stop()
        self._last = self._state(block, step, weights, loads, variances, event)
        return self._last

    def _wear_duration_s(self, block: Block) -> float:
        """How long ``block`` stands for in the wear and fatigue integration: its duration, at
        most ``filter.max_gap_s``; but where the motor's positions say it turned, at the
        block's speed, for less than half of that since the previous block (the stamps run
        fast, or it stood through part of a gap), only for as long as it turned. Wear grows
        with the travel: stamps in milliseconds read as seconds added 1,000 times too much
        wear (every sample a silence of a second at 1 kHz, of a quarter at 4 kHz; blocks of a
        few samples spanning 40 ms of stamps at 100 kHz; found by reviews). Otherwise the
        positions are not used (within the factor of two their noise would only bias the
        time), nor where they did not change at all: a stuck position sensor, not a clock."""
        duration = min(block.duration_s, self.params.filter.max_gap_s)
        speed = abs(block.motor_speed_rad_s)
        if not (block.travel_rad > 0.0 and speed > 0.0):  # NaN: no previous position
            return duration
        turning_s = block.travel_rad / speed
        return min(turning_s, duration) if turning_s < 0.5 * block.duration_s else duration

    def _reverses(self, block: Block) -> bool:
        """Whether the motion reverses through zero in ``block`` (its samples move both ways)
        or just before it (it moves against the last moving block, less than
        REVERSAL_WITHIN_S after it). The load may jump there: a load that resists the motion,
        e.g. the friction of the robot's body on the wall, changes sign with it. A time reset
        starts a time line without a last moving block."""
        if block.time_reset:
            self._moving_direction = 0
        reverses = block.reverses
        if block.direction:
            reverses = reverses or (
                block.direction == -self._moving_direction
                and block.stamp_s - self._moving_s < REVERSAL_WITHIN_S
            )
            self._moving_direction, self._moving_s = block.direction, block.stamp_s
        return reverses

    def _load_transition(self, block: Block, *, reverses: bool) -> bool:
        """Whether a stroke starts (the first ``model.load_transition_s`` of a direction of
        motion) or the actuator stands. The load model's jerk density is high there (the
        traction load builds up as the motion starts) and low in steady motion, where a load
        that follows the carrier-frequency ripple would otherwise hide a jammed roller. A time
        reset starts a new time line, and its first ``model.load_transition_s`` too. A direction
        that ``reverses`` the motion (:meth:`_reverses`) starts no transition: the load was
        forgotten there and is found again from the torque, not built up; on a sine stroke the
        transition took half of each 2 s half-cycle, where the healthy hypothesis' load followed
        a jammed roller's ripple and the jam was lost (docs/estimation.md, "Reversals"). With
        ``model.load_transition_acceleration_rad_s2`` set, a block whose drive accelerates or
        decelerates faster than that is a transition too (a stroke ending: the load released)."""
        if block.time_reset or block.direction != self._direction:
            self._direction = block.direction
            self._direction_since_s = -math.inf if reverses else block.stamp_s
        model = self.params.model
        return (
            block.direction == 0
            or block.stamp_s - self._direction_since_s < model.load_transition_s
            or model.releases_load(block.motor_acceleration_rad_s2)
        )

    def _after_hole(self, block: Block) -> bool:
        """More than HOLE_BLOCKS blocks without an accepted sample before ``block``."""
        return block.silence_before_s > HOLE_BLOCKS * self.params.filter.block_duration_s

    def _diverged(self, block: Block, step: StepResult) -> bool:
        """Gated for too long, the likeliest load beyond the divergence bound
        (EstimatorParams.diverged_load_n), or the mean NIS of the likeliest hypothesis too
        large."""
        self._gated_run = self._gated_run + 1 if step.gated else 0
        if self._gated_run >= GATED_BLOCKS_BEFORE_RESET:
            return True
        likeliest = self._bank.most_likely()
        if abs(float(likeliest.filter.x[LOAD])) > self.params.diverged_load_n:
            return True
        if step.gated:
            return False
        best = self._bank.hypotheses.index(likeliest)
        self._nis.append((block.stamp_s, step.nis[best]))
        window = self.params.filter.divergence_window_s
        while self._nis and self._nis[0][0] < block.stamp_s - window:
            self._nis.popleft()
        if len(self._nis) < MIN_BLOCKS_FOR_DIVERGENCE:
            return False
        return self._mean_nis() > self.params.filter.divergence_nis

    def _mean_nis(self) -> float:
        return sum(value for _, value in self._nis) / len(self._nis) if self._nis else math.nan

    def _state(
        self,
        block: Block,
        step: StepResult,
        weights: list[float],
        loads: list[float],
        variances: list[float],
        event: EstimateEvent,
    ) -> HealthState:
        """The estimate of ``block``: the hypotheses' loads and load variances
        (:meth:`_load_moments`) mixed with their ``weights``."""
        load, load_var = _mixed(weights, loads, variances)
        friction = sum(
            w * p.friction_torque_nm for w, p in zip(weights, step.predictions, strict=True)
        )
        geometry = self.params.actuator.preset.geometry
        return HealthState(
            stamp_s=block.stamp_s,
            axial_load_n=load,
            axial_load_std_n=math.sqrt(load_var),
            friction_torque_nm=friction,
            efficiency=float(efficiency(geometry, abs(load), friction)),
            screw_speed_rad_s=block.motor_speed_rad_s / self.params.actuator.drive_train.gear_ratio,
            event=event,
            **self._standing_fields(block.accepted_so_far, block.rejected_so_far),
        )

    def _load_moments(self) -> tuple[list[float], list[float]]:
        """Each hypothesis' load [N] and load variance [N^2]: its filter's, plus the torque
        scale's fixed error (``noise.torque_scale_error_rel``) times its load, squared."""
        error = self._torque_scale_error_rel
        loads = [float(h.filter.x[LOAD]) for h in self._bank.hypotheses]
        variances = [
            float(h.filter.P[LOAD, LOAD]) + (error * f) ** 2
            for h, f in zip(self._bank.hypotheses, loads, strict=True)
        ]
        return loads, variances

    def _standing_fields(self, samples_accepted: int, samples_rejected: int) -> dict[str, Any]:
        """The fields of an estimate that the estimator's state holds between blocks: jam
        probabilities, degradation, the given sample counters and mean NIS (0 while its window
        is empty); the others describe the block (:meth:`_state`, :meth:`current_state`)."""
        degradation = self._degradation.state
        nis = self._mean_nis()
        return {
            "jam_probabilities": tuple(float(p) for p in self._bank.probabilities()),
            "precision_loss_m": degradation.precision_loss_m,
            "precision_loss_std_m": self._degradation.precision_loss_std_m,
            "precision_loss_rate_m_per_s": degradation.rate_m_per_s,
            "fatigue_damage": degradation.fatigue_damage,
            "fatigue_damage_std": self._degradation.fatigue_damage_std,
            "samples_accepted": samples_accepted,
            "samples_rejected": samples_rejected,
            "nis": nis if math.isfinite(nis) else 0.0,
        }


def _mixed(weights: list[float], loads: list[float], variances: list[float]) -> tuple[float, float]:
    """Mean and variance of the hypotheses' load mixture (law of total variance)."""
    load = sum(w * f for w, f in zip(weights, loads, strict=True))
    load_var = sum(
        w * (v + (f - load) ** 2) for w, f, v in zip(weights, loads, variances, strict=True)
    )
    return load, load_var


def _radial_sensitivity(params: EstimatorParams) -> float:
    """Relative change of the healthy wear rate for one std of the radial ratio (at half the
    preset's largest load)."""
    ratio, std = params.model.radial_load_ratio, params.model.radial_load_ratio_std
    if not params.radial_terms or std == 0.0:
        return 0.0
    preset = params.actuator.preset
    upper = min(ratio + std, 0.9 * float(radial_capacity_ratio(preset.geometry)))
    nominal, shifted = (
        float(
            physics_averages(
                preset,
                [0.5 * preset.largest_axial_load_n],
                radial_ratio=r,
                misalignment=params.actuator.misalignment,
            ).wear_healthy_m[0]
        )
        for r in (ratio, upper)
    )
    return abs(shifted - nominal) / nominal if nominal > 0.0 else 0.0
