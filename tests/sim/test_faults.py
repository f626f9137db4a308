"""Fault injection (sim/faults.py) on fake devices: each wrapper injects its fault at its rate,
deterministically with a seed, and the tree answers a fault the way it answers a real one."""

from __future__ import annotations

import numpy as np
import py_trees
import pytest
from py_trees.common import Status

from drivers.arm import Arm, MotionState
from drivers.camera import Camera, Frame, Intrinsics
from drivers.devices import Devices
from drivers.ft_sensor import ForceTorqueSensor
from drivers.gripper import Gripper
from drivers.health import DeviceError
from drivers.pose import Pose
from sim.faults import (
    DEFAULT_RATES,
    FAULT_NAMES,
    GRIPPER_FAULT_CODE,
    SLIP_FRICTION,
    FaultInjector,
    TwinHooks,
    check_rates,
    no_faults,
)
from tests.skills.fakes import FakeArm, FakeClock, FakeFT, FakeGripper
from tests.trees.helpers import make_ctx
from trees import behaviours as lv
from trees.decorators import FTGuard, FTSampler


class FakeCamera:
    def __init__(self) -> None:
        self.frames = 0

    def intrinsics(self) -> Intrinsics:
        return Intrinsics(4, 3, 2.0, 2.0, 1.5, 1.0)

    def tool_T_camera(self) -> Pose:
        return Pose()

    def capture(self) -> Frame:
        self.frames += 1
        return Frame(np.zeros((3, 4, 3), np.uint8), np.full((3, 4), 0.5, np.float32), 0.0)


def _rig(rates: dict[str, float], seed: int = 0, hooks: TwinHooks | None = None):
    clock = FakeClock()
    raw = Devices(FakeArm(ticks_per_move=1000), FakeGripper(), FakeFT(), clock, FakeCamera())
    inj = FaultInjector({**no_faults(), **rates}, seed, clock, clock.dt, hooks)
    return inj, raw, inj.wrap(raw)


def _step(inj: FaultInjector, raw: Devices, n: int = 1) -> None:
    """What the world's step does: devices move, the clock advances, the injector ticks."""
    for _ in range(n):
        raw.arm.tick()
        raw.gripper.tick()
        raw.clock.t += raw.clock.dt
        inj.tick()


def test_the_wrappers_implement_the_device_interfaces() -> None:
    _, _, dev = _rig({})
    assert isinstance(dev.arm, Arm) and isinstance(dev.gripper, Gripper)
    assert isinstance(dev.ft, ForceTorqueSensor) and isinstance(dev.camera, Camera)
    assert dev.gripper.stroke == 0.085 and dev.gripper.finger_width == 0.020


def test_rates_are_checked_and_default_rates_name_every_fault() -> None:
    assert set(DEFAULT_RATES) == set(FAULT_NAMES)
    assert all(0.0 <= r <= 1.0 for r in DEFAULT_RATES.values())
    with pytest.raises(ValueError, match="unknown fault 'gremlins'"):
        check_rates({"gremlins": 0.1})
    with pytest.raises(ValueError, match=r"faults.rates.ft_spike: .* \[0, 1\], got 1.5"):
        check_rates({"ft_spike": 1.5})


def test_config_fields_are_the_fault_names() -> None:
    from cell.config import FaultRates

    assert tuple(FaultRates.model_fields) == FAULT_NAMES


def test_no_faults_passes_everything_through() -> None:
    inj, raw, dev = _rig({})
    dev.gripper.close(15.0)
    _step(inj, raw)
    assert raw.gripper.closed_on is not None
    dev.arm.move_to(Pose(np.array([0.5, 0.0, 0.2])), 0.1, 0.5)
    _step(inj, raw, 100)
    assert dev.camera.capture().depth.max() > 0
    assert not np.any(dev.ft.wrench())
    assert sum(inj.injected.values()) == 0


