"""UR5Arm's logic tick by tick against the recording double of the ur_rtde adapter.

These tests check what the driver sends and how it reads the controller's state; they cannot
check that a UR controller answers as the double is scripted to (that needs URSim or the cell).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from drivers.arm import Arm, MotionState
from drivers.health import DeviceError
from drivers.pose import Pose, rot_x, rot_y
from drivers.ur5.arm import (
    BLEND_FRACTION,
    UR5Arm,
    UR5Settings,
    describe_safety_bits,
    pose_to_vector,
    vector_to_pose,
)
from tests.drivers.ur5.recording_adapter import FakeClock, RecordingAdapter

NORMAL = 1
PROTECTIVE = 1 << 2
EMERGENCY = 1 << 7


def make(settings: UR5Settings | None = None) -> tuple[UR5Arm, RecordingAdapter, FakeClock]:
    rtde, clock = RecordingAdapter(), FakeClock()
    arm = UR5Arm(rtde, clock, settings, spawn=lambda f: f())
    return arm, rtde, clock


def goal_at(rtde: RecordingAdapter) -> Pose:
    return vector_to_pose(rtde.pose)


def test_implements_the_arm_protocol() -> None:
    arm, _, _ = make()
    assert isinstance(arm, Arm)
    assert arm.status().state is MotionState.IDLE


# --- asynchronous moves --------------------------------------------------------------------

def test_move_to_runs_moving_then_done() -> None:
    arm, rtde, _ = make()
    goal = goal_at(rtde)
    rtde.op = (False, 4)
    arm.move_to(goal, 0.1, 0.5)
    (pose, speed, acc), = rtde.args("move_l")
    assert np.allclose(pose, pose_to_vector(goal)) and (speed, acc) == (0.1, 0.5)
    assert arm.status().state is MotionState.MOVING
    for _ in range(3):  # running: operation 5, ours
        rtde.op = (True, 5)
        assert arm.status().state is MotionState.MOVING
    rtde.op = (False, 5)  # ours finished
    assert arm.status().state is MotionState.DONE
    assert arm.status().state is MotionState.DONE  # stays DONE, no more status reads needed
    assert rtde.names() == ["move_l"]


def test_move_too_short_to_be_seen_running_is_done_by_its_operation_id() -> None:
    arm, rtde, _ = make()
    rtde.op = (False, 7)
    arm.move_to(goal_at(rtde), 0.1, 0.5)
    rtde.op = (False, 8)  # started and ended between two ticks: a new id, not running
    assert arm.status().state is MotionState.DONE


def test_move_not_yet_started_stays_moving() -> None:
    arm, rtde, _ = make()
    rtde.op = (False, 3)
    arm.move_to(goal_at(rtde), 0.1, 0.5)
    for _ in range(5):  # the operation current before the command: ours has not started
        assert arm.status().state is MotionState.MOVING
    rtde.op_script = [(True, 4), (False, 4)]
    assert arm.status().state is MotionState.MOVING
    assert arm.status().state is MotionState.DONE


def test_replacing_a_running_move_needs_no_finished_value_in_between() -> None:
    arm, rtde, _ = make()
    rtde.op = (True, 9)  # an earlier async move still runs
    arm.move_to(goal_at(rtde), 0.1, 0.5)
    rtde.op = (True, 10)  # the script cancelled 9 and started ours in one cycle
    for _ in range(5):
        assert arm.status().state is MotionState.MOVING
    rtde.op = (False, 10)
    assert arm.status().state is MotionState.DONE


def test_operation_ids_wrap_after_127() -> None:
    arm, rtde, _ = make()
    rtde.op = (False, 127)
    arm.move_to(goal_at(rtde), 0.1, 0.5)
    rtde.op_script = [(True, 0), (False, 0)]
    assert arm.status().state is MotionState.MOVING
    assert arm.status().state is MotionState.DONE


def test_a_move_right_after_an_async_stop_waits_for_the_stop_to_end() -> None:
    arm, rtde, _ = make()
    rtde.op = (False, 1)
    arm.move_to(goal_at(rtde), 0.1, 0.5)
    rtde.op = (True, 2)
    assert arm.status().state is MotionState.MOVING
    arm.stop()
    rtde.op = (True, 3)  # the stop's own operation
    arm.move_to(goal_at(rtde), 0.1, 0.5)
    assert rtde.names() == ["move_l", "stop_l"]  # held back
    assert arm.status().state is MotionState.MOVING
    rtde.op = (False, 3)  # the stop ended: ours is sent now
    assert arm.status().state is MotionState.MOVING
    assert rtde.names() == ["move_l", "stop_l", "move_l"]
    rtde.op_script = [(True, 4), (False, 4)]
    assert arm.status().state is MotionState.MOVING
    assert arm.status().state is MotionState.DONE


def test_move_that_ends_away_from_its_goal_is_a_fault() -> None:
    arm, rtde, _ = make()
    goal = Pose(goal_at(rtde).position + [0.01, 0.0, 0.0], goal_at(rtde).rotation)
    rtde.op = (False, 0)
    arm.move_to(goal, 0.1, 0.5)
    rtde.op_script = [(True, 1), (False, 1)]
    arm.status()
    st = arm.status()
    assert st.state is MotionState.FAULT and "10.0 mm" in st.message


def test_move_rejected_by_the_controller_is_a_fault() -> None:
    arm, rtde, _ = make()
    rtde.accept = False
    arm.move_to(goal_at(rtde), 0.1, 0.5)
    st = arm.status()
    assert st.state is MotionState.FAULT and "moveL rejected" in st.message


def test_bad_speed_raises_before_anything_is_sent() -> None:
    arm, rtde, _ = make()
    with pytest.raises(ValueError):
        arm.move_to(goal_at(rtde), 0.0, 0.5)
    assert rtde.names() == []


def test_move_path_is_one_blended_movel_ending_on_the_last_waypoint() -> None:
    arm, rtde, _ = make(UR5Settings(path_blend=0.02))
    start = goal_at(rtde)
    w1 = Pose(start.position + [0.0, 0.0, 0.10], start.rotation)
    w2 = Pose(start.position + [0.10, 0.0, 0.10], start.rotation)
    w3 = Pose(start.position + [0.10, 0.03, 0.10], start.rotation)  # short segment: 3 cm
    w4 = Pose(start.position + [0.10, 0.23, 0.10], start.rotation @ rot_x(0.3))
    rtde.op = (False, 6)  # the old script's last operation
    arm.move_path([w1, w2, w3, w4], 0.2, 1.0)
    (rows,), = rtde.args("move_l_path")
    assert len(rows) == 4 and all(len(r) == 9 for r in rows)
    for row, w in zip(rows, [w1, w2, w3, w4], strict=True):
        assert np.allclose(row[:6], pose_to_vector(w))
        assert row[6:8] == [0.2, 1.0]
    blends = [r[8] for r in rows]
    assert blends[0] == pytest.approx(0.02)  # neighbours 10 cm and 10 cm: the setting
    assert blends[1] == pytest.approx(BLEND_FRACTION * 0.03)  # capped by the 3 cm segment
    assert blends[2] == pytest.approx(BLEND_FRACTION * 0.03)
    assert blends[3] == 0.0  # ends on the last waypoint
    rtde.pose = pose_to_vector(w4)
    # ur_rtde re-uploaded its script for the path: ids count from 0 again, and the injected
    # signal_async_progress(0) makes the path operation 2.
    rtde.op_script = [(True, 2), (False, 2)]
    assert arm.status().state is MotionState.MOVING
    assert arm.status().state is MotionState.DONE


def test_move_joints_is_an_async_movej_done_at_the_goal() -> None:
    arm, rtde, _ = make()
    q = [0.1, -1.5, 1.5, -1.6, -1.57, 0.2]
    rtde.op = (False, 0)
    arm.move_joints(q, 1.0, 2.0)
    assert rtde.args("move_j") == [(q, 1.0, 2.0)]
    rtde.op = (True, 1)
    assert arm.status().state is MotionState.MOVING
    rtde.q = q
    rtde.op = (False, 1)
    assert arm.status().state is MotionState.DONE


# --- stop ----------------------------------------------------------------------------------

@pytest.mark.parametrize(
    ("start", "expected"),
    [
        ("move", ("stop_l", (10.0,))),
        ("joints", ("stop_l", (10.0,))),  # every async stop is a stopl in the script
        ("servo", ("servo_stop", (10.0,))),
        ("force", ("force_mode_stop", ())),
    ],
)
def test_stop_is_idempotent_and_matches_the_mode(start: str, expected: tuple) -> None:
    arm, rtde, _ = make()
    goal = goal_at(rtde)
    {
        "move": lambda: arm.move_to(goal, 0.1, 0.5),
        "joints": lambda: arm.move_joints(rtde.q, 1.0, 1.0),
        "servo": lambda: arm.servo(goal),
        "force": lambda: arm.force_mode([False] * 6, [0.0] * 6, [0.1] * 6),
    }[start]()
    commands = len(rtde.names())
    arm.stop()
    assert rtde.calls[-1] == expected
    assert arm.status().state is MotionState.STOPPED
    arm.stop()
    arm.stop()
    assert len(rtde.names()) == commands + 1  # the later stops sent nothing
    assert arm.status().state is MotionState.STOPPED


def test_stop_when_idle_or_done_sends_nothing_and_keeps_the_state() -> None:
    arm, rtde, _ = make()
    arm.stop()
    assert rtde.names() == [] and arm.status().state is MotionState.IDLE
    rtde.op = (False, 0)
    arm.move_to(goal_at(rtde), 0.1, 0.5)
    rtde.op = (False, 1)
    assert arm.status().state is MotionState.DONE
    arm.stop()
    assert rtde.names() == ["move_l"] and arm.status().state is MotionState.DONE


def test_stop_never_raises_on_a_dead_link() -> None:
    arm, rtde, _ = make()
    arm.servo(goal_at(rtde))
    rtde.raise_on["servo_stop"] = RuntimeError("RTDE socket closed")
    rtde.reconnect_results = [False]
    arm.stop()
    st = arm.status()
    assert st.state is MotionState.FAULT and "RTDE socket closed" in st.message


# --- safety --------------------------------------------------------------------------------

def test_protective_stop_is_a_fault_with_the_flag_latched_until_the_next_command() -> None:
    arm, rtde, _ = make()
    rtde.op = (False, 0)
    arm.move_to(goal_at(rtde), 0.1, 0.5)
    rtde.op = (True, 1)
    assert arm.status().state is MotionState.MOVING
    rtde.safety_bits = NORMAL | PROTECTIVE
    rtde.program_running = False  # the control script ends with the stop
    st = arm.status()
    assert st.state is MotionState.FAULT and st.protective_stop
    assert "protective stop" in st.message
    # A command while the stop is active is refused without sending anything.
    arm.move_to(goal_at(rtde), 0.1, 0.5)
    assert rtde.names() == ["move_l"]
    st = arm.status()
    assert st.state is MotionState.FAULT and st.protective_stop
    # Unlocked (and the script back): the fault stays latched until the next command.
    rtde.safety_bits, rtde.program_running, rtde.op = NORMAL, True, (False, 1)
    st = arm.status()
    assert st.state is MotionState.FAULT and st.protective_stop
    arm.move_to(goal_at(rtde), 0.1, 0.5)
    st = arm.status()
    assert st.state is MotionState.MOVING and not st.protective_stop


@pytest.mark.parametrize(
    ("bits", "mode", "running", "words"),
    [
        (NORMAL | EMERGENCY, 7, True, "emergency stop"),
        (NORMAL | 1 << 6, 7, True, "robot emergency stop"),
        (NORMAL | 1 << 4, 7, True, "safeguard stop"),
        (NORMAL | 1 << 8, 7, True, "safety violation"),
        (NORMAL, 3, True, "robot mode POWER_OFF"),
        (NORMAL, 5, True, "robot mode IDLE"),
        (NORMAL, 7, False, "control script is not running"),
    ],
)
def test_other_stops_are_faults_without_the_protective_flag(
    bits: int, mode: int, running: bool, words: str
) -> None:
    arm, rtde, _ = make()
    arm.servo(goal_at(rtde))
    rtde.safety_bits, rtde.mode, rtde.program_running = bits, mode, running
    st = arm.status()
    assert st.state is MotionState.FAULT and not st.protective_stop
    assert words in st.message


# --- lost link and reconnect ---------------------------------------------------------------

def test_lost_link_is_a_fault_with_bounded_reconnects_and_backoff() -> None:
    arm, rtde, clock = make(UR5Settings(reconnect_attempts=4, reconnect_first_delay=0.5))
    rtde.op = (False, 0)
    arm.move_to(goal_at(rtde), 0.1, 0.5)
    rtde.connected = False
    st = arm.status()
    assert st.state is MotionState.FAULT and not st.protective_stop
    assert "lost connection to the controller at 10.0.0.2:30004" in st.message
    assert rtde.names().count("reconnect") == 1  # the first attempt at once
    attempt_times = [clock.t]
    # 125 Hz ticks for 10 s: attempts only when the back-off has passed, at most 4 in all.
    for _ in range(1250):
        clock.t += 0.008
        before = rtde.names().count("reconnect")
        st = arm.status()
        assert st.state is MotionState.FAULT
        if rtde.names().count("reconnect") > before:
            attempt_times.append(clock.t)
    gaps = np.diff(attempt_times)
    assert len(attempt_times) == 4
    assert np.allclose(gaps, [0.5, 1.0, 2.0], atol=0.01)
    assert "gave up after 4 reconnect attempts" in st.message
    # Reading the pose without a link is an error, not a stale value.
    with pytest.raises(DeviceError, match="10.0.0.2:30004"):
        arm.tool_pose()
    # An operator grants a fresh budget; this attempt succeeds.
    rtde.reconnect_results = [True]
    arm.reconnect()
    st = arm.status()
    assert st.state is MotionState.FAULT and "reconnected, the motion was dropped" in st.message
    assert rtde.names().count("reconnect") == 5
    rtde.op = (False, 0)
    arm.move_to(goal_at(rtde), 0.1, 0.5)
    assert arm.status().state is MotionState.MOVING


def test_close_abandons_a_lost_link_and_starts_no_further_attempt() -> None:
    arm, rtde, clock = make(UR5Settings(reconnect_attempts=4, reconnect_first_delay=0.5))
    arm.move_to(goal_at(rtde), 0.1, 0.5)
    rtde.connected = False
    assert arm.status().state is MotionState.FAULT
    arm.close()
    # ur_rtde's disconnect on a dead link blocks for seconds: the link is given up instead.
    assert "abandon" in rtde.names() and "disconnect" not in rtde.names()
    attempts = rtde.names().count("reconnect")
    for _ in range(500):
        clock.t += 0.008
        arm.status()
    assert rtde.names().count("reconnect") == attempts


def test_close_disconnects_a_link_lost_to_stale_data_whose_socket_is_still_up() -> None:
    # Only disconnect() stops the control script (and so a running move) once this process
    # ends: a link declared lost while ur_rtde still holds it open is not abandoned.
    arm, rtde, clock = make(UR5Settings(data_timeout=0.5, reconnect_attempts=1))
    rtde.op = (False, 0)
    arm.move_to(goal_at(rtde), 0.1, 0.5)
    rtde.data_frozen = True
    rtde.reconnect_results = [RuntimeError("timed out")]  # the socket stays as it was
    for _ in range(70):
        clock.t += 0.008
        st = arm.status()
    assert st.state is MotionState.FAULT and st.link_lost
    arm.close()
    assert "disconnect" in rtde.names() and "abandon" not in rtde.names()


def test_close_waits_a_moment_for_the_control_side_to_see_the_drop_then_abandons() -> None:
    # Two sockets: the receive side saw the cable go, the control side notices a little later.
    arm, rtde, _ = make(UR5Settings(reconnect_attempts=1))
    arm.move_to(goal_at(rtde), 0.1, 0.5)
    rtde.connected = False
    assert arm.status().link_lost
    answers = iter([True, True, True])
    rtde.control_connected = lambda: next(answers, False)  # type: ignore[method-assign]
    arm.close()
    assert "abandon" in rtde.names() and "disconnect" not in rtde.names()


def test_close_disconnects_a_live_link() -> None:
    arm, rtde, _ = make()
    arm.close()
    assert "disconnect" in rtde.names() and "abandon" not in rtde.names()


def test_reconnect_that_raises_counts_as_a_failed_attempt() -> None:
    arm, rtde, clock = make(UR5Settings(reconnect_attempts=2))
    rtde.reconnect_results = [RuntimeError("timed out connecting"), True]
    rtde.connected = False
    st = arm.status()
    assert "timed out connecting" in st.message and "attempt 2/2" in st.message
    clock.t += 0.5
    arm.status()
    assert arm.status().state is MotionState.FAULT  # latched until a new command
    assert rtde.names().count("reconnect") == 2
    assert np.allclose(arm.tool_pose().position, rtde.pose[:3])


def test_an_exception_from_a_read_is_a_lost_link() -> None:
    arm, rtde, _ = make()
    rtde.raise_on["safety_status_bits"] = RuntimeError("RTDE receive: connection reset")
    st = arm.status()
    assert st.state is MotionState.FAULT and "connection reset" in st.message
    assert st.link_lost


def test_commands_during_a_lost_link_are_refused_without_traffic() -> None:
    arm, rtde, _ = make(UR5Settings(reconnect_attempts=1))
    rtde.connected = False
    arm.status()
    n = len(rtde.calls)
    arm.move_to(goal_at(rtde), 0.1, 0.5)
    arm.servo(goal_at(rtde))
    arm.stop()
    assert [c for c, _ in rtde.calls[n:]] == []
    st = arm.status()
    assert st.state is MotionState.FAULT and "lost connection" in st.message
    assert st.link_lost and not st.protective_stop  # the cell decides on the flag, not the text


# --- servo and force mode ------------------------------------------------------------------

def test_servo_streams_one_servol_per_tick_at_the_control_rate() -> None:
    arm, rtde, _ = make(UR5Settings(frequency=125.0, servo_lookahead=0.05, servo_gain=500))
    start = goal_at(rtde)
    targets = [Pose(start.position + [0.0005 * i, 0, 0], start.rotation) for i in range(10)]
    for t in targets:
        arm.servo(t)
        assert arm.status().state is MotionState.MOVING
    sent = rtde.args("servo_l")
    assert len(sent) == 10
    for (pose, dt, lookahead, gain), t in zip(sent, targets, strict=True):
        assert np.allclose(pose, pose_to_vector(t))
        assert (dt, lookahead, gain) == (pytest.approx(0.008), 0.05, 500)
    assert arm.last_servo_target is targets[-1]
    assert "async_status" not in rtde.names(include_reads=True)  # servo has no progress


def test_leaving_servo_for_a_move_stops_servoing_first() -> None:
    arm, rtde, _ = make()
    arm.servo(goal_at(rtde))
    arm.move_to(goal_at(rtde), 0.1, 0.5)
    assert rtde.names() == ["servo_l", "servo_stop", "move_l"]


def test_force_mode_maps_selection_wrench_and_limits_in_the_base_frame() -> None:
    settings = UR5Settings(force_deviation=(0.01, 0.02, 0.03, 0.1, 0.2, 0.3))
    arm, rtde, _ = make(settings)
    arm.force_mode(
        [True, False, True, False, False, True],
        [5.0, 0.0, -10.0, 0.0, 0.0, 0.5],
        [0.02, 0.5, -0.01, 1.0, 1.0, 0.2],
    )
    (frame, sel, wrench, kind, limits), = rtde.args("force_mode")
    assert frame == [0.0] * 6 and kind == 2  # task frame = base, not transformed
    assert sel == [1, 0, 1, 0, 0, 1]
    assert wrench == [5.0, 0.0, -10.0, 0.0, 0.0, 0.5]
    # Compliant axes: the speed limits (magnitudes); the others: the allowed deviation.
    assert limits == [0.02, 0.02, 0.01, 0.1, 0.2, 0.2]
    assert arm.status().state is MotionState.MOVING
    with pytest.raises(ValueError):
        arm.force_mode([True] * 5, [0.0] * 6, [0.1] * 6)


def test_force_mode_during_a_move_stops_the_move_first() -> None:
    arm, rtde, _ = make()
    rtde.op = (False, 0)
    arm.move_to(goal_at(rtde), 0.1, 0.5)
    arm.force_mode([False, False, True, False, False, False], [0, 0, -5, 0, 0, 0], [0.01] * 6)
    assert rtde.names() == ["move_l", "stop_l", "force_mode"]
    arm.move_to(goal_at(rtde), 0.1, 0.5)
    assert rtde.names()[-2:] == ["force_mode_stop", "move_l"]


def test_watchdog_is_armed_when_started_and_kicked_as_often_as_it_needs() -> None:
    from drivers.ur5.arm import KICK_SHARE

    arm, rtde, clock = make(UR5Settings(watchdog_hz=5.0))
    arm.status()  # the start-up: connected and polled, not armed yet
    assert "set_watchdog" not in rtde.names() and "kick_watchdog" not in rtde.names()
    arm.start_watchdog()
    arm.start_watchdog()  # once
    assert rtde.args("set_watchdog") == [(5.0,)]
    share = KICK_SHARE / 5.0  # s between kicks
    arm.status()
    assert rtde.names().count("kick_watchdog") == 1
    for _ in range(3):  # polls within the share of the period: no more kicks
        clock.t += 0.3 * share
        arm.status()
    assert rtde.names().count("kick_watchdog") == 1
    clock.t += 0.2 * share
    arm.status()
    assert rtde.names().count("kick_watchdog") == 2
    # No kick until the controller has run three cycles since a command (its timestamp; the
    # recording controller's advances a cycle a read): it would overwrite the command's
    # register before the script read it (the command refreshes the watchdog itself), and the
    # next one a share of the period after the command.
    arm.force_mode([False, False, True, False, False, False], [0, 0, -5.0, 0, 0, 0],
                   [0, 0, 0.02, 0, 0, 0])
    kicks = rtde.names().count("kick_watchdog")
    clock.t += 2.0 / arm.settings.frequency
    arm.status()  # one controller cycle on
    assert rtde.names().count("kick_watchdog") == kicks
    clock.t += share
    arm.status()  # two
    assert rtde.names().count("kick_watchdog") == kicks
    arm.status()  # three
    assert rtde.names().count("kick_watchdog") == kicks + 1
    arm2, rtde2, _ = make()
    arm2.start_watchdog()
    arm2.status()
    assert "kick_watchdog" not in rtde2.names() and "set_watchdog" not in rtde2.names()


def test_no_kick_while_a_late_controller_has_not_read_the_command() -> None:
    """A controller running late (its timestamp not moving: the emulator on a loaded machine)
    has not read a force mode yet; a kick then would overwrite it however much wall-clock time
    passed. Once its cycles run on, the kick comes."""
    arm, rtde, clock = make(UR5Settings(watchdog_hz=10.0))
    arm.start_watchdog()
    arm.status()
    arm.force_mode([False, False, True, False, False, False], [0, 0, -5.0, 0, 0, 0],
                   [0, 0, 0.02, 0, 0, 0])
    kicks = rtde.names().count("kick_watchdog")
    rtde.data_frozen = True
    for _ in range(8):  # 80 ms of ticks, under the 0.5 s the data may stay stale
        clock.t += 0.01
        arm.status()
    assert rtde.names().count("kick_watchdog") == kicks
    rtde.data_frozen = False
    for _ in range(3):
        clock.t += 0.008
        arm.status()
    assert rtde.names().count("kick_watchdog") == kicks + 1


# --- conversions, settings, check ----------------------------------------------------------

def test_rotation_vector_round_trip() -> None:
    rng = np.random.default_rng(7)
    for _ in range(200):
        rv = Rotation.random(random_state=rng).as_rotvec()
        v = [*rng.uniform(-0.8, 0.8, 3), *rv]
        pose = vector_to_pose(v)
        back = pose_to_vector(pose)
        assert np.allclose(back, v, atol=1e-9)
        assert vector_to_pose(back).distance(pose)[1] < 1e-9


def test_rotation_vector_meaning() -> None:
    # UR's tool-down pose: rotation vector (0, pi, 0) is a half turn about the base y axis.
    pose = vector_to_pose([0.4, 0.1, 0.3, 0.0, np.pi, 0.0])
    assert np.allclose(pose.rotation, rot_y(np.pi))
    assert np.allclose(pose.rotation[:, 2], [0, 0, -1])  # tool z points down
    assert np.allclose(pose.position, [0.4, 0.1, 0.3])
    assert np.allclose(pose_to_vector(Pose([0, 0, 0], rot_x(np.pi / 2)))[3:], [np.pi / 2, 0, 0])
    with pytest.raises(ValueError):
        vector_to_pose([0.0] * 5)


def test_tool_pose_and_joints_read_the_receive_side() -> None:
    arm, rtde, _ = make()
    assert np.allclose(pose_to_vector(arm.tool_pose()), rtde.pose, atol=1e-9)
    assert np.allclose(arm.joint_positions(), rtde.q) and arm.joint_positions().shape == (6,)


def test_settings_reject_values_outside_urs_ranges() -> None:
    with pytest.raises(ValueError, match="servo_lookahead"):
        UR5Settings(servo_lookahead=0.5)
    with pytest.raises(ValueError, match="servo_gain"):
        UR5Settings(servo_gain=50)
    with pytest.raises(ValueError, match="frequency"):
        UR5Settings(frequency=0)


def test_check_reports_mode_safety_and_script_without_moving() -> None:
    arm, rtde, _ = make()
    res = arm.check()
    assert res.ok and res.error is None
    assert res.device == "UR5" and res.address == "10.0.0.2:30004"
    assert res.details["robot_mode"] == "RUNNING"
    assert res.details["safety_status"] == "normal mode"
    assert res.details["control_script"] == "running"
    assert rtde.names() == []  # no command sent
    rtde.safety_bits = NORMAL | PROTECTIVE
    res = arm.check()
    assert not res.ok and "protective stop" in (res.error or "")
    assert res.details["safety_status"] == "normal mode, protective stop"


def test_describe_safety_bits() -> None:
    assert describe_safety_bits(0) == "none"
    assert describe_safety_bits(NORMAL | 1 << 9) == "normal mode, safety fault"


def test_importing_the_driver_does_not_import_ur_rtde() -> None:
    import subprocess
    import sys

    code = (
        "import sys, drivers.ur5, drivers.ur5.arm, drivers.ur5.rtde_adapter;"
        "print(any(m.startswith(('rtde_control', 'rtde_receive')) for m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_a_path_whose_script_never_starts_faults_after_the_timeout() -> None:
    rtde, clock = RecordingAdapter(), FakeClock()
    stuck: list = []  # the upload's worker never returns (ur_rtde waits without a timeout)
    arm = UR5Arm(rtde, clock, UR5Settings(script_start_timeout=2.0), spawn=stuck.append)
    start = goal_at(rtde)
    arm.move_path([Pose(start.position + [0, 0, 0.05], start.rotation),
                   Pose(start.position + [0.05, 0, 0.05], start.rotation)], 0.1, 0.5)
    assert len(stuck) == 1
    for _ in range(int(2.0 / 0.008) - 1):
        clock.t += 0.008
        assert arm.status().state is MotionState.MOVING
    clock.t += 0.05
    st = arm.status()
    assert st.state is MotionState.FAULT and "did not start within 2 s" in st.message
    assert stuck[-1] == rtde.drop_control  # the stuck interface is given up, off the tick


def test_a_silent_link_that_still_looks_connected_is_lost_after_the_data_timeout() -> None:
    """A pulled cable seldom closes the socket: ur_rtde says connected while no package comes.
    The controller's timestamp standing still for data_timeout is the lost link."""
    arm, rtde, clock = make(UR5Settings(data_timeout=0.5, reconnect_attempts=1))
    rtde.op = (False, 0)
    arm.move_to(goal_at(rtde), 0.1, 0.5)
    assert arm.status().state is MotionState.MOVING
    rtde.data_frozen = True
    for _ in range(60):  # 0.48 s of ticks: not yet
        clock.t += 0.008
        assert arm.status().state is MotionState.MOVING
    for _ in range(5):
        clock.t += 0.008
    st = arm.status()
    assert st.state is MotionState.FAULT and "RTDE data stale" in st.message


