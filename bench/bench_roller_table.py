"""Build time and error of the per-roller table against the physics core (not a test).

For each configuration of dong2022-downhole (aligned with radial load, both loading cases;
axial only; 2' misalignment without and with radial load) builds the default table and
compares it with :func:`roller_values` at random off-grid points: axial load log-uniform over
0.1-1 x the preset's largest, radial ratio uniform up to the table's largest, carrier angle
uniform. Prints the largest relative error of the total friction torque at 300 rpm (healthy,
and with any one roller jammed), of the total wear rate and of the largest contact force.
The bounds in test/physics/test_roller_table.py and docs/scenes.md come from this.

    .venv/bin/python bench/bench_roller_table.py [--points N]
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np
from numpy.typing import NDArray

from prsm_health.physics.geometry import Misalignment
from prsm_health.physics.load_distribution import LoadingCase
from prsm_health.physics.presets import load_preset
from prsm_health.physics.roller_table import roller_table, roller_values

CONFIGURATIONS = (
    ("aligned, radial, case 1", Misalignment(), LoadingCase(1), True),
    ("aligned, radial, case 2", Misalignment(), LoadingCase(2), True),
    ("aligned, axial only, case 1", Misalignment(), LoadingCase(1), False),
    ("2' tilt, axial only, case 2", Misalignment.from_arcmin(2.0, 0.0), LoadingCase(2), False),
    ("2' tilt, radial, case 2", Misalignment.from_arcmin(2.0, 0.0), LoadingCase(2), True),
)


def worst(table_value: NDArray[np.float64], exact_value: NDArray[np.float64]) -> float:
    """Largest relative deviation."""
    return float(np.max(np.abs(table_value / exact_value - 1.0)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=600)
    points = parser.parse_args().points
    preset = load_preset("dong2022-downhole")
    n_rollers = preset.geometry.n_rollers
    speed = 300.0 * math.pi / 30.0
    largest = preset.largest_axial_load_n
    print(
        f"{'configuration':30s} {'build s':>8s} {'friction':>9s} {'1 jammed':>9s} "
        f"{'wear':>9s} {'peak':>9s}"
    )
    for label, tilt, case, radial in CONFIGURATIONS:
        start = time.perf_counter()
        table = roller_table(preset, tilt, case, radial=radial)
        build_s = time.perf_counter() - start
        rng = np.random.default_rng(12345)
        load = np.exp(rng.uniform(math.log(0.1 * largest), math.log(largest), points))
        ratio = rng.uniform(0.0, table.max_radial_ratio, points)
        carrier = rng.uniform(0.0, 2.0 * math.pi, points)
        exact = roller_values(
            preset,
            load,
            radial_load_n=ratio * load,
            carrier_angle_rad=carrier,
            misalignment=tilt,
            case=case,
        )
        angles = carrier[:, None] + 2.0 * math.pi * np.arange(n_rollers) / n_rollers
        looked_up = table.lookup(load[:, None], ratio[:, None], angles)
        healthy = np.zeros(n_rollers, dtype=bool)
        friction = worst(
            looked_up.friction_torque_nm(speed, healthy).sum(-1),
            exact.friction_torque_nm(speed, healthy).sum(-1),
        )
        jammed = max(
            worst(
                looked_up.friction_torque_nm(speed, np.arange(n_rollers) == i).sum(-1),
                exact.friction_torque_nm(speed, np.arange(n_rollers) == i).sum(-1),
            )
            for i in range(n_rollers)
        )
        wear = worst(looked_up.wear_m_per_rad.sum(-1), exact.wear_m_per_rad.sum(-1))
        peak = worst(looked_up.peak_contact_force_n.max(-1), exact.peak_contact_force_n.max(-1))
        print(f"{label:30s} {build_s:8.2f} {friction:9.2e} {jammed:9.2e} {wear:9.2e} {peak:9.2e}")


if __name__ == "__main__":
    main()
