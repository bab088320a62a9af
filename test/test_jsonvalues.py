"""JSON-safe values: the metrics file and monitor --json never write bare NaN."""

from __future__ import annotations

import json
import math

from prsm_health.jsonvalues import json_safe


def test_non_finite_floats_become_null_at_any_depth() -> None:
    value = {"a": math.nan, "b": [1.0, math.inf, (2, -math.inf)], "c": {"d": "x", "e": 3}}
    safe = json_safe(value)
    assert safe == {"a": None, "b": [1.0, None, [2, None]], "c": {"d": "x", "e": 3}}
    assert json.loads(json.dumps(safe, allow_nan=False)) == safe
