"""UR5Arm through the real ur_rtde (the version pinned in pyproject) against the UR controller
emulator (sim/emulate/ur_controller.py, the twin's arm behind it), tick by tick in wall time.

Each test here failed on the driver before the fix it names (see the commit messages): the
recording double in test_arm.py only plays back what the driver's authors assumed; the emulator
behaves as ur_rtde's control script does (no -1 between two async moves, every async stop a
stopl, a watchdog per script run, a program that starts some time after its upload).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable

import numpy as np
import pytest

pytest.importorskip("rtde_control")

from drivers.arm import MotionState  # noqa: E402
from drivers.pose import Pose  # noqa: E402
from drivers.ur5.arm import UR5Arm, UR5Settings  # noqa: E402
from sim.emulate.ur_standalone import URAloneProcess  # noqa: E402

TICK = 0.008  #: s: the cell's control period at 125 Hz
UNLOCK = 0.3  #: s: the emulator's protective-stop unlock delay (5 s on a real controller)


@pytest.fixture(scope="module")
def emulator():
    try:
        emu = URAloneProcess(script_start_delay=0.15, unlock_delay=UNLOCK).start()
    except TimeoutError:  # an emulator that never answers is a failure, not a skip
        raise
    except OSError as e:  # ports taken on our loopback address: nothing to test against
        pytest.skip(f"cannot bind the UR emulator: {e}")
    yield emu
    emu.stop()


@pytest.fixture
def connect(emulator: URAloneProcess):
    arms: list[UR5Arm] = []

    def make(settings: UR5Settings | None = None) -> UR5Arm:
        arm = UR5Arm.connect(emulator.host, settings=settings or UR5Settings())
        arms.append(arm)
        return arm

    yield make
    for arm in arms:
        try:
            arm.close()
        except Exception:
            pass


def run_until(arm: UR5Arm, done: Callable[[], bool], seconds: float) -> MotionState:
    """Poll status() once per tick (as the cell does) until ``done`` or the time is up."""
    t_end = time.monotonic() + seconds
    while time.monotonic() < t_end:
        state = arm.status().state
        if done():
            return state
        time.sleep(TICK)
    return arm.status().state


def settle(arm: UR5Arm) -> None:
    assert run_until(arm, lambda: arm.status().state is not MotionState.MOVING, 10.0) in (
        MotionState.DONE, MotionState.IDLE, MotionState.STOPPED)


def offset(pose: Pose, dx: float = 0.0, dy: float = 0.0, dz: float = 0.0) -> Pose:
    return Pose(pose.position + np.array([dx, dy, dz]), pose.rotation)


def test_a_move_sent_while_a_move_runs_ends_done_at_its_goal(connect, emulator) -> None:
    arm = connect()
    start = arm.tool_pose()
    arm.move_to(offset(start, dz=-0.10), 0.05, 0.5)
    assert run_until(arm, lambda: False, 0.3) is MotionState.MOVING
    goal = offset(start, dx=0.03)
    arm.move_to(goal, 0.1, 0.5)  # cancels the first within one controller cycle
    wall = time.monotonic()
    twin = emulator.status()["t"]
    # About 0.5 s of the controller's time; the emulator's clock slips behind the wall clock
    # when its process is starved (a loaded CI machine), so the wait is generous, and a failure
    # says how far the controller's clock got.
    state = run_until(arm, lambda: arm.status().state is not MotionState.MOVING, 10.0)
    assert state is MotionState.DONE, (
        f"{arm.status().message!r}; the controller's clock advanced "
        f"{emulator.status()['t'] - twin:.2f} s in {time.monotonic() - wall:.2f} s of wall time; "
        f"{arm.tool_pose().distance(goal)[0] * 1e3:.1f} mm from the goal"
    )
    assert arm.tool_pose().distance(goal)[0] < 0.002


def test_a_move_sent_right_after_an_async_stop_ends_done(connect) -> None:
    arm = connect()
    start = arm.tool_pose()
    arm.move_to(offset(start, dz=-0.10), 0.1, 0.5)
    run_until(arm, lambda: False, 0.3)
    arm.stop()
    goal = offset(start, dy=0.02)
    arm.move_to(goal, 0.1, 0.5)  # the stop thread is still decelerating
    state = run_until(arm, lambda: arm.status().state is not MotionState.MOVING, 5.0)
    assert state is MotionState.DONE, arm.status().message
    assert arm.tool_pose().distance(goal)[0] < 0.002


def test_a_stop_pauses_the_move_by_the_speed_slider_and_the_next_move_runs_at_full_speed(
        connect, emulator: URAloneProcess) -> None:
    """Through ur_rtde's own RTDEIOInterface: the controller takes the slider at 0 (a
    pause it counts as a stop) besides the stopL; the next move sets it back to 1.

    The slider travels on the IO interface's socket, the stopL on the control script's: which
    the controller reads first depends on the machine's load (the stopL first leaves the slider
    nothing to pause), so the slider's arrival is waited for and counted either way."""
    arm = connect()
    start = arm.tool_pose()
    arm.move_to(offset(start, dz=-0.10), 0.1, 0.5)
    run_until(arm, lambda: False, 0.3)
    zeros = emulator.status()["slider_zeros"]
    arm.stop()
    t_end = time.monotonic() + 2.0
    while emulator.status()["slider_zeros"] == zeros and time.monotonic() < t_end:
        time.sleep(0.005)
    status = emulator.status()
    assert status["slider_zeros"] == zeros + 1 and status["speed_slider"] == 0.0
    settle(arm)
    goal = offset(start, dy=0.02)
    arm.move_to(goal, 0.1, 0.5)
    state = run_until(arm, lambda: arm.status().state is not MotionState.MOVING, 5.0)
    assert state is MotionState.DONE, arm.status().message
    assert emulator.status()["speed_slider"] == 1.0
    assert arm.tool_pose().distance(goal)[0] < 0.002


