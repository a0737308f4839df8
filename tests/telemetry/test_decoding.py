"""Bulk decoding: bit fields, calibration, derived parameters and mixed-APID streams.

Truths: a pure-Python big-integer decoder and ccsdspy decoding the same bytes with the same
(deliberately unaligned) layout, numpy's
polyval, scipy's Rotation for the attitude error angle (seed 000 §4, E = Λ̃^p ∘ Λ), and the values
each test encoded.
"""

from __future__ import annotations

import struct
from io import BytesIO

import ccsdspy
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from telemetry import ccsds
from telemetry.decoding import calibrate, decode_packets, decode_raw, decode_stream, derive, quaternion_of
from telemetry.dictionary import DerivedParameter, PacketDefinition, Parameter
from tests.telemetry.packet_streams import NOW_UTC_NS, T0_UTC_NS, engineering_values, packets, reference

ANGLE_TOLERANCE_RAD = 1e-9  # float64 angle of a product of unit quaternions vs scipy's own
GRID_ROUNDING_ABS = 1e-15  # k * c1 recomputed from round(k * c1 / c1): float64 rounding of grid values
ODD_LAYOUT = [
    ("u3", "uint", 3),
    ("i13", "int", 13),
    ("u1", "uint", 1),
    ("u7", "uint", 7),
    ("i5", "int", 5),
    ("f32", "float", 32),
    ("u11", "uint", 11),
    ("u64", "uint", 64),
    ("i64", "int", 64),
    ("i2", "int", 2),
    ("u6", "uint", 6),
    ("f64", "float", 64),
]


