"""The motor speed's noise, measured in motion, for the variance of each block's acceleration.

A block's acceleration is its speed change over its span (inputs.py), with the variance
2 sigma^2 / span^2 of the difference of two speed samples. sigma is the larger of
``noise.speed_std_rad_s`` and the noise measured here: a drive that differences a coarse
encoder into its speed has ten times the noise of a fine one (docs/performance.md, "The
drive's sensors"), and with sigma too small the inertia torque's noise is taken for load
changes and jams.

The measurement: each moving block's speed variance about its straight-line trend (unbiased:
over n - 2 for n samples), and the median of the last HISTORY_BLOCKS of them. The median
leaves out the blocks where a stroke starts or ends, whose speed curves within the block and
whose variance about a straight line is the curve's, not noise; it lies about 2 % below
the mean of the variances at 40 samples a block. Until HISTORY_BLOCKS blocks have been
measured (2.6 s of motion at 40 ms a block) the parameter alone sets sigma. The measured
variances are part of the estimator's saved state, so a restart does not fall back to it.
"""

from __future__ import annotations

import numpy as np

from prsm_health.signals import BoolArray, FloatArray

#: The blocks whose median is the measured speed variance.
HISTORY_BLOCKS = 64
#: A block with fewer samples than this is not measured (its variance has too few degrees of
#: freedom; at 100 Hz a block holds four samples and the parameter alone sets sigma).
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


class SpeedNoise:
    """The speed noise's variance per block: max(floor^2, median of the last HISTORY_BLOCKS
    measured blocks up to and including this one); stateful across chunks, so the result does
    not depend on how the blocks are batched."""

    def __init__(self, floor_std_rad_s: float) -> None:
        self._floor_var = floor_std_rad_s**2
        self._history: FloatArray = np.empty(0)

    @property
    def measured_std_rad_s(self) -> float | None:
        """The measured noise (median of the last HISTORY_BLOCKS blocks), None before then."""
        if len(self._history) < HISTORY_BLOCKS:
            return None
        return float(np.sqrt(history_median(self._history)))

    def saved(self) -> list[float]:
        """The measured blocks' variances [rad^2/s^2], oldest first (at most HISTORY_BLOCKS)."""
        return [float(v) for v in self._history]

    def resume(self, variances_rad2_s2: list[float]) -> None:
        """Continue from :meth:`saved` (checked by the caller: finite, >= 0)."""
        self._history = np.asarray(variances_rad2_s2[-HISTORY_BLOCKS:], dtype=np.float64)

    def variances(self, block_var_rad2_s2: FloatArray, measured: BoolArray) -> FloatArray:
        """The speed variance [rad^2/s^2] to use for each block of a batch, in order, given each
        block's speed variance about its trend and whether it is measured (moving, at least
        MIN_SAMPLES samples)."""
        history = np.concatenate((self._history, block_var_rad2_s2[measured]))
        ends = len(self._history) + np.cumsum(measured)
        result = np.full(len(block_var_rad2_s2), self._floor_var)
        known = ends >= HISTORY_BLOCKS
        if known.any():
            windows = history[ends[known, None] + WINDOW]
            result[known] = np.maximum(self._floor_var, history_median(windows))
        self._history = history[-HISTORY_BLOCKS:]
        return result
