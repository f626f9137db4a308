"""The adapter's receive side through ur_rtde's real RTDEReceiveInterface, connected to an RTDE
output peer on localhost (protocol version, controller version, output recipe, start, data
packages). The control side cannot be tested this way: it uploads a URScript program that only a
UR controller or URSim runs."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
import pytest

from drivers.ur5.arm import describe_safety_bits, vector_to_pose
from drivers.ur5.rtde_adapter import RECEIVE_VARIABLES, URRTDEAdapter
from tests.drivers.peers.rtde_peer import RTDEPeerProcess

pytest.importorskip("rtde_receive")


@pytest.fixture(scope="module")
def peer():
    try:
        p = RTDEPeerProcess().start()
    except OSError as e:  # port 30004 taken on our loopback address: nothing to test against
        pytest.skip(f"cannot bind the RTDE peer: {e}")
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
def adapter(peer: RTDEPeerProcess):
    a = URRTDEAdapter(peer.host, frequency=125.0)
    a.connect_receive()
    yield a
    a._receive.disconnect()


def test_handshake_and_recipe(peer: RTDEPeerProcess, adapter: URRTDEAdapter) -> None:
    info = peer.info()
    assert info["protocol_versions"] == [2]
    assert info["requested"][0] == RECEIVE_VARIABLES
    assert adapter.receive_connected()


def test_reads_pose_joints_mode_and_safety_bits(peer: RTDEPeerProcess,
                                                adapter: URRTDEAdapter) -> None:
    pose = [0.45, -0.12, 0.31, 0.1, 3.0, -0.2]
    q = [0.1, -1.4, 1.6, -1.7, -1.57, 0.3]
    peer.set_state(actual_TCP_pose=pose, actual_q=q, robot_mode=7, safety_status_bits=1)
    assert wait_for(lambda: adapter.tcp_pose() == pose and adapter.joint_positions() == q)
    assert adapter.robot_mode() == 7 and adapter.safety_status_bits() == 1
    p = vector_to_pose(adapter.tcp_pose())
    assert np.allclose(p.position, pose[:3]) and np.allclose(p.rotvec, pose[3:])
    # A protective stop as the controller reports it.
    peer.set_state(safety_status_bits=1 | 1 << 2, robot_mode=7)
    assert wait_for(lambda: adapter.safety_status_bits() == 5)
    assert describe_safety_bits(adapter.safety_status_bits()) == "normal mode, protective stop"
    peer.set_state(robot_mode=3, safety_status_bits=1)
    assert wait_for(lambda: adapter.robot_mode() == 3)


def test_lost_link_is_seen_and_reconnect_resumes_the_data(peer: RTDEPeerProcess,
                                                          adapter: URRTDEAdapter) -> None:
    peer.drop_clients()
    assert wait_for(lambda: not adapter.receive_connected())
    connections = peer.info()["connections"]
    assert adapter.reconnect_receive()
    assert adapter.receive_connected()
    assert peer.info()["connections"] == connections + 1
    q = [0.2, -1.3, 1.5, -1.6, -1.5, 0.4]
    peer.set_state(actual_q=q)
    assert wait_for(lambda: adapter.joint_positions() == q)


def test_output_the_controller_lacks_names_it(peer: RTDEPeerProcess) -> None:
    import rtde_receive

    with pytest.raises(RuntimeError, match=r"not found by the controller: \[no_such_output\]"):
        rtde_receive.RTDEReceiveInterface(peer.host, 125.0, ["actual_q", "no_such_output"])