def test_a_stop_from_the_sensor_s_thread_waits_for_the_command_in_flight() -> None:
    """The force-torque guard stops the arm from the FT300's reader thread: the driver lets one
    caller in at a time, so that stop neither interleaves with the tick's command inside
    ur_rtde nor is lost -- it follows the command and ends the motion it started."""
    import threading

    arm, rtde, _ = make()
    inside, release = threading.Event(), threading.Event()
    plain_move_l = rtde.move_l

    def slow_move_l(*args: object) -> bool:
        inside.set()
        release.wait(2.0)
        return plain_move_l(*args)  # type: ignore[arg-type]

    rtde.move_l = slow_move_l  # type: ignore[method-assign]
    tick = threading.Thread(target=arm.move_to, args=(goal_at(rtde), 0.1, 0.5))
    tick.start()
    assert inside.wait(2.0)
    guard = threading.Thread(target=arm.stop)
    guard.start()
    guard.join(0.2)
    assert guard.is_alive() and "stop_l" not in rtde.names()  # waits for the command
    release.set()
    tick.join(2.0)
    guard.join(2.0)
    assert rtde.names()[-2:] == ["move_l", "stop_l"]
    assert arm.status().state is MotionState.STOPPED


def test_a_stop_pauses_a_move_by_the_speed_slider_before_waiting_for_the_command_in_flight(
) -> None:
    """``stopL`` waits behind the tick's command (above) and behind the control script's
    handshake; the speed slider has its own connection and no handshake, so it goes first,
    from the guard's thread, while the command is still in flight. The next command sets it
    back before it is sent."""
    import threading

    arm, rtde, _ = make()
    rtde.op = (False, 0)
    arm.move_to(goal_at(rtde), 0.1, 0.5)
    assert rtde.args("set_speed_slider") == [(1.0,)]  # start-up: whatever a last run left
    rtde.op = (True, 1)
    assert arm.status().state is MotionState.MOVING
    inside, release = threading.Event(), threading.Event()
    plain = rtde.async_status

    def slow_status() -> tuple[bool, int]:
        inside.set()
        release.wait(2.0)
        return plain()

    rtde.async_status = slow_status  # type: ignore[method-assign]
    tick = threading.Thread(target=arm.status)
    tick.start()
    assert inside.wait(2.0)
    guard = threading.Thread(target=arm.stop)
    guard.start()
    guard.join(0.2)
    assert guard.is_alive() and "stop_l" not in rtde.names()
    assert rtde.args("set_speed_slider")[-1] == (0.0,)  # sent without the lock
    release.set()
    tick.join(2.0)
    guard.join(2.0)
    rtde.async_status = plain  # type: ignore[method-assign]
    assert rtde.names()[-1] == "stop_l" and arm.status().state is MotionState.STOPPED
    rtde.op = (False, 2)
    arm.move_to(goal_at(rtde), 0.1, 0.5)
    order = [(n, a) for n, a in rtde.calls if n in ("set_speed_slider", "move_l")][-2:]
    assert order == [("set_speed_slider", (1.0,)), ("move_l", order[1][1])]
    arm.stop()
    arm.stop()  # idempotent: nothing runs, no second pause
    assert rtde.args("set_speed_slider")[-2:] == [(1.0,), (0.0,)]


