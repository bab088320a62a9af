"""Stamps: float seconds <-> builtin_interfaces/Time, non-finite markers, log times."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from prsm_health.bags.stamps import (
    NONFINITE_NANOSEC,
    StampRangeError,
    log_times_from_stamps,
    seconds_to_stamps,
    stamps_to_seconds,
)


def test_non_finite_stamps_survive_as_markers() -> None:
    sec, nanosec = seconds_to_stamps([np.nan, np.inf, -np.inf, 1.5])
    assert sec.tolist() == [0, 2**31 - 1, -(2**31), 1]
    assert nanosec.tolist() == [NONFINITE_NANOSEC] * 3 + [500_000_000]
    back = stamps_to_seconds(sec, nanosec)
    np.testing.assert_array_equal(back, [np.nan, np.inf, -np.inf, 1.5])


def test_a_nanosec_of_a_second_or_more_is_invalid_as_the_node_reads_it() -> None:
    """(sec - 1, nanosec + 1e9) was read as sec + nanosec and accepted, where the node's
    stamp_seconds rejects it (found by a review session); the markers stay markers."""
    back = stamps_to_seconds([4, 4, 3, -5], [1_000_000_000, 4_000_000_000, 999_999_999, 7])
    np.testing.assert_array_equal(back, [np.nan, np.nan, 3.999999999, -4.999999993])
    np.testing.assert_array_equal(
        stamps_to_seconds([5, -5, 0], [NONFINITE_NANOSEC] * 3), [np.inf, -np.inf, np.nan]
    )


def test_negative_stamps_and_rounding_carry() -> None:
    sec, nanosec = seconds_to_stamps([-3.25, 2.9999999999, -1e-10])
    assert sec.tolist() == [-4, 3, 0]
    assert nanosec.tolist() == [750_000_000, 0, 0]


@given(st.floats(min_value=-(2.0**31) + 1, max_value=2.0**31 - 1, allow_nan=False))
def test_finite_round_trip_is_within_half_a_nanosecond(t: float) -> None:
    sec, nanosec = seconds_to_stamps([t])
    assert 0 <= nanosec[0] < 1_000_000_000
    assert abs(stamps_to_seconds(sec, nanosec)[0] - t) <= 0.5e-9 + abs(t) * 2.3e-16


@given(st.floats(min_value=1e9, max_value=2.0**31 - 1))
def test_epoch_stamps_round_trip_exactly(t: float) -> None:
    assert stamps_to_seconds(*seconds_to_stamps([t]))[0] == t


def test_out_of_range_finite_stamps_are_refused() -> None:
    with pytest.raises(StampRangeError, match=r"1 finite stamp.*\[1\] = 3000000000.0") as info:
        seconds_to_stamps([0.0, 3e9, np.nan])
    assert info.value.indices.tolist() == [1]


def test_log_times_are_the_stamps_made_non_decreasing() -> None:
    stamps = [np.nan, 1.0, 2.0, 1.5, np.inf, -5.0, 3.0]
    log = log_times_from_stamps(stamps)
    assert log.dtype == np.uint64
    s = 1_000_000_000
    assert log.tolist() == [0, s, 2 * s, 2 * s, 2 * s, 2 * s, 3 * s]
    assert log_times_from_stamps([]).tolist() == []
