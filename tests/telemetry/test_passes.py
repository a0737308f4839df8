"""Pass prediction against skyfield's find_events, and received data assigned to passes."""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pytest
from skyfield.api import EarthSatellite, load, wgs84

from telemetry.archive import Archive, PacketBatch
from telemetry.passes import (
    DATA_PASS_GAP_S,
    assign_to_passes,
    elevation_deg,
    passes_from_data,
    predict_passes,
    predict_station_passes,
    record_reception,
)
from tests.telemetry.archive_databases import archive, archive_url  # noqa: F401  (fixtures)

SKYFIELD_EVENT_TOLERANCE_S = 1.0  # find_events refines rise/set/culmination to half a second
MAX_ELEVATION_TOLERANCE_DEG = 0.01  # 0.5 s off culmination changes elevation by < 1e-3 deg
AOS_ELEVATION_TOLERANCE_DEG = 1e-3  # AOS is refined to 1 ms; elevation changes < 0.1 deg/s near the horizon
STATIONS = {  # name: (lat_deg, lon_deg, alt_m, min_elevation_deg)
    "Svalbard": (78.2298, 15.4078, 458.0, 5.0),
    "Toulouse": (43.5617, 1.4811, 150.0, 0.0),
    "Fairbanks": (64.8594, -147.8542, 200.0, 10.0),
}
START_UTC = datetime(2021, 3, 7, tzinfo=UTC)
START_NS = int(START_UTC.timestamp()) * 10**9
DAYS = 2.0


def noaa20_tle(shared_data: Path) -> tuple[str, str]:
    """The first NOAA-20 element set of the shared real TLE file (epoch 2021-03-06)."""
    lines = (shared_data / "tle" / "real_sso_smallsats.tle").read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if line.startswith("NOAA 20"))
    return lines[k + 1], lines[k + 2]


def skyfield_passes(line1: str, line2: str, station: tuple[float, float, float, float]) -> np.ndarray:
    """(aos, culmination, los) UTC seconds of complete passes from skyfield's find_events."""
    ts = load.timescale(builtin=True)
    lat, lon, alt, min_el = station
    t0 = ts.from_datetime(START_UTC)
    t1 = ts.tt_jd(t0.tt + DAYS)
    times, events = EarthSatellite(line1, line2, ts=ts).find_events(
        wgs84.latlon(lat, lon, elevation_m=alt), t0, t1, altitude_degrees=min_el
    )
    unix = np.array([t.utc_datetime().timestamp() for t in times])
    out, rise, peak = [], None, None
    for t, event in zip(unix, events):
        if event == 0:
            rise, peak = t, None
        elif event == 1 and rise is not None and peak is None:
            peak = t
        elif event == 2 and rise is not None and peak is not None:
            out.append((rise, peak, t))
            rise = None
    return np.array(out)


@pytest.mark.parametrize("name", sorted(STATIONS))
def test_noaa20_passes_match_skyfield_find_events(shared_data: Path, name: str) -> None:
    line1, line2 = noaa20_tle(shared_data)
    lat, lon, alt, min_el = STATIONS[name]
    ours = predict_passes(line1, line2, lat, lon, alt, min_el, START_NS, DAYS)
    truth = skyfield_passes(line1, line2, STATIONS[name])
    assert ours.aos_ns.size == truth.shape[0] > 0
    np.testing.assert_allclose(ours.aos_ns / 1e9, truth[:, 0], atol=SKYFIELD_EVENT_TOLERANCE_S, rtol=0)
    np.testing.assert_allclose(ours.max_elevation_ns / 1e9, truth[:, 1], atol=SKYFIELD_EVENT_TOLERANCE_S, rtol=0)
    np.testing.assert_allclose(ours.los_ns / 1e9, truth[:, 2], atol=SKYFIELD_EVENT_TOLERANCE_S, rtol=0)
    sky_el = elevation_deg(line1, line2, lat, lon, alt, truth[:, 1])
    np.testing.assert_allclose(ours.max_elevation_deg, sky_el, atol=MAX_ELEVATION_TOLERANCE_DEG, rtol=0)
    np.testing.assert_allclose(
        elevation_deg(line1, line2, lat, lon, alt, ours.aos_ns / 1e9), min_el, atol=AOS_ELEVATION_TOLERANCE_DEG
    )


