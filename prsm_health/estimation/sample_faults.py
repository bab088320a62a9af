"""Spikes and stuck runs: the input stage's checks that need each sample's neighbours.

The input stage (inputs.py) runs them on complete blocks, with one sample of context on each
side, and counts what they reject (SPIKE, STUCK). A current spike is a sample SPIKE_SIGMAS of
the current's noise away from both neighbours, which agree; the noise is measured block by
block (:meth:`SampleFaults._current_spike_a`). A speed spike is a speed the motor cannot
accelerate to and back in the time between its neighbours (:meth:`SampleFaults._speed_spikes`).
A stuck current is a run of at least STUCK_RUN_SAMPLES identical values. A speed sample
inside a block that stands far off its neighbours' line but within the motor's reach is kept,
but marked wild (:meth:`SampleFaults.wild_inside`) for the block's direction. Their state (the last
sample before the pending ones, the identical run ending there, the current's noise measured
so far) is carried across chunks, so the result does not depend on how the samples come.
"""

from __future__ import annotations

import math

import numpy as np

from prsm_health.estimation.noise_history import MIN_SAMPLES, NoiseHistory
from prsm_health.estimation.params import EstimatorParams
from prsm_health.signals import BoolArray, FloatArray, IntArray, MotorSamples

#: A current sample this many noise standard deviations away from both neighbours, which
#: agree with each other, is a spike (the noise measured, SampleFaults._current_spike_a); a
#: speed sample is one this many beyond what the motor can accelerate in the time between
#: (SampleFaults._speed_spikes).
SPIKE_SIGMAS = 12.0
#: The median magnitude of a second difference of white noise of standard deviation sigma
#: (x[i + 2] - 2 x[i] + x[i - 2]), over sigma: the difference has the standard deviation
#: sqrt(6) sigma, and the median of a normal magnitude is 0.6745 of its standard deviation.
MEDIAN_SECOND_DIFFERENCE_SIGMAS = 0.6745 * math.sqrt(6.0)
#: The current's noise is measured from the first block on (the median of all the blocks
#: measured before, the first one judged by its own: NoiseHistory.variances_before), not
#: only from HISTORY_BLOCKS on as the speed's: ten times the parameter's noise had 9 % of
#: its samples rejected as spikes with the parameter alone, and 28 in each run's first 0.32 s
#: with the first eight blocks' median. Each block's estimate is within about 25 %, inside
#: the spike threshold's margin.
CURRENT_NOISE_FIRST_BLOCKS = 1
#: The fewest samples of a block whose current noise is measured: MIN_SAMPLES second
#: differences two samples apart (none at 100 Hz, four samples a block of 40 ms).
CURRENT_NOISE_BLOCK_SAMPLES = MIN_SAMPLES + 4
#: This many identical consecutive current samples (while the noise should vary them) are a
#: stuck sensor; all of them are rejected (blocks close this many samples late for it).
STUCK_RUN_SAMPLES = 20


