"""Feeding samples a few at a time, as the node does, and comparing what comes out."""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

from prsm_health.signals import MotorSamples

T = TypeVar("T")


def fed_in_chunks(
    feed: Callable[[MotorSamples], list[T]], samples: MotorSamples, size: int
) -> list[T]:
    """What ``feed`` returns for ``samples`` given ``size`` at a time, in order."""
    out: list[T] = []
    for start in range(0, len(samples), size):
        out += feed(samples[start : start + size])
    return out
