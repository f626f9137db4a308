"""The twin's parallel gripper: two mirrored, force-limited prismatic fingers, as the gripper's
description (:class:`drivers.gripper_spec.GripperSpec`, the 2F-85's by default) says it is.

What the description decides here, as on the unit: the force a close applies is the force
register's step in the unit's range (a 2F-85 asked for 2 N grips with 20 N: its register's 0 is
its weakest grip); the finger speed is clamped into the unit's range; the opening the skills
read is the unit's position count, refreshed at the driver's poll rate (sample and hold); an
object is detected when contact stops the fingers before the requested opening -- stopped as
a position sensor tells it: each finger's position moved less than ``stall_speed`` times
``stall_time`` over the last ``stall_time`` (the joints' speeds PyBullet reports in a stiff
pinch jitter at +-10 mm/s with the fingers still to 0.01 mm); and each pad
rides on a second, coupled joint along the approach axis (``<finger>_lift``) that follows the
linkage's tip travel as the opening changes (:meth:`GripperSpec.tip_advance`), so a 2F-85's tips
advance about 2.5 mm over a close from 70 to 61 mm, as the real fingers do.

Each finger is a PyBullet POSITION_CONTROL motor whose force is capped: closing on a part, a
finger stops where the part blocks it and then presses with exactly the commanded force, which is
how the 2F-85's grip-force setting behaves. Both fingers get the same command (mirrored about the
tool z axis); they are not mechanically coupled, so each one stops at its own contact and the pinch
does not push the part sideways.

Self-locking (on by default): the 2F-85 drives its fingers through a lead screw that the load
cannot turn back, so a part pressed in the pinch does not push the fingers open, however hard it
pushes; the motor only adds the set force inwards. The twin does the same with a ratchet: while
a close command runs, each finger's opening-side joint limit follows it in (``q +``
:data:`RATCHET_SLACK`), and an open command releases it. With ``self_locking=False`` a finger
yields as soon as the part pushes back harder than the grip force.

Finger geometry (tool frame: x the closing axis, ``finger_a`` on +x): finger ``k`` has joint
position ``q_k`` in [0, 0.0425] m, its pad face at ``|x| = q_k``; the opening is
``q_a + q_b`` (0..0.085 m).

:meth:`SimGripper.set_finger_friction` sets each finger link's lateral friction. PyBullet
multiplies the two bodies' coefficients at a contact, so with a part of friction 1.0 the finger's
own coefficient is the contact's: the cell gives the finger inside the hole mu_H and the outer
one mu_S.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from drivers.gripper_spec import GripperSpec, default_gripper
from sim.world import SimWorld

FINGER_NAMES = ("finger_a", "finger_b")
LIFT_NAMES = ("finger_a_lift", "finger_b_lift")
LIFT_FORCE = 2000.0  #: N the lift joint's motor may use: the linkage is not backdriven
LIFT_GAIN = 0.5  #: position gain of the lift joint's motor (PyBullet's, per physics step)
LIFT_PLAY = 2e-5  #: m the lift joint's limits leave either side of the linkage's tip position
LIFT_STEP = 1e-5  #: m the target must move before the limits are moved (a call each costs)
ARRIVED = 0.0004  #: m: a finger this near its target has arrived (about one 2F-85 step)
OPEN_FORCE = 100.0  #: N per finger when opening
LOST = 0.003  #: m: after a stall, the opening closing in by this much means the part is lost
RATCHET_SLACK = 0.0002  #: m a self-locking finger may be pushed back open


class SimGripper:
    """Implements :class:`drivers.gripper.Gripper` on the robot body's ``finger_a``/``finger_b``."""

    def __init__(
        self,
        world: SimWorld,
        body_id: int,
        joint_indices: dict[str, int],
        self_locking: bool = True,
        spec: GripperSpec | None = None,
    ) -> None:
        """``joint_indices`` maps ``finger_a``/``finger_b`` (and ``finger_a_lift``/
        ``finger_b_lift`` where the body has them) to the body's joint (= link) index;
        ``self_locking``: fingers cannot be pushed back open while closing (see module doc);
        ``spec``: the gripper's description (default: the shipped 2F-85)."""
        self.spec = spec = spec or default_gripper()
        self.stroke: float = spec.stroke  #: m, largest opening between the pads
        self.finger_width: float = spec.pad_width  #: m, pad width ``w``
        self._travel = 0.5 * spec.stroke  #: m each finger travels from the tool axis
        self._stall_steps = max(1, int(math.ceil(spec.stall_time / world.settings.control_dt)))
        self._next_poll = 0.0  #: s (the world's clock), when the driver next reads the status
        self.self_locking = self_locking
        self._world = world
        self._p = world.p
        self._body = body_id
        self._joints = tuple(joint_indices[name] for name in FINGER_NAMES)
        self._lifts = tuple(joint_indices[n] for n in LIFT_NAMES if n in joint_indices)
        self._lift_targets = [math.inf, math.inf]  #: m, where each lift joint is held now
        #: the lift joint is 0 fully open (the pads hang their length below the body) and goes
        #: down the linkage's advance as the jaws close
        self._open_advance = spec.tip_advance(spec.stroke)
        self.commanded_force = 0.0  #: N per finger the last close applies (the register's step)
        self._reported = (0.0, False, False)  #: (opening, moving, object) as last polled
        self._target: float | None = None  # opening (m) of the command being watched
        self._still = 0  # consecutive control steps with both fingers still
        #: the fingers' positions (m) over the last ``stall_time`` (its steps and the one before)
        self._trail: deque[tuple[float, float]] = deque(maxlen=self._stall_steps + 1)
        self._steps = 0  # control steps since the last command
        self._active = False  # a command is in progress (fingers not yet arrived or stalled)
        self._stalled = False
        self._stall_width = 0.0  # opening (m) where the fingers stalled
        self._locking = False  # the ratchet is engaged (a close command runs, self-locking)
        self._limits = [self._travel, self._travel]  # each finger's upper joint limit now (m)
        # The 2F-85's linkage moves both fingers together, symmetric about the tool axis; a
        # gear constraint couples the two prismatic joints the same way (q_b = q_a).
        self._gear = self._p.createConstraint(
            body_id, self._joints[0], body_id, self._joints[1], self._p.JOINT_GEAR,
            [1, 0, 0], [0, 0, 0], [0, 0, 0],
        )
        self._p.changeConstraint(self._gear, gearRatio=-1, maxForce=10 * spec.force_max, erp=0.2)
        world.after_step(self._after_step)
        self._follow_linkage()
        self._poll()

    # --- setup helpers (not part of the interface) ---------------------------------------

    def finger_link(self, name: str) -> int:
        """Link index of ``finger_a`` or ``finger_b`` (for friction, contact queries)."""
        if name not in FINGER_NAMES:
            raise ValueError(f"unknown finger {name!r}; valid: {', '.join(FINGER_NAMES)}")
        return self._joints[FINGER_NAMES.index(name)]

    def set_finger_friction(self, mu_a: float, mu_b: float) -> None:
        """Lateral friction coefficient of ``finger_a`` and ``finger_b`` (dimensionless, >= 0)."""
        for joint, mu in zip(self._joints, (mu_a, mu_b), strict=True):
            if mu < 0:
                raise ValueError(f"friction must be >= 0, got {mu}")
            self._p.changeDynamics(self._body, joint, lateralFriction=float(mu))

    def reset_width(self, width: float) -> None:
        """Teleport both fingers to ``width`` (m) and hold it; setup only, before any contact."""
        q = float(np.clip(width, 0.0, self.stroke)) / 2
        self._release()
        for joint in self._joints:
            self._p.resetJointState(self._body, joint, q)
        for joint in self._lifts:
            self._p.resetJointState(
                self._body, joint, self.spec.tip_advance(2 * q) - self._open_advance
            )
        self._lift_targets = [math.inf, math.inf]
        self._command(2 * q, self.spec.speed_max, OPEN_FORCE)
        self._active = False
        self._target = None
        self._follow_linkage()
        self._poll()

    # --- the Gripper interface -----------------------------------------------------------

    def open(self, width: float | None = None, speed: float = 0.1) -> None:
        """Start opening (or moving) to ``width`` (m, full stroke if None); ``speed`` (m/s) is
        each finger's speed, so the opening changes at twice it."""
        target = self.stroke if width is None else float(np.clip(width, 0.0, self.stroke))
        self._command(target, self.spec.applied_speed(speed), OPEN_FORCE)

    def close(self, force: float, speed: float = 0.05, width: float = 0.0) -> None:
        """Start closing towards ``width`` (m, 0 = fully) with at most ``force`` (N) per finger,
        each finger at ``speed`` (m/s). On a part the fingers stall and keep pressing with the
        force the unit applies for ``force`` (its register's step within its range: never less
        than its weakest grip); they never close past ``width``."""
        target = float(np.clip(width, 0.0, self.stroke))
        self.commanded_force = self.spec.applied_force(force)
        self._command(target, self.spec.applied_speed(speed), self.commanded_force)

    def width(self) -> float:
        """The opening (m) as the unit reports it: its position count, as last polled."""
        return self._reported[0]

    def true_width(self) -> float:
        """The opening between the pads (m) from the joint states (the judge's, not a skill's)."""
        return float(sum(self._p.getJointState(self._body, j)[0] for j in self._joints))

    def tip_advance(self, width: float) -> float:
        """m the fingertips reach further along the approach at ``width`` than fully closed
        (the description's linkage)."""
        return self.spec.tip_advance(width)

    def moving(self) -> bool:
        """True while a command is in progress: fingers neither arrived nor stalled. A command
        counts as moving until the unit has been polled after it."""
        return self._active or self._reported[1]

    def object_detected(self) -> bool:
        """True when both fingers stalled short of the commanded opening (a part between them),
        as last polled."""
        return self._reported[2] and self._stalled

    def fault(self) -> str | None:
        """The twin's gripper never faults."""
        return None

    # --- internals -----------------------------------------------------------------------

    def _command(self, opening: float, speed: float, force: float) -> None:
        if opening < self.width() and self.self_locking:
            self._locking = True
        else:
            self._release()
        self._target = opening
        speed = float(np.clip(speed, self.spec.speed_min, self.spec.speed_max))
        for joint in self._joints:
            self._p.setJointMotorControl2(
                self._body,
                joint,
                self._p.POSITION_CONTROL,
                targetPosition=opening / 2,
                force=force,
                maxVelocity=speed,
                positionGain=0.2,
            )
        self._active = True
        self._stalled = False
        self._still = 0
        self._trail.clear()
        self._steps = 0

    def _release(self) -> None:
        """Free the fingers to open again (full travel)."""
        self._locking = False
        for i, joint in enumerate(self._joints):
            if self._limits[i] != self._travel:
                self._limits[i] = self._travel
                self._p.changeDynamics(
                    self._body, joint, jointLowerLimit=0.0, jointUpperLimit=self._travel
                )

    def _after_step(self) -> None:
        """Ratchet and watch on one read of both fingers' joint states (each PyBullet state
        query costs about as much as all the arithmetic here; moving a joint limit does not
        change the state read)."""
        locking = self._locking
        if locking or self._target is not None:
            states = self._p.getJointStates(self._body, self._joints)
            if locking:
                self._ratchet(states)
            self._watch(states)
        self._follow_linkage()
        now = self._world.clock.now()
        if now >= self._next_poll - 1e-9:
            self._poll()
            self._next_poll = max(self._next_poll + 1.0 / self.spec.poll_hz, now)

    def _follow_linkage(self) -> None:
        """Hold each pad's lift joint where the linkage puts the tip at that finger's opening:
        the coupled second joint of the module doc. The joint's limits close round the target
        (a motor alone yields a millimetre under a 150 N press, a linkage does not)."""
        if not self._lifts or self.spec.crank <= 0:
            return
        for i, (finger, lift) in enumerate(zip(self._joints, self._lifts, strict=True)):
            q = self._p.getJointState(self._body, finger)[0]
            target = self.spec.tip_advance(2.0 * q) - self._open_advance
            if abs(target - self._lift_targets[i]) < LIFT_STEP:
                continue
            self._lift_targets[i] = target
            self._p.changeDynamics(self._body, lift, jointLowerLimit=target - LIFT_PLAY,
                                   jointUpperLimit=target + LIFT_PLAY,
                                   jointLimitForce=LIFT_FORCE)
            self._p.setJointMotorControl2(
                self._body, lift, self._p.POSITION_CONTROL,
                targetPosition=target, force=LIFT_FORCE, maxVelocity=1.0,
                positionGain=LIFT_GAIN,
            )

    def _poll(self) -> None:
        """The driver's status read: the opening in the unit's position counts, its motion and
        object flags."""
        self._reported = (
            self.spec.reported_width(self.true_width()), self._active, self._stalled
        )

    def _ratchet(self, states: list) -> None:  # type: ignore[type-arg]
        """Move each finger's opening limit in behind it: it may close further, not reopen.
        ``states``: PyBullet's joint states of the two fingers, read after this step."""
        for i, joint in enumerate(self._joints):
            q = states[i][0]
            limit = max(q + RATCHET_SLACK, RATCHET_SLACK)
            if limit < self._limits[i] - 1e-5:
                self._limits[i] = limit
                self._p.changeDynamics(
                    self._body, joint, jointLowerLimit=0.0, jointUpperLimit=limit
                )

    def _watch(self, states: list) -> None:  # type: ignore[type-arg]
        """After each control step: has the command arrived, or stalled on something?
        ``states``: PyBullet's joint states of the two fingers, read after this step.

        Watching goes on after a stall: if the opening then moves more than :data:`LOST` (m)
        towards the target, the part slipped out, and the fingers count as moving again
        (``moving()`` True, ``object_detected()`` False) until they arrive or stall anew. Small
        finger motion in a pinch (a part turning) does not end the stall.

        A stall is judged from the fingers' positions over ``stall_time`` (the module doc).

        Two fingers: plain floats, not numpy (the same double arithmetic, without numpy's
        per-call cost on two-element arrays every control step).
        """
        if self._target is None:
            return
        self._steps += 1
        qa, qb = states[0][0], states[1][0]
        half = self._target / 2
        if abs(qa - half) < ARRIVED and abs(qb - half) < ARRIVED:
            self._active = False
            self._stalled = False
            self._target = None
            return
        trail = self._trail
        trail.append((qa, qb))
        (qa0, qb0), span = trail[0], (len(trail) - 1) * self._world.settings.control_dt
        most = self.spec.stall_speed * span
        still = len(trail) > 1 and abs(qa - qa0) < most and abs(qb - qb0) < most
        self._still = self._still + 1 if still else 0
        width = qa + qb
        if self._stalled:
            if abs(width - self._target) < abs(self._stall_width - self._target) - LOST:
                self._stalled = False
                self._active = True
                self._still = 0
        elif self._still >= self._stall_steps and self._steps > self._stall_steps:
            self._active = False
            self._stalled = True
            self._stall_width = width
