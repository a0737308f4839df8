"""Hostile dictionaries and ground files: refused or quarantined with the field named, memory bounded.

Truths: the CCSDS packet length limit (133.0-B-2 §4.1.3.5: a data field of at most 65,536 octets),
the dictionary's own folder as the only place a layout may come from, and the line structure of the
damaged files (each bad line quarantined, its valid neighbours kept).
"""

from __future__ import annotations

import json
import resource
import shutil
from pathlib import Path

import pytest

from telemetry.dictionary import MAX_PACKET_BITS, SHIPPED, load_ccsdspy_csv, load_yaml
from telemetry.ground_files import read_ground_csv, read_ground_jsonl
from tests.telemetry.packet_streams import NOW_UTC_NS, reference

MEMORY_BUDGET_KB = 200_000  # issue 16: no request may raise the server's memory by more than 200 MB


def _peak_rss_kb() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss


@pytest.mark.parametrize("data_type", ["uint(100000000)", "uint(1000000)", "uint(65537)"])
def test_csv_array_larger_than_a_ccsdspy_packet_is_refused_without_expanding_it(tmp_path: Path, data_type) -> None:
    layout = tmp_path / "huge.csv"
    layout.write_text(f"name,data_type,bit_length\nword,{data_type},8\n")
    before = _peak_rss_kb()
    with pytest.raises(ValueError, match=r"word\.data_type: .*largest CCSDS packet"):
        load_ccsdspy_csv(layout, apid=5)
    assert _peak_rss_kb() - before < MEMORY_BUDGET_KB


def test_csv_array_filling_the_largest_packet_still_loads(tmp_path: Path) -> None:
    layout = tmp_path / "full.csv"
    words = (MAX_PACKET_BITS - 48) // 32
    layout.write_text(f"name,data_type,bit_length\nword,uint({words}),32\n")
    packet = load_ccsdspy_csv(layout, apid=5).packets[5]
    assert packet.packet_octets == 6 + 4 * words and len(packet.parameters) == words


@pytest.mark.parametrize("target", ["/dev/zero", "/etc/passwd", "../outside.csv", "sub/../../outside.csv"])
def test_layout_from_reads_only_the_dictionary_folder(tmp_path: Path, target: str) -> None:
    folder = tmp_path / "dicts"
    folder.mkdir()
    (tmp_path / "outside.csv").write_text("name,data_type,bit_length\nx,uint,8\n")
    spec = folder / "evil.yaml"
    spec.write_text(f"packets:\n  - name: EVIL\n    apid: 5\n    layout_from: {{ccsdspy_csv: {target}}}\n")
    with pytest.raises(ValueError, match=r"EVIL\.layout_from\.ccsdspy_csv: .*next to the dictionary"):
        load_yaml(spec)


def test_layout_from_a_symlink_out_of_the_folder_is_refused(tmp_path: Path) -> None:
    folder = tmp_path / "dicts"
    folder.mkdir()
    (folder / "zero.xml").symlink_to("/dev/zero")
    spec = folder / "evil.yaml"
    spec.write_text("packets:\n  - name: EVIL\n    apid: 5\n    layout_from: {xtce: zero.xml}\n")
    with pytest.raises(ValueError, match=r"EVIL\.layout_from\.xtce"):
        load_yaml(spec)


def test_layout_from_beside_the_dictionary_still_works(tmp_path: Path) -> None:
    for name in ("noaa20_apid11_ccsdspy.yaml", "ccsdspy_jpss1_geolocation.csv"):
        shutil.copy(SHIPPED / name, tmp_path / name)
    assert 11 in load_yaml(tmp_path / "noaa20_apid11_ccsdspy.yaml").packets


def _ground_csv(rows: list[str]) -> bytes:
    header = "t_utc_ns,wheel_speed_rad_s_1"
    return ("\n".join([header, *rows]) + "\n").encode()


def test_csv_with_a_stray_carriage_return_quarantines_that_line_only() -> None:
    t0 = NOW_UTC_NS - 10**9 * 3600
    good = [f"{t0 + i * 10**9},{i}.0" for i in range(4)]
    data = _ground_csv([good[0], good[1][:5] + "\r" + good[1][5:], good[2] + "\r", good[3]])  # CRLF ends are fine
    result = read_ground_csv(data, reference(), now_utc_ns=NOW_UTC_NS)
    assert [(q.reason, q.line) for q in result.report.quarantined] == [("bad_row", 3)]
    assert "carriage return" in result.report.quarantined[0].detail
    assert list(result.batches[0].values["wheel_speed_rad_s_1"]) == [0.0, 2.0, 3.0]


def test_csv_with_an_unclosed_quote_quarantines_that_line_only() -> None:
    t0 = NOW_UTC_NS - 10**9 * 3600
    data = _ground_csv([f"{t0},1.0", f'{t0 + 10**9},"2.0', f"{t0 + 2 * 10**9},3.0"])
    result = read_ground_csv(data, reference(), now_utc_ns=NOW_UTC_NS)
    assert [(q.reason, q.line) for q in result.report.quarantined] == [("bad_row", 3)]
    assert list(result.batches[0].values["wheel_speed_rad_s_1"]) == [1.0, 3.0]


def test_deeply_nested_jsonl_line_is_quarantined_and_neighbours_kept() -> None:
    t0 = NOW_UTC_NS - 10**9 * 3600
    lines = [
        json.dumps({"t_utc_ns": t0, "wheel_speed_rad_s_1": 1.0}),
        "[" * 200_000 + "]" * 200_000,
        json.dumps({"t_utc_ns": t0 + 10**9, "wheel_speed_rad_s_1": 2.0}),
    ]
    result = read_ground_jsonl("\n".join(lines).encode(), reference(), now_utc_ns=NOW_UTC_NS)
    assert [(q.reason, q.line) for q in result.report.quarantined] == [("bad_row", 2)]
    assert list(result.batches[0].values["wheel_speed_rad_s_1"]) == [1.0, 2.0]
