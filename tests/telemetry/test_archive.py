"""Archive store on SQLite and PostgreSQL: real NOAA-20 packets, duplicates, order, gaps, atomicity."""

from __future__ import annotations

import csv
from pathlib import Path

import ccsdspy
import numpy as np
import pytest
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import inspect, text

from telemetry.archive import NAME_MAX, Archive, PacketBatch, PendingUpload, upgrade
from telemetry.archive.engine import create_archive_engine
from telemetry.archive.migrate import alembic_config
from telemetry.archive.models import Base
from telemetry.archive.store import CHUNK_PACKETS
from tests.telemetry.archive_databases import archive, archive_url  # noqa: F401  (fixtures)

NOAA_DIR = Path("real/noaa20_jpss1_apid11")
NOAA_APID = 11
CDS_EPOCH_UNIX_DAYS = -4_383  # 1958-01-01 is 4,383 days before 1970-01-01 (CCSDS 301.0-B-4 §3.3)
NS_PER_DAY = 86_400 * 10**9
ONE_MICROSECOND_NS = 1_000  # the decoded CSV prints times to the microsecond
POSITIONS = ("ADGPSPOSX", "ADGPSPOSY", "ADGPSPOSZ")
SAT = "NOAA-20"


def noaa20_batch(shared_data: Path) -> tuple[PacketBatch, bytes]:
    """The real NOAA-20 file decoded independently with ccsdspy (not our decoder) + its raw bytes."""
    folder = shared_data / NOAA_DIR
    data_file = folder / "J01_G011_LZ_2021-04-09T00-00-00Z_V01.DAT1"
    fields = ccsdspy.FixedLength.from_file(folder / "ccsdspy_jpss1_geolocation.csv").load(
        data_file, include_primary_header=True
    )
    days = fields["DOY"].astype(np.int64) + CDS_EPOCH_UNIX_DAYS
    t_ns = days * NS_PER_DAY + fields["MSEC"].astype(np.int64) * 10**6 + fields["USEC"].astype(np.int64) * 10**3
    raw = data_file.read_bytes()
    packets = ccsdspy.utils.split_packet_bytes(str(data_file))
    values = {name: fields[name] for name in (*POSITIONS, "ADCFAQ4")}
    return PacketBatch.from_packets(NOAA_APID, t_ns, fields["CCSDS_SEQUENCE_COUNT"], packets, values), raw


