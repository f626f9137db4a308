"""A bushing left resting on another one (one end on the floor, the middle on its neighbour):
the pivot needs its far corner on the floor, so the cell lays it down first -- pinched where it
is, lifted clear, carried to where a pivot clears and lowered until it touches. Judged from the
twin's state: the part ends lying level on the floor, where it was carried (less its fall flat)."""

from __future__ import annotations

import math

import numpy as np

from cell.catalogue import load_catalogue
from cell.reach import ur5_reach
from drivers.parts import Gripper
from drivers.pose import Pose
from sim.camera import SimCamera, default_tool_T_camera
from sim.part_body import lying_pose, spawn_part
from sim.scenes import look_down_pose
from skills.mechanics.contact import Frictions
from skills.mechanics.planner import plan_pivot
from skills.perception.bin_parts import detect_parts
from skills.pivot.clearance import bin_walls, lying_part
from skills.pivot.frame import PivotFrame
from skills.pivot.params import PivotParams
from skills.reposition import MoveKind, Reposition, RepositionParams, plan_lay_down
from tests.skills.twin import make_twin


def test_a_bushing_resting_on_another_is_laid_down_level_on_the_floor() -> None:
    tw = make_twin(seed=7, spots=())
    try:
        part, layout = tw.part, tw.layout
        floor = layout.bin_floor_z
        under = (0.45, 0.0)
        spawn_part(tw.world, part, lying_pose(part, *under, 0.5 * math.pi, floor))
        # across it at 33 deg: one end on the floor, a bottom edge 6 mm from its other end
        # on the neighbour's top (as a tipped bin leaves one)
        theta, s_edge = math.radians(33.0), 0.006
        rot = np.array([[math.cos(theta), 0.0, math.sin(theta)], [0.0, 1.0, 0.0],
                        [-math.sin(theta), 0.0, math.cos(theta)]])
        u, n = rot[:, 0], rot[:, 2]
        edge = np.array([under[0], under[1], floor + part.outer + 0.002])
        centre = edge - (s_edge - 0.5 * part.length) * u + 0.5 * part.outer * n
        top = spawn_part(tw.world, part, Pose(centre, rot))
        tw.settle(1.5)
        pose = top.pose()
        axis = top.axis()
        raise_before = float(pose.position[2]) - floor - 0.5 * part.outer
        assert raise_before > 0.008, "the part should rest raised on its neighbour"
        assert abs(axis[2]) > math.sin(math.radians(4.0)), "and lean"

        x0, x1, y0, y1 = layout.bin_interior()
        roi = (x0, x1, y0, y1)
        walls = bin_walls(roi, floor, layout.bin_wall_height, layout.bin_wall_thickness)
        neighbour = lying_part("a neighbour", under, 0.5 * math.pi, part.length, part.outer,
                               floor)
        width = tw.dev.gripper.finger_width
        # as the cell's wide view sees it
        tool = look_down_pose(layout.bin_center, 0.5, default_tool_T_camera())
        cam = SimCamera(tw.world, lambda: tool)
        dets = detect_parts(cam.capture(), cam.intrinsics(), tool @ cam.tool_T_camera(),
                            [part], roi)
        d = min(dets, key=lambda d: float(np.hypot(*(d.center[:2] - pose.position[:2]))))
        assert float(np.hypot(*(d.center[:2] - pose.position[:2]))) < 0.01
        # seen raised: leaning, its axis' height at its middle as it is
        assert d.tilted
        assert abs(float(d.center[2]) - float(pose.position[2])) < 0.005
        assert abs(d.raised - raise_before) < 0.005
        lying = PivotFrame(part.section(width),
                           np.array([d.center[0], d.center[1], floor + 0.5 * part.outer]),
                           d.yaw, floor_z=floor)
        plan_ = plan_pivot(part, Gripper(), Frictions())
        pivot = PivotParams(l_a=plan_.l_a, alpha=plan_.alpha)
        params = RepositionParams()
        move = plan_lay_down(lying, 0.5 * part.outer + d.raised, part, pivot, params, walls,
                             [neighbour], roi, width, reach=ur5_reach, leaning=d.tilted)
        assert move is not None and move.kind is MoveKind.LAY_DOWN
        assert move.drop > 0.008

        failure = tw.run(Reposition(move, part, tw.dev, params), 40.0)
        assert failure is None, failure
        tw.settle(0.5)
        after = top.pose()
        # lying level on the floor, no longer on its neighbour, about where the plan put it
        assert abs(top.axis()[2]) < math.sin(math.radians(2.0))
        assert abs(float(after.position[2]) - floor - 0.5 * part.outer) < 0.003
        # let go with its low end on the floor, it falls flat about that end: its centre comes
        # back towards the high end by L/2 (1 - cos) + r sin of the lean it was held at (the
        # cell looks again before the pivot)
        lean = math.asin(min(1.0, abs(float(axis[2]))))
        fall = 0.5 * part.length * (1.0 - math.cos(lean)) + 0.5 * part.outer * math.sin(lean)
        carried = pose.position[:2] + np.asarray(move.shift, float)
        off = float(np.hypot(*(after.position[:2] - carried)))
        assert abs(off - fall) < 0.005, (off, fall)
    finally:
        tw.close()


def test_a_lay_down_takes_the_part_at_its_height_and_sets_it_on_the_floor() -> None:
    """Planned from a part whose axis is 25 mm higher than lying puts it, no neighbour: the
    pinch is at its raised axis, the place it goes to at the floor."""
    part = load_catalogue(None).get("bushing")
    width = Gripper().finger_width
    roi = (0.22, 0.72, -0.16, 0.16)
    walls = bin_walls(roi, 0.0, 0.08, 0.005)
    plan_ = plan_pivot(part, Gripper(), Frictions())
    pivot = PivotParams(l_a=plan_.l_a, alpha=plan_.alpha)
    params = RepositionParams()
    frame = PivotFrame(part.section(width), np.array([0.45, 0.0, 0.5 * part.outer]), 0.3, 0.0)
    axis = 0.5 * part.outer + 0.025
    move = plan_lay_down(frame, axis, part, pivot, params, walls, [], roi, width,
                         reach=ur5_reach)
    assert move is not None and move.kind is MoveKind.LAY_DOWN
    assert math.isclose(move.drop, 0.025)
    assert move.grip.height is not None
    assert math.isclose(move.grip.height, axis - params.grip_below_axis)
    assert math.isclose(float(move.target.center[2]), 0.5 * part.outer)
    # a part already lying is no lay down: its drop is none
    flat = plan_lay_down(frame, 0.5 * part.outer, part, pivot, params, walls, [], roi, width,
                         reach=ur5_reach)
    assert flat is not None and flat.kind is MoveKind.DRAG and flat.drop == 0.0
