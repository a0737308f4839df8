"""Spacecraft emulator: simulation → packets → decode round trip, the live TCP path, and a hidden wheel failure.

Truths: the simulation's own series (values must come back to the dictionary's resolution),
spacepackets parsing our primary headers, CUC seconds counted by hand from 2000-01-01, GPS time
from calendar arithmetic and the published leap seconds, ppigrf's IGRF field magnitude, the
rotation invariance of |r| between ECI and ECEF, and the scenario's sensor noise figures.
"""

from __future__ import annotations

import asyncio
import dataclasses
import datetime as dt
import math

import numpy as np
import ppigrf
import pytest
from spacepackets.ccsds import SpacePacketHeader

from backend.cli import main
from sim_core import engine, fdir, frames, modes, quaternion, scenario_library
from sim_core.closed_loop import TARGET_CODES
from telemetry import emulator
from telemetry.decoding import decode_stream
from telemetry.dictionary import load_dictionary
from telemetry.live import LiveStream, MemoryLink, hello
from tests.ports import free_port
from tests.telemetry.test_live import HANG_S, until_decoded

FAILED_WHEEL = 1  # sim_core index: the dictionary's wheel_*_2
FAILURE_ONSET_S = 350.0  # during the observing hold, before the 20° turn (420–520 s)
FDIR_LATENCY_S = (1 + fdir.CONFIRM_PERIODS) * 2.0  # sim_core.fdir: detected within one T_u = 2 s, then confirmed
ARCSEC = np.pi / 180.0 / 3600.0
FLOAT32_REL = 2.0**-23  # one unit in the last place of an IEEE 754 binary32 mantissa
FLOAT32_QUATERNION_ANGLE_RAD = 1e-6  # binary32 components (≈ 6e-8 each) move an angle by ~1e-7 rad; 10× margin
FLOAT32_RATE_RAD_S = 1e-9  # binary32 rounding of the rates flown (≤ 0.006 rad/s in the turn: ≤ 4e-10 each)
HALF_SPEED_COUNT_RAD_S = 0.5 * np.pi / 120.0 * (1 + 1e-9)  # half of the 0.25 rpm count, plus rounding of the division
HALF_TORQUE_COUNT_NM = 0.5e-5 * (1 + 1e-9)  # half of the 10 µN·m count
TIMESTAMP_FLOAT_TOL_NS = 1e3  # float64 seconds of 2026 carry ~0.2 µs; CUC 4+2 ticks are exact multiples of 2^-16 s
NOISE_STD_REL_TOL = 0.10  # 3,600 samples estimate a standard deviation to ~1.2 % (1σ); 10 % is > 8σ
UNIX_S_ROUNDING = 1e-6  # float64 Unix seconds of 2026 step by 2.4e-7 s; sums of the clock's waits round alike
GPS_LEAP_S = 18  # GPS − UTC since 2017-01-01 (IERS Bulletin C: TAI − UTC = 37 s, GPS = TAI − 19 s)
IGRF_NORM_TOL_T = 300e-9  # 6σ of the 50 nT magnetometer noise plus the 2 nT count and the 30 s field table


@pytest.fixture(scope="module")
def dictionary():
    return load_dictionary(emulator.REFERENCE_DICTIONARY)


@pytest.fixture(scope="module")
def nominal(dictionary):
    return emulator.emulate(dictionary=dictionary)


@pytest.fixture(scope="module")
def wheel_failure(dictionary):
    fault = emulator.parse_fault(f"wheel:{FAILED_WHEEL}:failure@{FAILURE_ONSET_S}")
    return emulator.emulate(faults=[fault], dictionary=dictionary)


@pytest.fixture(scope="module")
def decoded(nominal, dictionary):
    _, _, stream = nominal
    result = decode_stream(stream.data, dictionary)
    return {b.packet: b for b in result.batches}, result.report


def test_every_packet_decodes_with_its_sequence_count_and_time(nominal, decoded) -> None:
    _, series, stream = nominal
    batches, report = decoded
    assert report.quarantined == [] and report.packets_accepted == len(stream)
    assert np.all(np.diff(stream.t_utc_ns) >= 0)  # one time-ordered stream of both APIDs
    for name, item in series.items():
        np.testing.assert_array_equal(batches[name].t_utc_ns, item.t_utc_ns)
        np.testing.assert_array_equal(batches[name].sequence_count, np.arange(len(item.t_utc_ns)) % 16384)