def test_station_record_window_gives_the_same_passes(archive: Archive, shared_data: Path) -> None:
    line1, line2 = noaa20_tle(shared_data)
    archive.add_ground_station("Toulouse", *STATIONS["Toulouse"])
    end_ns = START_NS + int(DAYS * 86_400) * 10**9
    ours = predict_station_passes(line1, line2, archive.ground_station("Toulouse"), START_NS, end_ns)
    direct = predict_passes(line1, line2, *STATIONS["Toulouse"], START_NS, DAYS)
    assert list(ours) == direct.rows() and len(ours) == len(direct) > 0
    assert ours.aos_ns[0] >= START_NS and ours.los_ns[-1] <= end_ns


def test_tles_are_validated_and_the_newest_before_a_time_is_found(archive: Archive, shared_data: Path) -> None:
    lines = (shared_data / "tle" / "real_sso_smallsats.tle").read_text().splitlines()
    older, newer = [(lines[k + 1], lines[k + 2]) for k, line in enumerate(lines) if line.startswith("NOAA 20")]
    older_id = archive.add_tle("NOAA-20", *older)
    newer_id = archive.add_tle("NOAA-20", *newer)
    assert archive.add_tle("NOAA-20", *older) == older_id  # idempotent on the epoch
    assert archive.latest_tle("NOAA-20")[0] == newer_id
    assert archive.latest_tle("NOAA-20", before_ns=START_NS)[1:] == older  # 2021-03-07 is before the newer epoch
    with pytest.raises(ValueError, match="checksum"):
        archive.add_tle("NOAA-20", older[0][:-1] + "0", older[1])
    archive.add_ground_station("Svalbard", *STATIONS["Svalbard"])
    with pytest.raises(ValueError, match="passes"):
        archive.save_passes("NOAA-20", "Svalbard", [(START_NS + 10, START_NS, START_NS + 5, 10.0)])


def test_assign_to_passes_is_inclusive_and_minus_one_outside() -> None:
    aos, los = np.array([10, 100]), np.array([20, 150])
    t = np.array([5, 10, 15, 20, 21, 99, 100, 150, 151])
    np.testing.assert_array_equal(assign_to_passes(t, aos, los), [-1, 0, 0, 0, -1, -1, 1, 1, -1])
    with pytest.raises(ValueError, match="aos_ns"):
        assign_to_passes(t, np.array([10, 15]), np.array([20, 30]))


def test_bad_window_names_the_field(shared_data: Path) -> None:
    line1, line2 = noaa20_tle(shared_data)
    with pytest.raises(ValueError, match="days"):
        predict_passes(line1, line2, 0.0, 0.0, 0.0, 5.0, 0, 0.0)


def test_received_packets_give_pass_span_and_completeness(archive: Archive, shared_data: Path) -> None:
    line1, line2 = noaa20_tle(shared_data)
    lat, lon, alt, min_el = STATIONS["Svalbard"]
    archive.add_ground_station("Svalbard", lat, lon, alt, min_el)
    predicted = predict_passes(line1, line2, lat, lon, alt, min_el, START_NS, 0.3)
    archive.save_passes("NOAA-20", "Svalbard", predicted.rows())
    first = archive.passes("NOAA-20", 0, 2**62)[0]
    t = np.arange(first.aos_ns, first.los_ns, 10**9)  # 1 Hz over the pass
    kept = np.setdiff1d(np.arange(t.size), [5, 6, 7, 100])  # 4 packets lost on the link
    batch = PacketBatch.from_packets(11, t, np.arange(t.size) % 16_384, [b"\x00" * 8] * t.size, {"x": np.zeros(t.size)})
    archive.ingest("NOAA-20", [batch.take(kept)], source="pass", uploaded_by="tester")
    (updated, *_) = record_reception(archive, "NOAA-20", archive.passes("NOAA-20", 0, 2**62))
    assert (updated.packets_received, updated.packets_missing) == (t.size - 4, 4)
    assert (updated.received_start_ns, updated.received_end_ns) == (int(t[0]), int(t[-1]))
    assert updated.completeness == pytest.approx((t.size - 4) / t.size)
    assert archive.passes("NOAA-20", 0, 2**62)[0] == updated


