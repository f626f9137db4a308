"""The FT300 driver against a pseudo-terminal FT300: the emulator (sim/emulate/ft300_stream.py)
without noise or offset, each frame's values known (tests/drivers/peers.py).

Timing margins are generous (seconds where the stream needs tens of milliseconds) so the tests
hold on two busy CI cores; only the stale-stream test depends on a sample getting old.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator

import numpy as np
import pytest

from drivers.ft300 import FT300
from drivers.ft_sensor import ForceTorqueSensor
from drivers.health import DeviceError
from sim.emulate.ft300_stream import FT300Emulator
from tests.drivers.peers import ft300_peer

BASE = [1.0, -2.0, 3.5, 0.1, -0.2, 0.3]
GARBAGE = b"\x00\x13\x37\xaa\x55"  #: line noise between frames, no header in it


def seq_wrench(seq: int) -> list[float]:
    """Known values with the frame's sequence number in Tz (1 count = 0.001 N*m)."""
    return [1.0, -2.0, 3.5, 0.1, -0.2, (seq % 30000) / 1000.0]


def wait_for(cond: Callable[[], bool], timeout: float = 5.0) -> None:
    deadline = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > deadline:
            raise AssertionError("condition not met in time")
        time.sleep(0.005)


def wait_for_more(seen: list[np.ndarray], k: int) -> None:
    n = len(seen)
    wait_for(lambda: len(seen) > n + k)


def sent_seqs(peer: FT300Emulator) -> list[int]:
    """The sequence numbers of the frames the peer wrote, in order (Tz in counts)."""
    assert peer.sent is not None
    return [values[5] for values, _ in peer.sent]


@pytest.fixture
def peer() -> Iterator[FT300Emulator]:
    with ft300_peer(wrench_of=seq_wrench) as p:
        yield p


def test_stream_values_scaled_and_protocol_followed(peer: FT300Emulator) -> None:
    with FT300(peer.port, stale_after=1.0) as ft:
        assert isinstance(ft, ForceTorqueSensor)
        assert peer.received == [bytes.fromhex("09 10 01 9A 00 01 02 02 00 CD CA")]
        w = ft.wrench()
        np.testing.assert_allclose(w[:5], BASE[:5], atol=1e-9)
        assert w[5] == pytest.approx(round(w[5] * 1000) / 1000)
        assert ft.age() < 1.0
    # stop(): the reader is joined and the sensor was told to stop streaming.
    assert not ft.running
    wait_for(lambda: peer.ff_bytes >= 50 and not peer.streaming.is_set())


def test_damaged_frames_are_skipped_counted_and_never_read(peer: FT300Emulator) -> None:
    seen: list[np.ndarray] = []
    with FT300(peer.port, stale_after=1.0, on_sample=lambda s, t: seen.append(s)) as ft:
        wait_for(lambda: len(seen) >= 5)
        for k in range(3):
            peer.inject_damaged_frame(seq_wrench(1000 + k))
            peer.inject(GARBAGE)
            wait_for_more(seen, 2)
            peer.inject_partial_frame(seq_wrench(2000 + k), 5 + 3 * k)
            wait_for_more(seen, 2)
        wait_for(lambda: peer.injected_bytes == 3 * (16 + 5) + 5 + 8 + 11)
        n_sent = len(sent_seqs(peer))
        wait_for(lambda: len(seen) >= n_sent)
        stats = ft.stats()
    assert stats["crc_errors"] == 6
    # The Modbus response to the start request and every injected byte, nothing else.
    assert stats["skipped_bytes"] == peer.reply_bytes + peer.injected_bytes
    got = [round(s[5] * 1000) for s in seen]
    assert got == sent_seqs(peer)[: len(got)]  # every good frame, in order
    for s in seen:
        np.testing.assert_allclose(s[:5], BASE[:5], atol=1e-9)


def test_bias_averages_recent_samples(peer: FT300Emulator) -> None:
    with FT300(peer.port, stale_after=1.0, bias_samples=10) as ft:
        wait_for(lambda: ft.stats()["frames"] >= 12)
        ft.bias()
        w = ft.wrench()
        np.testing.assert_allclose(w[:5], 0.0, atol=1e-9)
        # Tz counts up by 1 mN*m per frame: the newest sample is a few counts above the mean.
        assert 0.0 < w[5] < 0.05