@pytest.mark.parametrize("rate", [0.1, 0.4])
def test_missed_grasp_at_its_rate_and_deterministic(rate: float) -> None:
    def misses(seed: int) -> list[bool]:
        inj, raw, dev = _rig({"missed_grasp": rate}, seed)
        out = []
        for _ in range(2000):
            raw.gripper.closed_on = None
            dev.gripper.close(2.0)
            out.append(raw.gripper.closed_on is None)  # not executed
            dev.gripper.open()
        assert inj.opportunities["missed_grasp"] == 2000
        assert inj.injected["missed_grasp"] == sum(out)
        return out

    a = misses(7)
    assert abs(np.mean(a) - rate) < 0.03
    assert a == misses(7)  # the same seed: the same faults
    assert a != misses(8)


def test_camera_lost_and_invalid_at_their_rates() -> None:
    inj, _, dev = _rig({"camera_lost": 0.2, "camera_invalid": 0.3}, seed=3)
    lost = invalid = 0
    for _ in range(3000):
        try:
            frame = dev.camera.capture()
        except TimeoutError as exc:
            assert "no frame" in str(exc)
            lost += 1
            continue
        if not frame.depth.any():
            invalid += 1
    assert abs(lost / 3000 - 0.2) < 0.025
    assert abs(invalid / (3000 - lost) - 0.3) < 0.03
    assert inj.opportunities["camera_invalid"] == 3000 - lost


def test_ft_spike_is_large_and_lasts_one_to_three_samples() -> None:
    inj, raw, dev = _rig({"ft_spike": 1.0}, seed=1)
    dev.arm.move_to(Pose(np.array([0.5, 0.0, 0.2])), 0.1, 0.5)
    forces = []
    for _ in range(80):
        _step(inj, raw)
        forces.append(float(np.linalg.norm(dev.ft.wrench()[:3])))
    big = [f > 150.0 for f in forces]
    assert 1 <= sum(big) <= 3 and forces.index(max(forces)) < 64  # within 0.5 s
    first = big.index(True)
    assert all(big[first : first + sum(big)])  # one burst
    assert inj.injected["ft_spike"] == 1


def test_arm_faults_are_drawn_per_motion_command_at_their_rate() -> None:
    inj, raw, dev = _rig({"protective_stop": 0.25}, seed=5)
    stops = 0
    for _ in range(400):
        dev.arm.move_to(Pose(np.array([0.5, 0.0, 0.2])), 0.1, 0.5)
        _step(inj, raw, 65)  # past the longest delay
        stops += dev.arm.status().protective_stop
    assert inj.opportunities["protective_stop"] == 400
    assert abs(stops / 400 - 0.25) < 0.06
    assert inj.injected["protective_stop"] == stops


def test_protective_stop_holds_the_arm_until_the_next_motion_command() -> None:
    inj, raw, dev = _rig({"protective_stop": 1.0})
    dev.arm.move_to(Pose(np.array([0.5, 0.0, 0.2])), 0.1, 0.5)
    _step(inj, raw, 64)
    st = dev.arm.status()
    assert st.state is MotionState.FAULT and st.protective_stop and "protective stop" in st.message
    assert raw.arm.stops == 1  # the arm itself stopped
    before = raw.arm.pose
    dev.arm.servo(Pose(np.array([0.9, 0.9, 0.9])))
    assert raw.arm.pose is before  # servo targets are refused
    inj.rates["protective_stop"] = 0.0
    dev.arm.move_to(Pose(np.array([0.5, 0.0, 0.3])), 0.1, 0.5)
    assert dev.arm.status().state is MotionState.MOVING


def test_link_lost_raises_device_error_for_some_samples_then_recovers() -> None:
    inj, raw, dev = _rig({"link_lost": 1.0}, seed=2)
    dev.arm.move_joints(np.zeros(6), 1.0, 2.0)
    lost = []
    for _ in range(130):
        _step(inj, raw)
        try:
            dev.ft.wrench()
            lost.append(False)
        except DeviceError as exc:
            assert "FT300" in str(exc) and "link loss" in str(exc)
            lost.append(True)
    assert 5 <= sum(lost) <= 50
    assert not lost[-1]


