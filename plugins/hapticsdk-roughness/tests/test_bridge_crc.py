"""The serial bridge's frame CRC (CRC-16/CCITT-FALSE) computed with binascii.crc_hqx must
equal the reference bit-by-bit definition on known vectors and on random frames."""

from __future__ import annotations

import random

import pytest

from hapticsdk_roughness import bridge_protocol as bp


def reference_crc16(data: bytes, crc: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE by its definition: MSB first, poly 0x1021, no reflection/xor."""
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


def test_published_check_value():
    # the catalogue check value of CRC-16/CCITT-FALSE over the ASCII digits 1..9
    assert bp.crc16(b"123456789") == 0x29B1
    assert reference_crc16(b"123456789") == 0x29B1


@pytest.mark.parametrize("data", [b"", b"\x00", b"\xff", bytes(range(256)), b"\x03\x07\x10\x59\x01\x02"])
def test_known_vectors_match_bit_loop(data):
    assert bp.crc16(data) == reference_crc16(data)
    assert bp.crc16(data, 0x1D0F) == reference_crc16(data, 0x1D0F)


def test_random_frames_match_bit_loop():
    rnd = random.Random(7)
    for n in (1, 3, 104, 253):
        for _ in range(20):
            data = bytes(rnd.randrange(256) for _ in range(n))
            assert bp.crc16(data) == reference_crc16(data)


def test_encoded_frame_round_trips():
    raw = bp.Frame(seq=7, cmd=bp.CMD_I2C_WRITE, payload=bytes([0x59, 0x01, 0x02])).encode()
    parser = bp.FrameParser()
    assert len(parser.feed(raw)) == 1 and parser.crc_errors == 0
    assert int.from_bytes(raw[-2:], "big") == reference_crc16(raw[1:-2])