def _odd_packet() -> PacketDefinition:
    """A packet whose fields straddle octet boundaries (a 64-bit field may span at most 8 octets)."""
    params, bit = [], 48
    for name, kind, bits in ODD_LAYOUT:
        params.append(Parameter(name, kind, bit, bits))
        bit += bits
    return PacketDefinition("ODD", 77, (bit + 7) // 8, tuple(params))


def test_unaligned_bit_fields_match_ccsdspy() -> None:
    packet = _odd_packet()
    rng = np.random.default_rng(21)
    n = 500
    rows = rng.integers(0, 256, (n, packet.packet_octets), dtype=np.uint8)
    rows[:, :6] = ccsds.encode_primary_headers(77, np.arange(n), packet.packet_octets)
    theirs = ccsdspy.FixedLength(
        [
            ccsdspy.PacketField(name=p.name, data_type=p.data_type, bit_length=p.bit_length, bit_offset=p.bit_offset)
            for p in packet.parameters
        ]
    ).load(BytesIO(rows.tobytes()))
    ours = decode_raw(rows, packet)
    for p in packet.parameters:
        if p.data_type != "float":  # ccsdspy 2.0.1 misreads floats that straddle octets
            np.testing.assert_array_equal(ours[p.name], theirs[p.name], err_msg=p.name)
        np.testing.assert_array_equal(ours[p.name], [_python_bit_field(r, p) for r in rows], err_msg=p.name)


def _python_bit_field(row: np.ndarray, p: Parameter) -> float | int:
    """One field read with Python's unbounded integers and struct (an independent reference decoder)."""
    whole = int.from_bytes(row.tobytes(), "big")
    bits = (whole >> (8 * len(row) - p.bit_offset - p.bit_length)) & ((1 << p.bit_length) - 1)
    if p.data_type == "float":
        return struct.unpack(">f" if p.bit_length == 32 else ">d", bits.to_bytes(p.bit_length // 8, "big"))[0]
    if p.data_type == "int" and bits >= 1 << (p.bit_length - 1):
        return bits - (1 << p.bit_length)
    return bits


@pytest.mark.parametrize(
    ("data_type", "bits", "polynomial"),
    [
        ("int", 16, (273.15, 0.0125, -3e-7, 1e-11)),
        ("uint", 12, (-0.0169754359, 0.000923349552, 4.60095316e-07, -1.98291712e-10)),  # IMAP-Lo BHV_DEF_NEG_I
        ("int", 32, (0.5, -2e-3, 0.0, 7e-21)),  # cubes beyond int64: Python's integers
        ("uint", 64, (1.0, 1e-3)),
        ("float", 32, (0.25, -1.5, 2e-2)),
        ("int", 16, (1, 2)),  # integer coefficients from a Python caller: still float64 engineering values
    ],
)
def test_polynomial_calibration_is_space_packet_parsers_to_the_bit(data_type: str, bits: int, polynomial) -> None:
    """Σ c_k x^k as space_packet_parser's PolynomialCalibrator evaluates it (terms in order on Python numbers):
    equal to the last bit, also where Horner's scheme differs by an ulp (cancellation near -13.34 here)."""
    from space_packet_parser.xtce.calibrators import PolynomialCalibrator, PolynomialCoefficient

    p = Parameter("t", data_type, 48, bits, polynomial=polynomial)
    rng = np.random.default_rng(bits)
    if data_type == "float":
        raw = rng.normal(0, 1e3, 2_000).astype(np.float32)
    else:
        low = -(2 ** (bits - 1)) if data_type == "int" else 0
        raw = np.array([low + int(v) % 2**bits for v in rng.integers(0, 2**63, 2_000)], dtype=object)
        raw = raw.astype(np.int64 if data_type == "int" or bits < 64 else np.uint64)
    terms = [PolynomialCoefficient(c, k) for k, c in enumerate(polynomial) if c != 0.0]
    theirs = [PolynomialCalibrator(terms).calibrate(v.item()) for v in raw]
    assert calibrate(raw, p).tolist() == theirs


def test_attitude_error_angle_matches_scipy_relative_rotation() -> None:
    rng = np.random.default_rng(4)
    est = Rotation.random(200, random_state=rng)
    prog = Rotation.random(200, random_state=rng)
    est_q, prog_q = est.as_quat(scalar_first=True), prog.as_quat(scalar_first=True)
    values = {f"e{k}": est_q[:, k] for k in range(4)} | {f"p{k}": prog_q[:, k] for k in range(4)}
    inputs = tuple(f"e{k}" for k in range(4)) + tuple(f"p{k}" for k in range(4))
    d = DerivedParameter("err", "attitude_error_angle", inputs)
    expected = (prog.inv() * est).magnitude()
    np.testing.assert_allclose(derive(d, values, None), expected, atol=ANGLE_TOLERANCE_RAD)


def test_reference_packets_round_trip_exactly() -> None:
    dictionary = reference()
    for packet in dictionary.packets.values():
        values = engineering_values(packet, 200, seed=9)
        rows = packets(packet, 200, seed=9)
        decoded = decode_packets(rows, packet)
        for p in packet.parameters:
            np.testing.assert_allclose(decoded[p.name], values[p.name], rtol=0, atol=GRID_ROUNDING_ABS, err_msg=p.name)


def test_mixed_apid_stream_yields_one_time_ordered_batch_per_packet() -> None:
    dictionary = reference()
    hk, gps = dictionary.packets[256], dictionary.packets[257]
    hk_rows, gps_rows = packets(hk, 400), packets(gps, 100)
    chunks = []
    for i in range(100):  # four HK packets then one GPS packet: 1 s of the real downlink order
        chunks += [hk_rows[4 * i : 4 * i + 4].tobytes(), gps_rows[i].tobytes()]
    result = decode_stream(b"".join(chunks), dictionary, now_utc_ns=NOW_UTC_NS)
    by_apid = {b.apid: b for b in result.batches}
    assert result.report.packets_accepted == 500 and result.report.quarantined == []
    np.testing.assert_array_equal(by_apid[256].packets, hk_rows)
    np.testing.assert_array_equal(by_apid[257].packets, gps_rows)
    np.testing.assert_array_equal(by_apid[257].t_utc_ns, T0_UTC_NS + np.arange(100) * 10**9)
    assert result.report.samples_accepted == 400 * 48 + 100 * 10


def test_quaternion_of_stacks_scalar_first_components() -> None:
    values = {f"q_{k}": np.full(3, float(k)) for k in range(4)}
    np.testing.assert_array_equal(quaternion_of(values, "q")[0], [0.0, 1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="prefix"):
        quaternion_of(values, "w")


def test_decode_raw_rejects_wrong_shape_naming_packets() -> None:
    with pytest.raises(ValueError, match="packets"):
        decode_raw(np.zeros((3, 10), dtype=np.uint8), reference().packets[256])


def test_packets_without_time_code_cannot_be_stamped() -> None:
    packet = PacketDefinition("NT", 9, 8, (Parameter("a", "uint", 48, 16),))
    from telemetry.dictionary import Dictionary

    rows = np.zeros((2, 8), dtype=np.uint8)
    rows[:, :6] = ccsds.encode_primary_headers(9, np.arange(2), 8)
    with pytest.raises(ValueError, match="time_code"):
        decode_stream(rows.tobytes(), Dictionary("t", {9: packet}))
