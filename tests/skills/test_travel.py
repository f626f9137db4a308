"""The travel by joint move: made only where its swept path is as clear as the straight one."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cell.catalogue import load_catalogue
from cell.reach import UR5_MODEL
from drivers.pose import Pose
from drivers.ur5.kinematics import HOME_JOINTS, forward_kinematics, solve_ik
from skills.packing import PackInBox
from skills.slot import FeedSlot
from skills.status import Status
from skills.travel import ArmModel, JointMove, joint_goal, sweep
from tests.skills.fakes import FakeArm, FakeClock, FakeFT, FakeGripper, run
from tests.skills.test_slot_packing_fakes import PACK_CONTACTS, PLACE, SLOT, push_back

PART = load_catalogue().get("bushing")
DOWN = np.diag([1.0, -1.0, -1.0])


def _yaw(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def toy(height: callable, tilt: callable = lambda q: 0.0) -> ArmModel:  # type: ignore[valid-type]
    """A toy arm whose first joint swings the TCP round the base axis at 0.5 m, its height and
    tilt given as functions of the joints: the checks, not the UR5, under test."""

    def forward(q: np.ndarray) -> Pose:
        pos = np.array([0.5 * math.cos(q[0]), 0.5 * math.sin(q[0]), height(q)])
        c, s = math.cos(tilt(q)), math.sin(tilt(q))
        tilted = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
        return Pose(pos, tilted @ DOWN)

    return ArmModel(solve=lambda pose, q: np.array([math.atan2(*pose.position[1::-1])] + [0] * 5),
                    forward=forward)


def q(angle: float) -> np.ndarray:
    return np.array([angle, 0.0, 0.0, 0.0, 0.0, 0.0])


def test_a_sweep_that_dips_below_the_leg_is_refused() -> None:
    # the TCP's height falls by 50 mm half way round the swing and rises again
    model = toy(lambda q: 0.2 - 0.05 * math.sin(abs(q[0])))
    assert "below the leg" in (sweep(model, q(0.0), q(math.pi), 0.3)[0] or "")
    level = toy(lambda q: 0.2)
    assert sweep(level, q(0.0), q(math.pi), 0.3)[0] is None


def test_a_sweep_that_tilts_the_tool_more_than_its_ends_is_refused() -> None:
    model = toy(lambda q: 0.2, tilt=lambda q: 0.3 * math.sin(q[0]))
    assert "tilt" in (sweep(model, q(0.0), q(math.pi), 0.3)[0] or "")


def test_a_sweep_nearer_the_base_than_the_straight_path_may_is_refused() -> None:
    # a toy whose TCP passes the base axis: radius 0.5 |cos|, through 0 at 90 deg
    def forward(j: np.ndarray) -> Pose:
        return Pose(np.array([0.5 * math.cos(j[0]), 0.0, 0.2]), DOWN)

    model = ArmModel(solve=lambda pose, j: j, forward=forward)
    assert "base axis" in (sweep(model, q(0.0), q(math.pi), 0.3)[0] or "")


def test_no_joint_move_from_below_the_target_nor_without_the_arms_model() -> None:
    model = toy(lambda q: 0.1 + 0.1 * q[0])  # rising with the swing
    target = Pose(np.array([0.0, 0.5, 0.2]), DOWN)
    assert joint_goal(model, q(0.0), target, 0.3) is None  # start 0.1 m, the target 0.2 m
    assert joint_goal(None, HOME_JOINTS, target, 0.3) is None
    ahead = toy(lambda q: 0.2)
    assert joint_goal(ahead, q(0.0), target, 0.3) is not None


def test_the_ur5s_joint_goal_reaches_the_pose_the_short_way_round() -> None:
    home = forward_kinematics(HOME_JOINTS)
    target = Pose(np.array([0.2, -0.45, 0.18]), _yaw(math.radians(135.0)) @ home.rotation)
    move = joint_goal(UR5_MODEL, HOME_JOINTS, target, 0.3)
    assert move is not None
    goal = move.goal
    pos_err, ang_err = forward_kinematics(goal).distance(target)
    assert pos_err < 1e-6 and ang_err < 1e-6
    # the solve alone turned the last joint by 201 deg; a whole turn less is the same pose
    assert np.max(np.abs(goal - HOME_JOINTS)) < math.pi


def _inverse(pose: Pose, q: np.ndarray) -> np.ndarray:
    return solve_ik(pose, q, iterations=200)[0]


def ur5_devices(q: np.ndarray = HOME_JOINTS) -> dict:
    arm = FakeArm(forward_kinematics(q))
    arm.forward, arm.inverse, arm.q = forward_kinematics, _inverse, q.copy()
    return {"arm": arm, "gripper": FakeGripper(0.007), "ft": FakeFT(), "clock": FakeClock()}


def dev(d: dict):  # type: ignore[no-untyped-def]
    from drivers.devices import Devices

    return Devices(d["arm"], d["gripper"], d["ft"], d["clock"])


@pytest.mark.parametrize("model, joint_speed, joint", [
    (UR5_MODEL, 2.0, True), (None, 2.0, False), (UR5_MODEL, 0.0, False),
])
def test_the_feed_travels_over_the_slot_by_a_joint_move_where_it_may(
    model: ArmModel | None, joint_speed: float, joint: bool
) -> None:
    d = ur5_devices()
    feed = FeedSlot(SLOT, PART, dev(d), arm_model=model, joint_speed=joint_speed,
                    weight_check=0.0)
    seen: list[tuple[str, str]] = []  # (the step, each command it gave)
    arm = d["arm"]

    def on_tick(_: int) -> None:
        seen.extend((feed.step, kind) for kind, _ in arm.commands[len(seen):])
        if feed.step == "into the slot" and arm.queue:
            arm.pose = arm.queue[-1]
            push_back(d, (0.0, 0.0, 10.0))

    result, _ = run(feed, d, on_tick=on_tick)
    assert result.status is Status.SUCCESS, result.message
    assert feed.joint_travel is joint
    kinds = [kind for step, kind in seen if step == "over the slot"]
    assert kinds == ["joints" if joint else "path"]
    if joint:  # the joint move ended where the straight path would have: over the slot
        over = forward_kinematics(arm.commands[[c[0] for c in arm.commands].index("joints")][1])
        assert np.linalg.norm(over.position[:2] - SLOT[:2]) < 0.05


def test_the_packing_travels_over_the_place_by_a_joint_move() -> None:
    d = ur5_devices()
    pack = PackInBox(PLACE, PART, dev(d), arm_model=UR5_MODEL, joint_speed=2.0,
                     weight_check=0.0)
    arm = d["arm"]

    def on_tick(_: int) -> None:
        arm.blocked = pack.step in PACK_CONTACTS
        if pack.step in PACK_CONTACTS and arm.force is not None:
            push_back(d, PACK_CONTACTS[pack.step])
        elif pack.step not in PACK_CONTACTS:
            d["ft"].value = np.zeros(6)

    result, _ = run(pack, d, on_tick=on_tick)
    assert result.status is Status.SUCCESS, result.message
    # from home, above the travel height: the rise stays where it is, then the joint move
    assert pack.joint_travel and [c[0] for c in arm.commands[:2]] == ["path", "joints"]
    assert np.allclose(arm.commands[0][1][0].position, forward_kinematics(HOME_JOINTS).position)


def test_the_feed_rises_straight_to_the_travel_height_before_its_joint_move() -> None:
    # the part lifted by Align still inside the bin: 100 mm below home, over the bin
    low = Pose(np.array([0.45, 0.05, 0.10]), forward_kinematics(HOME_JOINTS).rotation)
    d = ur5_devices(_inverse(low, HOME_JOINTS))
    feed = FeedSlot(SLOT, PART, dev(d), arm_model=UR5_MODEL, joint_speed=2.0, weight_check=0.0)
    arm = d["arm"]

    def on_tick(_: int) -> None:
        if feed.step == "into the slot" and arm.queue:
            arm.pose = arm.queue[-1]
            push_back(d, (0.0, 0.0, 10.0))

    result, _ = run(feed, d, on_tick=on_tick)
    assert result.status is Status.SUCCESS, result.message
    (kind, rise), (kind2, _) = arm.commands[0], arm.commands[1]
    assert kind == "path" and kind2 == "joints" and feed.joint_travel
    top = rise[-1].position
    assert np.allclose(top[:2], [0.45, 0.05], atol=1e-6)  # straight up from where it was
    assert top[2] == pytest.approx(feed._travel_target().position[2])


def test_the_joints_slow_so_the_tcp_keeps_its_limit() -> None:
    swing = toy(lambda q: 0.2)  # the TCP 0.5 m from the base axis: 0.5 m per rad of the base
    problem, per_rad = sweep(swing, q(0.0), q(1.0), 0.3)
    assert problem is None and per_rad == pytest.approx(0.5, rel=1e-3)
    move = JointMove(q(1.0), per_rad)
    assert move.joint_speed(3.0, 1.0) == pytest.approx(2.0, rel=1e-3)  # 1 m/s at 0.5 m
    assert move.joint_speed(1.5, 1.0) == pytest.approx(1.5)  # under the limit already


def test_the_ur5s_joint_goal_keeps_the_arms_branch() -> None:
    home = forward_kinematics(HOME_JOINTS)
    # the same TCP pose with the elbow on its other side
    down, miss = solve_ik(home, np.array([2.6, -0.3, -1.4, -2.9, -1.57, -1.8]), 300)
    assert miss < 1e-6 and math.sin(down[2]) * math.sin(HOME_JOINTS[2]) < 0
    for start in (HOME_JOINTS, down):
        for x, y in ((0.2, -0.45), (0.1, 0.45), (0.6, 0.1)):
            goal = UR5_MODEL.solve(Pose(np.array([x, y, 0.2]), home.rotation), start)
            assert goal is not None and (
                math.sin(goal[2]) * math.sin(start[2]) > 0
                and math.sin(goal[4]) * math.sin(start[4]) > 0
            )
