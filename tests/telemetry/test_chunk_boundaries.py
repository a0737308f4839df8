"""A file decoded in chunks cut at awkward offsets reports what one pass over it reports: per-APID packets, gaps,
duplicates and quarantine across every chunk boundary, and the archive stores and counts the same.

Truth: decode_stream over the whole file (one pass, no boundary). Streams: the real NOAA-20 APID 11 diary
(7,200 packets of 71 octets) edited where a ground segment damages a stream (packets lost, packets received
twice, a counter glitch), the real mixed CYGNSS FM07 stream (7 APIDs, lengths 76-272 octets) and the real IMAP
IDEX SUDA science stream (polymorphic XTCE, any length: 304-4,080 octets of mostly waveform octets).
"""

from __future__ import annotations

import hashlib
import os
import resource
from pathlib import Path

import numpy as np
import pytest

from telemetry.archive import Archive
from telemetry.decoding import decode_stream
from telemetry.dictionary import Dictionary, load_dictionary
from telemetry.ingest_report import IngestReport
from telemetry.packet_files import file_sha256, ingest_packet_file, keep_freed_heap

NOAA20_PACKETS = Path("real/noaa20_jpss1_apid11/J01_G011_LZ_2021-04-09T00-00-00Z_V01.DAT1")
NOAA20_OCTETS = 71
CYGNSS = Path(__file__).parents[1] / "data" / "cygnss_f7"
CYGNSS_STREAM = CYGNSS / "CYGNSS_F7_L0_2022_086_10_15_V01_F__first101pkts.tlm"
CYGNSS_TIME = "year=*_HDR_YEAR,doy=*_HDR_DAY,hour=*_HDR_HOUR,minute=*_HDR_MIN,second=*_HDR_SEC,microsecond=*_HDR_USEC"
IDEX = Path(__file__).parents[1] / "data" / "imap_idex_suda"
IDEX_TIME = "coarse=SHCOARSE,fine=SHFINE,fine_bits=16,epoch=2010-01-01T00:00:00Z"
# chunk sizes: primes (no packet length divides them), one under a packet, one of a packet and a few
AWKWARD_OCTETS = (53, 71, 100, 997, 4_099, 65_537)


def damaged_noaa20(shared_data: Path) -> bytes:
    """The diary with 3 packets lost at 1000, packet 2000 received twice in a row, packets 3000-3009 received
    twice (a repeated block), the count of packet 4000 garbled (a glitch), packets 5000-5099 lost."""
    packets = np.frombuffer((shared_data / NOAA20_PACKETS).read_bytes(), np.uint8).reshape(-1, NOAA20_OCTETS)
    garbled = packets[4000].copy()
    garbled[2:4] = [0xC0, 0x07]  # sequence flags kept (unsegmented), count 7
    parts = [
        packets[:1000],
        packets[1003:2001],
        packets[2000:3010],
        packets[3000:4000],
        garbled[None],
        packets[4001:5000],
        packets[5100:],
    ]
    return np.concatenate(parts).tobytes()


def one_pass(data: bytes, dictionary: Dictionary) -> IngestReport:
    return decode_stream(data, dictionary, source="file").report


def chunked(tmp_path: Path, data: bytes, dictionary: Dictionary, chunk_octets: int) -> IngestReport:
    path = tmp_path / f"stream-{chunk_octets}.bin"
    path.write_bytes(data)
    report, _ = ingest_packet_file(None, path, dictionary, satellite="S", uploaded_by="test", chunk_octets=chunk_octets)
    return report


def tallies(report: IngestReport) -> dict:
    """What must not depend on where the chunks were cut (quarantine records without their listing order)."""
    return {
        "packets_accepted": report.packets_accepted,
        "samples_accepted": report.samples_accepted,
        "duplicates": report.duplicates,
        "reasons": report.reason_counts(),
        "quarantined": sorted((q.offset, q.reason, q.apid, q.sequence_count) for q in report.quarantined),
        "undefined": report.undefined_apids,
        "apids": {
            a: (s.accepted, s.duplicates, s.quarantined, s.missing, s.gaps, s.t_first_utc_ns, s.t_last_utc_ns)
            for a, s in report.apids.items()
        },
    }


@pytest.mark.parametrize("chunk_octets", AWKWARD_OCTETS)
def test_damaged_diary_cut_anywhere_reports_the_gaps_and_duplicates_of_one_pass(
    tmp_path: Path, shared_data: Path, chunk_octets: int
) -> None:
    dictionary = load_dictionary("noaa20_apid11_ccsdspy.yaml")
    data = damaged_noaa20(shared_data)
    truth = one_pass(data, dictionary)
    assert truth.duplicates == 11 and truth.apids[11].missing == 3 + 1 + 100  # the edit (the glitch: 1)
    assert tallies(chunked(tmp_path, data, dictionary, chunk_octets)) == tallies(truth)