def test_gripper_fault_reports_a_code_for_a_while_and_refuses_commands() -> None:
    inj, raw, dev = _rig({"gripper_fault": 1.0})
    dev.gripper.close(15.0)
    assert dev.gripper.fault() == GRIPPER_FAULT_CODE and raw.gripper.closed_on is None
    inj.rates["gripper_fault"] = 0.0
    dev.gripper.open(0.05)
    assert raw.gripper._target == 0.085  # refused while faulted
    _step(inj, raw, int(2.0 / raw.clock.dt) + 2)
    assert dev.gripper.fault() is None
    dev.gripper.open(0.05)
    assert raw.gripper._target == 0.05


def test_slip_in_tilt_drops_the_finger_friction_briefly() -> None:
    calls: list[tuple[float, float]] = []
    hooks = TwinHooks(set_friction=lambda a, b: calls.append((a, b)), friction=(0.2, 0.4))
    inj, raw, dev = _rig({"slip_in_tilt": 1.0}, hooks=hooks)
    dev.gripper.close(2.0)  # the pivot's light pinch
    _step(inj, raw, 5)
    assert not calls  # no Tilt yet: the tool has not turned
    for k in range(1, 400):  # the Tilt turns the tool, 0.1 deg a tick
        raw.arm.pose = Pose(raw.arm.pose.position, _rot_y(np.radians(0.1 * k)))
        _step(inj, raw)
    assert calls[0] == (SLIP_FRICTION, SLIP_FRICTION) and calls[-1] == (0.2, 0.4)
    assert len(calls) == 2 and inj.injected["slip_in_tilt"] == 1


def test_drop_in_transit_opens_the_jaws_between_stations_only() -> None:
    hooks = TwinHooks(stations=((0.2, 0.7, -0.2, 0.2), (0.0, 0.2, 0.35, 0.55)))
    inj, raw, dev = _rig({"drop_in_transit": 1.0}, hooks=hooks)
    raw.arm.pose = Pose(np.array([0.45, 0.0, 0.2]))  # over the bin
    dev.gripper.close(15.0)  # the hole grasp
    _step(inj, raw, 200)
    assert raw.gripper.closed_on is not None  # at a station: held
    raw.arm.pose = Pose(np.array([0.3, 0.3, 0.3]))  # between the bin and the machine
    _step(inj, raw, 110)
    assert raw.gripper.closed_on is None and raw.gripper._target == 0.085  # opened: dropped
    assert inj.injected["drop_in_transit"] == 1 and inj.opportunities["drop_in_transit"] == 1


def test_reset_clears_pending_and_active_faults() -> None:
    inj, raw, dev = _rig({"link_lost": 1.0, "gripper_fault": 1.0})
    dev.arm.move_to(Pose(np.array([0.5, 0.0, 0.2])), 0.1, 0.5)
    dev.gripper.open()
    assert dev.gripper.fault() is not None
    inj.reset()
    assert dev.gripper.fault() is None
    _step(inj, raw, 80)
    dev.ft.wrench()  # the pending link loss was cleared


# ------------------------------------------------------------- the tree's answer to faults
def test_an_ft_spike_aborts_the_running_motion_with_the_reason() -> None:
    py_trees.blackboard.Blackboard.clear()
    ctx = make_ctx()
    raw = ctx.devices
    raw.arm.ticks_per_move = 1000
    inj = FaultInjector({**no_faults(), "ft_spike": 1.0}, 0, raw.clock, raw.clock.dt)
    ctx.devices = inj.wrap(raw)
    leaf = lv.GoHome("home", ctx)
    guard = FTGuard("home ft guard", leaf, ctx, max_force=80.0, max_torque=8.0)
    root = py_trees.composites.Parallel(
        "root",
        policy=py_trees.common.ParallelPolicy.SuccessOnSelected(children=[guard]),
        children=[FTSampler("ft", ctx), guard],
    )
    for _ in range(100):
        root.tick_once()
        if root.status != Status.RUNNING:
            break
        raw.arm.tick()
        raw.clock.t += raw.clock.dt
        inj.tick()
    assert guard.status == Status.FAILURE and leaf.status == Status.INVALID
    assert raw.arm.state is MotionState.STOPPED
    assert "force-torque abort" in ctx.events.aborts[-1] and "limit 80" in ctx.events.aborts[-1]


def _rot_y(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]]) @ np.diag([1.0, -1.0, -1.0])