@pytest.mark.parametrize("start", ["servo", "force"])
def test_servo_and_force_mode_stop_by_their_own_commands_without_a_pause(start: str) -> None:
    arm, rtde, _ = make()
    if start == "servo":
        arm.servo(goal_at(rtde))
    else:
        arm.force_mode([False] * 6, [0.0] * 6, [0.1] * 6)
    arm.stop()
    assert (0.0,) not in rtde.args("set_speed_slider")


def test_a_slider_the_controller_does_not_take_back_refuses_the_next_command() -> None:
    arm, rtde, _ = make()
    rtde.slider_ok = False
    rtde.op = (False, 0)
    arm.move_to(goal_at(rtde), 0.1, 0.5)
    st = arm.status()
    assert st.state is MotionState.FAULT and "speed slider" in st.message
    assert "move_l" not in rtde.names()
    rtde.slider_ok = True
    arm.move_to(goal_at(rtde), 0.1, 0.5)
    assert rtde.names() == ["move_l"]


class _SlowMoves:
    """An arm whose commands run on real worker threads, its ``moveL`` held in the handshake
    until :attr:`release` is set; counts the ``moveL`` calls inside ur_rtde at once."""

    def __init__(self, settings: UR5Settings | None = None) -> None:
        import threading

        self.rtde, self.clock = RecordingAdapter(), FakeClock()
        self.workers: list[threading.Thread] = []
        self.inside, self.release = threading.Event(), threading.Event()
        self.at_once = self.most_at_once = 0
        self._lock = threading.Lock()
        self.plain_move_l = self.rtde.move_l
        self.rtde.move_l = self._slow_move_l  # type: ignore[method-assign]
        self.arm = UR5Arm(self.rtde, self.clock, settings, spawn=self._spawn)

    def _spawn(self, fn):  # type: ignore[no-untyped-def]
        import threading

        t = threading.Thread(target=fn, daemon=True)
        self.workers.append(t)
        t.start()

    def _slow_move_l(self, *args: object) -> bool:
        with self._lock:
            self.at_once += 1
            self.most_at_once = max(self.most_at_once, self.at_once)
        self.inside.set()
        self.release.wait(2.0)
        try:
            return self.plain_move_l(*args)  # type: ignore[arg-type]
        finally:
            with self._lock:
                self.at_once -= 1

    def release_soon(self, delay: float = 0.05) -> None:
        import threading

        threading.Timer(delay, self.release.set).start()


