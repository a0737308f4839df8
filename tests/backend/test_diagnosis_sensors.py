"""Diagnosis of sensor faults from the reference satellite's packets: the magnetometer against the field model
(IGRF-14 at the GPS position, rotated by the estimated attitude), the emulator's hidden bias as the truth."""

from __future__ import annotations

from datetime import datetime

import pytest

from backend.twin.diagnosis import diagnose_batches
from sim_core import scenario_library
from telemetry import emulator
from telemetry.decoding import decode_stream
from telemetry.dictionary import load_dictionary

SCENARIO = "somov-ge4-scan"
FLIGHT_S, ONSET_S = 600.0, 300.0
BIAS_T = 1.0e-6  # 1 µT on body y: 20 σ of the 50 nT magnetometer noise, 500 counts of 2 nT
EPOCH = "2026-04-02T00:00:00Z"


def _batches(faults: list) -> tuple[list, object]:
    dictionary = load_dictionary(emulator.REFERENCE_DICTIONARY)
    _, _, stream = emulator.emulate(SCENARIO, faults, FLIGHT_S, EPOCH, dictionary, seed=5, fdir=False, truth_seed=5)
    return decode_stream(stream.data, dictionary).batches, dictionary


@pytest.fixture(scope="module")
def biased() -> tuple[list, object]:
    """The flight with the magnetometer bias, decoded: one emulation for the tests that diagnose it with and
    without its GPS packets (the diagnosis reads the batches, never changes them)."""
    return _batches([emulator.parse_fault(f"magnetometer:1:bias@{ONSET_S},value={BIAS_T}")])


def _diagnose(batches: list, dictionary) -> dict:
    return diagnose_batches(batches, dictionary, scenario_library.get(SCENARIO))  # type: ignore[arg-type]


def test_magnetometer_bias_is_named_with_its_size_and_onset(biased) -> None:
    result = _diagnose(*biased)
    top = result["hypotheses"][0]
    assert (top["fault"], top["wheel"]) == ("magnetometer_bias", None)
    assert top["magnitude"] == pytest.approx(BIAS_T, rel=0.1)
    start = datetime.fromisoformat(result["telemetry_start_utc"]).timestamp()
    assert abs(datetime.fromisoformat(top["onset_utc"]).timestamp() - start - ONSET_S) <= 5.0
    assert result["detection"]["detected"]
    assert result["detection"]["channel"] == "magnetometer y"


def test_nominal_flight_compares_the_magnetometer_without_alarm() -> None:
    result = _diagnose(*_batches([]))
    assert "magnetometer_bias" not in result["untestable"]
    assert not result["detection"]["detected"]
    assert result["hypotheses"][0]["fault"] == "none"


def test_without_gps_positions_the_magnetometer_is_untestable_and_says_why(biased) -> None:
    batches, dictionary = biased
    result = _diagnose([b for b in batches if "r_ecef_m_x" not in b.values], dictionary)
    assert "r_ecef_m" in result["untestable"]["magnetometer_bias"]
    assert all(h["fault"] != "magnetometer_bias" for h in result["hypotheses"])
