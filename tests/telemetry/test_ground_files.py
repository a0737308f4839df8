"""Ground-processed CSV and JSON Lines: the same samples as the packet path, and row problems located.

Truth: the same engineering values sent as CCSDS packets through telemetry.decoding, and the
line numbers and byte offsets of the rows each test damages.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from telemetry.decoding import decode_stream
from telemetry.ground_files import read_ground_csv, read_ground_file, read_ground_jsonl
from tests.telemetry.packet_streams import NOW_UTC_NS, packets, reference

N = 30
COLUMNS = ["wheel_speed_rad_s_1", "md_dipole_am2_z", "q_est_ib_0", "mode"]


def _packet_batch():
    dictionary = reference()
    return decode_stream(packets(dictionary.packets[256], N).tobytes(), dictionary, now_utc_ns=NOW_UTC_NS).batches[0]


def _csv(batch, rows: range) -> bytes:
    lines = ["t_utc_ns," + ",".join(COLUMNS)]
    for i in rows:
        lines.append(f"{batch.t_utc_ns[i]}," + ",".join(repr(float(batch.values[c][i])) for c in COLUMNS))
    return ("\n".join(lines) + "\n").encode()


def test_csv_and_jsonl_give_the_packet_path_values() -> None:
    batch = _packet_batch()
    from_csv = read_ground_csv(_csv(batch, range(N)), reference(), now_utc_ns=NOW_UTC_NS)
    iso = np.datetime_as_string(batch.t_utc_ns.astype("datetime64[ns]"), unit="ns")
    jsonl = "\n".join(
        json.dumps({"t_utc": iso[i] + "Z", **{c: float(batch.values[c][i]) for c in COLUMNS}}) for i in range(N)
    ).encode()
    from_jsonl = read_ground_jsonl(jsonl, reference(), now_utc_ns=NOW_UTC_NS)
    for result in (from_csv, from_jsonl):
        (ground,) = result.batches
        assert ground.apid == 256 and result.report.quarantined == []
        np.testing.assert_array_equal(ground.t_utc_ns, batch.t_utc_ns)
        for c in COLUMNS:
            np.testing.assert_array_equal(ground.values[c], batch.values[c], err_msg=c)


def test_bad_rows_are_quarantined_with_line_and_offset() -> None:
    batch = _packet_batch()
    text = _csv(batch, range(6)).decode().splitlines()
    text[2] = text[2].replace(text[2].split(",")[1], "fast", 1)  # non-numeric value, line 3
    text[4] = "2021-13-45T00:00:00,1,2,3,4"  # unreadable t_utc_ns, line 5
    text.insert(6, "1,2")  # wrong field count, line 7
    data = ("\n".join(text) + "\n").encode()
    result = read_ground_csv(data, reference(), now_utc_ns=NOW_UTC_NS)
    starts = [0] + [i + 1 for i, b in enumerate(data) if b == 0x0A]
    assert [(q.reason, q.line, q.offset) for q in result.report.quarantined] == [
        ("bad_row", 3, starts[2]),
        ("bad_row", 5, starts[4]),
        ("bad_row", 7, starts[6]),
    ]
    assert result.report.packets_accepted == 4  # 7 data rows, 3 bad


def test_unknown_columns_out_of_window_times_duplicates_and_labels() -> None:
    lines = [
        "t_utc,mode,no_such_parameter",
        "2025-06-15T15:06:40Z,PROGRAM_TURN,1",
        "2025-06-15T15:06:40Z,PROGRAM_TURN,1",
        "2019-01-01T00:00:00Z,FAULT,1",
        "2025-06-15T15:06:39.5Z,3,1",
    ]
    result = read_ground_csv(("\n".join(lines) + "\n").encode(), reference(), now_utc_ns=NOW_UTC_NS)
    report = result.report
    assert [(q.reason, q.line) for q in report.quarantined] == [("unknown_parameter", 1), ("time_out_of_range", 4)]
    assert report.duplicates == 1
    (batch,) = result.batches
    assert batch.values["mode"].tolist() == [3.0, 4.0]  # time-ordered; label PROGRAM_TURN = 4


def test_jsonl_bad_lines_and_missing_time_column(tmp_path: Path) -> None:
    path = tmp_path / "g.jsonl"
    path.write_text('{"t_utc_ns": 1750000000000000000, "mode": 1}\n[1, 2]\n{broken\n')
    result = read_ground_file(path, reference(), now_utc_ns=NOW_UTC_NS)
    assert [(q.reason, q.line) for q in result.report.quarantined] == [("bad_row", 2), ("bad_row", 3)]
    assert result.report.packets_accepted == 1
    with pytest.raises(ValueError, match="t_utc"):
        read_ground_csv(b"time,mode\n1,2\n", reference())
    with pytest.raises(ValueError, match="path"):
        read_ground_file(tmp_path / "g.txt", reference())
