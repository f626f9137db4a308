"""The whole cell in the twin, for `cell sim`: bin full of lying parts, machine, tray, robot.

It hands the cell the same device interfaces the hardware backend does (:attr:`devices`,
:attr:`machine`), advances the physics one control step per :meth:`step`, and -- the twin's
extra -- judges each outcome of the workflow from the simulated state (:meth:`judge`): a part
picked is held upright with a finger in its hole; a part fed rests in the slot; a part packed
stands in the tray, with its gaps to its neighbours measured. Nothing judged here reaches the
tree; it only goes into the run's report.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from drivers.machine import TimedMachine
from sim.camera import SimCamera
from sim.cell_layout import CellLayout, build_cell
from sim.judge import judge
from sim.part_body import PartBody, lying_pose, spawn_part
from sim.robot import SimRobot
from sim.world import PhysicsSettings, SimWorld
from skills.mechanics.contact import Frictions
from skills.mechanics.part import Part
from skills.motion import Devices


@dataclass(frozen=True)
class TwinOptions:
    seed: int = 0
    parts_in_bin: int = 10
    yaw_spread: float = math.radians(3.0)  #: rad, uniform +- about the radial direction
    position_jitter: float = 0.003  #: m, uniform +- on each spawn spot
    mu_ground: float = 0.4
    frictions: Frictions = field(default_factory=Frictions)
    machining_time: float = 5.0  #: s of simulated time
    physics: PhysicsSettings = field(default_factory=PhysicsSettings)


def spawn_spots(
    layout: CellLayout,
    part: Part,
    count: int,
    rng: np.random.Generator,
    jitter: float,
    yaw_spread: float,
) -> list[tuple[float, float, float]]:
    """``count`` poses ``(x, y, yaw)`` for lying parts in the bin, open ends pointing away from
    the robot along the radial direction, in two rows the pivot reaches.

    The rows are where the pivot works in this cell (measured with ``cell pivot``): an open end
    nearer than about 0.44 m from the base makes the swing back over G run the wrist into the
    bin's near wall or out of reach; one past ``x_max - 0.11`` puts the tilted gripper over the
    far wall. Neighbours keep a finger's width and more between them.
    """
    x0, x1, y0, y1 = layout.bin_interior()
    far = x1 - 0.11
    rows = [far - 0.13, far]
    pitch_y = part.outer + 0.045
    ny = int((y1 - y0 - 2 * 0.03) // pitch_y) + 1
    ys = (np.arange(ny) - 0.5 * (ny - 1)) * pitch_y + 0.5 * (y0 + y1)
    spots = []
    for xo in rows:
        for yo in ys:
            yaw = math.atan2(yo, xo)
            cx = xo - 0.5 * part.length * math.cos(yaw)
            cy = yo - 0.5 * part.length * math.sin(yaw)
            if x0 + 0.02 <= cx - 0.5 * part.length and abs(yo) + 0.5 * part.outer < y1 - 0.005:
                spots.append((cx, cy, yaw))
    if count > len(spots):
        raise ValueError(
            f"sim.parts_in_bin: {count} {part.name}s do not fit where the pivot reaches in this "
            f"bin ({len(spots)} places; a wider bin_inner_size holds more)"
        )
    chosen = rng.choice(len(spots), size=count, replace=False)
    return [
        (
            spots[i][0] + rng.uniform(-jitter, jitter),
            spots[i][1] + rng.uniform(-jitter, jitter),
            spots[i][2] + rng.uniform(-yaw_spread, yaw_spread),
        )
        for i in sorted(chosen)
    ]


class SimCellBackend:
    """The twin behind the cell's interfaces."""

    name = "sim"

    def __init__(self, layout: CellLayout, part: Part, options: TwinOptions) -> None:
        self.layout, self.part, self.options = layout, part, options
        rng = np.random.default_rng(options.seed)
        self.world = world = SimWorld(seed=options.seed, settings=options.physics)
        try:
            self.cell = build_cell(world, layout, floor_friction=options.mu_ground)
            self.robot = robot = SimRobot(world)
            robot.gripper.set_finger_friction(options.frictions.mu_s, options.frictions.mu_h)
            self.bodies: list[PartBody] = []
            for x, y, yaw in spawn_spots(
                layout,
                part,
                options.parts_in_bin,
                rng,
                options.position_jitter,
                options.yaw_spread,
            ):
                # Resting parts may sleep: without it the solver's jitter creeps a packed part
                # about 1 mm a minute, which over ten cycles would open the box's gaps.
                self.bodies.append(
                    spawn_part(
                        world,
                        part,
                        lying_pose(part, x, y, yaw),
                        lateral_friction=1.0,
                        sleep_threshold=0.05,
                    )
                )
            for _ in range(int(0.3 / world.settings.control_dt)):  # let the parts settle
                world.step()
            robot.ft.bias()
            camera = SimCamera(
                world,
                lambda: robot.world_pose(robot.arm.tool_pose()),
                tool_T_camera=layout.tool_T_camera(),
            )
            self.machine = TimedMachine(world.clock, options.machining_time)
            self.devices = Devices(robot.arm, robot.gripper, robot.ft, world.clock, camera)
        except Exception:
            world.close()
            raise
        self.packed_bodies: list[int] = []

    @property
    def clock(self):  # type: ignore[no-untyped-def]
        return self.world.clock

    def step(self) -> None:
        self.world.step()

    def close(self) -> None:
        self.world.close()

    # ------------------------------------------------------------------------- judging
    def _nearest(self, point: np.ndarray) -> PartBody:
        return min(
            self.bodies,
            key=lambda b: float(np.linalg.norm(b.pose().position[:2] - point[:2])),
        )

    def _tcp(self) -> np.ndarray:
        return self.robot.world_pose(self.robot.arm.tool_pose()).position

    def judge(self, kind: str, data: dict[str, Any]) -> dict[str, Any] | None:
        """The simulated state's verdict on a workflow event, or None for events not judged."""
        if kind in ("picked", "picked_from_slot"):
            body = self._nearest(self._tcp())
            tips = {n: self.robot.fingertip(n) for n in ("finger_a", "finger_b")}
            v = judge(
                self.world,
                body,
                self.cell.floor,
                self.robot.body_id,
                {n: self.robot.gripper.finger_link(n) for n in ("finger_a", "finger_b")},
                tips,
                floor_z=self.layout.bin_floor_z if kind == "picked" else 0.0,
            )
            return {"ok": v.success, "failure": v.failure, "tilt_deg": round(v.tilt_deg, 2)}
        if kind == "machined":
            from sim.judge import judge_in_slot

            slot = np.asarray(self.layout.slot_center, float)
            body = self._nearest(slot)
            sv = judge_in_slot(self.world, body, slot, self.layout.slot_width, self.robot.body_id)
            return {
                "ok": sv.success,
                "failure": sv.failure,
                "tilt_deg": round(sv.tilt_deg, 2),
                "offset_mm": round(1e3 * sv.offset_m, 2),
                "bottom_mm": round(1e3 * sv.bottom_m, 2),
            }
        if kind == "packed":
            from sim.judge import judge_packed

            body = self._nearest(self._tcp())
            if body.body_id not in self.packed_bodies:
                self.packed_bodies.append(body.body_id)
            packed = [b for b in self.bodies if b.body_id in self.packed_bodies]
            pv = judge_packed(
                self.world,
                packed,
                self.layout.tray_interior(),
                self.layout.tray_floor_z,
                self.robot.body_id,
            )
            gaps = sorted(
                {
                    (min(a.index, j), max(a.index, j)): g
                    for a in pv.parts
                    for j, g in a.neighbour_gaps.items()
                }.items()
            )
            return {
                "ok": pv.success,
                "failure": pv.failure,
                "parts": len(packed),
                "gaps_mm": [round(1e3 * g, 2) for _, g in gaps],
                "max_neighbour_gap_mm": round(1e3 * pv.max_neighbour_gap_m, 2),
                "max_home_gap_mm": round(1e3 * pv.max_home_gap_m, 2),
            }
        return None
