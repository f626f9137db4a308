"""UR5Arm's start-up check and protective-stop recovery: the dashboard side over real TCP
against the emulated controller's dashboard server, the RTDE side through the recording double."""

from __future__ import annotations

import pytest

from drivers.arm import MotionState
from drivers.health import DeviceError
from drivers.ur5.arm import UR5Arm
from drivers.ur5.dashboard import DashboardClient
from sim.emulate.ur_controller import DashboardServer
from tests.drivers.peers import dashboard_peer, protective_stop
from tests.drivers.ur5.recording_adapter import FakeClock, RecordingAdapter


@pytest.fixture
def peer():
    with dashboard_peer(robot_mode="RUNNING") as p:
        yield p


def make(peer: DashboardServer) -> tuple[UR5Arm, RecordingAdapter]:
    rtde = RecordingAdapter()
    dash = DashboardClient(peer.host, peer.port, timeout=0.5, connect_attempts=1)
    return UR5Arm(rtde, FakeClock(), dashboard=dash, spawn=lambda f: f()), rtde


def test_check_reports_version_serial_and_both_views_of_the_state(peer: DashboardServer
                                                                  ) -> None:
    arm, rtde = make(peer)
    res = arm.check()
    assert res.ok, res.error
    d = res.details
    assert d["controller_version"] == "URSoftware 3.15.7.106331 (Jun 08 2021)"
    assert d["serial_number"] == "2018300123"
    assert d["robot_model"] == "UR5"
    assert d["dashboard_robot_mode"] == "RUNNING" and d["robot_mode"] == "RUNNING"
    assert d["dashboard_safety_status"] == "NORMAL" and d["control_script"] == "running"
    assert rtde.names() == []  # the check never moves the arm
    assert "power on" not in peer.received and "brake release" not in peer.received


def test_check_fails_with_the_dashboard_reason(peer: DashboardServer) -> None:
    arm, _ = make(peer)
    peer.replies["polyscopeversion"] = "could not understand: 'PolyscopeVersion'"
    res = arm.check()
    assert not res.ok and "could not understand" in (res.error or "")
    assert f"UR5 dashboard at 127.0.0.1:{peer.port}" in (res.error or "")
    assert res.details["controller_version"] == "unavailable"


def test_check_passes_without_serial_on_older_software(peer: DashboardServer) -> None:
    arm, _ = make(peer)
    peer.replies["get serial number"] = "could not understand: 'get serial number'"
    res = arm.check()
    assert res.ok and res.details["serial_number"] == "unavailable"


def test_check_fails_when_the_dashboard_does_not_answer(peer: DashboardServer) -> None:
    arm, _ = make(peer)
    peer.stop()
    res = arm.check()
    assert not res.ok and "cannot connect" in (res.error or "")


def test_recover_unlocks_the_protective_stop_and_restarts_the_script(peer: DashboardServer
                                                                    ) -> None:
    arm, rtde = make(peer)
    protective_stop(peer)
    rtde.safety_bits, rtde.program_running = 1 | 1 << 2, False
    assert arm.status().protective_stop
    rtde.safety_bits = 1  # what the controller does on the unlock
    arm.recover()
    assert peer.received[-2:] == ["close safety popup", "unlock protective stop"]
    assert rtde.names() == ["reupload_script"]
    assert arm.status().state is MotionState.IDLE


def test_recover_refused_within_five_seconds() -> None:
    with dashboard_peer(robot_mode="RUNNING", unlock_delay=5.0) as peer:
        arm, rtde = make(peer)
        protective_stop(peer)
        with pytest.raises(DeviceError, match="until 5s after occurrence"):
            arm.recover()
    assert "reupload_script" not in rtde.names()
