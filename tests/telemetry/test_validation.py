"""Per-packet validation: duplicates, order, 14-bit sequence gaps and wrap, outliers, restarts, time window.

Truth: the packets each test builds — which counts it dropped, repeated, shuffled or corrupted —
and the modulo-16384 count of CCSDS 133.0-B-2 §4.1.3.4.3.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from telemetry.decoding import decode_stream
from telemetry.validation import SequenceState, validate_packets
from tests.telemetry.packet_streams import NOW_UTC_NS, T0_UTC_NS, packets, reference

HK = 256
PERIOD_NS = 250_000_000


def _ingest(rows: np.ndarray):
    return decode_stream(rows.tobytes(), reference(), source="test", now_utc_ns=NOW_UTC_NS)


def test_duplicate_packets_are_counted_once_and_not_quarantined() -> None:
    rows = packets(reference().packets[HK], 40)
    result = _ingest(np.concatenate([rows, rows[10:20]]))
    assert result.report.packets_accepted == 40 and result.report.duplicates == 10
    assert result.report.quarantined == []


def test_out_of_order_packets_are_accepted_in_time_order() -> None:
    rows = packets(reference().packets[HK], 64)
    shuffled = rows[np.random.default_rng(2).permutation(64)]
    (batch,) = _ingest(shuffled).batches
    np.testing.assert_array_equal(batch.t_utc_ns, T0_UTC_NS + np.arange(64) * PERIOD_NS)
    np.testing.assert_array_equal(batch.packets, rows)


def test_gap_in_sequence_counts_is_reported_with_its_size() -> None:
    rows = packets(reference().packets[HK], 50)
    result = _ingest(np.concatenate([rows[:10], rows[15:]]))
    summary = result.report.apids[HK]
    assert summary.missing == 5 and len(summary.gaps) == 1
    gap = summary.gaps[0]
    assert (gap.after_count, gap.before_count, gap.missing) == (9, 15, 5)


def test_sequence_count_wrap_at_16384_is_not_a_gap() -> None:
    rows = packets(reference().packets[HK], 12, first_count=16_380)
    result = _ingest(rows)
    assert result.report.apids[HK].gaps == [] and result.report.quarantined == []
    assert result.batches[0].sequence_count.tolist() == [16_380, 16_381, 16_382, 16_383] + list(range(8))


def test_single_count_outlier_is_quarantined_without_a_false_gap() -> None:
    count = np.arange(30)
    count[12] = 9_000
    t = T0_UTC_NS + np.arange(30) * PERIOD_NS
    verdict = validate_packets(HK, np.arange(30) * 126, count, t, 126, None, None)
    assert [(q.reason, q.offset, q.sequence_count) for q in verdict.quarantined] == [
        ("non_monotonic_sequence", 12 * 126, 9_000)
    ]
    assert [(g.after_count, g.before_count, g.missing) for g in verdict.gaps] == [(11, 13, 1)]


def test_packet_stamped_just_after_its_successor_is_kept_without_a_false_gap() -> None:
    """Count 12 stamped 1 us after count 13 (CTIM's APID 32 does so: 4104 at +3.9 ms, 4105 at +3.6 ms): in time order
    11, 13, 12, 14; 12 lies inside the gap 13 opened, so it is kept and the gap closes. With 13 and 14 truly lost
    and 12 stamped after 15, the gap 11 -> 15 is reported as 2, not 3, and nothing is quarantined."""
    count = np.arange(30)
    t = T0_UTC_NS + np.arange(30) * PERIOD_NS
    t[12] = t[13] + 1_000
    verdict = validate_packets(HK, np.arange(30) * 126, count, t, 126, None, None)
    assert verdict.quarantined == [] and sorted(verdict.accepted.tolist()) == list(range(30))
    assert verdict.gaps == []
    keep = np.array([i for i in range(30) if i not in (13, 14)])
    t[12] = t[15] + 1_000
    verdict = validate_packets(HK, keep * 126, count[keep], t[keep], 126, None, None)
    assert verdict.quarantined == [] and len(verdict.accepted) == 28
    assert [(g.after_count, g.before_count, g.missing) for g in verdict.gaps] == [(11, 15, 2)]


def test_a_chunk_ending_with_a_packet_kept_inside_a_gap_judges_the_next_chunk_from_the_gap_s_end() -> None:
    """Count 12 stamped after 13, last of a chunk: the next chunk's 14 follows 13 (no gap), as in one pass."""
    count = np.arange(21)
    t = T0_UTC_NS + np.arange(21) * PERIOD_NS
    t[12] = t[13] + 1_000
    assert validate_packets(HK, np.arange(21), count, t, 126, None, None).gaps == []
    first = validate_packets(HK, np.arange(14), count[:14], t[:14], 126, None, None)
    order = first.accepted
    assert first.gaps == [] and count[order[-1]] == 12 and count[first.ahead] == 13
    state = SequenceState.after(None, count[order], t[order], (int(count[first.ahead]), int(t[first.ahead])))
    second = validate_packets(HK, np.arange(7), count[14:], t[14:], 126, None, None, previous=state)
    assert second.gaps == [] and len(second.accepted) == 7


def test_late_repeat_of_a_count_after_a_gap_stays_quarantined() -> None:
    """Count 12 lost (gap 11 -> 13), then count 15 again after 20, stamped later: 15 lies between the gap and the
    latest count but not inside the gap, so it is a repeat (non_monotonic_sequence) and the gap keeps its 1."""
    count = np.concatenate([np.arange(12), np.arange(13, 21), [15], np.arange(21, 25)])
    t = T0_UTC_NS + np.arange(count.size) * PERIOD_NS
    verdict = validate_packets(HK, np.arange(count.size) * 126, count, t, 126, None, None)
    assert [(q.reason, q.offset, q.sequence_count) for q in verdict.quarantined] == [
        ("non_monotonic_sequence", 20 * 126, 15)
    ]
    assert [(g.after_count, g.before_count, g.missing) for g in verdict.gaps] == [(11, 13, 1)]


def test_a_count_kept_inside_a_gap_fills_it_once() -> None:
    """Counts 12 and 13 lost (gap 11 -> 14), then 12 twice, each stamped after 14: the first 12 is kept (1 left
    missing), the second is a repeat (non_monotonic_sequence), and 13 stays missing (review of cc3b333)."""
    count = np.concatenate([np.arange(12), [14, 12, 12, 15]])
    t = T0_UTC_NS + np.arange(count.size) * PERIOD_NS
    verdict = validate_packets(HK, np.arange(count.size) * 126, count, t, 126, None, None)
    assert [(q.reason, q.offset, q.sequence_count) for q in verdict.quarantined] == [
        ("non_monotonic_sequence", 14 * 126, 12)
    ]
    assert [(g.after_count, g.before_count, g.missing) for g in verdict.gaps] == [(11, 14, 1)]


def test_counter_restart_is_accepted_and_reported_as_unknown_gap() -> None:
    count = np.concatenate([np.arange(3_000, 3_020), np.arange(0, 20)])
    t = T0_UTC_NS + np.arange(40) * PERIOD_NS
    verdict = validate_packets(HK, np.arange(40), count, t, 126, None, None)
    assert verdict.quarantined == [] and len(verdict.accepted) == 40
    assert [(g.after_count, g.before_count, g.missing) for g in verdict.gaps] == [(3_019, 0, -1)]


def test_times_outside_the_mission_window_are_quarantined_at_their_offset() -> None:
    hk = reference().packets[HK]
    rows = packets(hk, 20)
    early = packets(hk, 1, first_count=20)
    from telemetry.ccsds import encode_time

    early[0, 6:12] = encode_time(np.array([1_500_000_000 * 10**9]), hk.time_code)[0]  # 2017: before mission start
    late = packets(hk, 1, first_count=21)
    late[0, 6:12] = encode_time(np.array([NOW_UTC_NS + 3 * 86_400 * 10**9]), hk.time_code)[0]
    from telemetry.ccsds import crc16_ccitt

    for row in (early, late):
        c = int(crc16_ccitt(row[:, :-2])[0])
        row[0, -2:] = [c >> 8, c & 0xFF]
    result = _ingest(np.concatenate([rows[:5], early, rows[5:10], late, rows[10:]]))
    reasons = [(q.reason, q.offset) for q in result.report.quarantined]
    assert reasons == [("time_out_of_range", 5 * 126), ("time_out_of_range", 11 * 126)]
    assert result.report.packets_accepted == 20


def test_report_json_lists_reasons_offsets_and_gaps() -> None:
    rows = packets(reference().packets[HK], 30)
    damaged = rows.copy()
    damaged[7, 40] ^= 0x01
    stream = np.concatenate([damaged[:20], damaged[22:]]).tobytes() + rows[29, :50].tobytes()
    report = json.loads(decode_stream(stream, reference(), now_utc_ns=NOW_UTC_NS).report.to_json())
    assert report["quarantine_reasons"] == {"crc_failure": 1, "truncated": 1}
    assert [q["offset"] for q in report["quarantined"]] == [7 * 126, 28 * 126]
    assert report["apids"]["256"]["missing"] == 3  # count 7 (CRC) and 20, 21 (dropped)
    assert report["apids"]["256"]["quarantined"] == 2
    assert report["packets_accepted"] == 27


def test_validate_packets_rejects_mismatched_arrays_naming_fields() -> None:
    with pytest.raises(ValueError, match="offset, sequence_count, t_utc_ns"):
        validate_packets(HK, np.arange(3), np.arange(4), np.arange(3), 126, None, None)


@pytest.mark.parametrize(
    ("octet", "xor", "detail"),
    [
        (0, 0x10, "packet type (telecommand)"),
        (2, 0x40, "sequence flags (segmented)"),
        (0, 0x08, "secondary header flag"),
    ],
)
def test_header_fields_contradicting_a_telemetry_packet_are_bad_header(octet: int, xor: int, detail: str) -> None:
    """Type, sequence-flag and secondary-header bits of §4.1.3, flipped with a CRC recomputed to match."""
    from telemetry.ccsds import crc16_ccitt

    rows = packets(reference().packets[HK], 10)
    rows[4, octet] ^= xor
    c = int(crc16_ccitt(rows[4:5, :-2])[0])
    rows[4, -2:] = [c >> 8, c & 0xFF]
    result = _ingest(rows)
    assert [(q.reason, q.offset, q.detail) for q in result.report.quarantined] == [("bad_header", 4 * 126, detail)]
    assert result.report.packets_accepted == 9


def test_a_yaml_packet_marked_segmented_decodes_segments_and_counts_them(tmp_path) -> None:
    """``segmented: true`` on ACS_HK: packets whose sequence flags mark a first, continuation or last segment
    (CCSDS 133.0-B-2 §4.1.3.4.2.2) decode like the others and the report counts them; ACS_HK without it still
    quarantines them as bad_header (above)."""
    from telemetry.ccsds import crc16_ccitt
    from telemetry.dictionary import SHIPPED, load_dictionary

    text = (SHIPPED / "reference_satellite.yaml").read_text()
    assert text.count("    apid: 256\n") == 1
    (tmp_path / "segmented.yaml").write_text(text.replace("    apid: 256\n", "    apid: 256\n    segmented: true\n"))
    dictionary = load_dictionary(tmp_path / "segmented.yaml")
    rows = packets(dictionary.packets[HK], 10)
    for i, flags in ((3, 0x40), (4, 0x00), (5, 0x80)):  # first, continuation, last segment
        rows[i, 2] = flags | (rows[i, 2] & 0x3F)
        c = int(crc16_ccitt(rows[i : i + 1, :-2])[0])
        rows[i, -2:] = [c >> 8, c & 0xFF]
    result = decode_stream(rows.tobytes(), dictionary, now_utc_ns=NOW_UTC_NS)
    assert result.report.quarantined == [] and result.report.packets_accepted == 10
    assert result.report.apids[HK].segmented == 3
    assert [q.detail for q in _ingest(rows).report.quarantined] == ["sequence flags (segmented)"] * 3


def test_undefined_apid_is_counted_and_kept_raw_garbage_is_quarantined() -> None:
    """APID 1,793 = 0x701 (uses the top APID bits) has no definition: counted and kept byte-exact; garbage has no APID."""
    from telemetry.ccsds import encode_primary_headers

    rows = packets(reference().packets[HK], 3)
    stranger = encode_primary_headers(1_793, np.array([5]), 20)[0].tobytes() + bytes(14)
    stream = rows[0].tobytes() + stranger + rows[1].tobytes() + b"\xff" * 9 + rows[2].tobytes()
    result = decode_stream(stream, reference(), now_utc_ns=NOW_UTC_NS)
    assert [(q.reason, q.apid, q.offset, q.length) for q in result.report.quarantined] == [("bad_header", None, 272, 9)]
    assert result.report.undefined_apids == {1_793: 1}
    assert [(u.apid, u.packets.tobytes(), u.sequence_count.tolist()) for u in result.undefined] == [
        (1_793, stranger, [5])
    ]
    assert result.report.packets_accepted == 3


PASS_GAP_S = 5_400  # 90 min between two passes: 21,600 ACS_HK packets, more than the 16,384 count range


def test_outage_between_passes_is_sized_from_the_packet_period() -> None:
    """Counts 0..99, then 90 min later the counter continues: the gap is 21,600 − 100 packets, not mod 2^14."""
    first = np.arange(100)
    second = np.arange(100) + PASS_GAP_S * 4
    count = np.concatenate([first, second]) % 16_384
    t = T0_UTC_NS + np.concatenate([first, second]) * PERIOD_NS
    verdict = validate_packets(HK, np.arange(200), count, t, 126, None, None, period_s=0.25)
    assert verdict.quarantined == [] and len(verdict.accepted) == 200
    assert [g.missing for g in verdict.gaps] == [PASS_GAP_S * 4 - 100]
    blind = validate_packets(HK, np.arange(200), count, t, 126, None, None)
    assert [g.missing for g in blind.gaps] != [PASS_GAP_S * 4 - 100]  # without the period it cannot be sized


def test_counter_reset_during_an_outage_is_a_restart() -> None:
    count = np.concatenate([np.arange(5_000, 5_100), np.arange(0, 100)])
    t = T0_UTC_NS + np.concatenate([np.arange(100), np.arange(100) + PASS_GAP_S * 4]) * PERIOD_NS
    verdict = validate_packets(HK, np.arange(200), count, t, 126, None, None, period_s=0.25)
    assert [(g.after_count, g.before_count, g.missing) for g in verdict.gaps] == [(5_099, 0, -1)]