def test_the_stop_of_a_joint_move_is_a_stopl_at_the_cartesian_deceleration(
        connect, emulator: URAloneProcess) -> None:
    settings = UR5Settings(stop_deceleration=6.0)
    arm = connect(settings)
    q = arm.joint_positions()
    arm.move_joints(q + np.array([0.3, 0, 0, 0, 0, 0]), 0.5, 1.0)
    run_until(arm, lambda: False, 0.3)
    arm.stop()
    kind, deceleration = emulator.status()["stops"][-1]
    assert kind == "stopl"  # what the control script runs for every async stop
    assert deceleration == settings.stop_deceleration  # m/s^2, not a rad/s^2 value
    settle(arm)


def test_a_path_does_not_block_the_tick_and_ends_done(connect) -> None:
    arm = connect()
    start = arm.tool_pose()
    waypoints = [offset(start, dz=-0.03), offset(start, dx=0.03, dz=-0.03),
                 offset(start, dx=0.03)]
    t0 = time.perf_counter()
    arm.move_path(waypoints, 0.1, 0.5)
    blocked = time.perf_counter() - t0
    # The upload used to wait for the re-started script (about 200 ms against the emulator,
    # unbounded if it never starts); now it returns at once. 100 ms leaves room for a loaded
    # machine's scheduling without letting the old wait through.
    assert blocked < 0.1, f"move_path blocked the tick for {blocked * 1e3:.1f} ms"
    state = run_until(arm, lambda: arm.status().state is not MotionState.MOVING, 8.0)
    assert state is MotionState.DONE, arm.status().message
    assert arm.tool_pose().distance(waypoints[-1])[0] < 0.002


def test_recover_returns_with_the_script_running_and_the_watchdog_armed(
        connect, emulator: URAloneProcess) -> None:
    arm = connect(UR5Settings(watchdog_hz=5.0))
    arm.start_watchdog()
    assert run_until(arm, lambda: emulator.status()["watchdog_hz"] == 5.0, 1.0)
    emulator.protective_stop("test")
    assert run_until(arm, lambda: arm.status().protective_stop, 1.0) is MotionState.FAULT
    time.sleep(UNLOCK + 0.05)
    arm.recover()
    start = arm.tool_pose()
    arm.move_to(offset(start, dz=-0.01), 0.1, 0.5)  # right after: must be accepted
    state = run_until(arm, lambda: arm.status().state is not MotionState.MOVING, 5.0)
    assert state is MotionState.DONE, arm.status().message
    assert emulator.status()["watchdog_hz"] == 5.0


def test_a_force_mode_under_the_watchdog_moves_the_arm(
        connect, emulator: URAloneProcess) -> None:
    """A kick writes the command register: polled right after a continuous command (force mode)
    it overwrote the command within the controller's cycle and the arm never moved."""
    arm = connect(UR5Settings(watchdog_hz=10.0))
    arm.start_watchdog()
    assert run_until(arm, lambda: emulator.status()["watchdog_hz"] == 10.0, 1.0)
    z0 = float(arm.tool_pose().position[2])
    trips = emulator.status()["watchdog_trips"]  # the emulator is the module's: counts add up
    arm.force_mode([False, False, True, False, False, False], [0, 0, -5.0, 0, 0, 0],
                   [0, 0, 0.02, 0, 0, 0])
    run_until(arm, lambda: False, 0.6)  # the tick loop's polls, every one a chance to kick
    moved = z0 - float(arm.tool_pose().position[2])
    status = emulator.status()
    arm.stop()
    assert moved > 0.005, f"force mode moved the TCP {moved * 1e3:.1f} mm down"
    assert status["watchdog_trips"] == trips and "forceMode" in status["commands"]


