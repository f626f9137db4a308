"""One py_trees behaviour per skill step: thin adapters over the skills.

Lifecycle, the same for all: ``initialise()`` builds the skill from the blackboard (and so starts
it on the first tick), ``update()`` advances it by one control step and never blocks,
``terminate()`` halts the motion it started when a parent stops it early (idempotent). Every
behaviour says where it is in ``feedback_message``.

Blackboard keys, each written by one behaviour only:

* ``/ft/wrench`` -- :class:`~trees.decorators.FTSampler`
* ``/part/detections``, ``/part/seen`` -- :class:`Perceive`
* ``/part/target``, ``/cell/bin_empty`` -- :class:`PlanPick`
* ``/part/pivot_frame`` -- :class:`Tilt`
* ``/cell/cycles_done`` -- :class:`~trees.decorators.Cycles`
* ``/cell/place`` -- :class:`PackInBox`
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator
from typing import Any, Protocol

import numpy as np
from py_trees import common
from py_trees.behaviour import Behaviour

from drivers.events import EventKind, SlotState
from drivers.health import DeviceError
from skills.home import go_home, put_back
from skills.offtick import OffTick, runs_in_real_time
from skills.packing import PackInBox as PackInBoxSkill
from skills.params import apply_config, with_limits
from skills.perception.bin_parts import Detection
from skills.perception.look import Look, tool_yaw
from skills.perception.pick_order import freest_first
from skills.pivot import Align as AlignSkill
from skills.pivot import Grasp as GraspSkill
from skills.pivot import PickFromAbove as PickFromAboveSkill
from skills.pivot import PickStanding as PickStandingSkill
from skills.pivot import PivotFrame, plan_standing_pick
from skills.pivot import Tilt as TiltSkill
from skills.pivot.clearance import (
    bin_walls,
    choose_end,
    likely_grasp_rotation,
    reach_problem,
    seen_part,
)
from skills.reposition import Reposition as RepositionSkill
from skills.reposition import RepositionPlan, plan_lay_down, plan_reposition
from skills.slot import FeedSlot as FeedSlotSkill
from skills.slot import PickFromSlot as PickFromSlotSkill
from skills.status import Failure, StepResult
from skills.status import Status as SkillStatus
from trees.context import CellContext
from trees.node_type import MOTION, Param, declare

Status = common.Status


class Skill(Protocol):
    def tick(self) -> StepResult: ...

    def halt(self) -> None: ...


class SetupError(Exception):
    """The skill cannot start (nothing to pick, no frame from the previous step)."""


class SkillBehaviour(Behaviour):
    """Adapter: builds its skill in ``initialise()``, ticks it in ``update()``.

    Its skill's parameters are the configuration's ``skills.<section>`` with this node's
    overrides (``overrides``: configuration keys, e.g. ``tilt_speed_m_s``), and every motion of
    the skill runs under this node's abort limits ``max_force_n`` and ``max_torque_nm`` (default:
    the cell's safety section) -- the same limits as the FT guard the tree builder puts around
    the leaf, so a limit changed in the YAML is the one the skill stops at."""

    #: True for leaves that move the arm or gripper: the tree builder wraps them in an FT guard
    #: and a timeout.
    moves = True
    #: The ``skills:`` section this leaf's skill reads (None: it has no parameters).
    section: str | None = None

    def __init__(
        self,
        name: str,
        ctx: CellContext,
        max_force_n: float | None = None,
        max_torque_nm: float | None = None,
        **overrides: float,
    ) -> None:
        super().__init__(name=name)
        self.ctx = ctx
        self.max_force = ctx.default_guard.max_force if max_force_n is None else max_force_n
        self.max_torque = ctx.default_guard.max_torque if max_torque_nm is None else max_torque_nm
        if overrides and self.section is None:
            raise TypeError(f"{type(self).__name__} takes no skill parameters: {list(overrides)}")
        self.overrides = overrides
        if self.section is not None:
            self.settings()  # an unknown override fails here, when the tree is built
        self.skill: Skill | None = None
        self._setup_error: str | None = None
        self._running = False
        self.bb = self.attach_blackboard_client(name=name)
        for key, access in self.keys().items():
            self.bb.register_key(key=key, access=access)

    def settings(self, section: str | None = None) -> Any:
        """The parameters of ``section`` (default: this leaf's) as this node runs them."""
        name = section or self.section
        assert name is not None
        base = self.ctx.section(name)
        if name == self.section and self.overrides:
            base = apply_config(base, self.overrides)
        return with_limits(base, self.max_force, self.max_torque)

    # -- for subclasses --------------------------------------------------------------------
    def keys(self) -> dict[str, common.Access]:
        return {}

    def make_skill(self) -> Skill:  # pragma: no cover - abstract
        raise NotImplementedError

    def on_success(self) -> None:
        """Publish what the finished skill found or did."""

    def on_unfinished(self) -> None:
        """Remember what a skill that ended without success left behind for the tree to
        finish: it failed (called after its abort is reported), or a parent halted it (a
        force-torque guard, a timeout, the cell stopping)."""

    # -- py_trees lifecycle ------------------------------------------------------------------
    def initialise(self) -> None:
        self.skill, self._setup_error = None, None
        try:
            self.skill = self.make_skill()
        except SetupError as exc:
            self._setup_error = str(exc)
        self._running = self.skill is not None
        self.failure: Failure | None = None  #: why the last run failed
        self.feedback_message = "starting"

    def update(self) -> Status:
        if self.skill is None:
            self.feedback_message = f"{self.name}: cannot start: {self._setup_error}"
            self.failure = Failure.CANNOT_START
            return Status.FAILURE
        result = self.skill.tick()
        if result.message:
            self.feedback_message = result.message
        if result.status is SkillStatus.RUNNING:
            return Status.RUNNING
        self._running = False
        if result.status is SkillStatus.SUCCESS:
            self.on_success()
            return Status.SUCCESS
        self.failure = result.code
        self.ctx.events.abort(self.feedback_message, result.code, self.name)
        self.on_unfinished()
        return Status.FAILURE

    def terminate(self, new_status: Status) -> None:
        if self._running and self.skill is not None:
            self._running = False  # idempotent: a second terminate() does nothing
            self.skill.halt()
            if new_status == Status.INVALID:
                self.feedback_message = f"{self.name}: halted by a parent; motion stopped"
                self.on_unfinished()


# ---------------------------------------------------------------------------------- leaves
@declare("perceive", "wrist camera over the bin, find the parts", "Action", MOTION)
class Perceive(SkillBehaviour):
    """Look down on the bin with the wrist camera; publish what it found."""

    section = "perceive"

    def keys(self) -> dict[str, common.Access]:
        return {
            "/part/detections": common.Access.WRITE,
            "/part/seen": common.Access.WRITE,
        }

    def make_skill(self) -> Skill:
        g = self.ctx.geometry
        near = _nearest_robot_corner(g.bin_roi)
        self.look = Look(
            self.ctx.devices,
            self.ctx.catalogue or [self.ctx.part],
            g.bin_roi,
            g.bin_view_xy,
            (float(near[0]), float(near[1])),
            self.settings(),
            grip_yaw=self._grip_yaw,
            # the look's views are straight moves from where the arm stands: not from home
            reach=self.ctx.reach_here or self.ctx.reach,
            floor_z=g.bin_floor_z,
            # the wide views take in every part the cell may pick: lying, or standing on an end
            wanted_top=max(self.ctx.part.outer, self.ctx.part.length),
        )
        return _TolerantLook(self.look)

    def _grip_yaw(self, d: Detection) -> float:
        """The yaw the pivot's Grasp will hold the tool at over ``d`` (the look's last view is
        turned to it): the end the plan prefers when both clear, without its sweeps."""
        ctx, g = self.ctx, self.ctx.geometry
        if d.part != ctx.part.name:
            return 0.0
        frame = PivotFrame(
            ctx.part.section(ctx.devices.gripper.finger_width),
            np.array([d.center[0], d.center[1], g.bin_floor_z + 0.5 * ctx.part.outer]),
            d.yaw,
            floor_z=g.bin_floor_z,
        )
        pivot = ctx.section("pivot")
        return tool_yaw(likely_grasp_rotation(frame, pivot.alpha, ctx.part.open_ends))

    def on_success(self) -> None:
        dets = list(self.look.detections)
        self.bb.set("/part/detections", dets)
        self.bb.set("/part/seen", self.look.result)
        self.feedback_message = f"perceive: {len(dets)} part(s) in the bin"


class _TolerantLook:
    """An empty bin is an answer (the cycle ends), not a failed look."""

    def __init__(self, look: Look) -> None:
        self.look = look

    def tick(self) -> StepResult:
        r = self.look.tick()
        if r.code is Failure.NOTHING_FOUND:
            return StepResult(SkillStatus.SUCCESS, "look: no part found in the bin")
        return r

    def halt(self) -> None:
        self.look.halt()


def _nearest_robot_corner(roi: tuple[float, float, float, float]) -> tuple[float, float]:
    return (roi[0], 0.5 * (roi[2] + roi[3]))


def location_key(xy: Any) -> tuple[int, int]:
    """A part's remembered location (1 cm cells), to count failed picks of the same part."""
    return (int(round(float(xy[0]) * 100)), int(round(float(xy[1]) * 100)))


@declare(
    "plan_pick",
    "choose the part and its pivot frame",
    "Action",
    {
        "ahead": Param(
            bool,
            doc="planned from a look while the machine runs: the next pick takes it "
            "(planned_ahead) instead of looking again",
        )
    },
)
class PlanPick(Behaviour):
    """Choose the part to pick from the detections and the pivot frame the skills use.

    Skips parts of another kind, parts outside the bin's inside, and parts that already failed
    ``max_failures_per_part`` picks. Nothing left: writes ``/cell/bin_empty`` and fails, which
    ends the cell's cycles. With ``ahead``, a plan made marks itself as the next pick's
    (:class:`PlannedAhead`): nothing touches the bin between a look while the machine runs and
    the next cycle's pick, so looking again would only cost the arm's time.
    """

    moves = False

    def __init__(self, name: str, ctx: CellContext, ahead: bool = False, **params: Any) -> None:
        super().__init__(name=name)
        self.ctx, self.params, self.ahead = ctx, params, ahead
        self.bb = self.attach_blackboard_client(name=name)
        self.bb.register_key(key="/part/detections", access=common.Access.READ)
        self.bb.register_key(key="/part/seen", access=common.Access.READ)
        self.bb.register_key(key="/part/target", access=common.Access.WRITE)
        self.bb.register_key(key="/cell/bin_empty", access=common.Access.WRITE)
        self.bb.set("/cell/bin_empty", False)
        #: the clearance sweeps (tens to hundreds of milliseconds a part) run off the tick on
        #: hardware (skills/offtick.py); in the twin they are spread over ticks, one part a
        #: tick; the leaf is RUNNING meanwhile either way
        self._work: Iterator[None] | None = None
        self._job: OffTick[None] | None = None
        self._pending: tuple | None = None
        self._found: tuple[dict, dict] = ({}, {})

    def initialise(self) -> None:
        self._work, self._pending, self._job = None, None, None
        self.ctx.planned_ahead = False  # whatever this plan chooses replaces an older one

    def terminate(self, new_status: Status) -> None:
        self._work, self._job = None, None  # a worker still running finishes unread
        if new_status == Status.SUCCESS:
            self.ctx.planned_ahead = self.ahead

    def update(self) -> Status:
        if self._job is not None:
            if not self._job.done():
                self.feedback_message = "plan pick: checking where the pivot's gripper goes"
                return Status.RUNNING
            self._job = None
            assert self._pending is not None
            return self._choose(*self._pending, *self._found)
        if self._work is not None:
            if next(self._work, StopIteration) is not StopIteration:
                self.feedback_message = "plan pick: checking where the pivot's gripper goes"
                return Status.RUNNING
            self._work = None
            assert self._pending is not None
            return self._choose(*self._pending, *self._found)
        ctx = self.ctx
        dets: list[Detection] = (
            self.bb.get("/part/detections") if self.bb.exists("/part/detections") else []
        )
        x0, x1, y0, y1 = ctx.geometry.bin_roi
        usable, skipped = [], 0
        left: list[dict[str, Any]] = []  #: the parts seen and passed over, with why
        for d in dets:
            where = f"{d.part} at ({d.center[0]:.3f}, {d.center[1]:.3f}) m"
            at = [round(float(d.center[0]), 4), round(float(d.center[1]), 4)]
            if d.part != ctx.part.name:
                left.append({"part": where, "reason": f"not a {ctx.part.name}", "at": at})
                continue
            if d.standing and not d.open_end_seen:
                left.append({"part": where, "reason": "standing on its open end", "at": at})
                continue
            if not d.open_end_seen and not d.tilted:  # a raised part is laid down first
                left.append({"part": where, "reason": "its open end was not made out", "at": at})
                continue
            if not (x0 <= d.center[0] <= x1 and y0 <= d.center[1] <= y1):
                left.append({"part": where, "reason": "outside the bin's inside", "at": at})
                continue
            tries = ctx.failures.get(location_key(d.center), 0)
            if tries >= ctx.limits.max_failures_per_part:
                skipped += 1
                left.append({"part": where, "reason": f"{tries} picks failed", "at": at})
                continue
            usable.append(d)
        if not usable:
            self.bb.set("/cell/bin_empty", True)
            extra = f" ({skipped} skipped after failed picks)" if skipped else ""
            self.feedback_message = f"plan pick: no {ctx.part.name} left to pick{extra}"
            ctx.events.event(EventKind.BIN_EMPTY, skipped=skipped, left=left)
            return Status.FAILURE
        self._pending = (usable, dets, left, skipped)
        self._found = ({}, {})
        work = self._clearances(usable, dets, left, *self._found)
        if runs_in_real_time(self.ctx.devices.clock):
            self._job = OffTick("off-tick plan pick", lambda: _exhaust(work), background=True)
            self._job.start()
        else:
            self._work = work
        self.feedback_message = "plan pick: checking where the pivot's gripper goes"
        return Status.RUNNING

    def _choose(
        self,
        usable: list[Detection],
        dets: list[Detection],
        left: list[dict[str, Any]],
        skipped: int,
        clear: dict[int, PivotFrame],
        drags: dict[int, RepositionPlan],
    ) -> Status:
        ctx = self.ctx
        seen = self.bb.get("/part/seen") if self.bb.exists("/part/seen") else None
        if not clear and not drags:
            self.bb.set("/cell/bin_empty", True)
            self.feedback_message = (
                f"plan pick: no {ctx.part.name} a pivot clears or a drag frees ({len(left)} left)"
            )
            ctx.events.event(EventKind.BIN_EMPTY, skipped=skipped, left=left)
            return Status.FAILURE
        pool = [d for d in usable if id(d) in (clear or drags)]
        # A part standing, its open end up, goes first: no pivot, and it shades its neighbours.
        pool = [d for d in pool if d.standing] or pool
        if pool[0].standing:
            target = min(pool, key=lambda d: math.hypot(d.center[0], d.center[1]))
        elif ctx.limits.pick_order == "freest":
            target = freest_first(pool, dets, ctx.geometry.bin_roi)[0]
        elif seen is not None and any(d is seen for d in pool):
            target = seen  # the one the Look looked at twice
        else:
            target = min(pool, key=lambda d: math.hypot(d.center[0], d.center[1]))
        move = None if clear else drags[id(target)]
        frame = clear[id(target)] if clear else move.frame
        self.bb.set(
            "/part/target",
            {"detection": target, "frame": frame, "reposition": move, "standing": target.standing},
        )
        what = f"{move.kind.value} {1e3 * move.distance:.0f} mm first, " if move else ""
        self.feedback_message = (
            f"plan pick: {ctx.part.name} at ({target.center[0]:.3f}, {target.center[1]:.3f}) m, "
            f"yaw {math.degrees(frame.yaw):.1f} deg, {what}{len(clear)} pickable as they lie"
        )
        return Status.SUCCESS

    def _clearances(
        self,
        usable: list[Detection],
        dets: list[Detection],
        left: list[dict[str, Any]],
        clear: dict[int, PivotFrame],
        drags: dict[int, RepositionPlan],
    ) -> Iterator[None]:
        """Fill ``clear`` with the usable parts a pivot clears as they lie (with the end to use)
        and ``drags`` with those a drag would free (keyed by ``id`` of the detection); the rest
        go to ``left`` with what is in the way. One part per step of the iteration. Walls from
        the configured layout, neighbours from this look's detections."""
        ctx = self.ctx
        g = ctx.geometry
        pivot = ctx.section("pivot")
        drag = ctx.section("reposition")
        width = ctx.devices.gripper.finger_width
        walls = bin_walls(g.bin_roi, g.bin_floor_z, g.bin_wall_height, g.bin_wall_thickness)
        section = ctx.part.section(width)
        for d in usable:
            yield  # one part a tick
            neighbours = [
                seen_part("a neighbour", o, g.bin_floor_z)
                for o in dets
                if o is not d
            ]
            if d.standing:  # its open end up already: the hole grasp from above, no pivot
                up = plan_standing_pick(
                    d.center, ctx.part, pivot, [*walls, *neighbours], width, g.bin_floor_z,
                    reach=ctx.reach,
                )
                if up is not None:
                    clear[id(d)] = up
                    continue
                left.append(_left(d, "standing: no side clears the grasp from above"))
                continue
            frame = PivotFrame(
                section,
                np.array([d.center[0], d.center[1], g.bin_floor_z + 0.5 * ctx.part.outer]),
                d.yaw,
                floor_z=g.bin_floor_z,
            )
            # its raise above the floor the view fitted, not the configured floor's height
            axis = 0.5 * ctx.part.outer + d.raised  # exact: lying, half the size up
            if d.tilted or d.raised > drag.max_raise:  # no G on the floor until laid down
                down = plan_lay_down(
                    frame, axis, ctx.part, pivot, drag, walls, neighbours, g.bin_roi, width,
                    reach=ctx.reach, leaning=d.tilted,
                )
                if down is not None:
                    drags[id(d)] = down
                    continue
                how = "leaning, " if d.tilted else ""
                reason = f"off the floor ({how}its axis {1e3 * axis:.0f} mm up): no lay down clears"
                left.append(_left(d, reason))
                continue
            choice = choose_end(
                frame, pivot, [*walls, *neighbours], width, ctx.part.open_ends, reach=ctx.reach
            )
            if choice.clearance.clear:
                clear[id(d)] = choice.frame
                continue
            move = plan_reposition(
                frame, ctx.part, pivot, drag, walls, neighbours, g.bin_roi, width, reach=ctx.reach
            )
            if move is not None:
                drags[id(d)] = move
                continue
            reason = f"no pivot clears: {choice.clearance.reason()}; no drag frees it"
            left.append(_left(d, reason))


def _left(d: Detection, reason: str) -> dict[str, Any]:
    """A part plan_pick passes over, as the bin-empty event names it: where, why."""
    return {
        "part": f"{d.part} at ({d.center[0]:.3f}, {d.center[1]:.3f}) m",
        "reason": reason,
        "at": [round(float(d.center[0]), 4), round(float(d.center[1]), 4)],
    }


def _exhaust(work: Iterator[None]) -> None:
    for _ in work:
        pass


def _target_frame(bb: Any) -> PivotFrame:
    if not bb.exists("/part/target"):
        raise SetupError("no part chosen (/part/target is empty)")
    return bb.get("/part/target")["frame"]


class _OnTarget(Behaviour):
    """A condition on plan_pick's choice (``/part/target``): :meth:`holds` judges it; nothing
    chosen: FAILURE."""

    moves = False

    def __init__(self, name: str, ctx: CellContext, **params: Any) -> None:
        super().__init__(name=name)
        self.ctx = ctx
        self.bb = self.attach_blackboard_client(name=name)
        self.bb.register_key(key="/part/target", access=common.Access.READ)

    def holds(self, target: dict[str, Any]) -> tuple[bool, str]:  # pragma: no cover - abstract
        raise NotImplementedError

    def update(self) -> Status:
        if not self.bb.exists("/part/target"):
            self.feedback_message = "no part chosen"
            return Status.FAILURE
        ok, self.feedback_message = self.holds(self.bb.get("/part/target"))
        return Status.SUCCESS if ok else Status.FAILURE


@declare(
    "pivot_clears",
    "condition: the chosen part's pivot clears the walls and neighbours where it lies",
    "Condition",
)
class PivotClears(_OnTarget):
    """Condition: SUCCESS when plan_pick found the chosen part pickable where it lies; FAILURE
    when it needs a drag first (or nothing was chosen)."""

    def holds(self, target: dict[str, Any]) -> tuple[bool, str]:
        if target.get("reposition") is not None:
            return False, "the pivot would hit a wall or a neighbour: drag it first"
        return True, "the pivot clears where the part lies"


class _TargetStands(_OnTarget):
    """Condition on plan_pick's choice: SUCCESS when it stands on an end as :attr:`wanted`
    says (nothing chosen: FAILURE)."""

    wanted = True

    def holds(self, target: dict[str, Any]) -> tuple[bool, str]:
        stands = bool(target.get("standing"))
        return stands == self.wanted, "the part stands on an end" if stands else "the part lies"


@declare(
    "part_standing",
    "condition: the chosen part stands, its open end up (picked from above, no pivot)",
    "Condition",
)
class PartStanding(_TargetStands):
    wanted = True


@declare(
    "planned_ahead",
    "condition: a pick was planned while the machine ran and nothing touched the bin since "
    "(true once)",
    "Condition",
)
class PlannedAhead(Behaviour):
    """Condition: SUCCESS when ``plan_pick`` with ``ahead`` chose a part since the bin was last
    touched. It consumes the plan: a pick that fails puts the part back, which moves the bin,
    so the next attempt must look again."""

    moves = False

    def __init__(self, name: str, ctx: CellContext) -> None:
        super().__init__(name=name)
        self.ctx = ctx
        self.bb = self.attach_blackboard_client(name=name)
        self.bb.register_key(key="/part/target", access=common.Access.READ)

    def update(self) -> Status:
        ready = self.ctx.planned_ahead and self.bb.exists("/part/target")
        self.ctx.planned_ahead = False
        self.feedback_message = (
            "planned while the machine ran" if ready else "no plan from a look while machining"
        )
        return Status.SUCCESS if ready else Status.FAILURE


@declare("part_lying", "condition: the chosen part lies (the pivot's case)", "Condition")
class PartLying(_TargetStands):
    wanted = False


@declare(
    "pick_standing",
    "hole grasp from above of a part found standing, its open end up (counted apart: no pivot)",
    "Action",
    MOTION,
)
class PickStanding(SkillBehaviour):
    """The chosen part stands, its open end up: look at its rim close up and take the hole
    grasp from above. Journaled as ``picked`` with ``standing: true``, counted apart."""

    section = "pivot"

    def keys(self) -> dict[str, common.Access]:
        return {"/part/target": common.Access.READ}

    def make_skill(self) -> Skill:
        if not self.bb.exists("/part/target"):
            raise SetupError("no part chosen (/part/target is empty)")
        target = self.bb.get("/part/target")
        if not target.get("standing"):
            raise SetupError("the chosen part does not stand on an end")
        d = target["detection"]
        return PickStandingSkill(
            target["frame"], self.ctx.part, self.settings(), self.ctx.devices, d.center
        )

    def on_success(self) -> None:
        c = self.bb.get("/part/target")["detection"].center
        self.ctx.events.event(
            EventKind.PICKED, standing=True, x=round(float(c[0]), 4), y=round(float(c[1]), 4)
        )


@declare(
    "reposition",
    "drag (or roll, a round part the jaws cannot come down beside; or lay down, a part raised "
    "off the floor) the chosen part to where a pivot clears (counted apart as repositioned)",
    "Action",
    MOTION,
)
class Reposition(SkillBehaviour):
    """Drag or roll the chosen part by plan_pick's plan; the part is then looked at again."""

    section = "reposition"

    def keys(self) -> dict[str, common.Access]:
        return {"/part/target": common.Access.READ}

    def make_skill(self) -> Skill:
        if not self.bb.exists("/part/target"):
            raise SetupError("no part chosen (/part/target is empty)")
        move = self.bb.get("/part/target").get("reposition")
        if move is None:
            raise SetupError("the chosen part needs no drag")
        self.move = move
        return RepositionSkill(move, self.ctx.part, self.ctx.devices, self.settings())

    def on_success(self) -> None:
        c = self.move.target.center
        self.ctx.events.event(
            EventKind.REPOSITIONED,
            x=round(float(c[0]), 4),
            y=round(float(c[1]), 4),
            shift_mm=round(1e3 * self.move.distance, 1),
            how=self.move.kind.value,
        )


@declare("grasp", "the pivot's Grasp (Sec. III-C)", "Action", MOTION)
class Grasp(SkillBehaviour):
    section = "pivot"

    def keys(self) -> dict[str, common.Access]:
        return {"/part/target": common.Access.READ}

    def make_skill(self) -> Skill:
        ctx, frame, params = self.ctx, _target_frame(self.bb), self.settings()
        grasp = GraspSkill(frame, params, ctx.devices)
        here = ctx.reach_here
        width = ctx.devices.gripper.finger_width
        if here is None or reach_problem(frame, params, width, here) is None:
            return grasp
        # planned from home (out of reach along straight moves from where the look left the
        # arm): go there first by a joint move
        home = go_home(ctx.devices, ctx.geometry.home_joints, self.settings("go_home"))
        return _Then(home, grasp)


class _Then:
    """One skill, then another: a failure of the first ends it. Not a
    :class:`skills.motion.Sequence` of the two: that reports only its steps' names while they
    run, and the Grasp's own step messages ("grasp: above the open end") are the leaf's
    feedback in the tick log."""

    def __init__(self, first: Skill, then: Skill) -> None:
        self.first, self.then, self._first_done = first, then, False

    def tick(self) -> StepResult:
        if not self._first_done:
            result = self.first.tick()
            if result.status is not SkillStatus.SUCCESS:
                return result
            self._first_done = True
        return self.then.tick()

    def halt(self) -> None:
        (self.then if self._first_done else self.first).halt()


@declare("tilt", "the pivot's Tilt about P_c", "Action", MOTION)
class Tilt(SkillBehaviour):
    section = "pivot"

    def keys(self) -> dict[str, common.Access]:
        return {"/part/target": common.Access.READ, "/part/pivot_frame": common.Access.WRITE}

    def make_skill(self) -> Skill:
        self.tilt = TiltSkill(_target_frame(self.bb), self.settings(), self.ctx.devices)
        return self.tilt

    def on_success(self) -> None:
        self.bb.set("/part/pivot_frame", self.tilt.frame)


@declare(
    "align",
    "in-hand Align: turn about the rim into the hole grasp, no release (Sec. III-C)",
    "Action",
    MOTION,
)
class Align(SkillBehaviour):
    section = "pivot"
    skill_type: type[AlignSkill] | type[PickFromAboveSkill] = AlignSkill
    recovered = False  #: picks journaled as the recovery's, counted apart

    def keys(self) -> dict[str, common.Access]:
        return {"/part/pivot_frame": common.Access.READ, "/part/target": common.Access.READ}

    def make_skill(self) -> Skill:
        if not self.bb.exists("/part/pivot_frame"):
            raise SetupError("no pivot frame from a Tilt")
        frame = self.bb.get("/part/pivot_frame")
        return self.skill_type(frame, self.ctx.part, self.settings(), self.ctx.devices)

    def on_success(self) -> None:
        data: dict[str, object] = {"recovered": True} if self.recovered else {}
        if self.bb.exists("/part/target"):  # where it lay: the journal's record of the bin
            c = self.bb.get("/part/target")["detection"].center
            data.update(x=round(float(c[0]), 4), y=round(float(c[1]), 4))
        self.ctx.events.event(EventKind.PICKED, **data)


@declare(
    "pick_from_above",
    "recovery after a failed align: let go, look, pick from above (counted apart)",
    "Action",
    MOTION,
)
class PickFromAbove(Align):
    """The recovery after a failed in-hand Align: let go, look, pick the standing part from
    above. Its picks are journaled with ``recovered: true`` and counted apart: a regrasp, not
    the paper's pivot."""

    skill_type = PickFromAboveSkill
    recovered = True


@declare(
    "put_back",
    "recovery: open, rise, home; then fails so a retry above tries again",
    "Action",
    MOTION,
)
class PutBack(SkillBehaviour):
    """Recovery after a failed pick: open the jaws (the part stays in the bin), rise, go home,
    remember the failure against the part's location -- then FAIL, so a Retry above tries again
    from a fresh look."""

    section = "put_back"

    def keys(self) -> dict[str, common.Access]:
        return {"/part/target": common.Access.READ, "/cell/bin_empty": common.Access.READ}

    def make_skill(self) -> Skill:
        ctx = self.ctx
        if self.bb.exists("/cell/bin_empty") and self.bb.get("/cell/bin_empty"):
            # nothing was taken: the arm is where the look left it, high over the bin (a rise
            # from there is out of reach); home by a joint move
            return go_home(ctx.devices, ctx.geometry.home_joints, self.settings("go_home"))
        if self.bb.exists("/part/target"):
            key = location_key(self.bb.get("/part/target")["detection"].center)
            ctx.failures[key] = ctx.failures.get(key, 0) + 1
        return put_back(
            ctx.devices, ctx.geometry.home_joints, self.settings(), self.settings("go_home")
        )

    def update(self) -> Status:
        status = super().update()
        if status == Status.SUCCESS:
            self.feedback_message = "put back: part left in the bin, jaws open, arm home"
            return Status.FAILURE
        return status


@declare("go_home", "arm to its home pose", "Action", MOTION)
class GoHome(SkillBehaviour):
    section = "go_home"

    def make_skill(self) -> Skill:
        return go_home(self.ctx.devices, self.ctx.geometry.home_joints, self.settings())


def _start_machine(ctx: CellContext) -> None:
    """Start the machine on the fed part unless it was started already (once per part)."""
    if not ctx.machining_started:
        ctx.machine.start()
        ctx.machining_started = True


@declare(
    "start_machining",
    "start the machine on the fed part, do not wait (wait_machining waits)",
    "Action",
)
class StartMachining(Behaviour):
    """Start the machine and go on: the arm can look at the bin while it runs, and
    ``wait_machining`` then waits only for what is left of the machining."""

    moves = False

    def __init__(self, name: str, ctx: CellContext, **params: Any) -> None:
        super().__init__(name=name)
        self.ctx, self.params = ctx, params

    def update(self) -> Status:
        fault = self.ctx.machine.fault()
        if fault:
            self.feedback_message = f"machine fault: {fault}"
            return Status.FAILURE
        _start_machine(self.ctx)
        self.feedback_message = "machine started"
        return Status.SUCCESS


@declare(
    "wait_machining",
    "start the machine unless start_machining did, wait until done",
    "Action",
)
class WaitMachining(Behaviour):
    """Wait for the machine on the fed part (polls once per tick); start it first unless
    ``start_machining`` did."""

    moves = False

    def __init__(self, name: str, ctx: CellContext, **params: Any) -> None:
        super().__init__(name=name)
        self.ctx, self.params = ctx, params

    def initialise(self) -> None:
        _start_machine(self.ctx)
        self._t0 = self.ctx.devices.clock.now()

    def update(self) -> Status:
        fault = self.ctx.machine.fault()
        if fault:
            self.feedback_message = f"machine fault: {fault}"
            return Status.FAILURE
        elapsed = self.ctx.devices.clock.now() - self._t0
        if self.ctx.machine.busy():
            self.feedback_message = f"machining: {elapsed:.1f} s"
            return Status.RUNNING
        self.feedback_message = f"machined ({elapsed:.1f} s waited)"
        self.ctx.machining_started = False
        self.ctx.slot_state = SlotState.MACHINED
        self.ctx.events.event(EventKind.MACHINED)
        return Status.SUCCESS


@declare(
    "cycle_follows",
    "condition: another cycle follows this one (workflow.cycles not reached with it)",
    "Condition",
)
class CycleFollows(Behaviour):
    """Condition: SUCCESS while the cycle running is not the last one asked for. Gates the look
    ahead: on the last cycle it would only move the arm."""

    moves = False

    def __init__(self, name: str, ctx: CellContext) -> None:
        super().__init__(name=name)
        self.ctx = ctx
        self.bb = self.attach_blackboard_client(name=name)
        self.bb.register_key(key="/cell/cycles_done", access=common.Access.READ)

    def update(self) -> Status:
        done = self.bb.get("/cell/cycles_done") if self.bb.exists("/cell/cycles_done") else 0
        left = self.ctx.limits.cycles - int(done) - 1
        self.feedback_message = f"{left} cycle(s) after this one"
        return Status.SUCCESS if left > 0 else Status.FAILURE


@declare("slot_holds_part", "condition: the slot holds a part (fed or machined)", "Condition")
class SlotHoldsPart(Behaviour):
    """Condition: SUCCESS when the slot holds a part in one of ``states`` (default: fed or
    machined). Lets a resumed cell go on with the part in the slot instead of feeding a second
    one."""

    moves = False
    states: frozenset[SlotState] = frozenset({SlotState.FED, SlotState.MACHINED})

    def __init__(self, name: str, ctx: CellContext) -> None:
        super().__init__(name=name)
        self.ctx = ctx

    def update(self) -> Status:
        slot = self.ctx.slot_state
        self.feedback_message = f"slot: {slot}"
        return Status.SUCCESS if slot in self.states else Status.FAILURE


@declare(
    "holding_part",
    "condition: the gripper holds something and reports no fault (gates a retry)",
    "Condition",
)
class HoldingPart(Behaviour):
    """Condition: SUCCESS while the gripper holds something and reports no fault.

    Why: it gates a retry of a step that starts with the part in the hand (feed the slot, pack
    in the box). After a transient fault (a force-torque spike, a timeout) the part is usually
    still held, and the step can start afresh from where the arm stopped -- its first move goes
    straight up. With an empty hand, or a gripper in fault, a retry could only do harm: the
    condition fails and the failure goes up to the person."""

    moves = False

    def __init__(self, name: str, ctx: CellContext, **params: Any) -> None:
        super().__init__(name=name)
        self.ctx = ctx

    def update(self) -> Status:
        gripper = self.ctx.devices.gripper
        try:
            fault = gripper.fault()
            held = gripper.object_detected()
        except DeviceError as exc:
            self.feedback_message = f"gripper unreadable: {exc}"
            return Status.FAILURE
        if fault:
            self.feedback_message = f"gripper fault: {fault}"
            return Status.FAILURE
        self.feedback_message = "holding the part" if held else "the hand is empty"
        return Status.SUCCESS if held else Status.FAILURE


@declare("slot_machined", "condition: the part in the slot is machined", "Condition")
class SlotMachined(SlotHoldsPart):
    states = frozenset({SlotState.MACHINED})


# ------------------------------------------------------------------ slot and box (skills/)
class _Finisher(SkillBehaviour):
    """The rest of a step that stopped after its part changed hands (see the subclasses),
    from where the arm stands. With nothing left halfway it fails at once, moving nothing and
    saying nothing: it is the fallback after that step in a selector, and its not applying is
    not why anything failed (the step's own failure is what a stop names). It runs with the
    stopped step's own parameters and limits, so it takes none of its own."""

    section = None

    def pending(self) -> Skill | None:  # pragma: no cover - abstract
        """The rest of the stopped step, or None."""
        raise NotImplementedError

    def make_skill(self) -> Skill:
        rest = self.pending()
        if rest is None:
            raise SetupError("nothing was left halfway")
        return rest

    def update(self) -> Status:
        if self.skill is None:
            self.feedback_message = ""
            self.failure = Failure.CANNOT_START
            return Status.FAILURE
        return super().update()


def _holding(ctx: CellContext) -> bool | None:
    """Whether the gripper feels something; None when it cannot be read."""
    try:
        return ctx.devices.gripper.object_detected()
    except DeviceError:
        return None


def _let_go_of(skill: FeedSlotSkill | PackInBoxSkill, ctx: CellContext) -> bool:
    """The skill stopped after its let go began, before its weight check, and the hand holds
    nothing: the part stays where it was let go, and only the hand's way out is left to do. A
    gripper that cannot be read counts as empty (it was told to open). A stop in the weight
    check itself is its verdict (a part that came up, perhaps being gripped again): a person
    is told, as before."""
    return skill.finishable and _holding(ctx) is not True


@declare("feed_slot", "part into the machine slot, release, drag away", "Action", MOTION)
class FeedSlot(SkillBehaviour):
    section = "slot"

    def initialise(self) -> None:
        self.ctx.left_in_slot = None  # a part in the hand again: nothing left half fed
        super().initialise()

    def make_skill(self) -> Skill:
        g = self.ctx.geometry
        return FeedSlotSkill(
            np.asarray(g.slot_center, float),
            self.ctx.part,
            self.ctx.devices,
            self.settings(),
            arm_model=self.ctx.arm_model,
        )

    def on_success(self) -> None:
        _fed(self.ctx)

    def on_unfinished(self) -> None:
        """Past the let go the part stands in the pocket and the hand is open: ``leave_slot``
        finishes the way out."""
        skill = self.skill
        if isinstance(skill, FeedSlotSkill) and _let_go_of(skill, self.ctx):
            self.ctx.left_in_slot = skill


def _fed(ctx: CellContext) -> None:
    ctx.slot_state = SlotState.FED
    ctx.machining_started = False  # a part just fed: its machining has not begun
    ctx.feed_end_joints = np.asarray(ctx.devices.arm.joint_positions(), float)
    ctx.events.event(EventKind.FED)


@declare(
    "leave_slot",
    "after a feed_slot stopped past its let go: the open hand out of the slot, the part left",
    "Action",
    MOTION,
)
class LeaveSlot(_Finisher):
    """The way out of the slot of a feed that stopped after it let go of the part (a
    force-torque spike or a timeout while dragging out): the jaws opened again to the let
    go's width, up to where the drag ends, the weight check; the part then counts as fed."""

    def pending(self) -> Skill | None:
        feed = self.ctx.left_in_slot
        return None if feed is None else feed.leave()

    def on_success(self) -> None:
        self.ctx.left_in_slot = None
        _fed(self.ctx)


@declare(
    "back_over_slot",
    "joint move over the slot (after a look while the machine runs): to where pick_from_slot "
    "looks from, or where feed_slot left the arm",
    "Action",
    MOTION,
)
class BackOverSlot(SkillBehaviour):
    """Return over the slot by a joint move: to the pose the pick from the slot looks at the
    slot from, where the arm's kinematics solve it and the swept path is clear (the pick then
    starts with its look, no travel left: 1.6 s of each cycle's travel done while the machine
    runs), else to the joints the feed ended at, so the pick starts where it always did. Why
    not a straight move: from the look over the bin to the slot's view the tool turns by about
    100 deg, and straight moves there ran the twin's arm into its joint speed limit (read as
    90-95 N at the wrist as it stopped). A cell resumed with a part in the slot has no feed's
    joints: it goes home instead."""

    section = "go_home"

    def make_skill(self) -> Skill:
        from skills.slot import pick_finger_dir, slot_view_pose
        from skills.travel import joint_goal

        ctx = self.ctx
        joints = ctx.feed_end_joints
        if joints is None:  # a resumed cell: no feed in this run; home, as a resume starts
            return go_home(ctx.devices, ctx.geometry.home_joints, self.settings())
        slot, camera = self.settings("slot"), ctx.devices.camera
        home = self.settings()
        if slot.use_camera and camera is not None:  # the pick looks first: go where it looks
            center = np.asarray(ctx.geometry.slot_center, float)
            view = slot_view_pose(center[:2], center[2] + ctx.part.length,
                                  pick_finger_dir(center[:2], slot), camera, slot)
            here = ctx.devices.arm.joint_positions()
            # An empty hand above every fixture (at the look's last view, or its fingertips
            # clear of the fed part's rim where no look ran): it may rise as it goes, never
            # below the lower of its ends.
            move = joint_goal(ctx.arm_model, here, view, slot.min_radius, rise_first=False)
            if move is not None:
                joints = move.goal
                speed = move.joint_speed(home.joint_speed, slot.joint_tcp_speed)
                home = dataclasses.replace(home, joint_speed=speed)
        return go_home(ctx.devices, joints, home)


@declare("pick_from_slot", "the same hole grasp on the part in the slot", "Action", MOTION)
class PickFromSlot(SkillBehaviour):
    section = "slot"

    def make_skill(self) -> Skill:
        if self.ctx.lifting_from_slot is not None:
            # the part is in the hand: a fresh pick would open the jaws over the wall
            raise SetupError("the part is in the hand, its lift out of the slot unfinished")
        g = self.ctx.geometry
        return PickFromSlotSkill(
            np.asarray(g.slot_center, float),
            self.ctx.part,
            self.ctx.devices,
            self.settings(),
        )

    def on_success(self) -> None:
        _picked_from_slot(self.ctx)

    def on_unfinished(self) -> None:
        """Past the checked pinch, with the part still held: ``lift_from_slot`` finishes the
        lift. A hand that lost the part is a pick to start again."""
        skill = self.skill
        # a gripper that cannot be read: unknown, look again
        if isinstance(skill, PickFromSlotSkill) and skill.finishable and _holding(self.ctx):
            self.ctx.lifting_from_slot = skill


def _picked_from_slot(ctx: CellContext) -> None:
    ctx.slot_state = SlotState.EMPTY
    ctx.events.event(EventKind.PICKED_FROM_SLOT)


@declare(
    "lift_from_slot",
    "after a pick_from_slot stopped past its pinch with the part held: the rest of the lift",
    "Action",
    MOTION,
)
class LiftFromSlot(_Finisher):
    """The rest of a pick from the slot that stopped after its pinch was checked, the part
    still in the hand (a force-torque spike or a timeout while lifting out): up to where the
    lift ends, the weight check."""

    def pending(self) -> Skill | None:
        pick = self.ctx.lifting_from_slot
        return None if pick is None else pick.finish()

    def on_success(self) -> None:
        self.ctx.lifting_from_slot = None
        _picked_from_slot(self.ctx)


@declare("pack_in_box", "push -z, +x, +y until contact, release", "Action", MOTION)
class PackInBox(SkillBehaviour):
    section = "pack_in_box"

    def keys(self) -> dict[str, common.Access]:
        return {"/cell/place": common.Access.WRITE}

    def make_skill(self) -> Skill:
        places = self.ctx.geometry.tray_places
        free = [i for i in range(len(places)) if i not in self.ctx.filled]
        if not free:
            raise SetupError(f"the box is full ({len(places)} places)")
        self.index = free[0]
        self.bb.set("/cell/place", self.index)
        return PackInBoxSkill(
            np.asarray(places[self.index], float),
            self.ctx.part,
            self.ctx.devices,
            self.settings(),
            arm_model=self.ctx.arm_model,
        )

    def initialise(self) -> None:
        self.ctx.left_in_box = None  # a part in the hand again: nothing left half packed
        super().initialise()

    def on_success(self) -> None:
        self.ctx.filled.add(self.index)
        self.ctx.events.event(EventKind.PACKED, place=self.index)

    def on_unfinished(self) -> None:
        """Past the let go the part stands in its place and the hand is open: the place is
        taken, and ``leave_box`` finishes the way out. A part that came up with the hand and
        was gripped again is held: the packing is simply run again."""
        skill = self.skill
        if isinstance(skill, PackInBoxSkill) and _let_go_of(skill, self.ctx):
            self.ctx.filled.add(self.index)
            self.ctx.left_in_box = (self.index, skill)


@declare(
    "leave_box",
    "after a packing stopped past its let go: the open hand out of the box, the part left",
    "Action",
    MOTION,
)
class LeaveBox(_Finisher):
    """The way out of the box of a packing that stopped after it let go of the part (a
    force-torque spike or a timeout on the way up): the jaws opened again to the let go's
    width, the hand off the wall, up giving way in the plane, the weight check. The part stands
    where the packing pushed it, so it is reported packed in that place once the hand is out
    and empty."""

    def pending(self) -> Skill | None:
        if self.ctx.left_in_box is None:
            return None
        self.index, packing = self.ctx.left_in_box
        return packing.leave()

    def on_success(self) -> None:
        self.ctx.left_in_box = None
        self.ctx.events.event(EventKind.PACKED, place=self.index)


__all__ = [
    "Align",
    "BackOverSlot",
    "CycleFollows",
    "PlannedAhead",
    "StartMachining",
    "PickFromAbove",
    "FeedSlot",
    "GoHome",
    "Grasp",
    "LeaveBox",
    "LeaveSlot",
    "LiftFromSlot",
    "PackInBox",
    "Perceive",
    "PickFromSlot",
    "PlanPick",
    "PutBack",
    "SkillBehaviour",
    "Tilt",
    "WaitMachining",
]
