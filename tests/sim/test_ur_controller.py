"""The UR controller emulator's script model, cycle by cycle, against rtde_control.script
(ur_rtde 1.6.5): the register handshake, the async status word and its quirks, the watchdog,
protective stops, and loud failures. A scripted backend stands in for the twin's arm (the
driver tests in tests/drivers/ur5/test_arm_emulated.py run the real ur_rtde against the twin)."""

from __future__ import annotations

from collections.abc import Sequence

import pytest

from sim.emulate.ur_controller import (
    DONE,
    READY,
    RUNTIME_PLAYING,
    RUNTIME_STOPPED,
    ArmBackend,
    ControllerSettings,
    URController,
    parse_injected_path,
)

HEADER = (
    "def rtde_control():\n# HEADER_BEGIN\n"
    "    global reg_offset_float = # float register offset\n{off}"
    "    global reg_offset_int = # int register offset\n{off}"
    "    global force_mode_type = 2\n"
    "    def exec_move_path():\n        textmsg(\"exec_move_path\")\n"
    "        # inject move path\n{path}    end\n"
    "# HEADER_END\n# NODE_CONTROL_LOOP_BEGINS\n"
    "        textmsg(\"RTDE Control Script Loaded (14.02.2024-12:23)\")\n"
    "# NODE_CONTROL_LOOP_ENDS\nend\n"
)


def script(offset: int = 0, path: str = "") -> str:
    return HEADER.format(off=offset, path=path)


class Backend:
    """Scripted arm: moves end when the test says so."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, tuple]] = []
        self.state = "idle"
        self.tripped: str | None = None

    def joint_positions(self) -> list[float]:
        return [0.0] * 6

    def joint_velocities(self) -> list[float]:
        return [0.0] * 6

    def tcp_pose(self) -> list[float]:
        return [0.4, 0.0, 0.3, 0.0, 3.14, 0.0]

    def tcp_speed(self) -> list[float]:
        return [0.1, 0.0, 0.0, 0.0, 0.0, 0.0]

    def tcp_force(self) -> list[float]:
        return [0.0] * 6

    def move_joints(self, q: Sequence[float], speed: float, acceleration: float) -> None:
        self.calls.append(("move_joints", (list(q), speed, acceleration)))
        self.state = "moving"

    def move_linear(self, poses, speed, acceleration) -> None:  # type: ignore[no-untyped-def]
        self.calls.append(("move_linear", ([list(p) for p in poses], speed, acceleration)))
        self.state = "moving"

    def servo(self, pose: Sequence[float], lookahead: float, gain: float) -> None:
        self.calls.append(("servo", (list(pose), lookahead, gain)))

    def force_mode(self, selection, wrench, limits) -> None:  # type: ignore[no-untyped-def]
        self.calls.append(("force_mode", (list(selection), list(wrench), list(limits))))

    def stop(self) -> None:
        self.calls.append(("stop", ()))
        self.state = "idle"

    def speed_fraction(self, fraction: float) -> None:
        self.calls.append(("speed_fraction", (fraction,)))

    def motion_state(self) -> str:
        return self.state

    def protective_stop(self) -> str | None:
        tripped, self.tripped = self.tripped, None
        return tripped

    def zero_ft(self) -> None:
        self.calls.append(("zero_ft", ()))


@pytest.fixture
def ctl() -> tuple[URController, Backend]:
    backend = Backend()
    assert isinstance(backend, ArmBackend)
    c = URController(backend, ControllerSettings(script_start_delay=0.02, unlock_delay=0.1))
    c.upload(script())
    for _ in range(4):
        c.cycle()
    assert c.outputs()["runtime_state"] == RUNTIME_PLAYING
    return c, backend


def word(c: URController, offset: int = 0) -> tuple[bool, int]:
    w = c.outputs()[f"output_int_register_{2 + offset}"]
    return bool(w & 0x8000), (w >> 24) & 0x7F


def command(c: URController, cmd: int, offset: int = 0, **registers: float) -> None:
    """What ur_rtde's sendCommand does: wait ready, write, wait done, clear."""
    assert c.outputs()[f"output_int_register_{offset}"] == READY
    values = {f"input_int_register_{offset}": cmd}
    for name, v in registers.items():
        kind, index = name.split("_")
        values[f"input_{kind}_register_{int(index) + offset}"] = v
    c.write_inputs(values)
    c.cycle()
    assert c.outputs()[f"output_int_register_{offset}"] == DONE
    c.write_inputs({f"input_int_register_{offset}": 0})
    c.cycle()


