"""A small twin cell for the slot and packing skills: a bushing is spawned standing upright in the
bin and Align takes the hole grasp on it by physics (no weld, no teleport).

Only the setup (spawning the part, building the cell) and the judges touch the simulator; the
skills get :class:`drivers.devices.Devices` over the twin's drivers.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from cell.catalogue import load_catalogue
from drivers.devices import Devices
from drivers.layout import CellLayout
from drivers.parts import Part
from drivers.pose import Pose, rot_z
from sim.camera import SimCamera
from sim.cell_layout import CellBodies, build_cell
from sim.part_body import PartBody, spawn_part, upright_pose
from sim.robot import SimRobot
from sim.robot_model import FINGER_WIDTH
from sim.world import SimWorld
from skills.pivot import PickFromAbove, PivotFrame, PivotParams
from skills.status import Status

#: Where the standing bushings are spawned in the bin (m, world): in reach, clear of the walls.
BIN_SPOTS = ((0.45, 0.08), (0.45, -0.08))
#: Fingertips this far below the rim in the hole grasp (m): near the top, so the outer finger
#: stays above the machine when the part stands on the slot floor (it protrudes 28 mm).
GRIP_DEPTH = 0.020
#: Parts fall asleep at rest (see :func:`sim.part_body.spawn_part`): packed ones do not creep.
SLEEP_THRESHOLD = 0.05


def bushing() -> Part:
    return load_catalogue().get("bushing")


@dataclass
class Twin:
    world: SimWorld
    robot: SimRobot
    cell: CellBodies
    layout: CellLayout
    dev: Devices
    part: Part
    bodies: list[PartBody]

    def run(self, skill, limit_s: float = 30.0) -> str | None:  # type: ignore[no-untyped-def]
        """Tick ``skill`` with the world until it ends; its failure message, or None."""
        t_end = self.world.clock.now() + limit_s
        result = skill.tick()
        while not result.done and self.world.clock.now() < t_end:
            self.world.step()
            result = skill.tick()
        if not result.done:
            skill.halt()
            return "out of time"
        return result.message if result.status is Status.FAILURE else None

    def settle(self, seconds: float = 0.3) -> None:
        for _ in range(int(seconds / self.world.settings.control_dt)):
            self.world.step()

    def finger_tips(self) -> dict[str, np.ndarray]:
        return {n: self.robot.fingertip(n) for n in ("finger_a", "finger_b")}

    def finger_links(self) -> dict[str, int]:
        return {n: self.robot.gripper.finger_link(n) for n in ("finger_a", "finger_b")}

    def close(self) -> None:
        self.world.close()


def make_twin(
    seed: int = 0, spots: tuple[tuple[float, float], ...] = BIN_SPOTS[:1],
    layout: CellLayout | None = None,
    jitter: float = 0.003,
) -> Twin:
    """The cell with bushings standing upright in the bin near ``spots`` (m), settled. The seed
    sets the sensor noise and each part's offset (``jitter``, m) and turn about its axis; the
    skills are told only the spots."""
    world = SimWorld(seed=seed)
    layout = layout or CellLayout()
    cell = build_cell(world, layout)
    robot = SimRobot(world)
    robot.gripper.set_finger_friction(0.4, 0.4)
    part = bushing()
    rng = np.random.default_rng(seed)
    bodies = []
    for x, y in spots:  # +-3 mm off the spot, any turn about the axis (the staves' phase)
        dx, dy = rng.uniform(-jitter, jitter, 2)
        pose = upright_pose(part, x + dx, y + dy, layout.bin_floor_z)
        turned = Pose(pose.position, rot_z(rng.uniform(0.0, np.pi)) @ pose.rotation)
        bodies.append(spawn_part(world, part, turned, sleep_threshold=SLEEP_THRESHOLD))
    camera = SimCamera(
        world, lambda: robot.world_pose(robot.arm.tool_pose()), tool_T_camera=layout.tool_T_camera()
    )
    dev = Devices(robot.arm, robot.gripper, robot.ft, world.clock, camera)
    twin = Twin(world, robot, cell, layout, dev, part, bodies)
    twin.settle(0.3)
    robot.ft.bias()
    return twin


def align_params(**overrides: float) -> PivotParams:
    """Align's parameters for a hole grasp near the top (``GRIP_DEPTH``)."""
    base = {"l_a": 0.65, "alpha": 0.3142, "wall_depth": GRIP_DEPTH}
    return PivotParams(**(base | overrides))  # type: ignore[arg-type]


def take_hole_grasp(
    twin: Twin, xy: tuple[float, float], yaw: float = 0.0, wall_depth: float = GRIP_DEPTH
) -> str | None:
    """Run Align on the part standing near ``xy``: the frame is built so that Align predicts the
    standing part's axis at ``xy`` (its camera then finds the rim); tool x ends towards ``-u``."""
    part = twin.part
    section = part.section(FINGER_WIDTH)
    u = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    centre = np.array([*xy, 0.0]) + (section.a + 0.5 * part.outer) * u
    centre[2] = 0.5 * part.outer
    frame = PivotFrame(section, centre, yaw, twin.layout.bin_floor_z)
    return twin.run(PickFromAbove(frame, part, align_params(wall_depth=wall_depth), twin.dev), 20.0)


def with_layout(**changes: object) -> CellLayout:
    return dataclasses.replace(CellLayout(), **changes)


OnStep = Callable[[Twin], None]
