"""The hardware backend's start-up and shut-down, with the device openers replaced by stand-ins
(the drivers themselves are tested against their protocol peers in tests/drivers/)."""

from __future__ import annotations

import pytest

from cell import hardware
from cell.assemble import prepare
from cell.config import config_from_text
from drivers.devices import Devices
from drivers.health import CheckResult, DeviceError
from drivers.pose import Pose
from drivers.ur5.kinematics import HOME_JOINTS, forward_kinematics
from trees.yaml_lines import ConfigError


class _Dev:
    def __init__(self, name: str, ok: bool = True) -> None:
        self.name, self.ok, self.calls = name, ok, []
        #: the arm's controller: its TCP where the UR5 model puts it (a test moves it)
        self.q = HOME_JOINTS.copy()
        self.tcp = forward_kinematics(self.q)

    def joint_positions(self):  # type: ignore[no-untyped-def]
        return self.q

    def tool_pose(self):  # type: ignore[no-untyped-def]
        return self.tcp

    def check(self, activate: bool = False, min_valid_fraction: float = 0.2) -> CheckResult:
        self.calls.append(("check", activate) if self.name != "camera" else
                          ("check", min_valid_fraction))
        return CheckResult(self.name, "addr", self.ok, error=None if self.ok else "it is on fire")

    def stop(self) -> None:
        self.calls.append("stop")

    def bias(self) -> None:
        self.calls.append("bias")

    def object_detected(self) -> bool:
        return False

    def tip_advance(self, width: float) -> float:
        return 0.0

    def calibrate(self) -> object:
        self.calls.append("calibrate")

        class Cal:
            open_count, closed_count = 3, 228

        return Cal()

    def open(self) -> None:
        self.calls.append("open")

    def close(self) -> None:
        self.calls.append("close")

    def disconnect(self) -> None:
        self.calls.append("disconnect")


#: Gripper forces a 2F-85 can apply (the defaults are the twin's, below its 20 N).
FORCES = "skills:\n  pivot: {grip_force_n: 20, hold_force_n: 20}\n  slot: {hold_force_n: 20}\n"


def _prep(text: str = "cell:\n  backend: hw\n" + FORCES):
    config, doc = config_from_text(text, "hw.yaml")
    return prepare(config, doc)


def test_a_grip_force_the_2f85_cannot_apply_is_refused_before_any_device_opens(
        monkeypatch) -> None:
    opened: list[str] = []

    def opener(name: str):
        def make(cfg, layout, clock):  # type: ignore[no-untyped-def]
            opened.append(name)
            return _Dev()

        return make

    monkeypatch.setattr(hardware, "OPENERS", {n: opener(n) for n in hardware.DEVICES})
    text = "cell:\n  backend: hw\n" + FORCES.replace("grip_force_n: 20", "grip_force_n: 2")
    with pytest.raises(ConfigError) as err:
        hardware.open_hardware(_prep(text))
    assert err.value.key == "skills.pivot.grip_force_n" and err.value.line == 4
    assert "20..235 N" in err.value.reason and "would not do what is asked" in err.value.reason
    assert opened == []


def test_a_failed_check_refuses_the_run_and_closes_what_was_opened(monkeypatch) -> None:
    made: dict[str, _Dev] = {}

    def opener(name: str, ok: bool = True):
        def make(cfg, layout, clock):  # type: ignore[no-untyped-def]
            made[name] = _Dev(name, ok)
            return made[name]

        return make

    def unreachable(cfg, layout, clock):  # type: ignore[no-untyped-def]
        raise DeviceError("D435", "usb (any)", "no RealSense camera connected")

    monkeypatch.setattr(
        hardware,
        "OPENERS",
        {
            "arm": opener("arm"),
            "gripper": opener("gripper", ok=False),
            "ft": opener("ft"),
            "camera": unreachable,
        },
    )
    with pytest.raises(ConfigError) as info:
        hardware.open_hardware(_prep())
    text = str(info.value)
    assert "start-up checks failed, nothing moved" in text
    assert "it is on fire" in text and "no RealSense camera" in text
    assert made["gripper"].calls[0] == ("check", True)  # the gripper is activated by its check
    assert made["arm"].calls[-2:] == ["stop", "close"]  # the arm stopped, then closed
    assert made["gripper"].calls[-1] == "disconnect"  # the gripper keeps its state
    assert made["ft"].calls[-1] == "stop"
    assert "bias" not in made["ft"].calls  # nothing zeroed on a refused start
    assert "calibrate" not in made["gripper"].calls


def test_all_checks_passing_gives_the_devices_to_the_tree(monkeypatch) -> None:
    made: dict[str, _Dev] = {}

    def opener(name: str):
        def make(cfg, layout, clock):  # type: ignore[no-untyped-def]
            made[name] = _Dev(name)
            return made[name]

        return make

    monkeypatch.setattr(hardware, "OPENERS", {n: opener(n) for n in hardware.DEVICES})
    backend = hardware.open_hardware(_prep())
    assert backend.devices.arm is made["arm"] and backend.devices.camera is made["camera"]
    # The wrist sensor is zeroed once, after every check passed, before the tree runs; the
    # gripper's width calibration is measured there (none configured), the fingers left open.
    assert made["ft"].calls == [("check", False), "bias"]
    assert made["gripper"].calls == [("check", True), "calibrate", "open"]
    assert made["camera"].calls[0] == ("check", 0.0)  # streaming is enough to start
    assert backend.judge("packed", {}) is None  # no ground truth on a real cell
    backend.close()
    assert made["arm"].calls[-2:] == ["stop", "close"]


