"""The bag speed table (``python -m prsm_health.bags.speed``): it runs and refuses empty runs."""

from __future__ import annotations

import pytest

from prsm_health.bags.speed import main


def test_the_speed_table_has_a_line_per_step(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--samples", "300", "--repeats", "1"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("300 MotorState messages, bag ")
    assert len(lines) == 6 and lines[-1].startswith("baseline / read = ")


@pytest.mark.parametrize("option", ["--samples", "--repeats"])
def test_no_samples_or_repeats_is_refused_by_name(
    capsys: pytest.CaptureFixture[str], option: str
) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main([option, "0"])
    assert exit_info.value.code == 2
    assert f"{option} must be at least 1, got 0" in capsys.readouterr().err
