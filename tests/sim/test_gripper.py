"""The twin's gripper: widths, force-limited closing, stall detection, finger friction."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.arm import MotionState
from drivers.pose import Pose
from drivers.ur5.kinematics import HOME_TCP
from sim.robot import SimRobot
from sim.world import SimWorld

from .conftest import add_box, add_floor, run_motion, run_until


def test_opens_and_closes_to_a_width(world: SimWorld, robot: SimRobot) -> None:
    g = robot.gripper
    assert (g.stroke, g.finger_width) == (0.085, 0.020)
    assert g.width() == pytest.approx(0.085)
    assert not g.moving() and g.fault() is None
    g.open(0.03, speed=0.1)
    assert g.moving()
    elapsed = run_until(world, lambda: not g.moving(), 2.0)
    assert g.width() == pytest.approx(0.03, abs=2e-3)
    assert not g.object_detected()
    assert elapsed < 0.5  # 27.5 mm per finger at 0.1 m/s, plus the approach
    g.open()
    run_until(world, lambda: not g.moving(), 2.0)
    assert g.width() == pytest.approx(0.085, abs=2e-3)
    for _ in range(50):
        world.step()
    assert g.width() == pytest.approx(0.085, abs=2e-4)


def test_closing_on_nothing_closes_fully(world: SimWorld, robot: SimRobot) -> None:
    g = robot.gripper
    g.close(force=40.0, speed=0.1)
    run_until(world, lambda: not g.moving(), 2.0)
    assert not g.object_detected()
    assert g.width() < 2e-3


def test_closing_on_a_box_stalls_and_detects_it(world: SimWorld) -> None:
    add_floor(world)
    robot = SimRobot(world)
    box = add_box(world, [0.02, 0.015, 0.03], [0.5, 0.0, 0.03], mass=0.1)  # 40 mm along x
    robot.arm.move_to(Pose(np.array([0.5, 0.0, 0.04]), HOME_TCP.rotation), 0.2, 1.0)
    run_motion(world, robot)
    g = robot.gripper
    g.close(force=40.0, speed=0.05)
    run_until(world, lambda: not g.moving(), 2.0)
    assert g.object_detected()
    assert g.width() == pytest.approx(0.040, abs=1.5e-3)
    # The pinch holds the box up while the arm lifts it.
    robot.arm.move_to(Pose(np.array([0.5, 0.0, 0.14]), HOME_TCP.rotation), 0.1, 0.5)
    run_motion(world, robot)
    assert robot.arm.status().state is MotionState.DONE
    assert world.p.getBasePositionAndOrientation(box)[0][2] == pytest.approx(0.13, abs=3e-3)
    assert g.object_detected()
    # Letting go: the fingers open and the detection clears.
    g.open()
    run_until(world, lambda: not g.moving(), 2.0)
    assert not g.object_detected()
    assert g.width() == pytest.approx(0.085, abs=2e-3)


@pytest.mark.parametrize(("force", "applied"), [(2.0, 20.0), (20.0, 20.0), (25.0, 25.06)])
def test_grip_force_is_what_the_unit_applies(
    world: SimWorld, force: float, applied: float
) -> None:
    """The 2F-85 cannot grip below 20 N (its force register's 0): asked for 2 N it grips with
    20 N; in range, the register's step. Above about 30 N per finger the coupled twin saturates
    (see docs/design.md)."""
    add_floor(world)
    robot = SimRobot(world)
    box = add_box(world, [0.02, 0.015, 0.03], [0.5, 0.0, 0.03], mass=0.1)
    robot.arm.move_to(Pose(np.array([0.5, 0.0, 0.04]), HOME_TCP.rotation), 0.2, 1.0)
    run_motion(world, robot)
    robot.gripper.close(force=force)
    run_until(world, lambda: not robot.gripper.moving(), 2.0)
    for _ in range(10):
        world.step()
    for name in ("finger_a", "finger_b"):
        link = robot.gripper.finger_link(name)
        contacts = world.p.getContactPoints(robot.body_id, box, link)
        normal = sum(c[9] for c in contacts)
        assert normal == pytest.approx(applied, rel=0.05), name


def test_finger_friction_and_links(robot: SimRobot) -> None:
    g, p = robot.gripper, robot.world.p
    g.set_finger_friction(0.4, 0.2)
    assert p.getDynamicsInfo(robot.body_id, g.finger_link("finger_a"))[1] == pytest.approx(0.4)
    assert p.getDynamicsInfo(robot.body_id, g.finger_link("finger_b"))[1] == pytest.approx(0.2)
    assert g.finger_link("finger_a") == robot.link_index["finger_a"]
    with pytest.raises(ValueError, match="finger_a, finger_b"):
        g.finger_link("thumb")
    with pytest.raises(ValueError):
        g.set_finger_friction(-0.1, 0.2)


@pytest.mark.parametrize("self_locking", [True, False])
def test_a_self_locking_pinch_is_not_pushed_open(world: SimWorld, self_locking: bool) -> None:
    """Pushing finger_a outwards with 3x the grip force: the 2F-85's lead screw holds; a plain
    force-limited finger yields."""
    add_floor(world)
    robot = SimRobot(world, gripper_self_locking=self_locking)
    add_box(world, [0.02, 0.015, 0.03], [0.5, 0.0, 0.03], mass=0.1)
    robot.arm.move_to(Pose(np.array([0.5, 0.0, 0.04]), HOME_TCP.rotation), 0.2, 1.0)
    run_motion(world, robot)
    g = robot.gripper
    g.close(force=20.0)
    run_until(world, lambda: not g.moving(), 2.0)
    gripped = g.width()
    link = g.finger_link("finger_a")
    outwards = robot.link_pose("tcp").rotation[:, 0] * 60.0  # tool +x, N

    def push() -> None:
        at = robot.link_pose("finger_a").position.tolist()
        world.p.applyExternalForce(robot.body_id, link, outwards.tolist(), at, world.p.WORLD_FRAME)

    world.before_substep(push)
    for _ in range(50):
        world.step()
    if self_locking:
        assert g.width() == pytest.approx(gripped, abs=5e-4)
        assert g.object_detected()
    else:
        assert g.width() > gripped + 2e-3
    # Opening releases the lock either way.
    g.open()
    run_until(world, lambda: not g.moving(), 2.0)
    assert g.width() > 0.08


def test_the_tips_advance_along_the_approach_as_the_jaws_close(world: SimWorld) -> None:
    """The 2F-85's linkage: closing from full open to 10 mm moves each pad's tip along the tool's
    z axis by what the description's crank gives (13 mm over the stroke), the coupled lift
    joint following the closing one."""
    robot = SimRobot(world)
    g = robot.gripper
    spec = g.spec

    def tip_depth() -> float:
        tcp = robot.link_pose("tcp")
        tip = robot.fingertip("finger_a")
        return float((tip - tcp.position) @ tcp.rotation[:, 2])

    run_until(world, lambda: not g.moving(), 2.0)
    open_depth = tip_depth()
    g.close(force=20.0, speed=0.15, width=0.010)
    run_until(world, lambda: not g.moving(), 3.0)
    for _ in range(10):
        world.step()
    travel = tip_depth() - open_depth
    expected = spec.tip_advance(g.true_width()) - spec.tip_advance(spec.stroke)
    assert expected > 0.012
    assert travel == pytest.approx(expected, abs=3e-4)


def test_the_opening_is_reported_in_counts_at_the_poll_rate(world: SimWorld) -> None:
    """What a skill reads is the unit's position count, refreshed at the driver's poll rate: it
    changes in steps of one count and holds between polls."""
    robot = SimRobot(world)
    g = robot.gripper
    step = g.spec.count_step
    g.close(force=20.0, speed=0.05, width=0.0)
    seen = []
    for _ in range(40):
        world.step()
        seen.append(g.width())
    for w in seen:
        assert (g.spec.stroke - w) / step == pytest.approx(round((g.spec.stroke - w) / step),
                                                            abs=1e-6)
    changes = sum(1 for a, b in zip(seen, seen[1:], strict=False) if a != b)
    polls = 40 * g.spec.poll_hz / world.settings.control_hz
    assert changes <= polls + 1
    assert changes >= 0.5 * polls


def _watch_states(g, states) -> int:  # type: ignore[no-untyped-def]
    """Feed ``g`` the given per-step ``(qa, va, qb, vb)`` joint states as its watch reads
    them after each control step; the step index where it first reported a stall, or -1."""
    for k, (qa, va, qb, vb) in enumerate(states):
        g._watch([(qa, va), (qb, vb)])
        if g._stalled:
            return k
    return -1


def test_a_pinch_stalls_on_the_fingers_positions_not_on_the_solvers_finger_speeds(
    world: SimWorld, robot: SimRobot
) -> None:
    """In a stiff pinch the twin's fingers stand still to 0.01 mm while PyBullet reports their
    speeds at +-10 mm/s tick to tick (measured on a 4 mm wall): that is a stall, as a position
    sensor tells it. A finger still moving, even with the other one stopped, closes on."""
    g = robot.gripper
    steps = g._stall_steps + 3
    noisy = [(0.0018, 0.010 * (-1) ** k, 0.0017, -0.008 * (-1) ** k) for k in range(steps * 3)]
    g.close(force=20.0, speed=0.02)
    assert _watch_states(g, noisy) >= 0
    dt = world.settings.control_dt
    one = [(0.0018, 0.0, 0.02 - 0.005 * dt * k, -0.005) for k in range(steps * 3)]
    g.close(force=20.0, speed=0.02)
    assert _watch_states(g, one) == -1
    closing = [(0.02 - 0.01 * dt * k, -0.01, 0.02 - 0.01 * dt * k, -0.01) for k in range(steps * 3)]
    g.close(force=20.0, speed=0.02)
    assert _watch_states(g, closing) == -1
