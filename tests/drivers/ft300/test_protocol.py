"""The FT300 stream protocol, byte by byte: CRC, scaling, and resync on damaged input."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.ft300.protocol import (
    FrameParser,
    crc16_modbus,
    decode_frame,
    encode_frame,
    start_stream_request,
    stop_stream_bytes,
)


def test_crc_matches_the_modbus_check_value() -> None:
    # The catalogue check value of CRC-16/MODBUS over "123456789".
    assert crc16_modbus(b"123456789") == 0x4B37


def test_start_request_is_the_manual_s_bytes() -> None:
    # Write 0x0200 into register 410 of unit 9 (function 16), CRC low byte first.
    assert start_stream_request(9) == bytes.fromhex("09 10 01 9A 00 01 02 02 00 CD CA")
    assert stop_stream_bytes() == b"\xff" * 50


def test_scaling_to_si() -> None:
    counts = [1234, -500, 32767, -1, 250, -32768]
    body = b"\x20\x4e" + np.array(counts, "<i2").tobytes()
    frame = body + crc16_modbus(body).to_bytes(2, "little")
    np.testing.assert_allclose(
        decode_frame(frame), [12.34, -5.0, 327.67, -0.001, 0.25, -32.768], atol=1e-12
    )


def test_decode_rejects_bad_crc() -> None:
    frame = bytearray(encode_frame([1, 2, 3, 0.1, 0.2, 0.3]))
    frame[4] ^= 0x40
    with pytest.raises(ValueError, match="CRC"):
        decode_frame(bytes(frame))


def test_encode_refuses_out_of_range() -> None:
    with pytest.raises(ValueError):
        encode_frame([400.0, 0, 0, 0, 0, 0])


def _frames(n: int) -> list[bytes]:
    return [encode_frame([i, -i, 0.5 * i, 0.001 * i, 0, 0]) for i in range(1, n + 1)]


def test_parser_survives_any_chunking() -> None:
    stream = b"".join(_frames(20))
    for chunk in (1, 3, 7, 16, 17, 1000):
        parser = FrameParser()
        out = []
        for k in range(0, len(stream), chunk):
            out += parser.feed(stream[k : k + chunk])
        assert [round(s[0]) for s in out] == list(range(1, 21))
        assert parser.stats.crc_errors == 0 and parser.stats.skipped_bytes == 0


def test_parser_skips_damage_and_never_emits_a_wrong_value() -> None:
    f = _frames(6)
    corrupt = bytearray(f[1])
    corrupt[15] ^= 0xFF  # the CRC itself
    bad_payload = bytearray(f[3])
    bad_payload[6] ^= 0x10
    garbage = b"\x01\x02\x03\x20"  # ends on a header's first byte
    stream = f[0] + bytes(corrupt) + f[2] + bytes(bad_payload) + f[4][:9] + garbage + f[5]
    parser = FrameParser()
    out = []
    for k in range(0, len(stream), 5):
        out += parser.feed(stream[k : k + 5])
    assert [round(s[0]) for s in out] == [1, 3, 6]
    for s in out:
        i = round(s[0])
        np.testing.assert_allclose(s, [i, -i, 0.5 * i, 0.001 * i, 0, 0], atol=1e-9)
    # Three damaged frames (two full with a bad CRC, one cut short): three losses of sync.
    assert parser.stats.crc_errors == 3
    assert parser.stats.skipped_bytes == 16 + 16 + 9 + len(garbage)
    assert parser.stats.frames == 3
