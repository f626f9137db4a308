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
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from drivers.devices import Devices
from drivers.events import EventKind, SlotState
from drivers.gripper_spec import GripperSpec
from drivers.layout import CellLayout
from drivers.machine import TimedMachine
from drivers.parts import Frictions, Part
from sim.camera import SimCamera
from sim.cell_layout import build_cell
from sim.judge import judge
from sim.part_body import PartBody, lying_pose, spawn_part
from sim.robot import SimRobot
from sim.scenes import dropped_bin_fill, situation
from sim.world import PhysicsSettings, SimWorld

#: m a part already packed may move while the next one is packed (the packing's own tolerance:
#: the judge's largest gap between neighbours)
PACKED_MOVE = 0.002


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
    #: "rows": lying along the radial direction where the pivot reaches (:func:`spawn_spots`);
    #: "random": tipped in as a person would (:func:`sim.scenes.dropped_bin_fill`).
    fill: str = "rows"
    #: the gripper's description (None: the shipped 2F-85)
    gripper: GripperSpec | None = None
    #: servoj's (lookahead s, gain) by which the arm follows the streamed targets (sim.servoj
    #: with devices.arm); None: each target within the control step
    servo: tuple[float, float] | None = None


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
            f"bin.parts: {count} {part.name}s do not fit where the pivot reaches in this "
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

    def __init__(
        self, layout: CellLayout, part: Part, options: TwinOptions, resume: Any = None
    ) -> None:
        """``resume`` (a :class:`cell.journal.Resume`): rebuild the world a journal describes
        after a crash -- the twin's world dies with the process, a real cell's does not. Parts
        packed stand in their box places, a part fed stands in the slot, the parts taken from
        the bin are gone from it, and a part that was in the hand is back in the bin (an
        operator's job on a real cell: nothing can re-create a grasp honestly)."""
        self.layout, self.part, self.options = layout, part, options
        self._packed_at_start: list[PartBody] = []
        rng = np.random.default_rng(options.seed)
        self.world = world = SimWorld(seed=options.seed, settings=options.physics)
        try:
            self.cell = build_cell(world, layout, floor_friction=options.mu_ground)
            self.robot = robot = SimRobot(world, gripper=options.gripper, servo=options.servo)
            robot.gripper.set_finger_friction(options.frictions.mu_s, options.frictions.mu_h)
            self.bodies: list[PartBody] = []
            self._fill(options.parts_in_bin, rng, resume)
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
        self.packed_bodies: list[int] = [b.body_id for b in self._packed_at_start]
        #: body id -> where its centre stood (m, floor plane) when it was judged packed
        self.packed_where: dict[int, np.ndarray] = {
            b.body_id: b.pose().position[:2].copy() for b in self._packed_at_start
        }

    def _fill(self, count: int, rng: np.random.Generator, resume: Any = None) -> list[PartBody]:
        """Put ``count`` parts into the bin as ``options.fill`` says (after a crash, those the
        journal says were not taken), let them settle, return them."""
        o, world = self.options, self.world
        if o.fill == "random":
            if resume is not None:
                taken = len(resume.picked_from) - (1 if resume.in_hand else 0)
                self._rebuild(resume, [])
                count = max(0, count - max(0, taken))
            new = dropped_bin_fill(world, self.layout, self.part, rng, count, self._spawn)
        else:
            spots = spawn_spots(
                self.layout, self.part, count, rng, o.position_jitter, o.yaw_spread
            )
            if resume is not None:
                spots = self._rebuild(resume, spots)
            new = [self._spawn(lying_pose(self.part, x, y, yaw)) for x, y, yaw in spots]
            for _ in range(int(0.3 / world.settings.control_dt)):  # let the parts settle
                world.step()
        self.bodies.extend(new)
        return new

    def _rebuild(
        self, resume: Any, spots: list[tuple[float, float, float]]
    ) -> list[tuple[float, float, float]]:
        """Spawn what left the bin where the journal says it is; the bin's spots still full."""
        from sim.part_body import upright_pose

        layout, part = self.layout, self.part
        taken = list(resume.picked_from)
        if resume.in_hand and taken:
            taken.pop()  # the part in the hand at the crash is back in the bin
        left = list(spots)
        for x, y in taken:
            if left:
                k = min(range(len(left)), key=lambda i: math.dist(left[i][:2], (x, y)))
                left.pop(k)
        places = layout.packing_places(part.outer)
        for i in resume.filled:
            px, py, pz = places[i]
            self._packed_at_start.append(self._spawn(upright_pose(part, px, py, pz)))
        self.bodies.extend(self._packed_at_start)
        if resume.slot != SlotState.EMPTY:
            sx, sy, sz = layout.slot_center
            self.bodies.append(self._spawn(upright_pose(part, sx, sy, sz)))
        return left

    def _spawn(self, pose: Any) -> PartBody:
        """A part of the cell's kind at ``pose``. Resting parts may sleep: without it the
        solver's jitter creeps a packed part about 1 mm a minute, which over ten cycles would
        open the box's gaps."""
        return spawn_part(self.world, self.part, pose, lateral_friction=1.0, sleep_threshold=0.05)

    def account(self) -> dict[str, int]:
        """Where every part is now, from the simulated state: in the bin, in the hand, in the
        slot, packed in the box, or elsewhere (on the floor: lost)."""
        out = {"in_bin": 0, "in_hand": 0, "in_slot": 0, "packed": 0, "on_floor": 0}
        for _, where in self.parts_where():
            out[where] += 1
        return out

    def left_in_bin(self) -> list[dict[str, Any]]:
        """The parts in the bin, named by the twin: kind, place (m) and how each lies (the
        words of :meth:`sim.scenes.Situation.label`). The cell itself cannot name a part it
        never saw; the twin can, so a run's summary says what perception missed."""
        bodies = [b for b, where in self.parts_where() if where == "in_bin"]
        out = []
        for b in bodies:
            c = b.pose().position
            lies = situation(self.world, b, self.bodies, self.cell.bin, self.layout).label()
            out.append(
                {
                    "part": f"{b.part.name} at ({c[0]:.3f}, {c[1]:.3f}) m",
                    "at": [round(float(c[0]), 4), round(float(c[1]), 4)],
                    "lies": lies,
                }
            )
        return out

    def parts_where(self) -> list[tuple[PartBody, str]]:
        """Each part with its place (the keys of :meth:`account`), from the simulated state."""
        out: list[tuple[PartBody, str]] = []
        x0, x1, y0, y1 = self.layout.bin_interior()
        tx0, tx1, ty0, ty1 = self.layout.tray_interior()
        slot = np.asarray(self.layout.slot_center, float)
        fingers = [self.robot.gripper.finger_link(n) for n in ("finger_a", "finger_b")]
        for b in self.bodies:
            pos = b.pose().position
            held = any(
                self.world.p.getContactPoints(
                    bodyA=b.body_id, bodyB=self.robot.body_id, linkIndexB=link
                )
                for link in fingers
            )
            if held and b.lowest_z() > 0.005:
                where = "in_hand"
            elif (
                float(np.max(np.abs(pos[:2] - slot[:2]))) < 0.5 * self.layout.slot_width
                and b.lowest_z() < slot[2] + 0.01
            ):
                where = "in_slot"
            elif tx0 <= pos[0] <= tx1 and ty0 <= pos[1] <= ty1:
                where = "packed"
            elif x0 <= pos[0] <= x1 and y0 <= pos[1] <= y1:
                where = "in_bin"
            else:
                where = "on_floor"
            out.append((b, where))
        return out

    # --------------------------------------------------- hooks for `cell soak` (sim/faults.py)
    def wrap_devices(self, wrap: Callable[[Devices], Devices]) -> Devices:
        """Put the devices behind ``wrap`` (fault injection): what the cell is handed from now."""
        self.devices = wrap(self.devices)
        return self.devices

    def remove_part(self, body: PartBody) -> None:
        """A person takes the part out of the cell (it leaves the world, recorded by the
        caller); the only way a part leaves other than by physics."""
        self.world.p.removeBody(body.body_id)
        self.bodies = [b for b in self.bodies if b.body_id != body.body_id]
        self.packed_bodies = [i for i in self.packed_bodies if i != body.body_id]
        self.packed_where.pop(body.body_id, None)

    def refill_bin(self, count: int, seed: int) -> list[PartBody]:
        """A person tips ``count`` new parts into the empty bin, as ``options.fill`` says
        (seeded), and they settle."""
        return self._fill(count, np.random.default_rng(seed))

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
        if kind in (EventKind.PICKED, EventKind.PICKED_FROM_SLOT):
            body = self._nearest(self._tcp())
            tips = {n: self.robot.fingertip(n) for n in ("finger_a", "finger_b")}
            v = judge(
                self.world,
                body,
                self.cell.floor,
                self.robot.body_id,
                {n: self.robot.gripper.finger_link(n) for n in ("finger_a", "finger_b")},
                tips,
                floor_z=self.layout.bin_floor_z if kind == EventKind.PICKED else 0.0,
            )
            return {"ok": v.success, "failure": v.failure, "tilt_deg": round(v.tilt_deg, 2)}
        if kind == EventKind.MACHINED:
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
        if kind == EventKind.PACKED:
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
            # A packing must leave the parts already in the box where they were put: each is
            # compared with where it stood after the last packing judged good with it in the box.
            # (the centres the judge above read, one per part: the world is not asked again)
            where = self.packed_where
            moved = {
                i: float(np.linalg.norm(np.subtract(pv.parts[i].center, where[b.body_id])))
                for i, b in enumerate(packed)
                if b.body_id in where and b.body_id != body.body_id
            }
            worst = max(moved.items(), key=lambda kv: kv[1], default=None)
            failure = pv.failure
            if worst is not None and worst[1] > PACKED_MOVE:
                shoved = (
                    f"part {worst[0]} (body {packed[worst[0]].body_id}): a packed part moved "
                    f"{1e3 * worst[1]:.1f} mm from where it was put"
                )
                # First, as the cause: a packed part shoved away opens the gaps the rest reports.
                failure = shoved if failure is None else f"{shoved}; {failure}"
            if failure is None:  # a good packing: where every part in the box now stands
                for b, judged in zip(packed, pv.parts, strict=True):
                    self.packed_where.setdefault(b.body_id, np.asarray(judged.center))
            return {
                "ok": failure is None,
                "failure": failure,
                "parts": len(packed),
                "moved_mm": round(1e3 * worst[1], 2) if worst is not None else 0.0,
                "gaps_mm": [round(1e3 * g, 2) for _, g in gaps],
                "max_neighbour_gap_mm": round(1e3 * pv.max_neighbour_gap_m, 2),
                "max_home_gap_mm": round(1e3 * pv.max_home_gap_m, 2),
            }
        return None
