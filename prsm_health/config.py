"""Building validated frozen dataclasses from parsed YAML sections.

Presets, scenes and estimator parameters are YAML files written by engineers; a typo must be
refused with the dotted name of the key, not ignored or reported as a Python TypeError.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any, TypeVar

from prsm_health.physics.errors import ParameterError

T = TypeVar("T")


def build_dataclass(cls: type[T], section: object, name: str, **fixed: Any) -> T:
    """``cls(**section, **fixed)``, refusing non-mappings and unknown keys by dotted name.

    Missing keys take the dataclass defaults; a missing key without default is named too.
    The dataclass's own validation (``__post_init__``) names bad values; every unknown key and
    bad value is named in one error.
    """
    if section is None:
        section = {}
    if not isinstance(section, dict):
        raise ParameterError(name, f"must be a mapping, got {type(section).__name__}")
    known = {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = [key for key in section if key not in known or key in fixed]
    allowed = ", ".join(sorted(known - set(fixed)))
    problems = [
        ParameterError(f"{name}.{key}", f"unknown key; allowed: {allowed}") for key in unknown
    ]
    # The known values are checked too: one run names every problem of the section.
    values = {key: value for key, value in section.items() if key not in unknown}
    try:
        built = cls(**values, **fixed)
    except ParameterError as exc:
        problems.append(exc)
    except TypeError as exc:  # a required key is missing
        problems.append(ParameterError(name, str(exc)))
    if problems:
        raise ParameterError.combined(problems)
    return built


def build_each(
    parts: Mapping[str, Callable[[], Any]], problems: list[ParameterError] | None = None
) -> dict[str, Any]:
    """Each part built, by name; the ParameterErrors of all of them (after ``problems``, found
    before) raised as one (:meth:`ParameterError.combined`), so that one edit of a data file
    can fix every bad part."""
    found = list(problems or ())
    built: dict[str, Any] = {}
    for name, build in parts.items():
        try:
            built[name] = build()
        except ParameterError as exc:
            found.append(exc)
    if found:
        raise ParameterError.combined(found)
    return built