class SampleFaults:
    """The spike and stuck-run checks of the pending samples, stateful across chunks."""

    def __init__(self, params: EstimatorParams) -> None:
        self._spike_rad_s = SPIKE_SIGMAS * params.noise.speed_std_rad_s
        self._max_acceleration = params.max_motor_acceleration_rad_s2
        self._previous_current = math.nan  # last sample before the pending ones
        # Whether the last two samples before the pending ones stood out from both neighbours.
        self._previous_spike_like = np.zeros(2, dtype=np.bool_)
        self._stuck_run = 0  # length of the identical-current run ending there
        self._previous_speed = math.nan  # the speed and stamp of that last sample
        self._previous_speed_stamp = math.nan
        self.current_noise = NoiseHistory(
            params.noise.current_std_a, first_blocks=CURRENT_NOISE_FIRST_BLOCKS
        )

    def find(
        self, pending: MotorSamples, starts: IntArray, processed: int, final: bool
    ) -> tuple[BoolArray, BoolArray]:
        """The spikes and the stuck samples (not spikes) among the first ``processed`` of the
        ``pending`` samples, the complete blocks that start at ``starts`` and end there.

        Spikes: speed spikes (:meth:`_speed_spikes`), and currents further than the spike
        threshold (:meth:`_current_spike_a`) from both neighbours, which agree within half of
        it (the context at either end is the neighbouring sample, or NaN: never a spike),
        unless they are the middle of five such in a row: a current alternating every sample
        by more than the threshold, a ripple aliased at the sampling frequency, was rejected
        nearly whole (a review session); only its first and last two samples are now. Two
        spikes two samples apart are three such samples (the one between stands out too), all
        rejected. Stuck: every sample of a run of at least STUCK_RUN_SAMPLES identical values.
        Blocks are closed only STUCK_RUN_SAMPLES samples before the end of what is pending
        (unless ``final``), so any run that reaches into the unprocessed tail is already long
        enough to be judged, and a whole stuck run is rejected, its first samples included.
        """
        current = pending.current_a
        spike_a = self._current_spike_a(current, starts, processed)
        x = np.r_[self._previous_current, current, math.nan]
        before, here = x[:-2], x[1:-1]
        spike_like = _off_their_line(x, spike_a, spike_a, 0.5 * spike_a)
        # Spike-like samples that are the middle of five in a row are a ripple, not spikes.
        flags = np.r_[self._previous_spike_like, spike_like, False, False]
        spikes = spike_like
        if spike_like.any():
            ripple = flags[:-4] & flags[1:-3] & flags[2:-2] & flags[3:-1] & flags[4:]
            spikes = spike_like & ~ripple
        spikes = spikes | self._speed_spikes(pending)
        run_ids = np.cumsum(here != before)  # run 0 continues the run before the pending ones
        lengths = np.bincount(run_ids)
        lengths[0] += self._stuck_run
        open_ended = run_ids == run_ids[-1]
        stuck = lengths[run_ids] >= STUCK_RUN_SAMPLES
        if not final:  # the last run may go on: judged once it is long enough
            stuck &= ~open_ended | (lengths[run_ids[-1]] >= STUCK_RUN_SAMPLES)
        if processed:
            last = run_ids[processed - 1]
            self._stuck_run = int(np.count_nonzero(run_ids[:processed] == last)) + (
                self._stuck_run if last == 0 else 0
            )
            self._previous_current = float(current[processed - 1])
            self._previous_spike_like = flags[processed : processed + 2].copy()
            self._previous_speed = float(pending.speed_rad_s[processed - 1])
            self._previous_speed_stamp = float(pending.stamp_s[processed - 1])
        spikes, stuck = spikes[:processed], stuck[:processed]
        return np.asarray(spikes), np.asarray(stuck & ~spikes)

    def _current_spike_a(self, current: FloatArray, starts: IntArray, end: int) -> FloatArray:
        """Per sample of ``current`` (the pending ones): the current spike threshold,
        SPIKE_SIGMAS times the current noise known before its block (``starts``: the first
        sample of each complete block, which end at ``end``; the samples after ``end`` take
        the noise known after the last). Each block's noise is measured from its samples,
        before the check, robustly: the median magnitude of their second differences two
        samples apart, over MEDIAN_SECOND_DIFFERENCE_SIGMAS (a spike or a step moves a few
        of them, a smooth change hardly any, and a current alternating every sample, a ripple
        aliased at the sampling frequency, none: it is no noise that would hide spikes),
        measured on blocks of at least MIN_SAMPLES such differences, and
        taken as NoiseHistory does the speed's (never below ``noise.current_std_a``). A
        current noisier than the parameter had its tails rejected as spikes: 0.5 % of the
        samples at four times it, 9 % at ten times."""
        counts = np.diff(np.r_[starts, end])
        block_of = np.repeat(np.arange(len(starts)), counts)
        inside = block_of[:-4] == block_of[4:]  # a sample and both others in one block
        x = current[:end]
        magnitude = np.abs(x[4:] - 2.0 * x[2:-2] + x[:-4])[inside]
        owner = block_of[2:-2][inside]
        per_block = np.bincount(owner, minlength=len(starts))
        variances = np.zeros(len(starts))
        if len(magnitude):
            ordered = magnitude[np.lexsort((magnitude, owner))]
            first = np.cumsum(per_block) - per_block
            low = np.minimum(first + (per_block - 1) // 2, len(ordered) - 1)
            high = np.minimum(first + per_block // 2, len(ordered) - 1)
            median = 0.5 * (ordered[low] + ordered[high])
            variances = (median / MEDIAN_SECOND_DIFFERENCE_SIGMAS) ** 2
        before, after = self.current_noise.variances_before(variances, per_block >= MIN_SAMPLES)
        variance = np.r_[np.repeat(before, counts), np.full(len(current) - end, after)]
        return np.asarray(SPIKE_SIGMAS * np.sqrt(variance))

    def _speed_spikes(self, pending: MotorSamples) -> BoolArray:
        """Per pending sample: a speed further from both neighbours than the motor can change
        its speed in the time between (``EstimatorParams.max_motor_acceleration_rad_s2``
        times it, plus SPIKE_SIGMAS of ``noise.speed_std_rad_s``), while the neighbours are
        within the sum of those two bounds of each other. No motion goes there and back: the
        sample is wrong (one at -500 rad/s in a stroke made its block a reversal, and the load
        was forgotten). The bound is the drive's, not the speed noise's: a coarse encoder
        differenced into the speed steps by a count per sample (6 rad/s at 1024 counts and
        1 kHz), which only the noise measured in motion, not yet there at the start, would
        allow for. Between samples stamped less than 20 us apart (stamps batched on receipt)
        such steps exceed it and are rejected, counted. The context at either end is as for
        the current; across a time reset or a stamp that did not advance (never between
        accepted samples of one time line) no bound applies."""
        w = np.r_[self._previous_speed, pending.speed_rad_s, math.nan]
        steps_s = np.diff(np.r_[self._previous_speed_stamp, pending.stamp_s, math.nan])
        # A NaN step (no neighbour) compares False: no bound, never a spike.
        advancing = steps_s > 0.0
        reach = np.full(len(steps_s), np.inf)
        reach[advancing] = self._max_acceleration * steps_s[advancing] + self._spike_rad_s
        return _off_their_line(w, reach[:-1], reach[1:], reach[:-1] + reach[1:])

    def wild_inside(self, w: FloatArray, starts: IntArray, last: IntArray) -> BoolArray:
        """Per speed of ``w`` (the accepted samples of complete blocks, whose first and last
        samples are ``starts`` and ``last``): a sample inside its block that stands SPIKE_SIGMAS
        of ``noise.speed_std_rad_s`` off the line its two neighbours agree on. Accepted (the
        motor could reach it: :meth:`_speed_spikes`), but no evidence of the block's
        direction (inputs.SampleBlocker._speed_range). A block's first and last samples are
        never wild: where the motion starts or stops they are the ones below the standstill
        speed, on the line of the others, and their other neighbour is in another block."""
        inside = np.ones(len(w), dtype=np.bool_)
        inside[starts] = inside[last] = False
        reach = self._spike_rad_s
        return inside & _off_their_line(np.r_[math.nan, w, math.nan], reach, reach, reach)


def _off_their_line(
    x: FloatArray,
    beyond_before: FloatArray | float,
    beyond_after: FloatArray | float,
    agree_within: FloatArray | float,
) -> BoolArray:
    """Per value of ``x`` but its first and last (the context: a NaN is never beside one):
    further than ``beyond_before`` from the value before it and ``beyond_after`` from the one
    after it, which are within ``agree_within`` of each other. One value off the line its
    neighbours agree on: a spike."""
    before, here, after = x[:-2], x[1:-1], x[2:]
    with np.errstate(invalid="ignore"):
        return np.asarray(
            (np.abs(here - before) > beyond_before)
            & (np.abs(here - after) > beyond_after)
            & (np.abs(after - before) < agree_within)
        )