def move_l(c: URController, z: float, asynchronous: int = 1) -> None:
    pose = [0.4, 0.0, z, 0.0, 3.14, 0.0]
    regs = {f"double_{i}": v for i, v in enumerate([*pose, 0.1, 0.5])}
    command(c, 3, int_1=asynchronous, **regs)


def test_a_fresh_script_is_ready_with_no_operation(ctl) -> None:
    c, _ = ctl
    assert c.outputs()["output_int_register_0"] == READY
    assert word(c) == (False, 0)


def test_a_move_cancelling_a_move_publishes_no_finished_value_between(ctl) -> None:
    c, backend = ctl
    move_l(c, 0.2)
    assert word(c) == (True, 1)
    c.write_inputs({"input_int_register_0": 3})  # the second moveL
    c.cycle()
    assert word(c) == (True, 2)  # finished(1) and started(2) in one cycle: only 2 is seen
    c.write_inputs({"input_int_register_0": 0})
    c.cycle()
    backend.state = "done"
    c.cycle()
    assert word(c) == (False, 2)


def test_every_async_stop_runs_stopl_and_marks_the_current_operation_finished(ctl) -> None:
    c, backend = ctl
    move_l(c, 0.2)
    command(c, 34, double_0=4.0, int_1=1)  # async stopJ with a joint deceleration
    assert c.log.stops[-1] == ("stopl", 4.0)
    running, stop_op = word(c)
    assert running and stop_op == 2
    move_l(c, 0.25)  # a move while the stop thread still runs
    assert word(c) == (True, 3)
    for _ in range(10):  # the stop thread ends (0.1 m/s / 4 m/s^2 = 25 ms)
        c.cycle()
    assert word(c) == (False, 3)  # "finished" written over the move's operation
    assert backend.state == "moving"  # while the arm still moves


def test_servol_runs_servoj_with_the_commands_lookahead_and_gain(ctl) -> None:
    """ur_rtde's script reads servoL's time, lookahead_time and gain from float registers
    8-10; the backend gets the last two, which decide how the arm follows the stream."""
    c, backend = ctl
    pose = [0.4, 0.0, 0.2, 0.0, 3.14, 0.0]
    regs = {f"input_double_register_{i}": v
            for i, v in enumerate([*pose, 0.0, 0.0, 0.008, 0.05, 500.0])}
    c.write_inputs({"input_int_register_0": 24, **regs})  # streamed: no done handshake
    c.cycle()
    assert backend.calls[-1] == ("servo", (pose, 0.05, 500.0))


def test_a_sync_stop_uses_the_last_stop_type(ctl) -> None:
    c, _ = ctl
    command(c, 33, double_0=2.0, int_1=0)  # stopL, sync: stop_type is still 0
    assert c.log.stops[-1] == ("stopj", 2.0)


def test_a_path_is_read_from_the_upload_and_numbered_two_above(ctl) -> None:
    c, backend = ctl
    path = ("\tsignal_async_progress(0)\n\tmovel(p[0.4,0,0.2,0,3.14,0],a=0.5,v=0.1,r=0.01)\n"
            "\tsignal_async_progress(1)\n\tmovel(p[0.45,0,0.2,0,3.14,0],a=0.5,v=0.1,r=0)\n")
    assert [m[1][0] for m in parse_injected_path(script(path=path))] == [0.4, 0.45]
    c.upload(script(path=path))
    for _ in range(4):
        c.cycle()
    assert word(c) == (False, 0)
    command(c, 45, int_1=1)
    assert word(c) == (True, 2)
    assert backend.calls[-1][0] == "move_linear" and len(backend.calls[-1][1][0]) == 2


