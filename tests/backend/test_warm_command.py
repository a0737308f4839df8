"""``acs-twin warm``: the kernels serve needs are flown once, so that the server starts on cached machine code."""

from __future__ import annotations

import pytest

from backend.cli import main


def test_warm_flies_the_demo_decodes_it_and_synchronises_a_live_twin(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["warm"]) == 0
    out = capsys.readouterr().out
    for step in ("emulator flight", "decoding", "live twin"):
        assert f"  {step}: " in out
    assert "kernels compiled and cached" in out


def test_warm_names_an_unknown_scenario() -> None:
    with pytest.raises(ValueError, match="no-such-scenario"):
        main(["warm", "--scenario", "no-such-scenario"])