@pytest.mark.skipif(
    os.environ.get("PIVOT_RUN_FLAKY") != "1",
    reason="fails now and then when the machine is loaded (the arm reads IDLE for 2 s after the "
    "pull; the race is not found yet); run it with PIVOT_RUN_FLAKY=1",
)
def test_after_a_cable_pull_the_link_comes_back_at_the_configured_rate_with_the_watchdog(
        connect, emulator: URAloneProcess) -> None:
    # Attempts enough to outlast a loaded machine's slow script start after the plug.
    settings = UR5Settings(frequency=50.0, watchdog_hz=5.0, reconnect_first_delay=0.2,
                           reconnect_attempts=12, reconnect_max_delay=1.0)
    arm = connect(settings)
    arm.start_watchdog()
    before = len(emulator.requested_frequencies())
    emulator.pull_cable()
    st = None
    t_end = time.monotonic() + 2.0
    while time.monotonic() < t_end:
        st = arm.status()
        if st.state is MotionState.FAULT:
            break
        time.sleep(TICK)
    assert st is not None and st.state is MotionState.FAULT and "lost connection" in st.message
    emulator.plug_cable()
    t_end = time.monotonic() + 10.0
    while time.monotonic() < t_end and "lost connection" in arm.status().message:
        time.sleep(TICK)
    arm.move_to(offset(arm.tool_pose(), dz=-0.01), 0.1, 0.5)
    state = run_until(arm, lambda: arm.status().state is not MotionState.MOVING, 5.0)
    assert state is MotionState.DONE, arm.status().message
    again = emulator.requested_frequencies()[before:]
    assert again and all(f == 50.0 for f in again), again
    assert emulator.status()["watchdog_hz"] == 5.0


def test_a_process_that_lost_the_link_ends_at_once_with_its_status_and_output() -> None:
    # bench/link_loss_exit.py's child, as `cell run` ends after a pulled cable: the arm's
    # close() abandons the dead interfaces and end_process skips their destructors. Leaving
    # them to the interpreter's exit instead aborted the process (terminate called, exit 134)
    # while a reconnect attempt was inside ur_rtde; disconnecting them took seconds.
    #
    # ur_rtde itself now and then dies by SIGSEGV right after the pull, before the driver sees
    # the loss: its control interface's receive thread and the command that met the closed
    # socket both run its reconnect() at once (1 child in the order of 100, on a loaded
    # machine). Nothing of this project's runs then; such a child is run again, at most twice.
    import signal
    import subprocess
    import sys
    from pathlib import Path

    bench = Path(__file__).resolve().parents[3] / "bench" / "link_loss_exit.py"
    for _ in range(3):
        proc = subprocess.run([sys.executable, str(bench), "--child", "abandon"],
                              capture_output=True, text=True, timeout=60, cwd=bench.parents[1])
        if proc.returncode != -signal.SIGSEGV or "PULLED" in proc.stdout:
            break
    assert proc.returncode == 1, proc.stderr[-2000:]
    assert "terminate called" not in proc.stderr
    assert "PULLED" in proc.stdout  # written before the end, and flushed


def test_the_standalone_emulator_ends_with_a_parent_killed_by_a_signal() -> None:
    # A parent that dies without clean-up (ur_rtde's SIGSEGV above, a SIGKILL) must not leave
    # the emulator running: it holds the parent's stdout and stderr, and a caller waiting on
    # them would wait for ever.
    import subprocess
    import sys
    from pathlib import Path

    code = ("import os, signal; from sim.emulate.ur_standalone import URAloneProcess; "
            "URAloneProcess().start(); print('UP', flush=True); "
            "os.kill(os.getpid(), signal.SIGKILL)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                          cwd=Path(__file__).resolve().parents[3])
    assert "UP" in proc.stdout, proc.stderr[-2000:]
    assert proc.returncode == -9


VANISHED = r"""
import sys, threading, time
from cell.cli import end_process
from drivers.arm import MotionState
from drivers.pose import Pose
from drivers.ur5.arm import UR5Arm, UR5Settings
from sim.emulate.ur_standalone import URAloneProcess

emu = URAloneProcess(script_start_delay=0.15).start()
arm = UR5Arm.connect(emu.host, settings=UR5Settings(reconnect_attempts=1))
tool = arm.tool_pose()
arm.move_to(Pose(tool.position - [0.0, 0.0, 0.10], tool.rotation), 0.02, 0.5)
time.sleep(0.1)
emu._proc.kill()  # a controller that vanishes, not one that says goodbye
emu._proc.join(timeout=5.0)
time.sleep(0.2)  # the sockets' ends reach ur_rtde's reader threads
done = threading.Event()
threading.Thread(target=lambda: (arm.stop(), done.set()), daemon=True).start()
if not done.wait(5.0):
    print("HUNG", flush=True)
    end_process(3)
st = arm.status()
print("STATE", st.state.name, st.link_lost, flush=True)
arm.close()
end_process(0)
"""


def test_a_stop_after_the_controller_vanished_returns_with_a_lost_link() -> None:
    # The whole controller gone at once (its process killed): the wrist sensor's loss reached the
    # cell first and its guard stopped the arm before any status poll had seen the link go.
    # ur_rtde's stopL on the dead link then never returned (the tick thread hung for minutes in
    # `cell run` against a killed `cell emulate`). In a process of its own: the lost link's
    # interfaces are abandoned there, and only the end of a process disposes of them.
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[3]
    proc = subprocess.run([sys.executable, "-c", VANISHED], capture_output=True, text=True,
                          timeout=90, cwd=root)
    assert "HUNG" not in proc.stdout, "stop() hung on the dead link"
    assert proc.returncode == 0, proc.stdout + proc.stderr[-2000:]
    assert "STATE FAULT True" in proc.stdout