def test_primary_headers_and_cuc_times_read_by_independent_parsers(nominal, dictionary) -> None:
    _, series, stream = nominal
    starts = np.concatenate([[0], stream.ends[:-1]])
    epoch_2000 = dt.datetime(2000, 1, 1, tzinfo=dt.UTC)
    counts: dict[int, int] = {}
    for k in range(0, len(stream), 97):
        packet = stream.data[starts[k] : stream.ends[k]]
        header = SpacePacketHeader.unpack(packet)
        definition = dictionary.packets[header.apid]
        assert (header.packet_len, header.sec_header_flag, int(header.seq_flags)) == (definition.packet_octets, True, 3)
        counts.setdefault(header.apid, 0)
        cuc_s = int.from_bytes(packet[6:10], "big") + int.from_bytes(packet[10:12], "big") / 65536
        stamp = epoch_2000 + dt.timedelta(seconds=cuc_s)
        assert stamp.timestamp() * 1e9 == pytest.approx(stream.t_utc_ns[k], abs=TIMESTAMP_FLOAT_TOL_NS)
    assert set(counts) == {256, 257}


def test_decoded_values_equal_the_emulated_values_to_the_dictionary_resolution(nominal, decoded) -> None:
    _, series, _ = nominal
    batches, _ = decoded
    for name, item in series.items():
        for p in item.definition.parameters:
            sent, got = np.asarray(item.values[p.name]), batches[name].values[p.name]
            if p.polynomial:
                np.testing.assert_allclose(got, sent, rtol=0, atol=0.5 * p.polynomial[1] * (1 + 1e-9), err_msg=p.name)
            elif p.data_type == "float" and p.bit_length == 32:
                np.testing.assert_array_equal(got, sent.astype(np.float32), err_msg=p.name)
            else:
                np.testing.assert_array_equal(got, sent, err_msg=p.name)


def test_decoded_telemetry_equals_the_simulation_truth(nominal, decoded) -> None:
    traj, series, _ = nominal
    batches, _ = decoded
    hk = batches["ACS_HK"].values
    rows = np.arange(len(batches["ACS_HK"].t_utc_ns))
    for prefix, key, suffixes in (
        ("q_est_ib", "q_est_ib", "0123"),
        ("q_prog_ib", "q_prog_ib", "0123"),
        ("omega_est_b_rad_s", "omega_est_b_rad_s", "xyz"),
    ):
        truth = traj[key][0, rows]
        for k, sfx in enumerate(suffixes):
            np.testing.assert_allclose(hk[f"{prefix}_{sfx}"], truth[:, k], rtol=FLOAT32_REL, atol=1e-30)
    for k in range(4):
        np.testing.assert_allclose(
            hk[f"wheel_speed_rad_s_{k + 1}"], traj["wheel_speed_rad_s"][0, rows, k], atol=HALF_SPEED_COUNT_RAD_S
        )
        np.testing.assert_allclose(
            hk[f"wheel_torque_cmd_nm_{k + 1}"], traj["wheel_torque_cmd_nm"][0, rows, k], atol=HALF_TORQUE_COUNT_NM
        )
    e = quaternion.multiply(quaternion.conjugate(traj["q_prog_ib"][0, rows]), traj["q_est_ib"][0, rows])
    np.testing.assert_allclose(hk["attitude_error_rad"], quaternion.angle(e), atol=FLOAT32_QUATERNION_ANGLE_RAD)


def test_sensor_samples_scatter_about_truth_with_the_scenario_noise(nominal, decoded) -> None:
    traj, _, _ = nominal
    batches, _ = decoded
    hk = batches["ACS_HK"].values
    rows = np.arange(len(batches["ACS_HK"].t_utc_ns))
    q_st = np.stack([hk[f"q_st_ib_{k}"] for k in range(4)], axis=-1).astype(np.float64)
    err = quaternion.angle(quaternion.multiply(quaternion.conjugate(traj["q_ib"][0, rows]), q_st))
    sigma_st = 3.0 * ARCSEC  # somov-ge4-scan: σ = 3″ per axis, so the angle's RMS is σ√3
    assert np.sqrt(np.mean(err**2)) == pytest.approx(sigma_st * np.sqrt(3.0), rel=NOISE_STD_REL_TOL)
    gyro = np.stack([hk[f"omega_gyro_b_rad_s_{a}"] for a in "xyz"], axis=-1) - traj["omega_b_rad_s"][0, rows]
    # about the satellite's own truth bias (emulator.truth_scenario), which only the MEKF estimates
    assert np.sqrt(np.mean(np.var(gyro, axis=0))) == pytest.approx(2e-6, rel=NOISE_STD_REL_TOL)
    assert np.all(np.abs(gyro.mean(axis=0)) <= emulator.TruthTolerances().gyro_bias_rad_s + 1e-7)