@pytest.mark.parametrize("chunk_octets", AWKWARD_OCTETS[:-1])
def test_mixed_stream_cut_anywhere_reports_what_one_pass_reports(tmp_path: Path, chunk_octets: int) -> None:
    dictionary = load_dictionary(CYGNSS / "ccsdspy", time_fields=CYGNSS_TIME)
    data = CYGNSS_STREAM.read_bytes()
    truth = one_pass(data, dictionary)
    assert sum(len(s.gaps) for s in truth.apids.values()) > 0  # its counters skip: gaps to find across cuts
    assert tallies(chunked(tmp_path, data, dictionary, chunk_octets)) == tallies(truth)


@pytest.mark.parametrize("chunk_octets", (997, 65_537, 1 << 20))
def test_variable_length_stream_cut_anywhere_reports_what_one_pass_reports(tmp_path: Path, chunk_octets: int) -> None:
    """Any-length packets full of waveform octets, the file six times over: a packet cut by a chunk's end is not
    taken for damage (nor a false header inside its neighbour for a packet): every packet is accepted or a
    duplicate, as in one pass."""
    dictionary = load_dictionary(IDEX / "suda_combined_science_definition.xml", time_fields=IDEX_TIME)
    data = (IDEX / "sciData_2023_052_14_45_05").read_bytes() * 6
    truth = one_pass(data, dictionary)
    assert (truth.packets_accepted, truth.duplicates, truth.quarantined) == (78, 5 * 78, [])
    assert tallies(chunked(tmp_path, data, dictionary, chunk_octets)) == tallies(truth)


def test_archive_counts_gaps_and_duplicates_across_chunks_as_one_pass(tmp_path: Path, shared_data: Path) -> None:
    dictionary = load_dictionary("noaa20_apid11_ccsdspy.yaml")
    data = damaged_noaa20(shared_data)
    path = tmp_path / "damaged.bin"
    path.write_bytes(data)
    results = []
    for name, chunk_octets in (("one", len(data)), ("cut", 997)):
        with Archive(f"sqlite:///{tmp_path / name}.sqlite") as archive:
            _, stored = ingest_packet_file(
                archive, path, dictionary, satellite="NOAA-20", uploaded_by="test", chunk_octets=chunk_octets
            )
            assert stored is not None
            results.append((stored.packets_accepted, stored.packets_duplicate, stored.gaps))
    assert results[1] == results[0]


def test_an_archived_file_is_known_by_the_sha256_of_its_bytes_and_again_adds_nothing(
    tmp_path: Path, shared_data: Path
) -> None:
    """The upload's checksum is hashlib's SHA-256 of the file's bytes although the file is hashed beside the decode
    of its first chunks (997 octets: several decoded before the checksum is known); the same file again is a
    duplicate upload that counts every archived packet of it per APID and adds nothing."""
    data = damaged_noaa20(shared_data)
    path = tmp_path / "damaged.bin"
    path.write_bytes(data)
    dictionary = load_dictionary("noaa20_apid11_ccsdspy.yaml")
    with Archive(f"sqlite:///{tmp_path / 'a'}.sqlite") as archive:
        _, first = ingest_packet_file(archive, path, dictionary, satellite="S", uploaded_by="test", chunk_octets=997)
        _, again = ingest_packet_file(archive, path, dictionary, satellite="S", uploaded_by="test", chunk_octets=997)
        uploads = archive.uploads("S")
    assert first is not None and again is not None
    assert [u.sha256 for u in uploads] == [hashlib.sha256(data).hexdigest()]
    assert again.duplicate_upload and again.duplicates_by_apid == {11: first.packets_accepted}


@pytest.mark.parametrize("octets", [0, 1, 65_535, 65_536, 65_537, 3 * 65_536 + 5])
def test_a_file_hashed_in_mapped_windows_has_hashlib_s_sha256(tmp_path: Path, octets: int) -> None:
    """Windows of 64 KiB (the smallest mmap offset step): a file shorter, equal, one octet longer and several."""
    data = np.random.default_rng(octets).integers(0, 256, octets, dtype=np.uint8).tobytes()
    path = tmp_path / "f.bin"
    path.write_bytes(data)
    assert file_sha256(path, window=65_536) == hashlib.sha256(data).hexdigest()


@pytest.mark.skipif(
    not hasattr(os, "confstr") or "CS_GNU_LIBC_VERSION" not in os.confstr_names, reason="glibc's malloc only"
)
def test_with_the_heap_kept_a_freed_block_is_reused_not_faulted_in_again() -> None:
    """glibc maps a block of 8 MiB on its own by default: freed, it is unmapped, and the next one is faulted in page
    by page again (2,048 minor faults); with keep_freed_heap it stays in the heap for the next allocation."""
    assert keep_freed_heap() and keep_freed_heap()  # accepted by glibc; once per process
    octets = 8 << 20
    block = np.ones(octets, np.uint8)  # touched: its pages are in
    del block
    before = resource.getrusage(resource.RUSAGE_THREAD).ru_minflt
    block = np.ones(octets, np.uint8)
    faults = resource.getrusage(resource.RUSAGE_THREAD).ru_minflt - before
    assert int(block.sum()) == octets
    assert faults < octets // 4096 // 10, faults


