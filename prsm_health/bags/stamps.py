"""Time conventions at the bag edge: float seconds <-> ``builtin_interfaces/Time``, log times.

A header stamp is ``(int32 sec, uint32 nanosec)`` with ``nanosec < 1e9``. Finite stamps are
rounded to the nearest nanosecond (the message's resolution); for epoch-scale stamps, whose
float64 spacing is far coarser than 1 ns, the round trip is exact. Non-finite stamps cannot be
times, so they are written as markers with the otherwise invalid ``nanosec = 0xFFFFFFFF``:

======  ==================  ==============
stamp   sec                 nanosec
======  ==================  ==============
NaN     0                   0xFFFFFFFF
+inf    2147483647          0xFFFFFFFF
-inf    -2147483648         0xFFFFFFFF
======  ==================  ==============

and read back as NaN, +inf and -inf, so faulty stamps survive a bag unchanged. Any other
``(sec, nanosec)`` reads as ``sec + nanosec / 1e9`` (correctly rounded below 2**53 ns). Finite
stamps outside the int32 seconds range are refused (:class:`StampRangeError`).

Log times (the bag's per-message receive time, uint64 ns) derived from stamps are made
non-decreasing, so a bag replays in the order it was written, as a recorder would have logged
it: see :func:`log_times_from_stamps`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]
Int32Array = NDArray[np.int32]
UInt32Array = NDArray[np.uint32]
Int64Array = NDArray[np.int64]
UInt64Array = NDArray[np.uint64]

NS_PER_S = 1_000_000_000
INT32_MIN = -(2**31)
INT32_MAX = 2**31 - 1
#: ``nanosec`` of a non-finite stamp (never a valid time: nanosec must be below 1e9).
NONFINITE_NANOSEC = 0xFFFFFFFF


class StampRangeError(ValueError):
    """Finite stamps that do not fit ``builtin_interfaces/Time``; ``indices`` lists them."""

    def __init__(self, indices: Int64Array, values: FloatArray) -> None:
        shown = ", ".join(
            f"[{int(i)}] = {float(v)!r}" for i, v in zip(indices[:3], values[:3], strict=True)
        )
        super().__init__(f"{len(indices)} finite stamp(s) outside [-2**31, 2**31) s, e.g. {shown}")
        self.indices = indices


def seconds_to_stamps(stamp_s: ArrayLike) -> tuple[Int32Array, UInt32Array]:
    """Float seconds -> ``(sec, nanosec)`` arrays, with the non-finite markers of the module.

    Raises:
        StampRangeError: a finite stamp is outside the int32 seconds range.
    """
    t = np.asarray(stamp_s, dtype=np.float64)
    finite = np.isfinite(t)
    tf = np.where(finite, t, 0.0)
    whole = np.floor(tf)
    nanosec = np.rint((tf - whole) * NS_PER_S)
    carry = nanosec >= NS_PER_S
    whole = whole + carry
    nanosec = np.where(carry, 0.0, nanosec)
    bad = finite & ((whole < INT32_MIN) | (whole > INT32_MAX))
    if bad.any():
        indices = np.flatnonzero(bad).astype(np.int64)
        raise StampRangeError(indices, t[indices])
    marker_sec = np.where(np.isnan(t), 0, np.where(t > 0, INT32_MAX, INT32_MIN))
    sec = np.where(finite, whole, marker_sec).astype(np.int32)
    nsec = np.where(finite, nanosec, NONFINITE_NANOSEC).astype(np.uint32)
    return sec, nsec


def stamps_to_seconds(sec: ArrayLike, nanosec: ArrayLike) -> FloatArray:
    """``(sec, nanosec)`` -> float seconds; the non-finite markers become NaN / +inf / -inf,
    and any other ``nanosec`` of a second or more NaN (invalid, as the node reads it:
    :func:`prsm_health.ros.messages.stamp_seconds`; the replay took (s - 1, 1e9 + ns) for
    s + ns and accepted samples the node rejected)."""
    s = np.asarray(sec, dtype=np.int64)
    ns = np.asarray(nanosec, dtype=np.int64)
    total = s * NS_PER_S + ns  # |total| < 2**62: no overflow
    # Below 2**53 ns (104 days) the total is exact in float64 and one division rounds it
    # correctly; beyond, the fraction is rounded once and added to the whole seconds.
    seconds = np.where(
        np.abs(total) < 2**53,
        total.astype(np.float64) / NS_PER_S,
        s.astype(np.float64) + ns.astype(np.float64) / NS_PER_S,
    )
    invalid = ns >= NS_PER_S
    if not invalid.any():
        return seconds
    marker = ns == NONFINITE_NANOSEC
    special = np.where(marker & (s > 0), np.inf, np.where(marker & (s < 0), -np.inf, np.nan))
    return np.where(invalid, special, seconds)


def log_times_from_stamps(stamp_s: ArrayLike) -> UInt64Array:
    """Bag log times [ns] for messages stamped ``stamp_s``, in write order.

    The stamp in nanoseconds (as written into the header), made non-decreasing by a running
    maximum: a stamp that goes backwards, a non-finite stamp and a negative stamp all take the
    largest log time so far (0 before the first usable stamp). Readers that sort by log time
    (rosbags, mcap, :mod:`prsm_health.bags.reader`) then return the messages in write order.
    """
    sec, nanosec = seconds_to_stamps(stamp_s)
    ns = sec.astype(np.int64) * NS_PER_S + nanosec.astype(np.int64)
    ns = np.where(nanosec == NONFINITE_NANOSEC, 0, np.maximum(ns, 0))
    return np.maximum.accumulate(ns).astype(np.uint64) if len(ns) else ns.astype(np.uint64)
