"""The sensor faults a scene injects, each on a hand-made run where its effect is known
(until a mutation review, the faults were checked only for not depending on the chunking and
by a floor on the estimator's rejected count: a spike that replaced the value instead of
adding to it, a non-finite run of one sample instead of three, a time jump or a dropout one
sample off all passed)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from prsm_health.scenes.faults import FaultInjector, sensor_faults_from_mapping
from prsm_health.scenes.scene import scene_from_mapping
from prsm_health.scenes.sensors import JITTER_LIMIT
from prsm_health.scenes.simulator import simulate
from prsm_health.signals import MotorSamples

RATE_HZ = 1000.0
FAULTS = sensor_faults_from_mapping(
    {
        "spikes": [{"time_s": 0.010, "field": "current_a", "value": 30.0}],
        "nonfinite": [{"time_s": 0.020, "field": "speed_rad_s", "value": math.nan, "samples": 3}],
        "stuck": [{"start_s": 0.030, "duration_s": 0.004, "field": "position_rad"}],
        "time_jumps": [{"time_s": 0.050, "jump_s": -0.5}],
        "dropouts": [{"start_s": 0.070, "duration_s": 0.005}],
    }
)


def clean_run() -> MotorSamples:
    """100 samples at 1 kHz: current 2 A, speed 100 rad/s, position sample number."""
    stamps = np.arange(100) / RATE_HZ
    return MotorSamples(stamps, np.full(100, 2.0), np.full(100, 100.0), np.arange(100.0))


@pytest.mark.parametrize("chunk", [100, 7, 1])
def test_each_fault_does_what_the_scene_says(chunk: int) -> None:
    injector = FaultInjector(FAULTS, RATE_HZ)
    run = clean_run()
    parts = [
        injector.apply(first, run[first : first + chunk], run.stamp_s[first : first + chunk])
        for first in range(0, 100, chunk)
    ]
    stamp = np.concatenate([p[0].stamp_s for p in parts])
    current = np.concatenate([p[0].current_a for p in parts])
    speed = np.concatenate([p[0].speed_rad_s for p in parts])
    position = np.concatenate([p[0].position_rad for p in parts])
    receive = np.concatenate([p[1] for p in parts])

    assert len(stamp) == len(receive) == 95  # samples 70..74 dropped
    kept = np.r_[0:70, 75:100]  # the original sample of each kept one
    assert current[10] == 32.0 and np.count_nonzero(current != 2.0) == 1  # added, once
    assert np.flatnonzero(np.isnan(speed)).tolist() == [20, 21, 22]
    assert position[30:34].tolist() == [30.0] * 4 and position[34] == 34.0
    expected_stamps = kept / RATE_HZ - np.where(kept >= 50, 0.5, 0.0)
    np.testing.assert_allclose(stamp, expected_stamps, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(receive, kept / RATE_HZ)  # the recorder's clock: no jump


def test_stamp_jitter_is_truncated_so_that_stamps_stay_in_order() -> None:
    """A jitter of a whole sample period (1 ms at 1 kHz) is cut at JITTER_LIMIT periods: the
    stamps stay in order (uncut, 2,409 of 10,000 went backwards)."""
    scene = scene_from_mapping(
        {
            "name": "jitter",
            "actuator": {"preset": "dong2022-downhole"},
            "duration_s": 10.0,
            "rate_hz": RATE_HZ,
            "profile": {"type": "constant", "speed_rpm": 300.0, "axial_load_n": 10e3},
            "sensors": {"stamp_jitter_s": 1e-3},
        }
    )
    stamps = simulate(scene).motor.stamp_s
    assert np.all(np.diff(stamps) > 0.0)
    offsets = stamps - np.arange(len(stamps)) / RATE_HZ
    assert np.abs(offsets).max() <= JITTER_LIMIT / RATE_HZ + 1e-12
    assert np.abs(offsets).max() > 0.9 * JITTER_LIMIT / RATE_HZ  # the cut was reached
