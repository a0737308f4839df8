"""Packet encoding: the inverse of decoding, range checks naming the field.

Truths: spacepackets parsing the headers we write, the published CRC of our packets recomputed by
fastcrc, and decoding (checked independently in test_decoding/test_dictionary) giving the values back.
"""

from __future__ import annotations

import numpy as np
import pytest
from fastcrc import crc16
from spacepackets.ccsds import SpacePacketHeader

from telemetry.encoding import encode_packets, raw_from_engineering
from tests.telemetry.packet_streams import T0_UTC_NS, engineering_values, reference


def test_encoded_packets_carry_spacepackets_headers_and_fastcrc_checksums() -> None:
    gps = reference().packets[257]
    rows = encode_packets(gps, T0_UTC_NS + np.arange(5) * 10**9, np.arange(100, 105), engineering_values(gps, 5))
    for i, row in enumerate(rows):
        header = SpacePacketHeader.unpack(row.tobytes())
        assert (header.apid, header.seq_count, header.packet_len, header.sec_header_flag) == (257, 100 + i, 62, True)
        assert int.from_bytes(row[-2:].tobytes(), "big") == crc16.ibm_3740(row[:-2].tobytes())


def test_values_off_the_raw_range_raise_naming_the_field() -> None:
    hk = reference().packets[256]
    _, md = reference().parameter("md_dipole_am2_x")
    assert raw_from_engineering(np.array([25.0]), md)[0] == 25_000
    with pytest.raises(ValueError, match="md_dipole_am2_x"):
        raw_from_engineering(np.array([40.0]), md)  # 40,000 counts > int16
    _, mode = reference().parameter("mode")
    with pytest.raises(ValueError, match="mode"):
        raw_from_engineering(np.array([np.nan]), mode)
    values = engineering_values(hk, 2)
    del values["mode"]
    with pytest.raises(ValueError, match="mode"):
        encode_packets(hk, T0_UTC_NS + np.arange(2), np.arange(2), values)
