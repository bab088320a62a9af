"""From raw motor samples to validated, averaged blocks: the estimator's input stage.

Every sample is checked and either accepted or rejected with a reason that is counted (never
silently dropped): non-finite values, values out of the drive's range or a stamp beyond
LARGEST_STAMP_S, a time stamp not after the last accepted one, an isolated spike in the
current or the speed, or a current stuck at one value (those two need each sample's
neighbours: sample_faults.py, on complete blocks).
Accepted samples are grouped into blocks of ``filter.block_duration_s`` on a fixed time grid;
each block becomes one filter measurement (:class:`Block`). Everything is vectorised over the
samples of a chunk; only chunks with time going backwards take a per-sample path.

Time handling: a stamp that does not advance is rejected (TIME_BACKWARDS). If the stamps keep
coming from a jumped-back clock, covering ``filter.time_reset_after_s`` from the first of them
and over at least TIME_RESET_SAMPLES samples, the new time line is accepted and the next block
carries ``time_reset``. A stamp behind the latest of that line but not before its first is a
late sample on it (jitter), not a new line; only a stamp before its first starts the count
again. A gap longer than ``filter.max_gap_s`` between accepted samples starts a new block with
``after_gap``. A stamp that jumps ahead by more than ``filter.max_gap_s`` (the first one ever
too) waits for the next accepted one: if that falls back strictly between the two, the jump
was a single wrong stamp and is rejected (TIME_BACKWARDS: out of order), instead of every
sample after it until a time reset; a stamp after it confirms it, and so does a time reset
(it is the last sample of the old line). A jump at the end of a chunk is held back for the
next chunk, its verdict still open, so the result does not depend on the chunking.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from prsm_health.estimation.motion_torque import TorqueAlongMotion
from prsm_health.estimation.noise_history import MIN_SAMPLES, NoiseHistory
from prsm_health.estimation.params import EstimatorParams
from prsm_health.estimation.position_speed import PositionPerSpeed
from prsm_health.estimation.sample_faults import STUCK_RUN_SAMPLES, SampleFaults
from prsm_health.physics.meshing import carrier_speed_rad_s
from prsm_health.signals import BoolArray, FloatArray, IntArray, MotorSamples

#: Per-sample counts, or one int when every sample has the same (the common case: no
#: rejection among the pending samples; spares the node's one-sample calls three array ops).
Counts = IntArray | int

#: Two consecutive motor positions within this [rad] of zero that differ by more than half a
#: turn show that the positions wrap into one turn: from then on no travel is taken from them.
WRAPPED_WITHIN_RAD = 2.0 * math.pi
#: A block holds at most ``filter.block_duration_s`` times this many samples (beyond any
#: drive's rate; 10,000 in the default 40 ms): with stamps that hardly advance (a clock in the
#: wrong unit) a block would never end, and the samples pending for it grew without bound
#: (23 MB and 16 ms per node batch in a minute).
MAX_SAMPLE_RATE_HZ = 250_000.0
#: A block whose samples span less than this [s] has no measurable slope: its current trend
#: is taken as zero, its acceleration from the sample before it (Block), or as zero if that
#: is as close (a speed step over a vanishing span would overflow).
SHORTEST_SLOPE_SPAN_S = 1e-6
#: A block's acceleration takes the speed at each of its ends as the median of that end's
#: this many samples, at their middle one's stamp, where the block holds twice as many: one
#: wild speed sample at a block's end, under the spike check's bound, moved its acceleration
#: (50 rad/s at 1 kHz: 1,280 rad/s^2, 0.31 N m of inertia torque on the downhole screw), and
#: a jam explained the step (sudden-jam: a false count of 3, 6.5 % of rated load RMSE).
END_SAMPLES = 3
#: The variance of the median of three (END_SAMPLES) independent standard normal values (the
#: median's density 6 F (1 - F) f, integrated).
MEDIAN_OF_THREE_VARIANCE = 0.448671
#: A jumped-back clock is followed only after this many samples on its new time line (and
#: ``filter.time_reset_after_s`` of its time): a few late samples far apart, a
#: stale message or two delivered out of order, are rejected, not a new time line.
TIME_RESET_SAMPLES = 10
#: Stamps beyond this magnitude [s] are out of range: a ROS ``builtin_interfaces/Time`` carries
#: its seconds as an int32, so no message stamp reaches 2^31 s (2038 as Unix time). Inside it
#: the block grid's cell numbers (at most 2^32 s over ``filter.block_duration_s`` >= 1e-4 s,
#: 4.3e13) and every time difference stay far from overflowing; a finite stamp of 1e308
#: overflowed them.
LARGEST_STAMP_S = 2.0**31
#: Motor positions beyond this magnitude [rad] are out of range: 1.6e11 motor revolutions, 50
#: years at 6000 rpm. Inside it the carrier angle keeps better than 1e-3 rad of precision (the
#: ripple's phase); 1e308 was accepted and the phase meant nothing.
LARGEST_POSITION_RAD = 1e12
#: The fields an out-of-range sample is counted by (SampleBlocker.out_of_range), in the order
#: of MotorSamples.
OUT_OF_RANGE_FIELDS = ("stamp", "current", "speed", "position")


class RejectReason(enum.IntEnum):
    """Why a sample was rejected (the counters of the input-health diagnostics)."""

    NON_FINITE = 0
    OUT_OF_RANGE = 1
    TIME_BACKWARDS = 2
    SPIKE = 3
    STUCK = 4


#: Reasons judged as the samples come, one by one in input order.
ON_ARRIVAL = (RejectReason.NON_FINITE, RejectReason.OUT_OF_RANGE, RejectReason.TIME_BACKWARDS)
#: Reasons judged on complete blocks (with their neighbours).
IN_BLOCKS = (RejectReason.SPIKE, RejectReason.STUCK)


@dataclass
class InputCounters:
    """Samples accepted and rejected (by reason) since start, and time events."""

    accepted: int = 0
    rejected: list[int] = field(default_factory=lambda: [0] * len(RejectReason))
    time_resets: int = 0
    gaps: int = 0

    @property
    def rejected_total(self) -> int:
        """All rejected samples."""
        return sum(self.rejected)


@dataclass(frozen=True)
class InputMeasures:
    """What the input stage has measured of its inputs so far (:meth:`SampleBlocker.measures`).

    speed_noise_std_rad_s: the motor speed's noise in motion, current_noise_std_a: the motor
    current's (:class:`~prsm_health.estimation.noise_history.NoiseHistory`; None: not yet).
    position_per_speed: how far the motor position moves per radian the speed says, in motion
    (1 when they agree; :mod:`prsm_health.estimation.position_speed`; None: not yet).
    torque_along_motion_nm: the motor torque along the motion in motion, forward and reverse
    (negative: braking it; both negative, a current of the other sign?
    :mod:`prsm_health.estimation.motion_torque`; None: not yet).
    out_of_range_by_field: the samples rejected as out of range, by the field beyond its range
    (one sample may count for several; :data:`OUT_OF_RANGE_FIELDS`; empty: not known). Only
    the noises are saved with the state.
    """

    speed_noise_std_rad_s: float | None = None
    current_noise_std_a: float | None = None
    position_per_speed: float | None = None
    torque_along_motion_nm: tuple[float | None, float | None] = (None, None)
    out_of_range_by_field: Mapping[str, int] = field(default_factory=dict)


@dataclass(frozen=True)
class Block:
    """One filter measurement: the accepted samples of one time-grid cell, averaged.

    stamp_s: mean stamp. stamp_var_s2: variance of the stamps about it (the block's load is a
    mean over them: measurement.TorqueModel.predict). duration_s: time since the previous
    block's mean stamp (the filter's prediction step, across a gap too; the grid period for
    the first block of a time line).
    motor_torque_nm: k_t times the mean current. motor_speed_rad_s, motor_acceleration_rad_s2:
    mean speed, and the speed change over the block's span divided by that span, each end's
    speed the median of its END_SAMPLES samples at their middle one's stamp in a block of
    at least twice as many (a block without a span, one sample: since the last sample before
    it on its time line); motor_acceleration_var_rad2_s4: that acceleration's variance from
    the speed noise, 2 v sigma^2 / span^2 (the difference of the two ends, v
    MEDIAN_OF_THREE_VARIANCE for medians or 1 for samples; 0 where there is no span to take
    one), sigma the larger of ``noise.speed_std_rad_s`` and the noise measured in motion
    (:class:`~prsm_health.estimation.noise_history.NoiseHistory`).
    carrier_cos, carrier_sin: means of cos and sin of the carrier angle (exact averaging of
    the carrier-frequency ripple).
    direction: +1 or -1 when every sample moves that way faster than the standstill speed
    (but wild ones inside the block: SampleFaults.wild_inside), else 0 (standstill or
    reversing). reverses: samples move both ways faster than it (the motion reverses inside
    the block). current_residual_var_a2: variance of the current about
    its straight-line trend in the block (a step inside the block, e.g. the onset of a jam,
    makes it large; the measurement noise uses it). silence_before_s: time from the previous
    block's last accepted sample to this block's first (a hole in the data: dropouts or
    rejected samples). travel_rad: how far the motor turned from the previous block's last
    accepted sample to this block's last (the difference of their positions; NaN where there
    is no previous sample on the time line, or the positions have been seen to wrap into one
    turn, WRAPPED_WITHIN_RAD). after_gap, time_reset: the block starts a new time line.
    accepted_so_far, rejected_so_far: the samples accepted and rejected from the start up to
    the block's last accepted sample, in input order (the same however the samples were
    chunked; rejected samples after it count in the next block).
    """

    stamp_s: float
    duration_s: float
    samples: int
    motor_torque_nm: float
    motor_speed_rad_s: float
    motor_acceleration_rad_s2: float
    carrier_cos: float
    carrier_sin: float
    direction: int
    reverses: bool = False
    current_residual_var_a2: float = 0.0
    motor_acceleration_var_rad2_s4: float = 0.0
    silence_before_s: float = 0.0
    travel_rad: float = math.nan
    after_gap: bool = False
    time_reset: bool = False
    accepted_so_far: int = 0
    rejected_so_far: int = 0
    stamp_var_s2: float = 0.0


def merge_blocks(blocks: list[Block]) -> Block:
    """One block standing for consecutive blocks (sample-weighted means; for standstill)."""
    weights = np.array([b.samples for b in blocks], dtype=np.float64)

    def weighted(values: list[float]) -> float:
        return float(np.dot(weights, values) / weights.sum())

    def mean(name: str) -> float:
        return weighted([getattr(b, name) for b in blocks])

    directions = {b.direction for b in blocks}
    stamp = mean("stamp_s")
    return Block(
        stamp_s=stamp,
        duration_s=blocks[-1].stamp_s - blocks[0].stamp_s + blocks[0].duration_s,
        samples=int(weights.sum()),
        motor_torque_nm=mean("motor_torque_nm"),
        motor_speed_rad_s=mean("motor_speed_rad_s"),
        motor_acceleration_rad_s2=mean("motor_acceleration_rad_s2"),
        carrier_cos=mean("carrier_cos"),
        carrier_sin=mean("carrier_sin"),
        direction=directions.pop() if len(directions) == 1 else 0,
        reverses=any(b.reverses for b in blocks),
        current_residual_var_a2=mean("current_residual_var_a2"),
        # The variance of the weighted mean of independent accelerations.
        motor_acceleration_var_rad2_s4=float(
            np.dot(weights**2, [b.motor_acceleration_var_rad2_s4 for b in blocks])
            / weights.sum() ** 2
        ),
        silence_before_s=blocks[0].silence_before_s,
        travel_rad=sum(b.travel_rad for b in blocks),
        after_gap=blocks[0].after_gap,
        time_reset=blocks[0].time_reset,
        accepted_so_far=blocks[-1].accepted_so_far,
        rejected_so_far=blocks[-1].rejected_so_far,
        # Each block's spread about the merged stamp: its own plus its mean's offset.
        stamp_var_s2=weighted([b.stamp_var_s2 + (b.stamp_s - stamp) ** 2 for b in blocks]),
    )


class SampleBlocker:
    """Validates samples and groups them into :class:`Block`s (stateful across chunks).

    The result does not depend on how the samples are chunked (one at a time in the node,
    thousands at a time in replay): per-sample checks carry their state, and the checks that
    need neighbours (spikes, stuck runs: :attr:`faults`) run on complete blocks with one
    sample of context on each side.
    """

    def __init__(self, params: EstimatorParams) -> None:
        drive = params.actuator.drive_train
        self._params = params
        self._torque_constant = drive.torque_constant_nm_per_a
        self._carrier_per_motor_rad = float(
            carrier_speed_rad_s(params.actuator.preset.geometry, 1.0 / drive.gear_ratio)
        )
        #: The largest magnitude of each field of a sample, in OUT_OF_RANGE_FIELDS' order.
        self._range_limits = (
            LARGEST_STAMP_S,
            drive.max_current_a,
            params.max_motor_speed_rad_s,
            LARGEST_POSITION_RAD,
        )
        #: The most samples a block holds (MAX_SAMPLE_RATE_HZ).
        self.block_capacity = math.ceil(params.filter.block_duration_s * MAX_SAMPLE_RATE_HZ)
        self.counters = InputCounters()
        #: Samples rejected as out of range since this blocker started, by the field beyond
        #: its range (one sample may count for several; not saved with the state): a speed in
        #: rpm instead of rad/s shows as "speed".
        self.out_of_range = dict.fromkeys(OUT_OF_RANGE_FIELDS, 0)
        self._last_stamp = -math.inf  # the latest accepted stamp (a held sample's too)
        self._jumped_from = -math.inf  # the stamp the latest accepted one jumped from
        self._held: MotorSamples | None = None  # a last sample that jumped ahead (module doc)
        self._held_rejected_before = 0  # the samples rejected before it (input order)
        self._backwards_since: float | None = None  # where the jumped-back line started
        self._backwards_samples = 0  # its samples so far
        self._pending = _empty()
        # Per pending sample: the samples rejected on arrival before it (input order).
        self._pending_rejected_before: Counts = 0
        self._anchor: float | None = None
        self._last_block_stamp: float | None = None
        self._last_sample_stamp: float | None = None  # the last accepted one in a block
        self._last_sample_position = math.nan  # and its motor position
        self._last_sample_speed = math.nan  # and its motor speed
        self._wrapped = False  # the positions wrapped into one turn (WRAPPED_WITHIN_RAD)
        self._position_turns_rad = 0.0  # the whole turns taken off them so far (unwrapped)
        self._last_processed_stamp = math.inf  # the last one of a block, rejected or not
        self._time_reset = False
        self.faults = SampleFaults(params)
        self.speed_noise = NoiseHistory(params.noise.speed_std_rad_s)
        self.position_per_speed = PositionPerSpeed()
        self.torque_along_motion = TorqueAlongMotion()

    def measures(self) -> InputMeasures:
        """What has been measured of the inputs so far."""
        return InputMeasures(
            speed_noise_std_rad_s=self.speed_noise.measured_std,
            current_noise_std_a=self.faults.current_noise.measured_std,
            position_per_speed=self.position_per_speed.ratio,
            torque_along_motion_nm=self.torque_along_motion.medians_nm,
            out_of_range_by_field=dict(self.out_of_range),
        )

    @property
    def input_clock_s(self) -> float | None:
        """The stamp of the latest sample accepted so far that is not held back: the time line
        the inputs are on (a rejected stamp does not move it, a time reset it follows moves it
        back; None before the first)."""
        if len(self._pending):
            return float(self._pending.stamp_s[-1])
        return self._last_sample_stamp

    def feed(self, samples: MotorSamples) -> list[Block]:
        """Validate ``samples`` and return the blocks they complete (in time order)."""
        rejected_earlier = self._rejected(ON_ARRIVAL)
        ok = self._in_range(samples)
        held = self._held
        if held is not None:  # accepted so far: what follows decides (module doc)
            samples, ok = MotorSamples.concatenate([held, samples]), np.r_[True, ok]
        ok, resets, jumped = self._advance_time(samples.stamp_s, ok, held=held is not None)
        self._held = None
        every = bool(ok.all())  # the common case: nothing to select
        rejected_before: Counts = rejected_earlier
        if not every or held is not None:  # counted in input order (accepted ones are not)
            rejected_before = rejected_earlier + np.cumsum(~ok)
            if held is not None:
                rejected_before[0] = self._held_rejected_before
        if jumped is not None:  # undecided: held back for the next chunk
            self._held = samples[np.array([jumped])]  # a copy
            self._held_rejected_before = int(_at(rejected_before, jumped))
            ok[jumped] = False
            every = False
        blocks: list[Block] = []
        begin = 0
        for reset in [*resets, len(samples)]:
            part, part_before = samples[begin:reset], _at(rejected_before, slice(begin, reset))
            if not every:
                kept = ok[begin:reset]
                part, part_before = part[kept], _at(part_before, kept)
            before = _joined(
                self._pending_rejected_before, len(self._pending), part_before, len(part)
            )
            # A copy: pending samples must not alias the caller's arrays.
            accepted = MotorSamples.concatenate([self._pending, part])
            if reset < len(samples):  # the old time line ends here: close its blocks
                blocks += self._blocks(accepted, before, final=True)
                self._anchor = None
                self._time_reset = True
            else:
                blocks += self._blocks(accepted, before, final=False)
            begin = reset
        return blocks

    def flush(self, *, end_of_data: bool = True) -> list[Block]:
        """Blocks from the samples still pending. At the end of the data a held sample is
        accepted (nothing came to contradict it); in a pause (``end_of_data`` False: a node
        whose input went silent) it stays held, its verdict open for what comes next."""
        pending, before = self._pending, self._pending_rejected_before
        if self._held is not None and end_of_data:
            before = _joined(before, len(pending), self._held_rejected_before, 1)
            pending, self._held = MotorSamples.concatenate([pending, self._held]), None
        return self._blocks(pending, before, final=True)

    # --- per-sample checks --------------------------------------------------------------
    def _count(self, reason: RejectReason, mask: BoolArray) -> None:
        self.counters.rejected[reason] += int(np.count_nonzero(mask))

    def _rejected(self, reasons: tuple[RejectReason, ...]) -> int:
        return sum(self.counters.rejected[reason] for reason in reasons)

    def _in_range(self, samples: MotorSamples) -> BoolArray:
        """Finite, within the drive's current and speed range, stamped within LARGEST_STAMP_S
        and at a position within LARGEST_POSITION_RAD."""
        # A comparison with NaN or inf is False here (numpy emits no warning for comparisons):
        # one test per column tells whether every sample passes, the reasons only on a failure.
        stamp_limit, current_limit, speed_limit, position_limit = self._range_limits
        in_range = (
            (np.abs(samples.stamp_s) <= stamp_limit)
            & (np.abs(samples.current_a) <= current_limit)
            & (np.abs(samples.speed_rad_s) <= speed_limit)
            & (np.abs(samples.position_rad) <= position_limit)
        )
        ok = np.asarray(in_range)
        if not ok.all():
            columns = (
                samples.stamp_s,
                samples.current_a,
                samples.speed_rad_s,
                samples.position_rad,
            )
            finite = np.asarray(np.logical_and.reduce([np.isfinite(c) for c in columns]))
            self._count(RejectReason.NON_FINITE, ~finite)
            self._count(RejectReason.OUT_OF_RANGE, finite & ~ok)
            fields = zip(OUT_OF_RANGE_FIELDS, columns, self._range_limits, strict=True)
            for name, column, limit in fields:
                self.out_of_range[name] += int(np.count_nonzero(finite & (np.abs(column) > limit)))
        return ok

    def _advance_time(
        self, stamps: FloatArray, ok: BoolArray, *, held: bool
    ) -> tuple[BoolArray, list[int], int | None]:
        """Reject stamps that do not advance; follow a jumped-back time line after a while.

        Judges the samples in ``ok`` one by one, in order, with every decision's state kept
        across chunks (module doc). ``held``: the first sample is the one held back at the end
        of the chunk before, accepted so far (``_last_stamp`` is its stamp); it is not judged
        again. Returns the accepted mask, the sample indices where a new time line starts, and
        the index of the latest accepted sample if it jumped ahead and nothing after it
        decided whether it was a wrong stamp (the caller holds it back).
        """
        index = np.flatnonzero(ok)
        jumped = 0 if held else None  # the latest accepted sample, if it jumped ahead
        judged = index[1:] if held else index
        t = stamps[judged]
        if len(t) == 0:
            return ok, [], jumped
        max_gap = self._params.filter.max_gap_s
        if t[0] > self._last_stamp and (len(t) == 1 or bool(np.all(np.diff(t) > 0.0))):
            # Every stamp advances (the common case): a jump is confirmed by the sample after
            # it, so only the last one can be undecided.
            previous = float(t[-2]) if len(t) > 1 else self._last_stamp
            self._last_stamp, self._backwards_since = float(t[-1]), None
            if self._last_stamp - previous > max_gap:
                self._jumped_from = previous
                return ok, [], int(judged[-1])
            return ok, [], None
        keep = ok.copy()
        resets = []
        reset_after = self._params.filter.time_reset_after_s
        for i, stamp in zip(judged.tolist(), t.tolist(), strict=True):
            if jumped is not None and self._jumped_from < stamp < self._last_stamp:
                # Back into the time line the latest sample jumped from: that one was wrong,
                # and this one is judged as if it had never come.
                keep[jumped] = False
                self.counters.rejected[RejectReason.TIME_BACKWARDS] += 1
                self._last_stamp, jumped = self._jumped_from, None
            if stamp > self._last_stamp:
                if stamp - self._last_stamp > max_gap:
                    jumped, self._jumped_from = i, self._last_stamp
                else:
                    jumped = None
                self._last_stamp, self._backwards_since = stamp, None
                continue
            if self._backwards_since is None or stamp < self._backwards_since:
                # A jumped-back line starts here. A stamp behind the line's latest but not
                # before its first is a late sample on it (jitter), not another line.
                self._backwards_since, self._backwards_samples = stamp, 0
            self._backwards_samples += 1
            if (
                stamp - self._backwards_since >= reset_after
                and self._backwards_samples >= TIME_RESET_SAMPLES
            ):
                # The jumped-back time line has run on its own: follow it from here. A sample
                # that jumped ahead is the last one of the old line, which ends here.
                self._last_stamp, self._backwards_since, jumped = stamp, None, None
                self.counters.time_resets += 1
                resets.append(i)
                continue
            keep[i] = False
            self.counters.rejected[RejectReason.TIME_BACKWARDS] += 1
        return keep, resets, jumped

    def _blocks(
        self, pending: MotorSamples, rejected_before: Counts, *, final: bool
    ) -> list[Block]:
        """The complete blocks of the ``pending`` samples (``rejected_before``: the samples
        rejected on arrival before each); the others stay pending."""
        self._pending, self._pending_rejected_before = pending, rejected_before
        if len(pending) == 0:
            return []
        period = self._params.filter.block_duration_s
        t = pending.stamp_s
        if self._anchor is None:
            self._anchor = float(t[0])
        if not final and self._no_block_yet(t, period):
            return []
        # The first pending sample is compared with the last one of the blocks before: a gap
        # may follow a block already closed, or a flush (after a time reset it is earlier).
        gap_before = np.diff(np.r_[self._last_processed_stamp, t]) > self._params.filter.max_gap_s
        # A gap starts a new time grid anchored at the first sample after it.
        anchors = np.where(gap_before, t, np.nan)
        anchors[0] = self._anchor if not gap_before[0] else t[0]
        anchors = np.maximum.accumulate(np.where(np.isnan(anchors), -np.inf, anchors))
        line = np.cumsum(gap_before)
        cells = np.floor((t - anchors) / period).astype(np.int64)
        new_cell = np.r_[True, (cells[1:] != cells[:-1]) | (line[1:] != line[:-1])]
        if len(t) > self.block_capacity:  # else no cell can be longer (the common case)
            # A longer cell is split every block_capacity samples from its first (the pending
            # samples start at a cell's first, so the split does not depend on the chunks).
            index = np.arange(len(t))
            since_start = index - np.maximum.accumulate(np.where(new_cell, index, 0))
            new_cell |= since_start % self.block_capacity == 0
        starts = np.flatnonzero(new_cell)
        if final:
            complete = len(starts)
        else:  # close cells that end STUCK_RUN_SAMPLES before the pending end (see above)
            complete = int(np.searchsorted(starts, len(t) - STUCK_RUN_SAMPLES, side="right")) - 1
        if complete <= 0:
            return []
        end = int(starts[complete]) if complete < len(starts) else len(t)
        self._anchor = float(anchors[end - 1])
        self._last_processed_stamp = float(t[end - 1])
        run = pending[:end]
        accepted_earlier, rejected_earlier = self.counters.accepted, self._rejected(IN_BLOCKS)
        spikes, stuck = self.faults.find(pending, starts[:complete], end, final)
        self._count(RejectReason.SPIKE, spikes)
        self._count(RejectReason.STUCK, stuck)
        rejected = spikes | stuck
        self.counters.accepted += end - int(np.count_nonzero(rejected))
        self._pending = pending[end:]
        self._pending_rejected_before = _compact(_at(rejected_before, slice(end, None)))
        keep = ~rejected
        so_far = (
            accepted_earlier + np.cumsum(keep),
            _at(rejected_before, slice(None, end)) + rejected_earlier + np.cumsum(rejected),
        )
        return self._summarise(
            run[keep],
            np.cumsum(new_cell[:end])[keep] - 1,
            gap_before[:end][keep],
            (so_far[0][keep], so_far[1][keep]),
        )

    def _no_block_yet(self, t: FloatArray, period: float) -> bool:
        """Cheap test (the node feeds a few samples at a time): the sample STUCK_RUN_SAMPLES
        from the end is still in the first pending sample's cell, with no gap between."""
        last = len(t) - STUCK_RUN_SAMPLES
        if last < 1:
            return True
        if last >= self.block_capacity:
            return False
        first_t, last_t = float(t[0]), float(t[last])
        if not 0.0 <= last_t - first_t <= self._params.filter.max_gap_s:
            return False
        anchor = self._anchor if self._anchor is not None else first_t
        return math.floor((first_t - anchor) / period) == math.floor((last_t - anchor) / period)

    def _summarise(
        self,
        run: MotorSamples,
        cell_ids: NDArray[np.int64],
        gap_before: BoolArray,
        so_far: tuple[IntArray, IntArray],
    ) -> list[Block]:
        """Average each cell's samples into a Block (all cells vectorised). ``so_far``: the
        samples accepted and rejected up to each sample (input order)."""
        if len(run) == 0:
            return []
        starts = np.flatnonzero(np.r_[True, cell_ids[1:] != cell_ids[:-1]])
        counts = np.diff(np.r_[starts, len(run)])
        t0 = run.stamp_s[starts]
        t = run.stamp_s - np.repeat(t0, counts)
        w = run.speed_rad_s
        wrapped_until, turning = self._turning_positions(run)
        angle = turning * self._carrier_per_motor_rad

        def means(x: FloatArray) -> FloatArray:
            return np.asarray(np.add.reduceat(x, starts) / counts, dtype=np.float64)

        mean_t, mean_w, mean_i = means(t), means(w), means(run.current_a)
        variance_t = means(t * t) - mean_t**2
        spread = variance_t > SHORTEST_SLOPE_SPAN_S**2
        # The mean acceleration over the block is the speed change over its span (a least
        # squares slope would miss an acceleration that starts or stops inside the block),
        # from the medians of the END_SAMPLES at each end where there are enough.
        last = np.r_[starts[1:], len(run)] - 1
        first_w, last_w, first_t, last_t, end_var = self._end_speeds(w, t, starts, last)
        span = last_t - first_t
        measurable = span > SHORTEST_SLOPE_SPAN_S
        slope = np.divide(last_w - first_w, span, out=np.zeros_like(span), where=measurable)
        residual_var = _variance_about_trend(
            run.current_a, mean_i, t, mean_t, variance_t, spread, means
        )
        threshold = self._params.filter.standstill_speed_rad_s
        lowest, highest = self._speed_range(w, starts, last)
        direction = (lowest > threshold).astype(np.int64) - (highest < -threshold).astype(np.int64)
        reverses = (lowest < -threshold) & (highest > threshold)
        speed_var = _variance_about_trend(w, mean_w, t, mean_t, variance_t, spread, means)
        measured = (direction != 0) & (counts >= MIN_SAMPLES)
        unbiased = speed_var * np.divide(
            counts, counts - 2.0, out=np.ones(len(counts)), where=measured
        )
        noise_var = self.speed_noise.variances(unbiased, measured)
        # Each block's travel by its speeds: the trapezoids between its consecutive samples.
        trapezoids = np.r_[0.5 * (w[1:] + w[:-1]) * np.diff(run.stamp_s), 0.0]
        trapezoids[last] = 0.0  # from a block's last sample to the next block's first
        compared = (direction != 0) & (counts >= 2)
        self.position_per_speed.add(
            turning[last] - turning[starts], np.add.reduceat(trapezoids, starts), compared
        )
        slope_var = np.divide(
            2.0 * end_var * noise_var, span**2, out=np.zeros_like(span), where=measurable
        )
        stamps = t0 + mean_t
        torque = mean_i * self._torque_constant
        self.torque_along_motion.add(torque, direction, compared)
        cos_mean, sin_mean = means(np.cos(angle)), means(np.sin(angle))
        new_line = np.add.reduceat(gap_before.astype(np.int64), starts) > 0
        self.counters.gaps += int(np.count_nonzero(new_line))
        period = self._params.filter.block_duration_s
        first_stamps = run.stamp_s[starts]
        last_stamps = run.stamp_s[last]
        last_positions = run.position_rad[last]
        # Travel is measured only until the positions are seen to wrap into one turn: the
        # difference of two wrapped positions says nothing of the turns across a hole.
        wrapped = wrapped_until[last]
        blocks = []
        for b in range(len(starts)):
            previous = self._last_block_stamp
            reset = self._time_reset
            duration = period
            if previous is not None and not reset:
                duration = float(stamps[b]) - previous
            silence, travel = 0.0, math.nan
            acceleration, acceleration_var = float(slope[b]), float(slope_var[b])
            if self._last_sample_stamp is not None and not reset:
                silence = float(first_stamps[b]) - self._last_sample_stamp
                if not wrapped[b]:
                    travel = abs(float(last_positions[b]) - self._last_sample_position)
                since_s = float(last_stamps[b]) - self._last_sample_stamp
                if not measurable[b] and not new_line[b] and since_s > SHORTEST_SLOPE_SPAN_S:
                    acceleration = (float(w[last[b]]) - self._last_sample_speed) / since_s
                    acceleration_var = 2.0 * float(noise_var[b]) / since_s**2
            blocks.append(
                Block(
                    stamp_s=float(stamps[b]),
                    duration_s=duration,
                    samples=int(counts[b]),
                    motor_torque_nm=float(torque[b]),
                    motor_speed_rad_s=float(mean_w[b]),
                    motor_acceleration_rad_s2=acceleration,
                    carrier_cos=float(cos_mean[b]),
                    carrier_sin=float(sin_mean[b]),
                    direction=int(direction[b]),
                    reverses=bool(reverses[b]),
                    current_residual_var_a2=float(residual_var[b]),
                    motor_acceleration_var_rad2_s4=acceleration_var,
                    silence_before_s=silence,
                    travel_rad=travel,
                    after_gap=bool(new_line[b]),
                    time_reset=reset,
                    accepted_so_far=int(so_far[0][last[b]]),
                    rejected_so_far=int(so_far[1][last[b]]),
                    stamp_var_s2=float(variance_t[b]),
                )
            )
            self._last_block_stamp = float(stamps[b])
            self._last_sample_stamp = float(last_stamps[b])
            self._last_sample_position = float(last_positions[b])
            self._last_sample_speed = float(w[last[b]])
            self._time_reset = False
        return blocks

    def _speed_range(
        self, w: FloatArray, starts: IntArray, last: IntArray
    ) -> tuple[FloatArray, FloatArray]:
        """Per block (first and last sample ``starts``, ``last``): its lowest and highest
        speed, leaving out the wild samples inside it (:meth:`SampleFaults.wild_inside`), so
        that one wild sample neither stops nor reverses a moving block (its direction and
        reversal are taken from them): 150 rad/s off in a stroke at 107 rad/s, under the
        spike check's bound, a sample made its block a reversal and the load was forgotten."""
        wild = self.faults.wild_inside(w, starts, last)
        lowest = np.minimum.reduceat(np.where(wild, np.inf, w), starts)
        highest = np.maximum.reduceat(np.where(wild, -np.inf, w), starts)
        return lowest, highest

    @staticmethod
    def _end_speeds(
        w: FloatArray, t: FloatArray, starts: IntArray, last: IntArray
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        """Per block (first and last sample ``starts``, ``last``): the speeds at its two ends
        and their stamps ``t`` (from the block's first), and the variance of each end's speed
        over the noise's. An end is the median of its END_SAMPLES samples at their middle
        one's stamp (exact on a straight line, whose middle sample is its median) where the
        block holds at least twice as many, else its sample."""
        first_w, last_w = w[starts].copy(), w[last].copy()
        first_t, last_t = t[starts].copy(), t[last].copy()
        end_var = np.ones(len(starts))
        long = last - starts + 1 >= 2 * END_SAMPLES
        if long.any():
            offsets = np.arange(END_SAMPLES)
            heads = starts[long, None] + offsets
            tails = last[long, None] - offsets[::-1]
            middle = END_SAMPLES // 2
            first_w[long] = np.median(w[heads], axis=1)
            last_w[long] = np.median(w[tails], axis=1)
            first_t[long] = t[heads[:, middle]]
            last_t[long] = t[tails[:, middle]]
            end_var[long] = MEDIAN_OF_THREE_VARIANCE
        return first_w, last_w, first_t, last_t, end_var

    def _turning_positions(self, run: MotorSamples) -> tuple[BoolArray, FloatArray]:
        """Per sample of ``run``: whether the positions have been seen to wrap into one turn by
        then (two consecutive ones within WRAPPED_WITHIN_RAD of zero that differ by more than
        half a turn; sample by sample, so whatever the chunks), and its position counting
        turns, for the carrier angle.

        Once wrapped (a single-turn encoder), whole turns are added where two consecutive
        positions within WRAPPED_WITHIN_RAD of zero differ from the travel their speeds say
        (mean speed times the time between them, none across a time reset) by half a turn or
        more. Exact between samples less than half a turn of travel apart; across a hole the
        speeds' travel is a guess, and so is the carrier's phase after it. Multi-turn
        positions are left as they are. Wrapped positions taken as they were made the carrier
        angle meaningless: 5 false jam declarations and a load RMSE of 6.2 % instead of 0.6 %
        on the sudden-jam bag with its positions wrapped into [-pi, pi).
        """
        position = np.r_[self._last_sample_position, run.position_rad]
        near = np.abs(position) <= WRAPPED_WITHIN_RAD
        near_both = near[1:] & near[:-1]
        step = np.diff(position)
        with np.errstate(invalid="ignore"):
            wraps = (np.abs(step) > math.pi) & near_both
        wrapped = np.logical_or.accumulate(np.r_[self._wrapped, wraps])[1:]
        self._wrapped = bool(wrapped[-1])
        if not wrapped.any():
            return wrapped, run.position_rad
        speed = np.r_[self._last_sample_speed, run.speed_rad_s]
        before = self._last_sample_stamp
        stamp = np.r_[run.stamp_s[0] if before is None else before, run.stamp_s]
        travel = 0.5 * (speed[1:] + speed[:-1]) * np.maximum(np.diff(stamp), 0.0)
        with np.errstate(invalid="ignore"):
            turns = np.round((step - travel) / (2.0 * math.pi))
        turns = np.where(wrapped & near_both & np.isfinite(turns), turns, 0.0)
        offset = self._position_turns_rad + 2.0 * math.pi * np.cumsum(turns)
        self._position_turns_rad = float(offset[-1])
        return wrapped, np.asarray(run.position_rad - offset, dtype=np.float64)


def _variance_about_trend(
    x: FloatArray,
    mean_x: FloatArray,
    t: FloatArray,
    mean_t: FloatArray,
    variance_t: FloatArray,
    spread: BoolArray,
    means: Callable[[FloatArray], FloatArray],
) -> FloatArray:
    """Each block's variance of ``x`` (block means ``mean_x``) about its least-squares
    straight line in ``t`` (about its mean where the stamps have no ``spread``); ``means``
    averages per block."""
    covariance = means(t * x) - mean_t * mean_x
    trend = np.divide(covariance**2, variance_t, out=np.zeros_like(mean_t), where=spread)
    return np.maximum(means(x * x) - mean_x**2 - trend, 0.0)


def _at(counts: Counts, index: int | slice | BoolArray) -> Counts:
    """``counts[index]``."""
    return counts if isinstance(counts, int) else counts[index]


def _compact(counts: Counts) -> Counts:
    """``counts`` as one int if they are all the same (counts in input order never fall)."""
    if isinstance(counts, int) or len(counts) == 0 or counts[0] != counts[-1]:
        return counts
    return int(counts[0])


def _joined(first: Counts, first_samples: int, second: Counts, second_samples: int) -> Counts:
    """The counts of ``first_samples`` samples followed by those of ``second_samples``."""
    if first_samples == 0:
        return second
    if second_samples == 0 or (
        isinstance(first, int) and isinstance(second, int) and first == second
    ):
        return first
    return np.concatenate(
        (np.broadcast_to(first, first_samples), np.broadcast_to(second, second_samples))
    )


def _empty() -> MotorSamples:
    empty = np.zeros(0)
    return MotorSamples(empty, empty, empty, empty)