def test_an_empty_file_is_an_upload_of_nothing(tmp_path: Path) -> None:
    path = tmp_path / "empty.bin"
    path.write_bytes(b"")
    with Archive(f"sqlite:///{tmp_path / 'a'}.sqlite") as archive:
        report, stored = ingest_packet_file(
            archive, path, load_dictionary("noaa20_apid11_ccsdspy.yaml"), satellite="S", uploaded_by="test"
        )
        uploads = archive.uploads("S")
    assert stored is not None and stored.packets_accepted == 0
    assert [u.sha256 for u in uploads] == [hashlib.sha256(b"").hexdigest()]
    assert report.packets_accepted == 0


def test_archive_gaps_across_its_own_chunk_flushes_are_those_of_one_pass(
    tmp_path: Path, shared_data: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Archive chunks of 100 packets (the archive writes an APID's pending packets every CHUNK_PACKETS): a gap
    every 7th packet straddles many flushes and each is counted once, as in one pass."""
    from telemetry.archive import store

    packets = np.frombuffer((shared_data / NOAA20_PACKETS).read_bytes(), np.uint8).reshape(-1, NOAA20_OCTETS)
    lost = np.arange(len(packets)) % 7 == 3
    data = packets[~lost].tobytes()
    path = tmp_path / "holes.bin"
    path.write_bytes(data)
    dictionary = load_dictionary("noaa20_apid11_ccsdspy.yaml")
    with Archive(f"sqlite:///{tmp_path / 'one'}.sqlite") as archive:
        _, one = ingest_packet_file(archive, path, dictionary, satellite="NOAA-20", uploaded_by="test")
    monkeypatch.setattr(store, "CHUNK_PACKETS", 100)
    with Archive(f"sqlite:///{tmp_path / 'cut'}.sqlite") as archive:
        _, cut = ingest_packet_file(
            archive, path, dictionary, satellite="NOAA-20", uploaded_by="test", chunk_octets=997
        )
    assert one is not None and cut is not None
    assert len(one.gaps) == np.count_nonzero(lost[:-1])  # the last packet is lost after the last one received
    assert cut.gaps == one.gaps


def test_chunks_grow_where_the_dictionary_only_bounds_their_values_and_report_what_one_pass_reports() -> None:
    """IDEX (XTCE: decoded octets per octet only bounded, 4.5 against 0.09 here), the file 30 times over, in default
    chunks: the first as chunk_octets_for sizes it, later ones longer (at most GROWTH times), and the same tallies
    as one pass; a fixed-layout dictionary (CYGNSS) keeps its chunk length."""
    import io

    from telemetry.packet_files import GROWTH, chunk_octets_for, decode_chunks

    dictionary = load_dictionary(IDEX / "suda_combined_science_definition.xml", time_fields=IDEX_TIME)
    data = (IDEX / "sciData_2023_052_14_45_05").read_bytes() * 30
    bounded = chunk_octets_for(dictionary)
    report = IngestReport(source="file")
    sizes = []
    for offset, result in decode_chunks(io.BytesIO(data), dictionary, source="file"):
        report.absorb(result.report, offset)
        sizes.append(result.consumed)
    assert sizes[0] <= bounded < max(sizes) <= GROWTH * bounded and sum(sizes) == len(data)
    assert tallies(report) == tallies(one_pass(data, dictionary))
    cygnss = load_dictionary(CYGNSS / "ccsdspy", time_fields=CYGNSS_TIME)
    stream = CYGNSS_STREAM.read_bytes() * (2 * chunk_octets_for(cygnss) // len(CYGNSS_STREAM.read_bytes()) + 1)
    lengths = [r.consumed for _, r in decode_chunks(io.BytesIO(stream), cygnss)]
    assert max(lengths) <= chunk_octets_for(cygnss) and len(lengths) >= 3


def test_a_packet_kept_inside_a_gap_last_in_a_chunk_leaves_no_false_gap_in_the_next() -> None:
    """HK count 12 stamped after 13 (CTIM's clock, cc3b333): one pass keeps it and reports no gap. A first chunk
    whose decided packets end with 13, 12 (file order) must leave the next chunk judged from 13, not 12: 14 follows."""
    from telemetry.ccsds import crc16_ccitt, encode_time
    from tests.telemetry.packet_streams import T0_UTC_NS, packets, reference

    dictionary = reference()
    hk = dictionary.packets[256]
    rows = packets(hk, 40)
    rows[12, 6:12] = encode_time(np.array([T0_UTC_NS + int(13.004 * hk.period_s * 1e9)]), hk.time_code)[0]
    crc = int(crc16_ccitt(rows[12, :-2].tobytes()))
    rows[12, -2:] = (crc >> 8, crc & 0xFF)
    data, octets = rows.tobytes(), rows.shape[1]
    assert one_pass(data, dictionary).apids[256].missing == 0
    carry: dict = {}
    first = decode_stream(data[: 18 * octets], dictionary, source="file", final=False, carry=carry)
    assert first.consumed == 14 * octets and carry[256].count == 13  # the decided packets: 0..13, 12 the newest
    rest = decode_stream(data[first.consumed :], dictionary, source="file", carry=carry)
    assert (first.report.apids[256].missing, rest.report.apids[256].missing) == (0, 0)
