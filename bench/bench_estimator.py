"""The estimator benchmark (run time against error; a benchmark, not a test).

The same as ``prsm-health bench`` (prsm_health/benchmark.py, docs/performance.md): every
estimator configuration on the bundled bags and generated runs, scored against the truth, with
the issue's floors in ``build/bench/results.md``.

    .venv/bin/python bench/bench_estimator.py [--quick] [--out DIR] [--scenes ...] [--configs ...]
"""

from __future__ import annotations

import sys

from prsm_health.cli import main

if __name__ == "__main__":
    sys.exit(main(["bench", *sys.argv[1:]]))