def test_upper_range_registers_move_the_whole_handshake() -> None:
    c = URController(Backend(), ControllerSettings(script_start_delay=0.0))
    c.upload(script(offset=24))
    c.cycle()
    c.cycle()
    assert c.outputs()["output_int_register_24"] == READY
    move_l_offset = {f"double_{i}": v for i, v in enumerate([0.4, 0, 0.2, 0, 3.14, 0, 0.1, 0.5])}
    command(c, 3, offset=24, int_1=1, **move_l_offset)
    assert word(c, 24) == (True, 1)


def test_an_unknown_command_id_stops_the_program_loudly(ctl) -> None:
    c, _ = ctl
    c.write_inputs({"input_int_register_0": 51})  # moveUntilContact: not modelled
    c.cycle()
    assert c.outputs()["runtime_state"] == RUNTIME_STOPPED
    assert "unsupported command id 51" in c.errors[-1]


def test_an_upload_that_is_not_the_control_script_is_refused(ctl) -> None:
    c, _ = ctl
    c.upload("def prog():\n  movej([0,0,0,0,0,0])\nend\n")
    c.cycle()
    assert c.outputs()["runtime_state"] == RUNTIME_STOPPED
    assert "not ur_rtde's control script" in c.errors[-1]


def test_the_watchdog_stops_the_program_and_a_new_upload_has_none(ctl) -> None:
    c, _ = ctl
    command(c, 35, double_0=10.0)
    assert c.status()["watchdog_hz"] == 10.0
    for _ in range(20):  # 160 ms without an input package
        c.cycle()
    assert c.outputs()["runtime_state"] == RUNTIME_STOPPED and c.log.watchdog_trips == 1
    c.upload(script())
    for _ in range(4):
        c.cycle()
    assert c.outputs()["runtime_state"] == RUNTIME_PLAYING
    assert c.status()["watchdog_hz"] is None


def test_a_protective_stop_ends_the_program_and_unlocks_only_after_the_delay(ctl) -> None:
    c, backend = ctl
    move_l(c, 0.2)
    backend.tripped = "tool force 180 N > 150 N"
    c.cycle()
    out = c.outputs()
    assert out["safety_status_bits"] & (1 << 2) and out["runtime_state"] == RUNTIME_STOPPED
    assert backend.calls[-1] == ("stop", ())
    assert c.dashboard("unlock protective stop").startswith("Cannot unlock")
    for _ in range(15):
        c.cycle()
    assert c.dashboard("unlock protective stop") == "Protective stop releasing"
    c.cycle()
    assert c.outputs()["safety_status_bits"] == 1


