"""A sensor's noise measured block by block: the median of the last HISTORY_BLOCKS measured
blocks' variances, never below the parameter's. The input stage keeps two: the speed's
(inputs.py) and the current's (sample_faults.py).

The motor speed's, for the variance of each block's acceleration: a block's acceleration is
its speed change over its span, with the variance 2 sigma^2 / span^2 of the difference of
two speed samples. sigma is the larger of ``noise.speed_std_rad_s`` and the noise measured:
a drive that differences a coarse encoder into its speed has ten times the noise of a fine
one (docs/performance.md, "The drive's sensors"), and with sigma too small the inertia
torque's noise is taken for load changes and jams. Each moving block's speed variance about
its straight-line trend (unbiased: over n - 2 for n samples) is measured. The median leaves
out the blocks where a stroke starts or ends, whose speed curves within the block and whose
variance about a straight line is the curve's, not noise; it lies about 2 % below the mean
of the variances at 40 samples a block.

The motor current's, for the current spike check: a current noisier than
``noise.current_std_a`` had its tails rejected as spikes (9 % of the samples at ten times
it). Each block's is measured from its raw samples, before that check, robustly: the median
magnitude of the second differences two samples apart (sample_faults.py).

Until HISTORY_BLOCKS blocks have been measured (2.6 s at 40 ms a block) the parameter alone
sets the speed's sigma; the current's is the median of those measured so far from the
first on (sample_faults.CURRENT_NOISE_FIRST_BLOCKS). The measured variances are part of the
estimator's saved state, so a restart does not fall back to it.
"""

from __future__ import annotations

import numpy as np

from prsm_health.signals import BoolArray, FloatArray, IntArray

#: The blocks whose median is the measured variance.
HISTORY_BLOCKS = 64
#: A block with fewer samples (second differences, for the current) than this is not
#: measured (its variance has too few degrees of freedom; at 100 Hz a block holds four
#: samples and the parameter alone sets sigma).
MIN_SAMPLES = 8
#: The offsets of a block's window from the end of its history.
WINDOW = np.arange(-HISTORY_BLOCKS, 0)
#: The two middle ranks of a full history (an even count): its median is their mean.
MIDDLE = (HISTORY_BLOCKS // 2 - 1, HISTORY_BLOCKS // 2)


def history_median(windows: FloatArray) -> FloatArray:
    """The median of each row of HISTORY_BLOCKS values (np.median's, by a partial sort: under
    half its cost, once per block in the node)."""
    return np.asarray(
        np.partition(windows, MIDDLE, axis=-1)[..., MIDDLE[0] : MIDDLE[1] + 1].mean(axis=-1)
    )


class NoiseHistory:
    """A noise's variance per block: max(floor^2, median of the last HISTORY_BLOCKS measured
    blocks), up to and including the block (:meth:`variances`) or before it
    (:meth:`variances_before`); stateful across chunks, so the result does not depend on how
    the blocks are batched."""

    def __init__(self, floor_std: float, *, first_blocks: int = HISTORY_BLOCKS) -> None:
        """``first_blocks``: until HISTORY_BLOCKS blocks are measured, the median of all the
        measured ones once there are this many (HISTORY_BLOCKS: the floor alone until then)."""
        self._floor_var = floor_std**2
        self._first_blocks = first_blocks
        self._history: FloatArray = np.empty(0)

    @property
    def measured_std(self) -> float | None:
        """The measured noise (median of the last HISTORY_BLOCKS blocks, or of the first
        ones), None before there are enough."""
        if len(self._history) < HISTORY_BLOCKS:
            if len(self._history) < self._first_blocks:
                return None
            return float(np.sqrt(np.median(self._history)))
        return float(np.sqrt(history_median(self._history)))

    def saved(self) -> list[float]:
        """The measured blocks' variances (the sensor's unit squared), oldest first (at most
        HISTORY_BLOCKS)."""
        return [float(v) for v in self._history]

    def resume(self, variances: list[float]) -> None:
        """Continue from :meth:`saved` (checked by the caller: finite, >= 0)."""
        self._history = np.asarray(variances[-HISTORY_BLOCKS:], dtype=np.float64)

    def variances(self, block_var: FloatArray, measured: BoolArray) -> FloatArray:
        """The variance to use for each block of a batch, in order, given each block's
        measured variance and whether it is measured, up to and including the block."""
        history, ends = self._extended(block_var, measured)
        return self._at(history, ends)

    def variances_before(
        self, block_var: FloatArray, measured: BoolArray
    ) -> tuple[FloatArray, float]:
        """As :meth:`variances`, from the blocks before each block only, but the first block
        ever measured, which has none before it, from itself where ``first_blocks`` is 1
        (not from the floor alone: it depends on no other block, so the result still does
        not depend on the batches); and the variance after the last one (for the samples
        that follow it)."""
        history, ends = self._extended(block_var, measured)
        before_ends = np.r_[len(history) - np.count_nonzero(measured), ends]
        own = np.flatnonzero((before_ends[:-1] == 0) & measured)  # the first block measured
        before_ends[own] = 1
        before = self._at(history, before_ends)
        return before[:-1], float(before[-1])

    def _extended(self, block_var: FloatArray, measured: BoolArray) -> tuple[FloatArray, IntArray]:
        """The history with the batch's measured blocks, and where it ends after each block;
        the last HISTORY_BLOCKS of it are kept."""
        history = np.concatenate((self._history, block_var[measured]))
        self._history = history[-HISTORY_BLOCKS:]
        return history, len(history) - np.count_nonzero(measured) + np.cumsum(measured)

    def _at(self, history: FloatArray, ends: IntArray) -> FloatArray:
        """max(floor^2, the median of the HISTORY_BLOCKS values of ``history`` before each of
        ``ends``, or of all of them from ``first_blocks`` on), the floor where fewer."""
        result = np.full(len(ends), self._floor_var)
        known = ends >= HISTORY_BLOCKS
        if known.any():
            windows = history[ends[known, None] + WINDOW]
            result[known] = np.maximum(self._floor_var, history_median(windows))
        for i in np.flatnonzero(~known & (ends >= self._first_blocks)):  # the first blocks
            result[i] = max(self._floor_var, float(np.median(history[: ends[i]])))
        return result
