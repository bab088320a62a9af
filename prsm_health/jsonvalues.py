"""Values for JSON: JSON has null but no NaN or infinity (``json.dumps`` writes bare ``NaN``,
which strict parsers refuse)."""

from __future__ import annotations

import math


def json_safe(value: object) -> object:
    """``value`` with every non-finite float in it (in lists, tuples and dicts too) replaced
    by None."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, list | tuple):
        return [json_safe(v) for v in value]
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    return value
