"""YAML reading shared by presets, scenes and parameter files.

PyYAML implements YAML 1.1; our data files are written by engineers who expect the YAML 1.2
core schema, so the loader differs from ``yaml.SafeLoader`` in three ways:

- YAML 1.2 floats: ``2.12e11`` (no dot before the exponent sign) is a number, not a string.
- YAML 1.2 booleans: only true/false (any case spelling YAML allows) are booleans; yes, no,
  on and off stay strings, so ``radial_terms: on`` means the listed value "on" (YAML 1.1 read
  it as True, and the user who wrote a listed word was told it is not one). No field of ours
  takes yes/no/on/off for a boolean: the bundled files write true/false.
- A key twice in one mapping (two ``noise:`` sections) is an error naming its line; YAML 1.1
  silently keeps the last one.

Every error is one line that names the file (and the line, when the parser knows it).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml

_BOOL = "tag:yaml.org,2002:bool"


class _Loader(yaml.SafeLoader):
    """SafeLoader with YAML 1.2 floats and booleans that refuses duplicate keys."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        """The mapping, after refusing a key that appears twice in it (merge keys ``<<``
        excepted: a mapping may override what it merges)."""
        first_line: dict[Any, int] = {}
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                continue
            key = self.construct_object(key_node, deep=deep)
            try:
                first = first_line.get(key)
            except TypeError:  # an unhashable key: SafeLoader refuses it itself
                continue
            if first is not None:
                raise yaml.constructor.ConstructorError(
                    None,
                    None,
                    f"duplicate key {key!r} (first on line {first + 1})",
                    key_node.start_mark,
                )
            first_line[key] = key_node.start_mark.line
        return super().construct_mapping(node, deep=deep)


_Loader.yaml_implicit_resolvers = {
    first: [(tag, regexp) for tag, regexp in resolvers if tag != _BOOL]
    for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
_Loader.add_implicit_resolver(
    _BOOL, re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$"), list("tTfF")
)
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


def _parse_error(path: Path, exc: yaml.YAMLError) -> str:
    """One line for a parser error: the file, the line and column, what was wrong (PyYAML's
    own text spans several lines and names the text "<unicode string>", not the file)."""
    if isinstance(exc, yaml.MarkedYAMLError):
        mark = exc.problem_mark or exc.context_mark
        what = ", ".join(part for part in (exc.context, exc.problem) if part)
        if mark is not None:
            return f"{path}, line {mark.line + 1}, column {mark.column + 1}: {what}"
        return f"{path}: {what}"
    return f"{path}: {' '.join(str(exc).split())}"


def load_yaml_mapping(path: Path) -> dict[str, Any]:
    """Parse ``path`` (UTF-8 text) and return its top-level mapping; an empty document (no
    text, or only comments) is the empty mapping, every key left to its default."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise YamlError(f"cannot read {path}: {exc.strerror or exc}") from exc
    except UnicodeDecodeError as exc:
        line = exc.object[: exc.start].count(b"\n") + 1
        raise YamlError(
            f"{path}, line {line}: not UTF-8 text (byte {exc.object[exc.start]:#04x}); "
            "save the file as UTF-8"
        ) from exc
    try:
        data = yaml.load(text, Loader=_Loader)  # noqa: S506
    except yaml.YAMLError as exc:
        raise YamlError(_parse_error(path, exc)) from exc
    except ValueError as exc:  # e.g. an integer beyond Python's 4300-digit conversion limit
        raise YamlError(f"{path}: {exc}") from exc
    except RecursionError as exc:  # the parser recurses per level of nesting
        raise YamlError(f"{path}: nested too deeply") from exc
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise YamlError(f"{path} does not hold a mapping (it holds a {type(data).__name__})")
    return data
