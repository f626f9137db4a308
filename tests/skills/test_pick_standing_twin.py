"""A bushing found standing on an end in the bin: the hole grasp from above (not the pivot), on
the side whose jaws clear the walls and neighbours, judged from the twin's state."""

from __future__ import annotations

import numpy as np

from sim.judge import judge
from sim.part_body import lying_pose, spawn_part
from skills.pivot import PickStanding, plan_standing_pick
from skills.pivot.clearance import bin_walls, lying_part
from tests.skills.twin import BIN_SPOTS, align_params, make_twin


def test_a_standing_bushing_is_taken_from_the_side_its_neighbour_leaves_free() -> None:
    tw = make_twin(seed=4)
    try:
        part, layout = tw.part, tw.layout
        spot = np.array(BIN_SPOTS[0])
        # a bushing lying on the robot's side of it, 6 mm off its wall, across the approach
        beside = (spot[0] - 0.5 * part.outer - 0.006 - 0.5 * part.outer, spot[1])
        spawn_part(tw.world, part, lying_pose(part, *beside, np.pi / 2, layout.bin_floor_z))
        tw.settle(0.3)
        params = align_params(wall_depth=0.040)  # the cell's: tips 28 mm up, beside the neighbour
        x0, x1, y0, y1 = layout.bin_interior()
        walls = bin_walls((x0, x1, y0, y1), layout.bin_floor_z, layout.bin_wall_height,
                          layout.bin_wall_thickness)
        neighbour = lying_part("a neighbour", beside, np.pi / 2, part.length, part.outer,
                               layout.bin_floor_z)
        seen = spot + np.array([0.002, -0.001])  # where the wide view put its axis
        frame = plan_standing_pick(seen, part, params, [*walls, neighbour], tw.dev.gripper
                                   .finger_width, layout.bin_floor_z)
        assert frame is not None
        # the robot's side (u along +x from the base) is blocked: another side was chosen
        assert abs(np.cos(frame.yaw)) < 0.9
        failure = tw.run(PickStanding(frame, part, params, tw.dev, seen), 30.0)
        assert failure is None, failure
        tw.settle(0.3)
        verdict = judge(tw.world, tw.bodies[0], tw.cell.floor, tw.robot.body_id,
                        tw.finger_links(), tw.finger_tips(), layout.bin_floor_z)
        assert verdict.success and verdict.finger_in_hole, verdict.failure
    finally:
        tw.close()


def test_no_side_clears_a_standing_part_boxed_in_by_neighbours() -> None:
    tw = make_twin(seed=4)
    try:
        part, layout = tw.part, tw.layout
        spot = np.array(BIN_SPOTS[0])
        gap = 0.5 * part.outer + 0.004 + 0.5 * part.outer
        ring = [
            lying_part("a neighbour", spot + gap * np.array([np.cos(a), np.sin(a)]), a + np.pi / 2,
                       part.length, part.outer, layout.bin_floor_z)
            for a in np.linspace(0, 2 * np.pi, 8, endpoint=False)
        ]
        frame = plan_standing_pick(spot, part, align_params(wall_depth=0.040), ring,
                                   tw.dev.gripper.finger_width, layout.bin_floor_z)
        assert frame is None
    finally:
        tw.close()