def test_a_move_s_handshake_runs_off_the_tick_and_a_stop_meanwhile_follows_it() -> None:
    """ur_rtde's ``moveL`` waits for the control script's handshake (two to three controller
    cycles, 16-24 ms on a CB3): sent on a worker, the tick returns at once and polls it. A stop
    while it is in flight is sent by the worker right after the command, never beside it."""
    m = _SlowMoves()
    arm, rtde = m.arm, m.rtde
    rtde.op = (False, 0)
    arm.move_to(goal_at(rtde), 0.1, 0.5)  # returns while the handshake is under way
    assert m.inside.wait(2.0) and "move_l" not in rtde.names()
    assert arm.status().state is MotionState.MOVING
    arm.stop()  # from the tick or the guard: does not wait, sends nothing beside the move
    assert "stop_l" not in rtde.names()
    m.release.set()
    m.workers[-1].join(2.0)
    assert rtde.names()[-2:] == ["move_l", "stop_l"]
    assert arm.status().state is MotionState.STOPPED


def test_a_command_while_a_move_s_handshake_runs_waits_for_it() -> None:
    """The next command (a new move, a servo) waits for the handshake in flight rather than
    enter ur_rtde's control interface beside it, and is not refused."""
    m = _SlowMoves()
    arm, rtde = m.arm, m.rtde
    rtde.op = (True, 3)
    arm.move_to(goal_at(rtde), 0.1, 0.5)
    assert m.inside.wait(2.0)
    m.release_soon()
    arm.move_to(goal_at(rtde), 0.1, 0.5)  # waits up to the first's end, then sends
    for w in m.workers:
        w.join(2.0)
    assert rtde.names().count("move_l") == 2 and m.most_at_once == 1
    assert arm.status().state is MotionState.MOVING


def test_the_watchdog_is_armed_after_the_move_in_flight_not_beside_it() -> None:
    """The tick loop arms the watchdog after its first tick, whose move may still be in its
    handshake on the worker: two commands at once in ur_rtde's control interface overwrite each
    other (on the emulated cell the first move never ran and its leaf timed out after 10 s)."""
    m = _SlowMoves(UR5Settings(watchdog_hz=10.0))
    m.rtde.op = (False, 0)
    m.arm.move_to(goal_at(m.rtde), 0.1, 0.5)
    m.release_soon()
    m.arm.start_watchdog()
    names = m.rtde.names()
    assert "set_watchdog" in names and names.index("move_l") < names.index("set_watchdog")


@pytest.mark.parametrize(
    "name", ["move_to", "move_path", "move_joints", "servo", "force_mode", "recover"]
)
def test_every_command_holds_the_drivers_lock(name: str) -> None:
    """The force-torque guard stops the arm from the sensor's thread while the tick may be
    inside a command: each command runs under the driver's lock (``__wrapped__`` is what
    :func:`functools.wraps` leaves on the locking wrapper)."""
    from drivers.ur5.arm import UR5Arm

    assert hasattr(getattr(UR5Arm, name), "__wrapped__")
