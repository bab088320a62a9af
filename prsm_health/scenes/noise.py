"""Reproducible random numbers for the simulator, independent of how a run is chunked.

Every random input of a scene (load noise, sensor noise, jitter, the drawn stroke levels, the
wall profile, the wear coefficient) comes from its own stream, keyed by the scene seed and the
stream's :class:`Stream` id. Per-sample streams are counter-based: sample k of a stream is the
(k mod B)-th draw of a generator seeded with (seed, stream, k // B), so a chunk [start, stop)
gets exactly the numbers of those samples whatever the chunk boundaries are, and a long scene
never holds more than a block in memory.
"""

from __future__ import annotations

import enum

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: Samples per generator block of a per-sample stream.
BLOCK_SAMPLES = 65_536


class Stream(enum.IntEnum):
    """Ids of the random streams of a scene (part of the generator seed: never renumber)."""

    SCHEDULE = 1  # per-stroke speed and load levels of the downhole cycle
    WALL = 2  # phases of the radial wall-contact profile
    WEAR_PRIOR = 3  # the wear coefficient drawn from its prior
    LOAD_NOISE = 4
    CURRENT_NOISE = 5
    SPEED_NOISE = 6
    STAMP_JITTER = 7
    RECEIVE_JITTER = 8


def scene_generator(seed: int, stream: Stream) -> np.random.Generator:
    """A generator for the scene-level draws of ``stream`` (a few numbers, drawn once)."""
    return np.random.default_rng([seed, int(stream)])


class NormalStream:
    """Standard normal numbers indexed by sample: :meth:`take` of [start, stop) is fixed."""

    def __init__(self, seed: int, stream: Stream) -> None:
        self._key = (seed, int(stream))
        self._cached: tuple[int, FloatArray] | None = None

    def _block(self, index: int) -> FloatArray:
        if self._cached is None or self._cached[0] != index:
            generator = np.random.default_rng([*self._key, 0, index])
            self._cached = (index, generator.standard_normal(BLOCK_SAMPLES))
        return self._cached[1]

    def take(self, start: int, stop: int) -> FloatArray:
        """The numbers of samples start .. stop - 1 (0 <= start <= stop)."""
        if stop <= start:
            return np.zeros(0)
        first, last = start // BLOCK_SAMPLES, (stop - 1) // BLOCK_SAMPLES
        parts = [self._block(b) for b in range(first, last + 1)]
        offset = start - first * BLOCK_SAMPLES
        return np.concatenate(parts)[offset : offset + stop - start]