def _ingest_seconds(archive: Archive, t0_ns: int, seconds: range) -> None:
    """1 Hz packets of APID 11 at t0 + each second, sequence counts following on (no gaps)."""
    k = np.asarray(seconds)
    t = t0_ns + k * 10**9
    raw = [int(s).to_bytes(8, "big") for s in k]  # distinct packets (the archive refuses an upload twice)
    batch = PacketBatch.from_packets(11, t, k % 16_384, raw, {"x": np.zeros(k.size)})
    archive.ingest("SAT-A", [batch], source=f"seconds {k[0]}-{k[-1]}", uploaded_by="tester")


def test_data_filling_the_gap_between_two_passes_from_data_merges_them(archive: Archive) -> None:
    gap_s = int(DATA_PASS_GAP_S)
    _ingest_seconds(archive, START_NS, range(0, 300))
    passes_from_data(archive, "SAT-A", START_NS, START_NS + 300 * 10**9)
    later = range(300 + 2 * gap_s, 600 + 2 * gap_s)  # too far from the first: a second pass from data
    _ingest_seconds(archive, START_NS, later)
    passes_from_data(archive, "SAT-A", START_NS + later[0] * 10**9, START_NS + later[-1] * 10**9)
    assert len(archive.passes("SAT-A", 0, 2**62)) == 2
    _ingest_seconds(archive, START_NS, range(300, later[0]))  # the gap filled by a later upload
    (merged,) = passes_from_data(archive, "SAT-A", START_NS + 300 * 10**9, START_NS + later[0] * 10**9)
    assert archive.passes("SAT-A", 0, 2**62) == [merged]
    assert (merged.aos_ns, merged.los_ns) == (START_NS, START_NS + later[-1] * 10**9)
    assert (merged.packets_received, merged.packets_missing, merged.completeness) == (later[-1] + 1, 0, 1.0)


def test_overlapping_passes_from_data_become_one_with_its_completeness_recounted(archive: Archive) -> None:
    """Two passes made at once over overlapping data (the live stream and an upload), one more adjacent to them:
    one pass over all three, its completeness from the sequence-count gaps of everything inside it."""
    archive.add_ground_station("Kiruna", 67.86, 20.96, 400.0, 5.0)
    _ingest_seconds(archive, START_NS, [*range(0, 100), *range(103, 400)])  # 3 packets lost on the link
    first = archive.save_data_pass("SAT-A", START_NS, START_NS + 250 * 10**9)
    second = archive.save_data_pass("SAT-A", START_NS + 200 * 10**9, START_NS + 350 * 10**9, station="Kiruna")
    archive.save_data_pass("SAT-A", START_NS + 360 * 10**9, START_NS + 399 * 10**9)
    (merged,) = passes_from_data(archive, "SAT-A", START_NS, START_NS + 399 * 10**9)
    assert merged.id == first and merged.id != second and merged.station == "Kiruna"
    assert archive.passes("SAT-A", 0, 2**62) == [merged]
    assert (merged.aos_ns, merged.los_ns) == (START_NS, START_NS + 399 * 10**9)
    assert (merged.packets_received, merged.packets_missing) == (397, 3)
    assert merged.completeness == pytest.approx(397 / 400)


def test_passes_from_data_at_two_stations_stay_apart(archive: Archive) -> None:
    for name in ("Kiruna", "Svalbard"):
        archive.add_ground_station(name, 70.0, 20.0, 0.0, 5.0)
    _ingest_seconds(archive, START_NS, range(0, 200))
    archive.save_data_pass("SAT-A", START_NS, START_NS + 120 * 10**9, station="Kiruna")
    archive.save_data_pass("SAT-A", START_NS + 100 * 10**9, START_NS + 199 * 10**9, station="Svalbard")
    made = passes_from_data(archive, "SAT-A", START_NS, START_NS + 199 * 10**9)
    assert sorted(p.station for p in made) == ["Kiruna", "Svalbard"]
