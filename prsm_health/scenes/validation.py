"""Checks for the fields of scene sections, with the dotted field name in every error.

Scene sections are frozen dataclasses built from YAML by
:func:`prsm_health.config.build_dataclass`; their ``__post_init__`` checks each field with the
helpers here (names relative to the section), and :func:`section` prefixes the section's
dotted name, so an error reads e.g. ``profile.speed_rpm: must be > 0, got -3.0``.
"""

from __future__ import annotations

from typing import Any, TypeVar

from prsm_health.config import build_dataclass
from prsm_health.physics.errors import ParameterError
from prsm_health.physics.geometry import require_integer, require_real

T = TypeVar("T")


def checked_number(
    value: object,
    name: str,
    *,
    low: float | None = None,
    high: float | None = None,
    open_low: bool = False,
) -> float:
    """``value`` as a float if it is a finite number in range, else a ParameterError on ``name``.

    ``low`` is inclusive unless ``open_low``; ``high`` is inclusive.
    """
    value = require_real(value, name)
    if low is not None and (value <= low if open_low else value < low):
        raise ParameterError(name, f"must be {'>' if open_low else '>='} {low:g}, got {value!r}")
    if high is not None and value > high:
        raise ParameterError(name, f"must be <= {high:g}, got {value!r}")
    return value


def number(
    obj: object,
    name: str,
    *,
    low: float | None = None,
    high: float | None = None,
    open_low: bool = False,
) -> float:
    """Check field ``name`` of ``obj`` with :func:`checked_number`; store it as a float."""
    value = checked_number(getattr(obj, name), name, low=low, high=high, open_low=open_low)
    object.__setattr__(obj, name, value)
    return value


def integer(obj: object, name: str, *, low: int, high: int | None = None) -> int:
    """Check field ``name`` of ``obj`` with :func:`require_integer` (an int in [low, high])."""
    return require_integer(getattr(obj, name), name, low, high)


def flag(obj: object, name: str) -> bool:
    """Check field ``name`` of ``obj`` is a bool."""
    value = getattr(obj, name)
    if not isinstance(value, bool):
        raise ParameterError(name, f"must be true or false, got {value!r}")
    return value


def level_or_range(obj: object, name: str, *, low: float, open_low: bool = False) -> None:
    """A field given as one number or as [min, max] (drawn uniformly); stored as a tuple."""
    value = getattr(obj, name)
    pair = list(value) if isinstance(value, list | tuple) else [value, value]
    if len(pair) != 2:
        raise ParameterError(name, f"must be a number or [min, max], got {value!r}")
    lower, upper = (checked_number(v, name, low=low, open_low=open_low) for v in pair)
    if lower > upper:
        raise ParameterError(name, f"[min, max] must have min <= max, got {value!r}")
    object.__setattr__(obj, name, (lower, upper))


def prefixed(exc: ParameterError, prefix: str, separator: str = ".") -> ParameterError:
    """The same error with ``prefix`` before its field (unless the field already has it)."""
    if exc.field == prefix or exc.field.startswith(f"{prefix}{separator}"):
        return exc
    return ParameterError(f"{prefix}{separator}{exc.field}", exc.message)


def section(cls: type[T], data: object, name: str, **fixed: Any) -> T:
    """:func:`build_dataclass` whose field errors carry the section's dotted ``name``."""
    try:
        return build_dataclass(cls, data, name, **fixed)
    except ParameterError as exc:
        raise prefixed(exc, name) from exc


def text(obj: object, name: str) -> str:
    """Check field ``name`` of ``obj`` is a string."""
    value = getattr(obj, name)
    if not isinstance(value, str):
        raise ParameterError(name, f"must be text, got {value!r}")
    return value


def items(data: object, name: str) -> list[Any]:
    """A YAML list (None or missing = empty), refusing anything else by name."""
    if data is None:
        return []
    if not isinstance(data, list):
        raise ParameterError(name, f"must be a list, got {type(data).__name__}")
    return data
