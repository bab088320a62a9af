"""Cost of the physics core on this machine (a benchmark, not a test).

Prints the median time of one load-distribution solve (10 rollers x 20 threads, paper 004
preset) for the aligned axial case, with a radial load, and with a misalignment; of a
vectorised batch of 1,000 axial loads (per load); and of the whole model chain at one point.
Issue floors: one solve <= 2 ms; batch <= 0.1 ms per load.

    .venv/bin/python bench/bench_physics.py [--repeat N]
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import numpy as np

from prsm_health.physics.geometry import Misalignment
from prsm_health.physics.load_distribution import solve_load_distribution
from prsm_health.physics.meshing import meshing
from prsm_health.physics.model import OperatingPoint, evaluate
from prsm_health.physics.presets import load_preset


def median_s(run: Callable[[], object], repeat: int) -> float:
    """Median wall time of ``run`` over ``repeat`` calls, after one warm-up call."""
    run()
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=50)
    repeat = parser.parse_args().repeat
    preset = load_preset("meng2022-misalignment")
    geometry = preset.geometry
    tilt = meshing(geometry, Misalignment.from_arcmin(1.0, 1.0))
    batch = np.linspace(1_000.0, 50_000.0, 1_000)
    cases: dict[str, tuple[Callable[[], object], int]] = {
        "solve, axial 50 kN (symmetric)": (lambda: solve_load_distribution(geometry, 5e4), 1),
        "solve, 30 kN + radial 6 kN": (
            lambda: solve_load_distribution(geometry, 3e4, radial_load_n=6e3),
            1,
        ),
        "solve, 50 kN + 1'/1' misalignment": (
            lambda: solve_load_distribution(
                geometry, 5e4, clearance_screw_roller_m=tilt.axial_clearance_screw_roller_m
            ),
            1,
        ),
        "batch of 1,000 axial loads, per load": (
            lambda: solve_load_distribution(geometry, batch),
            batch.size,
        ),
        "model chain (all physics), 30 kN 300 rpm": (
            lambda: evaluate(
                preset,
                OperatingPoint(axial_load_n=3e4, screw_speed_rad_s=300 * 2 * np.pi / 60),
            ),
            1,
        ),
    }
    print(f"{'case':45s} {'median':>12s}")
    for name, (run, per) in cases.items():
        seconds = median_s(run, max(3, repeat // per if per > 1 else repeat)) / per
        print(f"{name:45s} {seconds * 1e3:9.4f} ms")


if __name__ == "__main__":
    main()