def test_configured_gripper_counts_skip_the_start_up_calibration(monkeypatch) -> None:
    made: dict[str, _Dev] = {}
    seen: dict[str, object] = {}

    def opener(name: str):
        def make(cfg, layout, clock):  # type: ignore[no-untyped-def]
            seen[name] = cfg.gripper
            made[name] = _Dev(name)
            return made[name]

        return make

    monkeypatch.setattr(hardware, "OPENERS", {n: opener(n) for n in hardware.DEVICES})
    config, doc = config_from_text(
        "cell:\n  backend: hw\ndevices:\n  gripper:\n    open_count: 3\n    closed_count: 228\n"
        + FORCES,
        "hw.yaml")
    backend = hardware.open_hardware(prepare(config, doc))
    assert "calibrate" not in made["gripper"].calls
    assert (seen["gripper"].open_count, seen["gripper"].closed_count) == (3, 228)  # type: ignore[attr-defined]
    backend.close()


def test_a_gripper_that_holds_something_is_not_opened_to_calibrate_it(monkeypatch) -> None:
    made: dict[str, _Dev] = {}

    def opener(name: str):
        def make(cfg, layout, clock):  # type: ignore[no-untyped-def]
            made[name] = _Dev(name)
            if name == "gripper":
                made[name].object_detected = lambda: True  # type: ignore[method-assign]
            return made[name]

        return make

    monkeypatch.setattr(hardware, "OPENERS", {n: opener(n) for n in hardware.DEVICES})
    with pytest.raises(ConfigError, match="holds something.*open_count and closed_count"):
        hardware.open_hardware(_prep())
    assert "calibrate" not in made["gripper"].calls and "bias" not in made["ft"].calls


def test_the_arms_watchdog_is_armed_at_10_hz_unless_configured_and_reaches_the_driver(
        monkeypatch) -> None:
    from drivers.ur5.arm import UR5Arm

    seen: list[object] = []
    monkeypatch.setattr(UR5Arm, "connect",
                        classmethod(lambda cls, host, **kw: seen.append(kw["settings"])))
    for text, hz in (("", 10.0), ("devices:\n  arm:\n    watchdog_hz: 2\n", 2.0),
                     ("devices:\n  arm:\n    watchdog_hz: null\n", None)):
        prep = _prep("cell:\n  backend: hw\n" + FORCES + text)
        hardware._open_arm(prep.config.devices, prep.layout, None)
        assert seen[-1].watchdog_hz == hz  # type: ignore[attr-defined]


def test_the_watchdog_is_armed_on_the_first_tick_not_during_the_start_up() -> None:
    """The start-up polls the arm less often than a 10 Hz watchdog needs: the backend arms it
    once, on its first step, and polls the arm every step after."""
    from drivers.ur5.arm import UR5Arm, UR5Settings
    from tests.drivers.ur5.recording_adapter import FakeClock, RecordingAdapter

    rtde = RecordingAdapter()
    arm = UR5Arm(rtde, FakeClock(), UR5Settings(watchdog_hz=10.0), spawn=lambda f: f())
    assert "set_watchdog" not in rtde.names(include_reads=True)  # connected, not armed
    backend = hardware.HardwareBackend(Devices(arm, None, None, None), None)  # type: ignore[arg-type]
    for _ in range(3):
        backend.step()
    names = rtde.names(include_reads=True)
    assert names.count("set_watchdog") == 1
    assert names.index("set_watchdog") < names.index("kick_watchdog")
    # polled every step (kicked as often as the watchdog needs: the clock stands still here)
    assert names.count("safety_status_bits") == 3


def test_a_controller_tcp_other_than_the_models_is_refused_before_anything_moves(
        monkeypatch) -> None:
    made: dict[str, _Dev] = {}

    def opener(name: str):
        def make(cfg, layout, clock):  # type: ignore[no-untyped-def]
            made[name] = _Dev(name)
            if name == "arm":  # PolyScope's TCP 20 mm shorter than the model's
                tcp = made[name].tcp
                made[name].tcp = Pose(tcp.position - 0.02 * tcp.rotation[:, 2], tcp.rotation)
            return made[name]

        return make

    monkeypatch.setattr(hardware, "OPENERS", {n: opener(n) for n in hardware.DEVICES})
    with pytest.raises(ConfigError) as info:
        hardware.open_hardware(_prep())
    text = str(info.value)
    assert "nothing moved" in text and "20.0 mm" in text and "set the TCP in PolyScope" in text
    assert "bias" not in made["ft"].calls and "calibrate" not in made["gripper"].calls
    assert made["arm"].calls[-2:] == ["stop", "close"]