def test_a_connection_accepted_while_the_cable_is_pulled_does_not_survive_the_pull(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The race behind a flaky cable-pull test: a connection the accept thread had taken but not
    yet listed when the cable was pulled stayed open, so a client kept talking over a pulled
    cable. Here the accept thread is held right after accept() until the pull is done."""
    import socket
    import threading

    from sim.emulate.ur_controller import _Listener
    from sim.emulate.ur_standalone import loopback_host

    accepted, pulled = threading.Event(), threading.Event()
    served: list[socket.socket] = []
    real_setsockopt = socket.socket.setsockopt

    def held_setsockopt(self, *args):  # type: ignore[no-untyped-def]
        if args[:2] == (socket.IPPROTO_TCP, socket.TCP_NODELAY):
            accepted.set()
            pulled.wait(5.0)
        return real_setsockopt(self, *args)

    monkeypatch.setattr(socket.socket, "setsockopt", held_setsockopt)
    listener = _Listener(loopback_host(), 0, served.append, "test")
    listener.open()
    assert listener._server is not None
    port = listener._server.getsockname()[1]
    client = socket.create_connection((listener.host, port), timeout=2.0)
    try:
        assert accepted.wait(5.0)
        listener.close()  # the cable is pulled while the accept thread holds the connection
        pulled.set()
        client.settimeout(2.0)
        try:
            data = client.recv(1)  # closed by the emulator: EOF (b"") or a reset
        except ConnectionResetError:
            data = b""
        assert data == b""
        assert not served and listener.connections == 0
    finally:
        pulled.set()
        client.close()
        listener.shutdown()


def test_the_speed_slider_acts_in_the_next_cycle_without_a_handshake(ctl) -> None:
    """``speed_slider_fraction`` with bit 0 of its mask, from any client (ur_rtde's
    RTDEIOInterface): read in the next cycle like every input, with no command handshake; a 0
    while the arm moves is counted as a stop (the arm begins to stop in that cycle)."""
    c, backend = ctl
    c.write_inputs({"speed_slider_mask": 0, "speed_slider_fraction": 0.0})
    c.cycle()
    assert ("speed_fraction", (0.0,)) not in backend.calls  # without the mask, nothing
    move_l(c, 0.2)
    before = len(c.log.stop_times)
    c.write_inputs({"speed_slider_mask": 1, "speed_slider_fraction": 0.0})
    c.cycle()
    assert backend.calls[-1] == ("speed_fraction", (0.0,))
    assert c.outputs()["target_speed_fraction"] == 0.0
    assert len(c.log.stop_times) == before + 1 and len(c.log.pauses) == 1
    assert c.log.stops == []  # not one of the script's stops
    c.write_inputs({"speed_slider_mask": 1, "speed_slider_fraction": 1.5})
    c.cycle()
    assert backend.calls[-1] == ("speed_fraction", (1.0,))  # clamped to the slider's range
    backend.state = "idle"
    c.write_inputs({"speed_slider_mask": 1, "speed_slider_fraction": 0.0})
    c.cycle()
    assert len(c.log.pauses) == 1  # nothing moved: no stop to count


def test_each_stop_keeps_when_its_message_reached_the_controller(ctl) -> None:
    """The stop's arrival (what the guard-latency bench times) is the message's, not the
    cycle's that took it: a server thread or a cycle that runs late does not add to it."""
    c, backend = ctl
    move_l(c, 0.2)
    c.write_inputs({"speed_slider_mask": 1, "speed_slider_fraction": 0.0}, arrived=12.5)
    c.cycle()
    assert c.log.stop_arrivals == [12.5] and len(c.log.stop_times) == 1
    c.write_inputs({"speed_slider_mask": 1, "speed_slider_fraction": 1.0}, arrived=13.0)
    c.cycle()
    command(c, 33, double_0=2.0, int_1=1)  # stopL: its command register's message
    assert len(c.log.stop_arrivals) == 2 and c.log.stop_arrivals[1] > 13.0
    backend.state = "idle"
    c.write_inputs({"speed_slider_mask": 1, "speed_slider_fraction": 0.0}, arrived=20.0)
    c.cycle()
    assert c.log.rest_stop_arrivals == [20.0]  # reached a controller with nothing to stop
    assert len(c.log.stop_arrivals) == 2


def test_a_read_carries_the_kernels_receive_time() -> None:
    """The RTDE server's reads are stamped by the network stack: bytes that waited in the
    socket while the reading thread was busy keep the time they came."""
    import socket
    import time

    from sim.emulate.ur_controller import SO_TIMESTAMPNS, _read_stamped

    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    client = socket.create_connection(server.getsockname())
    conn, _ = server.accept()
    try:
        conn.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
        # The kernel turns receive timestamps on a moment after the first socket asks (the
        # emulator's first messages are stamped at their read, later); a first message waits
        # for that here.
        time.sleep(0.1)
        client.sendall(b"x")
        assert _read_stamped(conn, 1) is not None
        sent = time.monotonic()
        client.sendall(b"abcdef")
        time.sleep(0.05)  # the server thread is late
        got = _read_stamped(conn, 6)
        assert got is not None
        data, arrived = got
        assert data == b"abcdef"
        assert sent - 0.002 <= arrived < sent + 0.02  # not the read's time, 50 ms later
    finally:
        for s in (client, conn, server):
            s.close()
