"""``acs-twin warm``: the kernels serve needs are flown once, so that the server starts on cached machine code."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from backend.cli import main
from backend.jobs import kernel_signatures


def test_warm_flies_the_demo_decodes_it_synchronises_a_live_twin_and_compiles_the_record(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    record = tmp_path / "kernel_signatures.json"
    vectors = ["float64[1d,C]", "float64[1d,C]"]
    record.write_text(json.dumps({"sim_core.quaternion": {"multiply_1": [vectors], "no_such_kernel": [vectors]}}))
    monkeypatch.setattr(kernel_signatures, "RECORD", record)
    assert main(["warm", "--recorded"]) == 0
    out = capsys.readouterr().out
    for step in ("emulator flight", "decoding", "live twin"):
        assert f"  {step}: " in out
    assert "  recorded signatures (kernel_signatures.json, beside the flight): 1, all done in " in out
    assert "skipped (numba compiles it on first call instead): sim_core.quaternion.no_such_kernel" in out
    assert "kernels compiled and cached" in out


def test_warm_names_an_unknown_scenario() -> None:
    with pytest.raises(ValueError, match="no-such-scenario"):
        main(["warm", "--scenario", "no-such-scenario"])