def test_stale_stream_is_an_error_and_recovers(peer: FT300Emulator) -> None:
    with FT300(peer.port, stale_after=0.05) as ft:
        peer.go_silent()
        time.sleep(0.3)
        with pytest.raises(DeviceError, match=r"stale stream") as err:
            ft.wrench()
        assert err.value.address == peer.port and err.value.device == "FT300"
        with pytest.raises(DeviceError):
            ft.bias()
        assert ft.age() > 0.25
        peer.resume()
        wait_for(lambda: reads(ft))  # fresh again once the stream is back


def test_a_reader_thread_that_does_not_run_does_not_make_the_stream_stale(
        peer: FT300Emulator) -> None:
    # On a loaded machine the reader thread may not get the interpreter for 50 ms while frames
    # wait in the line (seen against `cell emulate`: the guard stopped the cell on a stale
    # sample with frames readable). wrench() must then take what has arrived itself.
    with FT300(peer.port, stale_after=0.05) as ft:
        wait_for(lambda: reads(ft))
        ft._stopping.set()  # noqa: SLF001 -- the reader ends: as if never scheduled again
        assert ft._thread is not None  # noqa: SLF001
        ft._thread.join(timeout=2.0)  # noqa: SLF001
        ft._stopping.clear()  # noqa: SLF001
        before = int(round(ft.wrench()[5] * 1000))
        for _ in range(20):  # 0.4 s: eight times the stale limit
            time.sleep(0.02)
            w = ft.wrench()  # fresh: what the line holds, read by the caller
        assert int(round(w[5] * 1000)) > before + 20  # newer frames, in order


def reads(ft: FT300) -> bool:
    """True when ``wrench()`` returns a value (the stream is fresh) rather than raising."""
    try:
        ft.wrench()
    except DeviceError:
        return False
    return True


def test_wrong_port_names_the_port() -> None:
    port = "/dev/does-not-exist-ft300"
    with pytest.raises(DeviceError, match="cannot open") as err:
        FT300(port, open_attempts=2).start()
    assert err.value.address == port and port in str(err.value)


def test_wrong_unit_id_gets_no_stream(peer: FT300Emulator) -> None:
    ft = FT300(peer.port, unit_id=5, timeout=0.3)
    with pytest.raises(DeviceError, match="no valid stream frame.*unit 5"):
        ft.start()
    assert not ft.running
    assert peer.received == [] and len(peer.ignored) == 1


def test_lost_line_is_an_error(peer: FT300Emulator) -> None:
    ft = FT300(peer.port, stale_after=1.0)
    ft.start()
    try:
        peer.close()  # the pty's device side disappears, like a USB adapter unplugged
        wait_for(lambda: not ft.running, timeout=5.0)
        with pytest.raises(DeviceError, match="serial read failed"):
            ft.wrench()
    finally:
        ft.stop()


def test_check_reports_rate_and_offset(peer: FT300Emulator) -> None:
    ft = FT300(peer.port, stale_after=1.0)
    try:
        result = ft.check(window_s=0.5, min_rate_hz=50.0)
    finally:
        ft.stop()
    assert result.ok, result.error
    assert 60.0 < float(result.details["stream_rate_hz"]) < 130.0
    assert result.details["raw_force_n"] == "+1.00 -2.00 +3.50"


def test_check_fails_cleanly_without_a_sensor(peer: FT300Emulator) -> None:
    peer.go_silent()
    ft = FT300(peer.port, timeout=0.2)
    result = ft.check(window_s=0.1)
    assert not result.ok and "no valid stream frame" in (result.error or "")
    assert not ft.running


def test_rate_and_latency_against_the_peer(peer: FT300Emulator) -> None:
    """Measure what the driver sees: rate over ~1 s and write-to-available latency per frame."""
    arrivals: dict[int, float] = {}
    with FT300(peer.port, stale_after=1.0,
               on_sample=lambda s, t: arrivals.__setitem__(round(s[5] * 1000), t)) as ft:
        time.sleep(1.0)
        stats = ft.stats()
    assert peer.sent is not None
    written = {values[5]: t for values, t in peer.sent}
    lat = np.array([arrivals[s] - written[s] for s in arrivals if s in written])
    assert len(lat) >= 50
    print(f"\nFT300 peer: rate {stats['rate_hz']:.1f} Hz, latency median "
          f"{np.median(lat) * 1e3:.2f} ms, p95 {np.percentile(lat, 95) * 1e3:.2f} ms, "
          f"max {lat.max() * 1e3:.2f} ms over {len(lat)} frames; max gap "
          f"{stats['max_gap_s'] * 1e3:.1f} ms")
    assert 60.0 < stats["rate_hz"] < 130.0
    assert np.median(lat) < 0.05  # generous: typically well under a millisecond
