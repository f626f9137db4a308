"""The adapter's receive side through ur_rtde's real RTDEReceiveInterface, connected to the
emulated controller's RTDE server on a loopback address of this process's own (protocol
version, controller version, output recipe, start, data packages), over a still arm in a child
process (sim/emulate/ur_standalone.py). The control side against the emulator, with the twin's
arm: test_arm_emulated.py."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
import pytest

from drivers.ur5.arm import describe_safety_bits, vector_to_pose
from drivers.ur5.rtde_adapter import RECEIVE_VARIABLES, URRTDEAdapter
from sim.emulate.ur_standalone import URAloneProcess

pytest.importorskip("rtde_receive")


@pytest.fixture(scope="module")
def peer():
    try:  # a running controller (RUNNING, no protective stop) whose stop unlocks at once
        p = URAloneProcess(arm="still", unlock_delay=0.0).start()
    except TimeoutError:  # an emulator that never answers is a failure, not a skip
        raise
    except OSError as e:  # ports taken on our loopback address: nothing to test against
        pytest.skip(f"cannot bind the UR emulator: {e}")
    yield p
    p.stop()


def wait_for(check: Callable[[], bool], timeout: float = 1.0) -> bool:
    """Poll until the receive thread has taken in a new package (8 ms apart at 125 Hz)."""
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        if check():
            return True
        time.sleep(0.005)
    return False


@pytest.fixture(scope="module")
def adapter(peer: URAloneProcess):
    a = URRTDEAdapter(peer.host, frequency=125.0)
    a.connect_receive()
    yield a
    a._receive.disconnect()


def test_handshake_and_recipe(peer: URAloneProcess, adapter: URRTDEAdapter) -> None:
    info = peer.rtde_log()
    assert info["protocol_versions"] == [2]
    assert info["recipes"][0] == RECEIVE_VARIABLES
    assert adapter.receive_connected()


def test_reads_pose_joints_mode_and_safety_bits(peer: URAloneProcess,
                                                adapter: URRTDEAdapter) -> None:
    pose = [0.45, -0.12, 0.31, 0.1, 3.0, -0.2]
    q = [0.1, -1.4, 1.6, -1.7, -1.57, 0.3]
    peer.place(q=q, tcp=pose)
    assert wait_for(lambda: adapter.tcp_pose() == pose and adapter.joint_positions() == q)
    assert adapter.robot_mode() == 7 and adapter.safety_status_bits() == 1
    p = vector_to_pose(adapter.tcp_pose())
    assert np.allclose(p.position, pose[:3]) and np.allclose(p.rotvec, pose[3:])
    # A protective stop as the controller reports it.
    peer.protective_stop()
    assert wait_for(lambda: adapter.safety_status_bits() == 5)
    assert adapter.robot_mode() == 7
    assert describe_safety_bits(adapter.safety_status_bits()) == "normal mode, protective stop"
    # Unlocked, then powered off (robot mode 3, POWER_OFF).
    assert peer.dashboard("unlock protective stop") == "Protective stop releasing"
    assert peer.dashboard("power off") == "Powering off"
    assert wait_for(lambda: adapter.robot_mode() == 3)
    assert adapter.safety_status_bits() == 1


def test_lost_link_is_seen_and_reconnect_resumes_the_data(peer: URAloneProcess,
                                                          adapter: URRTDEAdapter) -> None:
    peer.drop_rtde_clients()
    assert wait_for(lambda: not adapter.receive_connected())
    connections = peer.rtde_log()["connections"]
    assert adapter.reconnect_receive()
    assert adapter.receive_connected()
    assert peer.rtde_log()["connections"] == connections + 1
    q = [0.2, -1.3, 1.5, -1.6, -1.5, 0.4]
    peer.place(q=q)
    assert wait_for(lambda: adapter.joint_positions() == q)


def test_output_the_controller_lacks_names_it(peer: URAloneProcess) -> None:
    import rtde_receive

    with pytest.raises(RuntimeError, match=r"not found by the controller: \[no_such_output\]"):
        rtde_receive.RTDEReceiveInterface(peer.host, 125.0, ["actual_q", "no_such_output"])
