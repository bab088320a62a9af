"""YAML reading shared by presets, scenes and parameter files.

PyYAML implements YAML 1.1, where ``2.12e11`` (no dot before the exponent sign) is a string.
Our data files are written by engineers in the usual scientific notation, so the loader also
resolves YAML 1.2 floats.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml


class _Loader(yaml.SafeLoader):
    """SafeLoader that also reads YAML 1.2 floats such as ``1e5`` and ``2.12e11``."""


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(
        r"""^(?:[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?(?:[eE][-+]?[0-9]+)?
        |[-+]?\.[0-9_]+(?:[eE][-+]?[0-9]+)?
        |[-+]?\.(?:inf|Inf|INF)
        |\.(?:nan|NaN|NAN))$""",
        re.X,
    ),
    list("-+0123456789."),
)


class YamlError(ValueError):
    """A YAML file could not be read or parsed; the message names the file."""


def load_yaml_mapping(path: Path) -> dict[str, Any]:
    """Parse ``path`` and return its top-level mapping."""
    try:
        data = yaml.load(path.read_text(encoding="utf-8"), Loader=_Loader)  # noqa: S506
    except (OSError, yaml.YAMLError) as exc:
        raise YamlError(f"cannot read {path}: {exc}") from exc
    if not isinstance(data, dict):
        raise YamlError(f"{path} does not hold a mapping")
    return data
