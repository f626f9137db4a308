"""The dashboard client over real TCP against the emulated controller's dashboard server
(sim/emulate/ur_controller.py): a controller just booted, over a still arm
(tests/drivers/peers.py)."""

from __future__ import annotations

import time

import pytest

from drivers.health import DeviceError
from drivers.ur5.dashboard import DashboardClient
from sim.emulate.ur_controller import DashboardServer
from tests.addresses import free_port
from tests.drivers.peers import dashboard_peer, protective_stop


@pytest.fixture
def peer():
    with dashboard_peer() as p:
        yield p


def client(peer: DashboardServer, timeout: float = 1.0) -> DashboardClient:
    return DashboardClient(peer.host, peer.port, timeout=timeout, connect_attempts=1)


def test_every_command_round_trips(peer: DashboardServer) -> None:
    protective_stop(peer)
    with client(peer) as dash:
        assert dash.robot_mode() == "POWER_OFF"
        dash.power_on()
        assert dash.robot_mode() == "IDLE"
        dash.brake_release()
        assert dash.robot_mode() == "RUNNING"
        assert dash.safety_status() == "PROTECTIVE_STOP"
        dash.close_safety_popup()
        dash.unlock_protective_stop()
        assert dash.safety_status() == "NORMAL"
        dash.close_popup()
        assert dash.polyscope_version() == "URSoftware 3.15.7.106331 (Jun 08 2021)"
        assert dash.serial_number() == "2018300123"
        assert dash.robot_model() == "UR5"
        dash.power_off()
        assert dash.robot_mode() == "POWER_OFF"
    assert peer.received == [
        "robotmode", "power on", "robotmode", "brake release", "robotmode", "safetystatus",
        "close safety popup", "unlock protective stop", "safetystatus", "close popup",
        "PolyscopeVersion", "get serial number", "get robot model", "power off", "robotmode",
    ]


def test_old_controller_falls_back_to_safetymode() -> None:
    with dashboard_peer(version=(3, 10, 0, 0)) as peer:  # safetystatus came with 3.11
        with client(peer) as dash:
            assert dash.safety_status() == "NORMAL"
        assert peer.received == ["safetystatus", "safetymode"]


def test_unexpected_reply_is_an_error_naming_address_and_reply(peer: DashboardServer) -> None:
    peer.replies["power on"] = "Not in remote control"
    with client(peer) as dash, pytest.raises(DeviceError) as err:
        dash.power_on()
    e = err.value
    assert e.device == "UR5 dashboard"
    assert e.address == f"127.0.0.1:{peer.port}"
    assert "Not in remote control" in e.cause and "'power on'" in e.cause


def test_refused_unlock_carries_the_controller_reason() -> None:
    with dashboard_peer(unlock_delay=5.0) as peer:
        protective_stop(peer)  # a real controller refuses the unlock for 5 s
        with client(peer) as dash, pytest.raises(DeviceError,
                                                 match="until 5s after occurrence"):
            dash.unlock_protective_stop()


def test_unknown_command_reply(peer: DashboardServer) -> None:
    peer.replies["get serial number"] = "could not understand: 'get serial number'"
    with client(peer) as dash, pytest.raises(DeviceError, match="could not understand"):
        dash.serial_number()
    with client(peer) as dash:
        assert dash.command("no such command") == "could not understand: 'no such command'"


def test_peer_that_never_answers_times_out_naming_the_address(peer: DashboardServer) -> None:
    peer.silent = True
    dash = client(peer, timeout=0.2)
    t0 = time.monotonic()
    with pytest.raises(DeviceError) as err:
        dash.robot_mode()
    assert time.monotonic() - t0 < 1.0
    assert err.value.address == f"127.0.0.1:{peer.port}"
    assert "no reply to 'robotmode' within 0.2 s" in err.value.cause
    assert str(err.value).startswith(f"UR5 dashboard at 127.0.0.1:{peer.port}: ")


def test_no_greeting_times_out(peer: DashboardServer) -> None:
    peer.no_greeting = True
    with pytest.raises(DeviceError, match="no reply to the greeting within 0.2 s"):
        client(peer, timeout=0.2).connect()


def test_refused_connection_bounded_retries_with_backoff() -> None:
    port = free_port()
    waits: list[float] = []
    dash = DashboardClient("127.0.0.1", port, timeout=0.5, connect_attempts=3, sleep=waits.append)
    with pytest.raises(DeviceError) as err:
        dash.robot_mode()
    assert err.value.address == f"127.0.0.1:{port}"
    assert "cannot connect after 3 attempt(s)" in err.value.cause
    assert "ConnectionRefusedError" in err.value.cause
    assert waits == [0.1, 0.2]  # drivers.health.backoff_delays(3): two waits between 3 tries


def test_wrong_greeting_is_not_a_ur_controller(peer: DashboardServer) -> None:
    import drivers.ur5.dashboard as d

    dash = client(peer)
    original = d.GREETING
    try:
        d.GREETING = "Something else"
        with pytest.raises(DeviceError, match="unexpected greeting"):
            dash.connect()
    finally:
        d.GREETING = original


def test_connection_closed_by_peer(peer: DashboardServer) -> None:
    with client(peer) as dash:
        assert dash.command("quit") == "Disconnected"
        with pytest.raises(DeviceError, match="connection closed by the controller"):
            dash.robot_mode()
        # The client reconnects on the next command.
        assert dash.robot_mode() == "POWER_OFF"
