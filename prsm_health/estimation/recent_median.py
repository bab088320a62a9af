"""The median of the last HISTORY_BLOCKS values the input stage measured of its moving blocks,
one value a block: how it sums up its checks of the inputs (position_speed.py,
motion_torque.py). The median leaves out the blocks where a stroke starts or ends."""

from __future__ import annotations

import numpy as np

from prsm_health.estimation.noise_history import HISTORY_BLOCKS, history_median
from prsm_health.signals import FloatArray


class RecentMedian:
    """The median of the last HISTORY_BLOCKS values added, None until that many; stateful
    across batches, so the result does not depend on how the blocks are batched."""

    def __init__(self) -> None:
        self._values: FloatArray = np.empty(0)

    @property
    def median(self) -> float | None:
        """The median of the last HISTORY_BLOCKS values, None before that many."""
        if len(self._values) < HISTORY_BLOCKS:
            return None
        return float(history_median(self._values))

    def add(self, values: FloatArray) -> None:
        """Record a batch of values, oldest first."""
        self._values = np.concatenate((self._values, values))[-HISTORY_BLOCKS:]
