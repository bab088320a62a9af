"""Input validation at the edges: the YAML reader of every data file (YAML 1.2 booleans,
duplicate keys, one-line errors naming the file) and the MotorSamples container."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from prsm_health.signals import MotorSamples
from prsm_health.yamlio import YamlError, load_yaml_mapping


def _load(tmp_path: Path, text: str) -> dict[str, object]:
    path = tmp_path / "data.yaml"
    path.write_text(text, encoding="utf-8")
    return load_yaml_mapping(path)


def test_only_true_and_false_are_booleans(tmp_path: Path) -> None:
    """YAML 1.2: yes/no/on/off are the words written (YAML 1.1 read them as booleans)."""
    data = _load(
        tmp_path,
        "a: on\nb: off\nc: yes\nd: no\ne: On\nf: NO\ng: true\nh: False\ni: TRUE\nj: 'true'\n",
    )
    assert data == {
        "a": "on",
        "b": "off",
        "c": "yes",
        "d": "no",
        "e": "On",
        "f": "NO",
        "g": True,
        "h": False,
        "i": True,
        "j": "true",
    }
    assert _load(tmp_path, "on: 1\n") == {"on": 1}  # a key too


def test_numbers_keep_their_yaml_12_reading(tmp_path: Path) -> None:
    assert _load(tmp_path, "a: 2.12e11\nb: 1e5\nc: 7\nd: .inf\n") == {
        "a": 2.12e11,
        "b": 1e5,
        "c": 7,
        "d": float("inf"),
    }


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "noise: {a: 1}\nnoise: {a: 2}\n",
            "line 2, column 1: duplicate key 'noise' (first on line 1)",
        ),
        (
            "noise:\n  a: 1\n  b: 2\n  a: 3\n",
            "line 4, column 3: duplicate key 'a' (first on line 2)",
        ),
        ("x: {a: 1, a: 2}\n", "line 1, column 11: duplicate key 'a' (first on line 1)"),
        ("x: [{a: 1}, {b: 1, b: 2}]\n", "line 1, column 20: duplicate key 'b' (first on line 1)"),
    ],
)
def test_a_duplicate_key_is_refused_naming_file_key_and_line(
    tmp_path: Path, text: str, message: str
) -> None:
    """PyYAML keeps the last of two equal keys silently."""
    with pytest.raises(YamlError, match=rf"^{re.escape(str(tmp_path / 'data.yaml'))}, "):
        _load(tmp_path, text)
    with pytest.raises(YamlError, match=re.escape(message)):
        _load(tmp_path, text)


def test_a_mapping_may_override_what_it_merges(tmp_path: Path) -> None:
    text = "base: &b {a: 1, c: 3}\nx:\n  <<: *b\n  a: 2\n"
    assert _load(tmp_path, text)["x"] == {"a": 2, "c": 3}


def test_an_empty_file_is_the_empty_mapping(tmp_path: Path) -> None:
    """Every key left to its default; it was refused as "does not hold a mapping", which sent
    a user hunting for a syntax error in a file of comments."""
    path = tmp_path / "params.yaml"
    for text in ("", "# every value left to its default\n"):
        path.write_text(text)
        assert load_yaml_mapping(path) == {}


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"a: 1\nb: \xff\n", r"data\.yaml, line 2: not UTF-8 text \(byte 0xff\)"),
        (
            b"a: [1\nb: 2\n",
            r"data\.yaml, line 2, column 2: while parsing a flow sequence, expected",
        ),
        (b"a: 1" + b"1" * 5000 + b"\n", r"data\.yaml: Exceeds the limit \(4300 digits\)"),
        (b"- 1\n", r"data\.yaml does not hold a mapping \(it holds a list\)"),
    ],
)
def test_unreadable_files_are_one_line_naming_the_file(
    tmp_path: Path, content: bytes, message: str
) -> None:
    path = tmp_path / "data.yaml"
    path.write_bytes(content)
    with pytest.raises(YamlError, match=message) as info:
        load_yaml_mapping(path)
    assert "\n" not in str(info.value)


N = 5
COLUMNS = ("stamp_s", "current_a", "speed_rad_s", "position_rad")


def _columns() -> dict[str, object]:
    return {name: np.arange(N, dtype=np.float64) for name in COLUMNS}


@pytest.mark.parametrize("dtype", [np.float64, np.float32, np.float16, np.int64, np.uint16])
def test_motor_samples_take_real_1d_columns(dtype: type[np.generic]) -> None:
    columns = _columns() | {"current_a": np.arange(N).astype(dtype)}
    assert len(MotorSamples(**columns)) == N  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("stamp_s", np.zeros((N, 1)), r"MotorSamples\.stamp_s: must be 1-D .*shape \(5, 1\)"),
        ("speed_rad_s", np.zeros((2, N)), r"MotorSamples\.speed_rad_s: must be 1-D"),
        ("current_a", np.zeros(N, dtype=object), r"MotorSamples\.current_a: .*dtype object"),
        ("current_a", np.zeros(N, dtype=bool), r"MotorSamples\.current_a: .*dtype bool"),
        ("position_rad", np.zeros(N, dtype=complex), r"MotorSamples\.position_rad: .*complex"),
        ("position_rad", [0.0] * N, r"MotorSamples\.position_rad: must be a numpy array, got list"),
        ("stamp_s", np.float64(1.0), r"MotorSamples\.stamp_s: must be a numpy array"),
        ("speed_rad_s", np.zeros(N - 1), r"MotorSamples: fields differ in length"),
    ],
)
def test_motor_samples_name_a_bad_column(field: str, value: object, message: str) -> None:
    """The estimator failed deep inside on these, naming neither the field nor the problem."""
    with pytest.raises(ValueError, match=message):
        MotorSamples(**(_columns() | {field: value}))  # type: ignore[arg-type]


def test_a_file_nested_too_deeply_is_one_line_naming_it(tmp_path: Path) -> None:
    """The parser recurses per level: a RecursionError escaped (the node logged only that
    configure failed)."""
    path = tmp_path / "deep.yaml"
    path.write_text("a: " + "[" * 5000 + "]" * 5000 + "\n", encoding="utf-8")
    with pytest.raises(YamlError, match=rf"^{re.escape(str(path))}: nested too deeply$"):
        load_yaml_mapping(path)