def decoded_csv(shared_data: Path) -> dict[str, np.ndarray]:
    """Columns of the reference decoded CSV (times as UTC ns via numpy datetime64[us])."""
    with open(shared_data / NOAA_DIR / "jpss1_apid11_decoded.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    t = np.array([r["pkt_time_utc_cds"] for r in rows], dtype="datetime64[us]").astype(np.int64) * 1_000
    return {"t_ns": t, **{k: np.array([float(r[k]) for r in rows]) for k in ("pos_x_m", "pos_y_m", "pos_z_m", "q4")}}


def synthetic_batch(
    n: int, seq0: int = 0, t0_ns: int = 1_700_000_000 * 10**9, period_ns: int = 250_000_000
) -> PacketBatch:
    """n packets of APID 100 at 4 Hz, one value column equal to the packet index."""
    index = np.arange(n)
    packets = [bytes([0x08, 0x64]) + int(i).to_bytes(4, "big") for i in index]
    return PacketBatch.from_packets(
        100, t0_ns + index * period_ns, (seq0 + index) % 16_384, packets, {"index": index.astype(np.float64)}
    )


def test_upgrade_creates_every_model_table_at_head_and_is_idempotent(archive_url: str) -> None:
    upgrade(archive_url)
    upgrade(archive_url)
    engine = create_archive_engine(archive_url)
    with engine.connect() as conn:
        current = MigrationContext.configure(conn).get_current_revision()
        tables = set(inspect(conn).get_table_names())
    engine.dispose()
    assert current == ScriptDirectory.from_config(alembic_config(archive_url)).get_current_head()
    assert set(Base.metadata.tables) <= tables


def test_migrations_downgrade_to_base_and_upgrade_again(archive_url: str) -> None:
    from alembic import command

    upgrade(archive_url)
    engine = create_archive_engine(archive_url)
    with engine.begin() as conn:
        config = alembic_config(archive_url)
        config.attributes["connection"] = conn
        command.downgrade(config, "base")
    with engine.connect() as conn:
        assert not set(Base.metadata.tables) & set(inspect(conn).get_table_names())
    engine.dispose()
    upgrade(archive_url)
    with Archive(archive_url) as store:
        assert store.ingest(SAT, [synthetic_batch(5)], source="after", uploaded_by="tester").packets_accepted == 5


def test_real_noaa20_file_round_trips_to_the_decoded_csv_and_replays_byte_exact(
    archive: Archive, shared_data: Path
) -> None:
    batch, raw = noaa20_batch(shared_data)
    truth = decoded_csv(shared_data)
    result = archive.ingest(SAT, [batch], source="J01_G011.DAT1", uploaded_by="tester")
    assert result.packets_accepted == 7_200 and result.samples_accepted == 7_200 * 4
    t, x = archive.read_parameter(SAT, "ADGPSPOSX", int(truth["t_ns"][0]), int(truth["t_ns"][-1]))
    np.testing.assert_allclose(t, truth["t_ns"], rtol=0, atol=ONE_MICROSECOND_NS)
    np.testing.assert_array_equal(x, truth["pos_x_m"].astype(np.float32))
    _, q4 = archive.read_parameter(SAT, "ADCFAQ4", int(t[0]), int(t[-1]))
    np.testing.assert_array_equal(q4, truth["q4"].astype(np.float32))
    replayed = archive.replay(SAT, int(t[0]), int(t[-1]))
    assert b"".join(p for _, p in replayed) == raw


def test_real_noaa20_file_through_our_xtce_decoder_archives_to_the_decoded_csv(
    archive: Archive, shared_data: Path
) -> None:
    from telemetry.decoding import decode_stream
    from telemetry.dictionary import load_dictionary

    raw = (shared_data / NOAA_DIR / "J01_G011_LZ_2021-04-09T00-00-00Z_V01.DAT1").read_bytes()
    truth = decoded_csv(shared_data)
    decoded = decode_stream(raw, load_dictionary("noaa20_apid11_xtce.yaml"), source="J01_G011.DAT1")
    result = archive.ingest_decoded(SAT, decoded, uploaded_by="tester")
    assert result.packets_accepted == 7_200
    t, q0 = archive.read_parameter(SAT, "q_ib_0", int(truth["t_ns"][0]), int(truth["t_ns"][-1]))
    np.testing.assert_allclose(t, truth["t_ns"], rtol=0, atol=ONE_MICROSECOND_NS)
    np.testing.assert_array_equal(q0, truth["q4"].astype(np.float32))
    assert archive.uploads(SAT)[0].report["decode"]["packets_accepted"] == 7_200
    assert b"".join(p for _, p in archive.replay(SAT, int(t[0]), int(t[-1]))) == raw


def test_same_file_twice_is_a_reported_no_op(archive: Archive) -> None:
    batch = synthetic_batch(500)
    first = archive.ingest(SAT, [batch], source="a.bin", uploaded_by="tester", sha256="ab" * 32)
    second = archive.ingest(SAT, [batch], source="a-again.bin", uploaded_by="tester", sha256="ab" * 32)
    assert second.duplicate_upload and second.upload_id == first.upload_id and second.packets_accepted == 0
    assert len(archive.uploads(SAT)) == 1
    assert archive.upload_contents(first.upload_id) == (500, 500)


def test_names_fill_their_columns_and_longer_ones_name_their_field(archive: Archive) -> None:
    """varchar(NAME_MAX) on PostgreSQL refused longer names as a DataError (SQLite stored them): the archive says so
    first, for the API, the CLI and the live paths alike."""
    full, over = "N" * NAME_MAX, "N" * (NAME_MAX + 1)
    assert archive.satellite_id(full) > 0
    assert archive.add_ground_station(full, 64.86, -147.85, 200.0, 5.0) > 0
    assert archive.ingest(full, [synthetic_batch(10)], source="a.bin", uploaded_by=full).packets_accepted == 10
    refusals = {
        "satellite": lambda: archive.satellite_id(over),
        "name": lambda: archive.add_ground_station(over, 64.86, -147.85, 200.0, 5.0),
        "uploaded_by": lambda: archive.ingest(SAT, [synthetic_batch(10)], source="b.bin", uploaded_by=over),
        "actor": lambda: archive.alarm_action(1, "acknowledge", over),
    }
    for field, call in refusals.items():
        with pytest.raises(ValueError, match=f"^{field}: .* at most {NAME_MAX} characters, got {NAME_MAX + 1}$"):
            call()


def test_ground_files_without_raw_bytes_are_told_apart_by_their_values(archive: Archive) -> None:
    t = 1_750_000_000 * 10**9 + np.arange(3) * 10**9
    first = PacketBatch(7, t, np.zeros(3), b"", np.zeros(3), {"temp_c": np.array([1.0, 2.0, 3.0])})
    second = PacketBatch(7, t + 3 * 10**9, np.zeros(3), b"", np.zeros(3), {"temp_c": np.array([4.0, 5.0, 6.0])})
    result = archive.ingest(SAT, [first], source="a.csv", uploaded_by="tester")
    assert not result.duplicate_upload and result.gaps == []
    assert not archive.ingest(SAT, [second], source="b.csv", uploaded_by="tester").duplicate_upload
    assert archive.ingest(SAT, [first], source="a-again.csv", uploaded_by="tester").duplicate_upload
    np.testing.assert_array_equal(
        archive.read_parameter(SAT, "temp_c", int(t[0]), int(t[0]) + 10**10)[1], np.arange(1.0, 7.0)
    )


def test_overlapping_upload_keeps_each_packet_once(archive: Archive) -> None:
    whole = synthetic_batch(900)
    archive.ingest(SAT, [whole.take(np.arange(0, 600))], source="first", uploaded_by="tester")
    second = archive.ingest(SAT, [whole.take(np.arange(300, 900))], source="second", uploaded_by="tester")
    assert (second.packets_accepted, second.packets_duplicate) == (300, 300)
    t, v = archive.read_parameter(SAT, "index", int(whole.t_utc_ns[0]), int(whole.t_utc_ns[-1]))
    np.testing.assert_array_equal(v, np.arange(900.0))
    np.testing.assert_array_equal(t, whole.t_utc_ns)


def test_duplicates_inside_one_upload_are_dropped(archive: Archive) -> None:
    whole = synthetic_batch(50)
    result = archive.ingest(
        SAT, [whole.take(np.r_[np.arange(50), np.arange(10, 20)])], source="dup", uploaded_by="tester"
    )
    assert (result.packets_accepted, result.packets_duplicate) == (50, 10)


def test_out_of_order_data_is_accepted_and_read_back_in_time_order(archive: Archive) -> None:
    n = 4 * CHUNK_PACKETS + 123  # each upload spans several chunks, interleaved in time
    whole = synthetic_batch(n)
    shuffled = whole.take(np.random.default_rng(7).permutation(n))
    archive.ingest(SAT, [shuffled.take(np.arange(n // 2, n))], source="late", uploaded_by="tester")
    archive.ingest(SAT, [shuffled.take(np.arange(0, n // 2))], source="early", uploaded_by="tester")
    t, v = archive.read_parameter(SAT, "index", int(whole.t_utc_ns[0]), int(whole.t_utc_ns[-1]))
    np.testing.assert_array_equal(t, whole.t_utc_ns)
    np.testing.assert_array_equal(v, np.arange(float(n)))
    replayed = archive.replay(SAT, int(whole.t_utc_ns[0]), int(whole.t_utc_ns[-1]))
    assert [p for _, p in replayed] == whole.packets()


def test_gaps_are_counted_from_sequence_counts_across_the_14_bit_wrap(archive: Archive) -> None:
    whole = synthetic_batch(12, seq0=16_378)  # counts 16378..16383, 0..5
    kept = np.array([0, 1, 2, 5, 6, 7, 11])  # drops 16381, 16382 (before the wrap), 2, 3, 4 (after)
    result = archive.ingest(SAT, [whole.take(kept)], source="gappy", uploaded_by="tester")
    assert [(g.after_t_ns, g.before_t_ns, g.missing) for g in result.gaps] == [
        (int(whole.t_utc_ns[2]), int(whole.t_utc_ns[5]), 2),
        (int(whole.t_utc_ns[7]), int(whole.t_utc_ns[11]), 3),
    ]
    assert archive.uploads(SAT)[0].report["gaps"][1]["missing"] == 3


def test_a_failing_upload_leaves_nothing_behind(archive: Archive) -> None:
    """The second batch's values are not numbers: the first batch, already written, is rolled back with it."""
    good = synthetic_batch(100)
    clash = PacketBatch.from_packets(101, good.t_utc_ns, good.seq_count, good.packets(), {"label": np.full(100, "x")})
    archive.satellite_id(SAT)
    with pytest.raises(ValueError, match="not numeric"):
        archive.ingest(SAT, [good, clash], source="bad", uploaded_by="tester")
    assert archive.uploads(SAT) == []
    assert archive.parameters(SAT) == {}
    assert archive.packet_keys(SAT, 0, 2**62) == {}


def test_group_commit_archives_each_satellite_as_its_own_upload(archive: Archive) -> None:
    """Archive.ingest_many: one transaction for many uploads, each read back as if ingested alone."""
    whole = synthetic_batch(300)
    group = [
        PendingUpload(f"SAT-{k}", [whole.take(np.arange(100 * k, 100 * k + 100))], "live", "tester") for k in range(3)
    ]
    results = archive.ingest_many([*group, PendingUpload("SAT-0", [whole.take(np.arange(50, 150))], "more", "tester")])
    assert [(r.packets_accepted, r.packets_duplicate) for r in results] == [(100, 0), (100, 0), (100, 0), (50, 50)]
    for k in range(3):
        assert [u.source for u in archive.uploads(f"SAT-{k}")] == (["live", "more"] if k == 0 else ["live"])
        t, v = archive.read_parameter(f"SAT-{k}", "index", 0, 2**62)
        np.testing.assert_array_equal(v, np.arange(100.0 * k, 100.0 * k + (150 if k == 0 else 100)))


def test_a_failing_upload_in_a_group_commit_leaves_nothing_of_the_group(archive: Archive) -> None:
    good = synthetic_batch(100)
    clash = PacketBatch.from_packets(101, good.t_utc_ns, good.seq_count, good.packets(), {"label": np.full(100, "x")})
    with pytest.raises(ValueError, match="not numeric"):
        archive.ingest_many(
            [PendingUpload("SAT-A", [good], "ok", "tester"), PendingUpload("SAT-B", [clash], "bad", "t")]
        )
    assert archive.uploads("SAT-A") == [] and archive.packet_keys("SAT-A", 0, 2**62) == {}


def test_latest_values_are_the_newest_samples(archive: Archive) -> None:
    whole = synthetic_batch(30)
    archive.ingest(
        SAT,
        [
            whole.take(np.arange(20, 30)),
        ],
        source="b",
        uploaded_by="tester",
    )
    archive.ingest(SAT, [whole.take(np.arange(0, 20))], source="a", uploaded_by="tester")
    assert archive.latest_values(SAT) == {"index": (int(whole.t_utc_ns[-1]), 29.0)}


def test_bad_input_names_the_field(archive: Archive) -> None:
    with pytest.raises(ValueError, match="seq_count"):
        PacketBatch.from_packets(1, np.arange(3), np.array([0, 1, 20_000]), [b"a", b"b", b"c"], {})
    with pytest.raises(ValueError, match="uploaded_by"):
        archive.ingest(SAT, [synthetic_batch(3)], source="x", uploaded_by="")
    with pytest.raises(ValueError, match="satellite"):
        archive.read_parameter("NO-SUCH-SAT", "x", 0, 1)
    archive.satellite_id(SAT)
    with pytest.raises(ValueError, match="name"):
        archive.read_parameter(SAT, "no-such-parameter", 0, 1)
    with pytest.raises(ValueError, match="url"):
        Archive("mysql://nowhere/db")


def test_reads_are_not_blocked_by_an_open_upload_transaction(archive: Archive, archive_url: str) -> None:
    whole = synthetic_batch(100)
    archive.ingest(SAT, [whole], source="first", uploaded_by="tester")
    other_writer = create_archive_engine(archive_url)
    with other_writer.begin() as conn:
        conn.execute(text("UPDATE upload SET uploaded_by = 'someone-else'"))  # holds the write lock
        # answered while the lock is held (this thread cannot release it meanwhile): a read that waited for the
        # writer would end in "database is locked" after the busy timeout, or never
        _, v = archive.read_parameter(SAT, "index", int(whole.t_utc_ns[0]), int(whole.t_utc_ns[-1]))
    other_writer.dispose()
    assert v.size == 100


def test_concurrent_overlapping_uploads_store_each_packet_once(archive: Archive, archive_url: str) -> None:
    from concurrent.futures import ThreadPoolExecutor

    whole = synthetic_batch(30_000)
    parts = [whole.take(np.arange(0, 20_000)), whole.take(np.arange(10_000, 30_000))]
    archive.satellite_id(SAT)
    stores = [Archive(archive_url, migrate=False) for _ in parts]
    with ThreadPoolExecutor(2) as pool:
        results = list(
            pool.map(lambda sp: sp[0].ingest(SAT, [sp[1]], source=f"{id(sp[1])}", uploaded_by="t"), zip(stores, parts))
        )
    for store in stores:
        store.close()
    assert sum(r.packets_accepted for r in results) == 30_000
    assert sum(r.packets_duplicate for r in results) == 10_000
    t, v = archive.read_parameter(SAT, "index", int(whole.t_utc_ns[0]), int(whole.t_utc_ns[-1]))
    np.testing.assert_array_equal(v, np.arange(30_000.0))


def test_exported_members_are_the_documented_surface() -> None:
    import telemetry.archive as package

    assert sorted(package.__all__) == sorted(
        [
            "Archive",
            "DERIVED_APID",
            "NAME_MAX",  # the width of its name columns: the API declares it on every name it stores
            "PacketBatch",
            "sequence_gaps",
            "upgrade",
            "IngestResult",
            "Gap",
            "PendingUpload",
            "UploadRecord",
            "AlarmRecord",
            "AlarmEventRecord",
            "PassRecord",
            "StationRecord",
        ]
    )
    assert all(hasattr(package, name) for name in package.__all__)


def test_pending_memory_of_a_batch_counts_whole_arrays_its_columns_view() -> None:
    """A column that is one row of a decoder's matrix keeps the whole matrix alive: the pending buffer's memory
    bound counts that matrix, the times, counts and lengths, and the raw octets."""
    from telemetry.archive.store import _batch_octets

    n = 1_000
    matrix = np.zeros((40, n), dtype=np.uint16)
    batch = PacketBatch(7, np.arange(n), np.arange(n) % 16_384, bytes(10 * n), np.full(n, 10), {"a": matrix[3]})
    assert _batch_octets(batch) == matrix.nbytes + 3 * 8 * n + 10 * n


def test_an_ingest_result_reports_as_its_dataclass_fields() -> None:
    """The stored and returned report of an upload: its fields in order, gaps and duplicates as plain values,
    the same JSON as dataclasses.asdict gives (upload rows written before keep reading alike)."""
    import dataclasses
    import json

    from telemetry.archive import Gap, IngestResult

    result = IngestResult(3, False, 10, 2, 100, 1, [Gap(5, 1, 2, 3), Gap(6, 4, 5, 6)], {5: 1, 6: 1})
    for r in (result, IngestResult(4, True)):
        assert json.dumps(r.as_report()) == json.dumps(dataclasses.asdict(r))
    report = result.as_report()
    report["gaps"].clear()
    report["duplicates_by_apid"].clear()
    assert result.gaps and result.duplicates_by_apid  # copies, not the result's own