def test_magnetometer_field_magnitude_matches_ppigrf(nominal, decoded) -> None:
    traj, _, _ = nominal
    batches, _ = decoded
    hk = batches["ACS_HK"].values
    rows = np.arange(0, len(batches["ACS_HK"].t_utc_ns), 40)
    t_unix = traj.extra["epoch_unix_s"] + traj.t_s[rows]
    r_ecef = np.einsum("nij,nj->ni", frames.eci_to_ecef_matrix(t_unix), traj["r_eci_m"][0, rows])
    lat, lon, h = frames.ecef_to_geodetic(r_ecef)
    date = dt.datetime.fromtimestamp(float(t_unix[0]), dt.UTC).replace(tzinfo=None)
    be, bn, bu = ppigrf.igrf(lon, lat, h / 1e3, date)
    reference = np.sqrt(be**2 + bn**2 + bu**2).ravel() * 1e-9
    sent = np.linalg.norm(np.stack([hk[f"b_mag_b_t_{a}"][rows] for a in "xyz"], axis=-1), axis=-1)
    np.testing.assert_allclose(sent, reference, atol=IGRF_NORM_TOL_T)


def test_gps_fix_keeps_the_orbit_radius_and_counts_gps_time(nominal, decoded) -> None:
    traj, _, _ = nominal
    gps = decoded[0]["GPS_NAV"]
    rows = np.arange(len(gps.t_utc_ns)) * 4  # GPS every 1 s, trajectory every 0.25 s
    r_fix = np.linalg.norm(np.stack([gps.values[f"r_ecef_m_{a}"] for a in "xyz"], axis=-1), axis=-1)
    residual = r_fix - np.linalg.norm(traj["r_eci_m"][0, rows], axis=-1)  # |r| is frame-invariant
    assert np.std(residual) == pytest.approx(emulator.GPS_SIGMA_R_M, rel=NOISE_STD_REL_TOL * 2)  # 900 fixes
    first = dt.datetime.fromtimestamp(int(gps.t_utc_ns[0]) // 10**9, dt.UTC)
    days = (first.date() - dt.date(1980, 1, 6)).days
    assert gps.values["gps_week"][0] == days // 7
    seconds_of_day = first.hour * 3600 + first.minute * 60 + first.second
    assert gps.values["gps_seconds_of_week"][0] == (days % 7) * 86_400 + seconds_of_day + GPS_LEAP_S


def test_mode_reports_the_scheduled_turn_of_the_route(nominal, decoded) -> None:
    traj, _, _ = nominal
    hk = decoded[0]["ACS_HK"]
    turn = (traj.t_s[: len(hk.t_utc_ns)] >= 420.0) & (traj.t_s[: len(hk.t_utc_ns)] < 520.0)  # 300 + 120 s, 100 s turn
    assert np.all(hk.values["mode"][turn] == 4) and np.all(hk.values["mode"][~turn] == 3)  # PROGRAM_TURN, THREE_AXIS


def test_hidden_wheel_failure_shows_in_wheel_speeds_and_onboard_fdir_flags(nominal, wheel_failure, dictionary) -> None:
    batches = {}
    for label, (_, _, stream) in (("nominal", nominal), ("failed", wheel_failure)):
        batches[label] = {b.packet: b for b in decode_stream(stream.data, dictionary).batches}["ACS_HK"]
    t_s = (batches["failed"].t_utc_ns - batches["failed"].t_utc_ns[0]) / 1e9
    before, after = t_s < FAILURE_ONSET_S, t_s >= FAILURE_ONSET_S
    speed = f"wheel_speed_rad_s_{FAILED_WHEEL + 1}"
    for name in ("wheel_speed_rad_s_1", speed, "q_est_ib_1"):  # same flight until the fault
        np.testing.assert_array_equal(batches["failed"].values[name][before], batches["nominal"].values[name][before])
    failed_speed = batches["failed"].values[speed][after]
    nominal_swing = np.ptp(batches["nominal"].values[speed][after])
    assert np.ptp(failed_speed) <= np.pi / 120.0 < 0.01 * nominal_swing  # frozen to one 0.25 rpm count
    assert np.all(batches["failed"].values[f"wheel_current_a_{FAILED_WHEEL + 1}"][after] == 0.0)
    isolated = batches["failed"].values[f"fault_wheel_{FAILED_WHEEL + 1}"]
    first = t_s[np.argmax(isolated > 0)]
    assert np.all(isolated[t_s >= first] == 1) and FAILURE_ONSET_S < first <= FAILURE_ONSET_S + FDIR_LATENCY_S
    others = [n for n in batches["failed"].values if n.startswith("fault_") and n != f"fault_wheel_{FAILED_WHEEL + 1}"]
    assert all(np.all(batches["failed"].values[n] == 0) for n in others)
    assert not np.any(batches["failed"].values["fdir_event"] == 2)  # FAULT_ONSET is ground truth, never sent


def test_hidden_sensor_faults_show_in_the_raw_sensor_telemetry(nominal, dictionary) -> None:
    bias_rad_s, onset_s, failure_s = 1e-4, 200.0, 600.0
    faults = [
        emulator.parse_fault(f"gyro:2:bias@{onset_s},value={bias_rad_s}"),
        emulator.parse_fault(f"star_tracker:0:failure@{failure_s}"),
    ]
    traj, series, stream = emulator.emulate(faults=faults, dictionary=dictionary)
    hk = {b.packet: b for b in decode_stream(stream.data, dictionary).batches}["ACS_HK"].values
    t_s = traj.t_s[: len(hk["mode"])]
    rows = np.arange(len(t_s))

    def gyro_minus_truth(values, trajectory):
        return np.stack([values[f"omega_gyro_b_rad_s_{a}"] for a in "xyz"], -1) - trajectory["omega_b_rad_s"][0, rows]

    nominal_hk = nominal[1]["ACS_HK"].values
    step = gyro_minus_truth(hk, traj) - gyro_minus_truth(nominal_hk, nominal[0])  # same noise draws in both runs
    expected = np.where(t_s[:, None] >= onset_s, [0.0, 0.0, bias_rad_s], 0.0)
    np.testing.assert_allclose(step, expected, atol=FLOAT32_RATE_RAD_S)
    q_st = np.stack([hk[f"q_st_ib_{k}"] for k in range(4)], -1)
    assert np.all(q_st[t_s >= failure_s] == 0.0) and np.all(np.linalg.norm(q_st[t_s < failure_s], axis=-1) > 0.99)


def test_hidden_tachometer_bias_shows_in_the_telemetered_wheel_speed_not_the_rotor(dictionary) -> None:
    """A speed-sensor bias of 3 counts on wheel 2 (sim_core.faults tachometer fault): the satellite telemeters what
    its tachometer reads, so the decoded speed minus the rotor's (both at 0.25 rpm counts) steps by exactly the bias
    at the onset; the other wheels read their rotors."""
    q, onset_s = 0.25 * np.pi / 30.0, 200.0
    fault = emulator.parse_fault(f"tachometer:1:bias@{onset_s},value={3.0 * q}")
    traj, _, stream = emulator.emulate(faults=[fault], dictionary=dictionary)
    hk = {b.packet: b for b in decode_stream(stream.data, dictionary).batches}["ACS_HK"].values
    t_s = traj.t_s[: len(hk["mode"])]
    read = np.stack([hk[f"wheel_speed_rad_s_{w}"] for w in range(1, 5)], -1)
    rotor = q * np.round(traj["wheel_speed_rad_s"][0, : len(t_s)] / q)
    expected = np.where(t_s[:, None] >= onset_s, [0.0, 3.0 * q, 0.0, 0.0], 0.0)
    np.testing.assert_allclose(read - rotor, expected, atol=1e-9)


def test_onboard_fdir_events_set_the_isolation_flags_and_fault_mode(nominal, dictionary) -> None:
    traj, _, _ = nominal
    gyro_axis_1 = fdir.SENSOR_ARG + 10 * TARGET_CODES["gyro"] + 1  # sim_core.fdir's sensor argument
    events = [
        (100.0, "fault_detected", 2),
        (100.5, "fault_isolated", 2),
        (101.0, "reconfigured", 0b1011),
        (200.0, "fault_isolated", gyro_axis_1),
        (300.0, "mode_change", modes.MODE_FAULT),
    ]
    reported = dataclasses.replace(traj, events=[events])
    s = emulator.satellite_scenario()
    hk = emulator.packet_series(reported, s, dictionary)["ACS_HK"].values
    t_s = traj.t_s[: len(hk["mode"])]
    np.testing.assert_array_equal(hk["fault_wheel_3"], t_s >= 100.5)
    np.testing.assert_array_equal(hk["fault_gyro"], t_s >= 200.0)
    assert not any(hk[f"fault_wheel_{k}"].any() for k in (1, 2, 4)) and not hk["fault_star_tracker"].any()
    assert np.all(hk["mode"][t_s >= 300.0] == 5) and not np.any(hk["mode"][t_s < 300.0] == 5)  # FAULT
    codes = {t: (e, a) for t, e, a in zip(t_s, hk["fdir_event"], hk["fdir_event_argument"])}
    assert codes[99.75] == (0, 0) and codes[100.75] == (5, 2) and codes[101.0] == (6, 0b1011)
    assert codes[250.0] == (5, gyro_axis_1) and codes[300.0] == (1, 5)  # MODE_CHANGE to the dictionary's FAULT


def drain(subscriber) -> list:
    out = []
    while subscriber.pending:
        out.append(subscriber.get_nowait())
    return out


class SteppedClock:
    """A clock the test owns: it moves only when the sender waits, by exactly the wait (then yields to the loop, so
    the listener reads what arrived); the UTC clock reads ``utc0_s`` plus the seconds stepped."""

    def __init__(self, utc0_s: float = 0.0) -> None:
        self.now_s, self.utc0_s = 0.0, utc0_s

    def monotonic(self) -> float:
        return self.now_s

    def time(self) -> float:
        return self.utc0_s + self.now_s

    async def sleep(self, delay_s: float) -> None:
        self.now_s += max(delay_s, 0.0)
        await asyncio.sleep(0)


def test_live_emulator_to_listener_delivers_decoded_samples_paced(nominal, decoded, dictionary) -> None:
    _, _, stream = nominal
    t0 = int(stream.t_utc_ns[0])
    piece = stream.window(t0 + 10 * 10**9, t0 + 30 * 10**9)  # 20 s of flight
    rate = 20.0
    clock = SteppedClock()

    async def fly() -> tuple[list, emulator.SendReport]:
        live = LiveStream(dictionary)
        subscriber = live.subscribe(max_messages=10_000)
        port = await live.start()
        report = await emulator.send_stream(piece, emulator.SendOptions("127.0.0.1", port, rate, clock=clock))
        await until_decoded(live, len(piece))
        await live.stop()
        return drain(subscriber), report

    messages, report = asyncio.run(fly())
    span_s = (piece.t_utc_ns[-1] - piece.t_utc_ns[0]) / 1e9
    assert clock.now_s == pytest.approx(span_s / rate, abs=1e-9)  # paced at ×20: the last packet left when due
    assert report.packets_sent == len(piece) and all(m.dropped_packets == 0 for m in messages)
    hk = [m.batch for m in messages if m.batch.packet == "ACS_HK"]
    live_t = np.concatenate([b.t_utc_ns for b in hk])
    offline = decoded[0]["ACS_HK"]
    sel = np.isin(offline.t_utc_ns, live_t)
    assert sel.sum() == len(live_t) == 80  # 20 s at T_q = 0.25 s
    for name in ("wheel_speed_rad_s_3", "q_est_ib_0", "attitude_error_rad"):
        np.testing.assert_array_equal(np.concatenate([b.values[name] for b in hk]), offline.values[name][sel])


def test_sender_reconnects_and_resends_after_the_link_drops_each_connection_naming_its_satellite(
    nominal, dictionary
) -> None:

    _, _, stream = nominal
    t0 = int(stream.t_utc_ns[0])
    piece = stream.window(t0, t0 + 20 * 10**9)
    received: list[bytearray] = []
    handled: list[bool] = []  # one per connection the server has finished with

    async def link() -> emulator.SendReport:
        async def handle(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            buffer = bytearray()
            received.append(buffer)
            first = len(received) == 1
            while data := await reader.read(4096):
                buffer.extend(data)
                if first and len(buffer) > 3000:  # drop the first link mid-stream
                    break
            writer.close()
            handled.append(True)

        async def all_handled(n: int) -> None:
            while len(handled) < n:
                await asyncio.sleep(0.01)

        server = await asyncio.start_server(handle, "127.0.0.1", 0)
        port = server.sockets[0].getsockname()[1]
        report = await emulator.send_stream(
            piece, emulator.SendOptions("127.0.0.1", port, rate=40.0, retry_s=0.05, satellite="SAT-7")
        )
        await asyncio.wait_for(all_handled(report.connections), HANG_S)  # the server read each link to its end
        server.close()
        await server.wait_closed()
        return report

    report = asyncio.run(link())
    assert report.connections == 2 == len(received)
    seen = set()
    for buffer in received:
        assert buffer.startswith(hello("SAT-7"))
        for batch in decode_stream(bytes(buffer[len(hello("SAT-7")) :]), dictionary).batches:
            seen.update(zip([batch.apid] * len(batch.t_utc_ns), batch.t_utc_ns.tolist()))
    assert seen == set(zip(piece.apid.tolist(), piece.t_utc_ns.tolist()))  # nothing lost across the drop


def test_sender_waits_for_a_listener_that_starts_late(nominal, dictionary) -> None:
    _, _, stream = nominal
    piece = stream.window(int(stream.t_utc_ns[0]), int(stream.t_utc_ns[0]) + 5 * 10**9)
    port = free_port()  # a port nobody listens on yet

    async def late() -> tuple[emulator.SendReport, list]:
        sending = asyncio.create_task(
            emulator.send_stream(piece, emulator.SendOptions("127.0.0.1", port, rate=math.inf, retry_s=0.05))
        )
        await asyncio.sleep(0.3)
        live = LiveStream(dictionary)
        subscriber = live.subscribe(max_messages=1_000)
        await live.start(port=port)
        report = await sending
        await until_decoded(live, len(piece))
        await live.stop()
        return report, drain(subscriber)

    report, messages = asyncio.run(late())
    assert report.connections == 1 and sum(len(m.batch.t_utc_ns) for m in messages) == len(piece) == 25
    with pytest.raises(OSError):
        asyncio.run(
            emulator.send_stream(
                piece, emulator.SendOptions("127.0.0.1", port, rate=math.inf, retry_s=0.01, attempts=2)
            )
        )


def test_real_time_sender_releases_each_packet_at_its_utc_time_stamp(dictionary) -> None:
    _, _, stream = emulator.emulate(duration_s=2.0, start_utc="2026-03-20T00:00:00Z", dictionary=dictionary)
    first_stamp_s = int(stream.t_utc_ns[0]) / 1e9
    clock = SteppedClock(utc0_s=first_stamp_s - 1.5)  # the UTC clock 1.5 s before the first packet's time stamp
    arrivals: list[tuple[float, int]] = []  # (UTC s read as the bytes arrived, octets received so far)

    async def link() -> float:
        async def handle(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            while data := await reader.read(4096):
                arrivals.append((clock.time(), (arrivals[-1][1] if arrivals else 0) + len(data)))
            writer.close()

        server = await asyncio.start_server(handle, "127.0.0.1", 0)
        await emulator.send_stream(
            stream,
            emulator.SendOptions("127.0.0.1", server.sockets[0].getsockname()[1], on_wall_clock=True, clock=clock),
        )
        finished = clock.time()
        server.close()
        await server.wait_closed()
        return finished

    finished = asyncio.run(link())
    stamps_s = stream.t_utc_ns / 1e9
    starts = np.concatenate([[0], stream.ends[:-1]])
    for utc_s, octets in arrivals:  # no packet has begun to arrive before its time stamp
        assert np.all(stamps_s[starts < octets] <= utc_s + UNIX_S_ROUNDING)
    assert finished == pytest.approx(stamps_s[-1], abs=UNIX_S_ROUNDING)  # the last left at its time stamp, not later
    assert arrivals[-1][1] == len(stream.data)
    with pytest.raises(ValueError, match="on_wall_clock"):
        asyncio.run(emulator.send_stream(stream, emulator.SendOptions(rate=2.0, on_wall_clock=True)))


def test_cli_streams_to_a_live_listener(dictionary) -> None:
    async def listen() -> tuple[int, list]:
        live = LiveStream(dictionary)
        subscriber = live.subscribe(max_messages=1_000)
        port = await live.start()
        code = await asyncio.to_thread(
            main,
            [
                "emulate",
                "--duration",
                "10",
                "--segment",
                "4",
                "--rate",
                "inf",
                "--port",
                str(port),
                "--attempts",
                "3",
                "--satellite",
                "S9",
            ],
        )
        await until_decoded(live, 50)  # 10 s: 40 ACS_HK at T_q = 0.25 s, 10 GPS_NAV at 1 s
        await live.stop()
        return code, drain(subscriber)

    code, messages = asyncio.run(listen())
    received = {
        packet: sum(len(m.batch.t_utc_ns) for m in messages if m.batch.packet == packet)
        for packet in ("ACS_HK", "GPS_NAV")
    }
    assert code == 0 and received == {"ACS_HK": 40, "GPS_NAV": 10} and {m.satellite for m in messages} == {"S9"}


SEGMENT_S = 20.0  # short segments: several seams in a fast test (the demo flies 600 s at a time)
NOISE_CORRELATION_MAX = 0.3  # two independent runs of 80 × 3 star-tracker errors: |r| ~ 0.065 (1σ); 0.3 is 4.6σ


def test_an_endless_satellite_keeps_streaming_segment_after_segment_as_one_flight(dictionary) -> None:
    s = emulator.satellite_scenario(faults=[emulator.parse_fault(f"wheel:{FAILED_WHEEL}:failure@30")])
    n_segments = 4
    whole_traj, _, whole_stream = emulator.Satellite(s, dictionary).fly(n_segments * SEGMENT_S)
    whole = {b.packet: b for b in decode_stream(whole_stream.data, dictionary).batches}

    async def listen() -> list:
        live, link = LiveStream(dictionary), MemoryLink()
        subscriber = live.subscribe(max_messages=10_000)
        await live.start(link=link)
        connection, sent = link.connect(), 0
        streams = emulator.flight_streams(emulator.Satellite(s, dictionary), SEGMENT_S)  # without end
        async for stream in streams:
            connection.write(stream.data)
            sent += 1
            if sent == n_segments:
                break
        await streams.aclose()
        await connection.aclose()
        await live.stop()
        return drain(subscriber)

    batches: dict[str, list] = {}
    for m in asyncio.run(listen()):
        batches.setdefault(m.batch.packet, []).append(m.batch)
    for name, offline in whole.items():
        np.testing.assert_array_equal(np.concatenate([b.t_utc_ns for b in batches[name]]), offline.t_utc_ns)
        counts = np.concatenate([b.sequence_count for b in batches[name]])
        np.testing.assert_array_equal(counts, np.arange(len(offline.t_utc_ns)) % 16384)  # on across the seams
    hk = {k: np.concatenate([b.values[k] for b in batches["ACS_HK"]]) for k in whole["ACS_HK"].values}
    for k in ("q_est_ib_0", "q_est_ib_3", "omega_est_b_rad_s_x", "wheel_speed_rad_s_2", "wheel_speed_rad_s_4"):
        np.testing.assert_array_equal(hk[k], whole["ACS_HK"].values[k], err_msg=k)  # the flight is one flight
    assert hk["fault_wheel_2"][-1] == 1  # the wheel failed at 30 s, isolated by the onboard FDIR, still shown
    q_st = np.stack([hk[f"q_st_ib_{i}"] for i in range(4)], axis=-1)
    e = quaternion.multiply(quaternion.conjugate(whole_traj["q_ib"][0]), q_st)[:, 1:]  # the noise rotation / 2
    per_segment = int(SEGMENT_S / s.output_dt_s)
    r = np.corrcoef(e[:per_segment].ravel(), e[per_segment : 2 * per_segment].ravel())[0, 1]
    assert abs(r) < NOISE_CORRELATION_MAX  # the sensor noise goes on, it does not start again each segment


def test_a_frozen_sensor_holds_its_last_output_across_a_segment_seam(dictionary) -> None:
    onset_s = 5.0
    s = emulator.satellite_scenario(faults=[emulator.parse_fault(f"gyro:0:frozen@{onset_s}")])
    satellite = emulator.Satellite(s, dictionary)
    parts = [satellite.fly(10.0)[1]["ACS_HK"] for _ in range(2)]  # the seam at 10 s, inside the fault
    gyro = np.concatenate([p.values["omega_gyro_b_rad_s_x"] for p in parts])
    t_ns = np.concatenate([p.t_utc_ns for p in parts])
    t_s = (t_ns - t_ns[0]) / 1e9
    last_free = gyro[np.flatnonzero(t_s < onset_s)[-1]]
    assert np.all(gyro[t_s >= onset_s] == last_free)  # frozen at the output before the onset, through the seam
    assert np.unique(gyro[t_s < onset_s]).size > 1  # noisy before: the hold is the fault's, not a dead stream


def test_demo_pass_file_holds_the_window_with_mission_sequence_counts(dictionary) -> None:
    data = emulator.demo_pass_bytes(t_start_s=100.0, t_stop_s=130.0)
    batches = {b.packet: b for b in decode_stream(data, dictionary).batches}
    hk, gps = batches["ACS_HK"], batches["GPS_NAV"]
    t_s = (hk.t_utc_ns - hk.t_utc_ns[0]) / 1e9
    assert len(hk.t_utc_ns) == 120 and len(gps.t_utc_ns) == 30 and t_s[-1] == 29.75
    assert hk.sequence_count[0] == 400 and gps.sequence_count[0] == 100  # counted from the start of the flight


def test_bad_fault_and_scenario_raise_value_errors_naming_the_field() -> None:
    with pytest.raises(ValueError, match="fault.type"):
        emulator.parse_fault("wheel:1:explode@600")
    with pytest.raises(ValueError, match="fault: expected"):
        emulator.parse_fault("wheel:1:failure")
    with pytest.raises(ValueError, match="scenario 'nope'"):
        emulator.satellite_scenario("nope")
    with pytest.raises(ValueError, match="faults.index"):
        emulator.satellite_scenario(faults=[emulator.parse_fault("wheel:7:failure@1")])
    with pytest.raises(ValueError, match="scenario: output_dt_s: must be a whole multiple"):
        emulator.satellite_scenario("peer-basilisk-rw4")  # RK4 at 0.1 s cannot sample at T_q = 0.25 s
    with pytest.raises(ValueError, match="cluster.wheels: the dictionary carries 4 wheels, the scenario flies 3"):
        emulator.emulate("aist-scheduled-turn", duration_s=1.0)
    with pytest.raises(ValueError, match="rate"):
        emulator.SendOptions(rate=0.0)


def test_cli_writes_a_packet_file_that_decodes(tmp_path, dictionary, capsys) -> None:
    out = tmp_path / "pass.bin"
    assert main(["emulate", "--duration", "20", "--fault", "wheel:0:failure@5", "--out", str(out)]) == 0
    result = decode_stream(out.read_bytes(), dictionary)
    assert result.report.quarantined == [] and result.report.packets_accepted == 80 + 20
    assert main(["emulate", "--duration", "20", "--fault", "wheel:0:melt@5", "--out", str(out)]) == 2
    assert "fault.type" in capsys.readouterr().err
    scenario = tmp_path / "short.json"
    scenario.write_text(scenario_library.get("somov-ge4-scan").model_copy(update={"duration_s": 4.0}).model_dump_json())
    assert main(["emulate", "--scenario", str(scenario), "--out", str(out)]) == 0
    assert decode_stream(out.read_bytes(), dictionary).report.packets_accepted == 16 + 4
    for endless in (["--out", str(out)], ["--duration", "20"], ["--segment", "0"]):
        assert main(["emulate", "--forever", "--port", "9", *endless]) == 2  # refused before anything is sent
    assert "forever" in capsys.readouterr().err
    assert main(["emulate", "--port", "9", "--dictionary", "reference_satellite.yaml"]) == 2  # no --satellite
    assert "dictionary" in capsys.readouterr().err


def test_the_satellite_is_the_same_spacecraft_with_its_own_truth_within_the_stated_tolerances() -> None:
    model = scenario_library.get(emulator.DEFAULT_SCENARIO)
    tol = emulator.TruthTolerances()
    truths = [emulator.satellite_scenario(model, truth_seed=k) for k in range(5)]
    j = np.array(model.spacecraft.inertia_kg_m2)
    axes = engine.cluster_axes(model)
    for s in truths:
        jt = np.array(s.truth.inertia_kg_m2)
        assert np.all(np.abs(np.diag(jt) / np.diag(j) - 1.0) <= tol.inertia_rel)
        assert np.max(np.abs((jt - j)[~np.eye(3, dtype=bool)])) <= tol.product_rel * np.trace(j) / 3.0
        assert np.all(np.linalg.eigvalsh(jt) > 0.0)
        tilt = np.arccos(np.clip(np.sum(np.array(s.truth.wheel_axes_b).T * axes, axis=0), -1.0, 1.0))
        assert np.all(tilt <= tol.wheel_axis_rad + 1e-12)
        assert np.all(
            np.abs(np.subtract(s.sensors.gyro_bias_rad_s, model.sensors.gyro_bias_rad_s)) <= tol.gyro_bias_rad_s
        )
        assert s.seed != model.seed and s.spacecraft == model.spacecraft  # onboard software keeps the model
    assert truths[0] == emulator.satellite_scenario(model, truth_seed=0)  # reproducible
    assert truths[0].truth != truths[1].truth
    assert emulator.satellite_scenario(model, truth_seed=None).truth is None
