"""The twin's arm: Cartesian motion of the UR5's TCP, advanced one control step at a time.

Every command returns at once; :meth:`SimWorld.step` moves the arm. Poses are of the ``tcp``
link in the robot base frame (UR ``Base``; see :mod:`drivers.ur5.kinematics`), metres and
radians.

How it moves, and why:

* **Trajectories** (:meth:`SimArm.move_to`, :meth:`SimArm.move_path`) are straight lines in
  position with the rotation slerped along (:meth:`drivers.pose.Pose.interpolate`), timed by one
  trapezoidal speed profile over the whole path. The path length counts rotation as
  :data:`ROTATION_LENGTH` m per rad, so ``speed`` also bounds the turning rate. The whole path is
  checked for reachability before the arm moves; an unreachable one faults at once.
* **Inverse kinematics** is damped least squares on the model's own Jacobian
  (:func:`drivers.ur5.kinematics.jacobian`, the same chain as the URDF, in plain float
  arithmetic; :func:`drivers.ur5.kinematics.solve_ik`), seeded with the last command so it
  never jumps branches: one step per control step while following (about 1e-7 m, see
  :meth:`SimArm._track`), iterated to 1e-9 m for checks and jumps.
  PyBullet's ``calculateInverseKinematics`` (100 iterations, threshold 1e-5) leaves about
  1e-5 m here and starts from the body's live state; ours is cheaper per step as well.
  The per-step path (:meth:`SimArm._track_frame`, :meth:`SimArm._actuate`) works on
  ``(position, rotation)`` pairs and float lists rather than :class:`Pose` objects and tiny
  numpy arrays, whose per-call costs outweighed the arithmetic; it keeps every numpy matrix
  product and the LAPACK solve (BLAS rounds those its own way), so the joint commands are the
  ones the numpy formulas give, bit for bit (``tests/drivers/ur5/test_kinematics_exact.py``):
  contacts are chaotic, and a last-bit change would change trial outcomes.
* **Joint control** is PyBullet POSITION_CONTROL with the joint torque limits, fed a position
  target interpolated per physics substep and the matching velocity as feed-forward. A line at
  constant speed stays on the line to micrometres; along it the TCP trails the command by one
  physics substep (4 ms, 0.2 mm at 0.05 m/s). The joint speed limit (pi rad/s) is enforced on
  the commands.
* **Force mode** drops the joint motors for torque control: gravity compensation
  (``calculateInverseDynamics``) plus a Cartesian spring-damper to a virtual target pose. Along
  selected axes the virtual target moves by admittance on the wrist sensor,
  ``v = gain * (wrench - measured)`` clipped to the speed limits; along the others it holds. The
  spring gives the contact a finite stiffness (:data:`FORCE_STIFFNESS`), which a stiff position
  servo against a rigid simulated contact cannot: there the force jumps from zero to the joint
  torque limit.
* **Command lag** (:meth:`SimArm.set_command_lag`, 0 by default): over RTDE a target takes
  effect a few milliseconds after it is sent. With a lag of ``n`` control steps the joint
  targets the motors get are the ones commanded ``n`` steps earlier (a delay line on the
  commands); what the arm reports (state, commanded joints) is at once, as a controller
  acknowledges a command before it moves. Force mode's own loop runs on the controller without
  the lag; a protective stop holds at once.
* **servoj** (:meth:`SimArm.set_servo_tracking`, off by default): a UR follows each
  ``servoL`` target by ``servoj``, which UR describes as a P-controller (``gain``) on the error
  from the current position projected ``lookahead_time`` ahead with the current velocity:
  ``q'' = gain (q_goal - q - lookahead q')``. At the driver's 0.05 s and 1000 that is a filter
  of about 5 Hz, damping 0.79, trailing a steady stream by about ``lookahead`` seconds (less one
  control step: a target is followed from the step after it is sent); a stream whose
  targets arrive unevenly (two in one controller cycle, none in the next) moves the arm
  smoothly. Off, a target is reached within the step, as the twin's own ticks land one per
  step. The emulated controller turns it on with each ``servoL``'s values.
* **Protective stop**: like a UR5 at its default 150 N safety limit, the arm faults with
  ``protective_stop=True`` and holds where it is when the force on the tool (less its weight)
  stays above :data:`PROTECTIVE_FORCE`; the next motion command clears it. Position control
  into a rigid surface trips it after a fraction of a millimetre.
"""

from __future__ import annotations

import bisect
import functools
import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from drivers.arm import ArmStatus, MotionState
from drivers.pose import Pose
from drivers.ur5.kinematics import (
    ARM_LIMIT,
    ARM_VELOCITY,
    REACH_TOLERANCE,
    ROTATION_LENGTH,
    TCP_Z,
    dls_step,
    frame_error_list,
    jacobian_frame,
    largest_magnitude,
    residual,
    rotvec_to_matrix,
    solve_ik,
)
from drivers.ur5.kinematics import forward_kinematics as fk
from sim.ft_sensor import SimForceTorqueSensor
from sim.robot_model import ARM_EFFORT, TOOL_MASS
from sim.world import SimWorld

DONE_POSITION = 0.001  #: m: the TCP within this of the goal (and DONE_ANGLE) ends a move
DONE_ANGLE = np.radians(0.5)  #: rad
SETTLE_TIME = 0.5  #: s after the profile ends before a move is reported done regardless
POSITION_GAIN = 0.5  #: PyBullet motor position gain (fraction of the error corrected per substep)
JUMP = 0.002  #: m: a servo target farther than this from the command gets the full IK solve
CHECK_STEP = 0.01  #: m of path length between poses checked for reachability before a move

# Protective stop, as a UR5's default safety force limit: the contact force at the tool (the
# sensor's true load less the tool's own weight) above PROTECTIVE_FORCE for PROTECTIVE_STEPS
# control steps in a row (so one solver spike does not trip it).
PROTECTIVE_FORCE = 150.0  #: N
PROTECTIVE_STEPS = 3
PROTECTIVE_RELIEF = 1.0  #: N a step: a contact force falling faster than this is being relieved

# Force mode (impedance to a virtual target + admittance on the sensor).
FORCE_STIFFNESS = np.array([4000.0] * 3 + [30.0] * 3)  #: N/m, N*m/rad at the TCP
FORCE_DAMPING = np.array([80.0] * 3 + [0.3] * 3)  #: N*s/m, N*m*s/rad at the TCP
ADMITTANCE_GAIN = np.array([0.005] * 3 + [0.5] * 3)  #: (m/s)/N, (rad/s)/(N*m)


@dataclass(frozen=True)
class _Path:
    """Poses joined by straight segments and one trapezoidal profile over their length."""

    poses: tuple[Pose, ...]
    cumulative: NDArray[np.float64]  # path length (m) at each pose
    turns: NDArray[np.float64]  # per segment, the rotation vector (rad) in the segment's start
    speed: float  # m/s
    acceleration: float  # m/s^2

    @classmethod
    def through(cls, poses: Sequence[Pose], speed: float, acceleration: float) -> _Path:
        lengths = [0.0]
        turns = []
        for a, b in zip(poses[:-1], poses[1:], strict=True):
            turn = Rotation.from_matrix(a.rotation.T @ b.rotation).as_rotvec()
            d = float(np.linalg.norm(b.position - a.position))
            lengths.append(max(d, ROTATION_LENGTH * float(np.linalg.norm(turn))))
            turns.append(turn)
        return cls(tuple(poses), np.cumsum(lengths), np.array(turns), speed, acceleration)

    # Cached: the path is frozen, and the follower asks for both every control step.
    @functools.cached_property
    def length(self) -> float:
        return float(self.cumulative[-1])

    @functools.cached_property
    def _breaks(self) -> list[float]:
        """``cumulative`` as floats, for :func:`bisect.bisect_right` (numpy's searchsorted
        with side='right' on a sorted array finds the same index, at several times the cost)."""
        return self.cumulative.tolist()  # type: ignore[no-any-return]

    @functools.cached_property
    def duration(self) -> float:
        v, a, length = self.speed, self.acceleration, self.length
        if length <= 0.0:
            return 0.0
        if length < v * v / a:  # triangular: never reaches full speed
            return 2.0 * np.sqrt(length / a)
        return length / v + v / a

    def distance_at(self, t: float) -> float:
        """Path length (m) covered at time ``t`` (s) from the start."""
        v, a, length = self.speed, self.acceleration, self.length
        total = self.duration
        if t <= 0.0 or length <= 0.0:
            return 0.0
        if t >= total:
            return length
        t_acc = min(v / a, total / 2.0)
        peak = a * t_acc
        if t < t_acc:
            return 0.5 * a * t * t
        if t > total - t_acc:
            rest = total - t
            return length - 0.5 * a * rest * rest
        return 0.5 * a * t_acc * t_acc + peak * (t - t_acc)

    def pose_at(self, s: float) -> Pose:
        """Pose at path length ``s`` (m): :meth:`Pose.interpolate` within the segment (the same
        formula, with the segment's rotation vector computed once)."""
        if s >= self.length:
            return self.poses[-1]
        return Pose(*self.frame_at(s))

    def frame_at(self, s: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """:meth:`pose_at` as ``(position, rotation)`` arrays, without building a :class:`Pose`
        (the follower asks every control step; the same numbers, float for float)."""
        if s >= self.length:
            end = self.poses[-1]
            return end.position, end.rotation
        breaks = self._breaks
        i = bisect.bisect_right(breaks, s) - 1
        i = min(max(i, 0), len(self.poses) - 2)
        seg = breaks[i + 1] - breaks[i]
        u = 0.0 if seg <= 0.0 else (s - breaks[i]) / seg
        a, b = self.poses[i], self.poses[i + 1]
        position = [
            p + u * (q - p) for p, q in zip(a.position.tolist(), b.position.tolist(), strict=True)
        ]
        turn = [u * t for t in self.turns[i].tolist()]
        return np.array(position), a.rotation @ rotvec_to_matrix(turn)


class SimArm:
    """Implements :class:`drivers.arm.Arm` for the ``tcp`` link of a loaded robot body."""

    def __init__(
        self,
        world: SimWorld,
        body_id: int,
        joint_indices: Sequence[int],
        ft: SimForceTorqueSensor | None = None,
        home_joints: ArrayLike | None = None,
    ) -> None:
        """``joint_indices``: the body's six arm joints, base to wrist 3; ``ft`` enables
        :meth:`force_mode`; ``home_joints`` (rad) is where :meth:`home` goes."""
        self._world = world
        self._p = world.p
        self._body = body_id
        self._joints = list(joint_indices)
        self._ft = ft
        self._dt = world.settings.control_dt
        self._substeps = world.settings.substeps
        self._effort = list(ARM_EFFORT)
        self._home = None if home_joints is None else np.asarray(home_joints, float)
        # Every movable joint of the body (inverse dynamics wants them all) and where ours are.
        movable = [
            j for j in range(self._p.getNumJoints(body_id))
            if self._p.getJointInfo(body_id, j)[2] != self._p.JOINT_FIXED
        ]
        self._movable = (movable, [movable.index(j) for j in self._joints])
        # The command: joints at the start and end of the current control step.
        self._q_from = self.joint_positions()
        self._q_to = self._q_from.copy()
        self._substep = 0
        self._mode = "hold"  # hold | path | servo | force
        self._state = MotionState.IDLE
        self._message = ""
        self._path: _Path | None = None
        self._t = 0.0
        self._speed = 1.0  #: the speed slider: trajectory time per control step, in steps
        self._servo_target: Pose | None = None
        # The pose commanded for the step just run, as (position, rotation).
        self._last_target: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None
        self._clipped = False  # the last step was slowed to the joint speed limit
        self._over = 0  # control steps in a row with the tool force over the protective limit
        self._last_force = 0.0  # N, the contact force at the last step it was computed
        self._protective = False  # the current FAULT is a protective stop
        self._force: dict[str, NDArray[np.float64]] = {}
        self._virtual: Pose | None = None
        # What _actuate sends, worked out once per control step (see _command_for). PyBullet's
        # constants read once: BulletClient finds each through __getattr__, microseconds a read.
        self._position_control: int = self._p.POSITION_CONTROL
        self._torque_control: int = self._p.TORQUE_CONTROL
        self._gains = ([POSITION_GAIN] * 6, [1.0] * 6)
        self._command_of: tuple[object, object] | None = None
        self._command: tuple[list[float], list[float], list[float]] = ([], [], [])
        # The command lag: the last lag + 1 steps' (q_from, q_to), the oldest actuated.
        self._lag = 0
        self._line: deque[tuple[NDArray[np.float64], NDArray[np.float64]]] = deque()
        # servoj's tracking law (lookahead s, gain) or None: the target reached within a step.
        self._servoj: tuple[float, float] | None = None
        self._goal: NDArray[np.float64] | None = None  # joints that reach the servo target
        self._ref_speed = np.zeros(6)  # rad/s, the servo reference's joint speeds
        world.before_step(self._control)
        world.before_substep(self._actuate)

    # --- setup helpers (not part of the interface) ---------------------------------------

    def set_command_lag(self, steps: int) -> None:
        """Targets take effect ``steps`` control steps after they are commanded (0: at once);
        see the module doc. Set it before the arm moves."""
        if int(steps) != steps or steps < 0:
            raise ValueError(f"the command lag must be a whole number of steps >= 0, got {steps}")
        self._lag = int(steps)
        self._line.clear()

    def set_servo_tracking(self, lookahead: float | None, gain: float | None = None) -> None:
        """How a servo target is followed: None (the default) reaches it within a control step;
        ``(lookahead s, gain)`` follows it by UR's ``servoj`` law (see the module doc), as the
        emulated controller runs each ``servoL`` with the driver's own values."""
        if lookahead is None:
            self._servoj = None
            return
        if lookahead <= 0.0 or gain is None or gain <= 0.0:
            raise ValueError(f"servoj needs lookahead > 0 and gain > 0, got {lookahead}, {gain}")
        self._servoj = (float(lookahead), float(gain))

    def set_speed_fraction(self, fraction: float) -> None:
        """The UR's speed slider (0-1), as its controller applies it: the timing of a path or
        a joint move runs at this fraction, so 0 holds the arm where the trajectory is and
        a later value resumes it from there. Servo and force mode are not scaled."""
        if not 0.0 <= fraction <= 1.0:
            raise ValueError(f"the speed fraction must lie in [0, 1], got {fraction}")
        self._speed = float(fraction)

    @property
    def command_lag(self) -> int:
        """Control steps between a target commanded and the motors getting it."""
        return self._lag

    def reset_joints(self, q: ArrayLike) -> None:
        """Teleport the arm to joints ``q`` (rad) and hold them; setup only, before contact."""
        q = np.asarray(q, float).reshape(6)
        for joint, angle in zip(self._joints, q, strict=True):
            self._p.resetJointState(self._body, joint, float(angle))
        self._line.clear()
        self._hold(q)
        self._state, self._message, self._protective = MotionState.IDLE, "", False
        self._over = 0

    def home(self, speed: float = 0.25, acceleration: float = 1.0) -> None:
        """Start a straight-line move to the home joints' TCP pose (m/s, m/s^2)."""
        if self._home is None:
            raise ValueError("this arm has no home joints")
        self.move_to(fk(self._home), speed, acceleration)

    @property
    def home_joints(self) -> NDArray[np.float64] | None:
        return None if self._home is None else self._home.copy()

    def commanded_joints(self) -> NDArray[np.float64]:
        """The joint target (rad) at the end of the current control step."""
        return self._q_to.copy()

    # --- the Arm interface ---------------------------------------------------------------

    def tool_pose(self) -> Pose:
        """Current TCP pose in the base frame (m, rad), from the measured joints."""
        return fk(self.joint_positions())

    def joint_positions(self) -> NDArray[np.float64]:
        """Measured joint angles (rad), base to wrist 3."""
        return np.array([s[0] for s in self._p.getJointStates(self._body, self._joints)])

    def joint_velocities(self) -> NDArray[np.float64]:
        """Measured joint speeds (rad/s), base to wrist 3 (what a controller publishes)."""
        return np.array([s[1] for s in self._p.getJointStates(self._body, self._joints)])

    def move_to(self, pose: Pose, speed: float, acceleration: float) -> None:
        """Start a straight-line move of the TCP to ``pose`` (m/s, m/s^2)."""
        self.move_path([pose], speed, acceleration)

    def move_path(self, waypoints: Sequence[Pose], speed: float, acceleration: float) -> None:
        """Start a straight-line path from the commanded pose through ``waypoints``.

        One trapezoidal profile (``speed`` m/s, ``acceleration`` m/s^2) spans the whole path, so
        the TCP does not stop at intermediate waypoints. The path is checked first: if IK cannot
        follow it to within :data:`REACH_TOLERANCE`, the arm holds and reports FAULT.
        """
        if speed <= 0 or acceleration <= 0:
            raise ValueError(f"speed and acceleration must be > 0, got {speed}, {acceleration}")
        self._leave_force_mode()
        start_q = self._q_to.copy()
        path = _Path.through([fk(start_q), *waypoints], float(speed), float(acceleration))
        samples = max(1, int(np.ceil(path.length / CHECK_STEP)))
        q = start_q
        for s in np.linspace(0.0, path.length, samples + 1)[1:]:
            q, miss = solve_ik(path.pose_at(float(s)), q, iterations=100)
            if miss > REACH_TOLERANCE:
                self._fault("target unreachable", start_q)
                return
        self._path, self._t = path, 0.0
        self._last_target = None
        self._mode = "path"
        self._start_motion()

    def move_joints(self, q: Sequence[float], speed: float, acceleration: float) -> None:
        """Start a joint-space move to ``q`` (rad): every joint on one trapezoidal profile
        (``speed`` rad/s, ``acceleration`` rad/s^2 for the joint with the longest way)."""
        if speed <= 0 or acceleration <= 0:
            raise ValueError(f"speed and acceleration must be > 0, got {speed}, {acceleration}")
        goal = np.asarray(q, float).reshape(6)
        if np.any(np.abs(goal) > ARM_LIMIT):
            self._fault("joint target outside the joint limits", self._q_to)
            return
        self._leave_force_mode()
        start = self._q_to.copy()
        span = float(np.max(np.abs(goal - start)))
        # Trapezoid (or triangle) over the longest joint's way.
        t_acc = speed / acceleration
        if span < speed * t_acc:
            t_acc = float(np.sqrt(span / acceleration))
            duration = 2 * t_acc
            speed = acceleration * t_acc
        else:
            duration = span / speed + t_acc
        self._joint_move = (start, goal, span, float(speed), float(acceleration), duration)
        self._t = 0.0
        self._path = None
        self._last_target = None
        self._mode = "joints"
        self._start_motion()

    def _follow_joints(self) -> None:
        start, goal, span, v, a, duration = self._joint_move
        self._t += self._dt * self._speed
        t = min(self._t, duration)
        t_acc = v / a
        if t < t_acc:
            d = 0.5 * a * t * t
        elif t < duration - t_acc:
            d = 0.5 * a * t_acc * t_acc + v * (t - t_acc)
        else:
            d = span - 0.5 * a * (duration - t) ** 2
        u = 1.0 if span <= 0 else min(max(d / span, 0.0), 1.0)
        if self._t <= duration + self._dt:
            self._advance_to(start + u * (goal - start))
            return
        self._q_from = self._q_to.copy()
        if np.max(np.abs(self.joint_positions() - goal)) < 1e-3 or self._t > duration + SETTLE_TIME:
            self._mode = "hold"
            self._state = MotionState.DONE

    @property
    def mode(self) -> str:
        """What drives the joints now: hold, path, joints, servo or force (diagnostics)."""
        return self._mode

    def servo_lag(self) -> float:
        """servoj's lookahead (s) when the arm follows by that law, else 0."""
        return 0.0 if self._servoj is None else self._servoj[0]

    def servo(self, target: Pose) -> None:
        """Set the TCP target (base frame) for the next control step.

        The caller streams targets close together; the joints move there within one step if
        the joint speed limit allows, and otherwise as fast as it does.
        """
        self._leave_force_mode()
        if self._mode != "servo":
            self._last_target = None
            self._goal = None
        self._servo_target = target
        self._mode = "servo"
        self._path = None
        self._start_motion()

    def force_mode(
        self,
        selection: Sequence[bool],
        wrench: Sequence[float],
        speed_limits: Sequence[float],
    ) -> None:
        """Push with ``wrench`` (N, N*m; the force the TCP applies to the environment, base
        frame, torques about the TCP) on the ``selection`` axes, moving at most
        ``speed_limits`` (m/s, rad/s) there; hold the other axes. Runs until :meth:`stop`."""
        if self._ft is None:
            raise RuntimeError("force mode needs the wrist force-torque sensor")
        sel = np.asarray(selection, bool).reshape(6)
        if self._mode != "force":
            self._virtual = self.tool_pose()
            self._p.setJointMotorControlArray(
                self._body, self._joints, self._p.VELOCITY_CONTROL,
                targetVelocities=[0.0] * 6, forces=[0.0] * 6,
            )
        self._force = {
            "selection": sel,
            "wrench": np.asarray(wrench, float).reshape(6),
            "speed": np.abs(np.asarray(speed_limits, float).reshape(6)),
        }
        self._mode = "force"
        self._path = None
        self._start_motion()

    def stop(self) -> None:
        """Hold the last commanded joints (force mode: the measured ones); a motion in progress
        ends STOPPED, a finished or faulted one keeps its state.

        The arm comes to standstill within about one control step; at the twin's slow skill
        speeds that is the UR's stop with a high deceleration. Idempotent.
        """
        if self._mode == "force":
            self._leave_force_mode()
        elif self._mode != "hold":
            self._hold(self._q_to)
        if self._state is MotionState.MOVING:
            self._state, self._message = MotionState.STOPPED, ""

    def status(self) -> ArmStatus:
        """State of the last commanded motion; ``protective_stop`` after a force-limit trip."""
        return ArmStatus(self._state, self._message, self._protective)

    # --- per-step control ----------------------------------------------------------------

    def _hold(self, q: ArrayLike) -> None:
        self._q_from = np.array(q, float)
        self._q_to = self._q_from.copy()
        self._mode = "hold"
        self._path = None
        self._servo_target = None
        self._last_target = None
        self._goal = None
        self._send(self._q_to, np.zeros(6))

    def _start_motion(self) -> None:
        """A new command clears any fault, a protective stop included (as unlocking it does)."""
        self._state, self._message, self._protective = MotionState.MOVING, "", False

    def _fault(self, message: str, q_hold: ArrayLike) -> None:
        self._hold(q_hold)
        self._state, self._message, self._protective = MotionState.FAULT, message, False

    def _leave_force_mode(self) -> None:
        if self._mode == "force":
            self._line.clear()  # nothing commanded before force mode is still on its way
            self._hold(self.joint_positions())

    def contact_force(self) -> float:
        """Magnitude (N) of the force on the tool other than its own weight, from the sensor's
        newest noiseless sample; what the protective stop watches (0 without a sensor)."""
        if self._ft is None:
            return 0.0
        weight = np.array([0.0, 0.0, -TOOL_MASS * self._world.settings.gravity])
        load = self._ft.sampled_true_load()[:3]
        return float(np.linalg.norm(load - self.tool_pose().rotation.T @ weight))

    def _protective_stop(self) -> bool:
        """Trip the protective stop if the contact force stayed over the limit; True if so."""
        if self._state is MotionState.FAULT or self._ft is None:
            return False
        # |load - weight| <= |load| + |weight|: most steps need no kinematics to rule it out.
        fx, fy, fz = self._ft.sampled_true_load()[:3].tolist()
        weight = TOOL_MASS * self._world.settings.gravity
        if math.sqrt(fx * fx + fy * fy + fz * fz) + weight <= PROTECTIVE_FORCE:
            self._over = 0
            self._last_force = 0.0
            return False
        force = self.contact_force()
        # A force over the limit that falls is being relieved (the arm backing away from what it
        # pressed, after the stop was cleared): only a force that stays or grows trips it.
        rising = force >= self._last_force - PROTECTIVE_RELIEF
        self._last_force = force
        self._over = self._over + 1 if force > PROTECTIVE_FORCE and rising else 0
        if self._over < PROTECTIVE_STEPS:
            return False
        self._leave_force_mode()
        self._line.clear()  # the controller's own stop: no lag
        self._hold(self.joint_positions())
        self._state = MotionState.FAULT
        self._message = f"protective stop: tool force {force:.0f} N > {PROTECTIVE_FORCE:.0f} N"
        self._protective = True
        self._over = 0
        return True

    def _control(self) -> None:
        """Once per control step, before physics: the next joint target, into the delay line
        of the command lag."""
        self._control_step()
        if self._lag:
            if self._mode == "force":
                self._line.clear()
            else:
                self._line.append((self._q_from, self._q_to))
                while len(self._line) > self._lag + 1:
                    self._line.popleft()

    def _control_step(self) -> None:
        """The next joint target, ``(q_from, q_to)`` of this control step, as commanded."""
        self._substep = 0
        if self._protective_stop():
            return
        if self._mode == "path":
            self._follow_path()
        elif self._mode == "servo":
            self._follow_servo()
        elif self._mode == "joints":
            self._follow_joints()
        elif self._mode == "force":
            self._update_virtual()
        else:
            self._q_from = self._q_to.copy()

    def _advance_to(self, q_next: NDArray[np.float64] | list[float]) -> None:
        """Start a control step from the last target to ``q_next``, within the speed limit.

        Float arithmetic on lists: numpy's elementwise results exactly, without its per-call
        cost on six numbers.
        """
        start = self._q_to.tolist()
        goal = q_next.tolist() if isinstance(q_next, np.ndarray) else q_next
        dq = [b - a for a, b in zip(start, goal, strict=True)]
        biggest = largest_magnitude(dq)
        limit = ARM_VELOCITY * self._dt
        self._clipped = biggest > limit
        if self._clipped:
            scale = limit / biggest
            dq = [d * scale for d in dq]
        self._q_from = np.array(start)
        self._q_to = np.array([a + d for a, d in zip(start, dq, strict=True)])

    def _track(self, target: Pose, servo: bool = False) -> None:
        """Command the joints towards ``target`` for the end of this control step.

        One damped-least-squares step from the last command per control step: the target moves
        well under a millimetre per step, so one Newton step leaves about 1e-7 m, and the next
        step starts from the true error again, so nothing accumulates. A jump over
        :data:`JUMP` (a new servo target far away) gets the full iterative solve. The error
        still left from the previous step's target is the tracking check: above
        :data:`REACH_TOLERANCE` the arm cannot follow and faults, with "joint speed limit" when
        the commands were being slowed to pi rad/s (a path through a singularity) and "target
        unreachable" otherwise. A servo target the speed limit keeps out of reach for a while
        is not a fault: the arm goes there as fast as it may.
        """
        self._track_frame(target.position, target.rotation, servo)

    def _track_frame(
        self, position: NDArray[np.float64], rotation: NDArray[np.float64], servo: bool = False
    ) -> None:
        """:meth:`_track` to the target ``(position, rotation)``: the arithmetic of
        :func:`pose_error`, :func:`residual` and :func:`jacobian` on plain floats where it
        can be, with no :class:`Pose` built (the same numbers; see
        :func:`drivers.ur5.kinematics.jacobian_frame`)."""
        jac, here, here_rotation = jacobian_frame(self._q_to)
        if self._last_target is not None:
            behind = residual(frame_error_list(*self._last_target, here, here_rotation))
            if behind > REACH_TOLERANCE and not (servo and self._clipped):
                reason = "joint speed limit" if self._clipped else "target unreachable"
                self._fault(reason, self._q_to)
                return
        err = frame_error_list(position, rotation, here, here_rotation)
        if residual(err) > JUMP:
            q_next, miss = solve_ik(Pose(position, rotation), self._q_to)
            if miss > REACH_TOLERANCE:
                self._fault("target unreachable", self._q_to)
                return
        else:
            # np.clip(q + dq, -limit, limit) on floats: its max, then min, NaN kept.
            step = dls_step(jac, err).tolist()
            q_next = [
                min(max(a + d, -ARM_LIMIT), ARM_LIMIT)
                for a, d in zip(self._q_to.tolist(), step, strict=True)
            ]
        self._last_target = (position, rotation)
        self._advance_to(q_next)

    def _follow_path(self) -> None:
        assert self._path is not None
        path = self._path
        self._t += self._dt * self._speed
        goal = path.poses[-1]
        if self._t <= path.duration + self._dt:
            self._track_frame(*path.frame_at(path.distance_at(self._t)))
            return
        self._q_from = self._q_to.copy()
        d, angle = self.tool_pose().distance(goal)
        settled = d <= DONE_POSITION and angle <= DONE_ANGLE
        if settled or self._t > path.duration + SETTLE_TIME:
            self._mode = "hold"
            self._path = None
            self._last_target = None
            self._state = MotionState.DONE
            if not settled:
                self._message = (
                    f"settled {d * 1e3:.1f} mm, {np.degrees(angle):.2f} deg from goal"
                )

    def _follow_servo(self) -> None:
        assert self._servo_target is not None
        if self._servoj is None:
            self._track(self._servo_target, servo=True)
            return
        # servoj: the joints that reach the target are tracked as without the law (the same
        # reach checks), then the reference follows them by
        # q'' = gain * (goal - (q + lookahead * q')), the damping term taken implicitly so
        # any gain and lookahead in UR's ranges stays stable at the control step.
        lookahead, gain = self._servoj
        here = self._q_to
        if self._goal is None:
            self._goal, self._ref_speed = here.copy(), np.zeros(6)
        self._q_to = self._goal
        self._track(self._servo_target, servo=True)
        if self._state is MotionState.FAULT:
            self._hold(here)  # where the arm is, not the goal it trails
            return
        goal, goal_clipped = self._q_to, self._clipped
        k = self._dt * gain
        speed = (self._ref_speed + k * (goal - here)) / (1.0 + k * lookahead)
        self._goal, self._ref_speed, self._q_to = goal, speed, here
        self._advance_to(here + speed * self._dt)
        self._clipped = goal_clipped  # the next step's reach check is the goal's

    def _actuate(self) -> None:
        """Before each physics substep: joint targets interpolated through the step, or torques.

        The target at substep k of n is ``q_from + (k / n) (q_to - q_from)``, with the step's
        velocity ``(q_to - q_from) / dt`` as feed-forward.
        """
        if self._mode == "force":
            self._apply_impedance()
            return
        self._substep += 1
        u = min(self._substep / self._substeps, 1.0)
        start, change, velocity = self._command_for()
        self._send_lists([a + u * d for a, d in zip(start, change, strict=True)], velocity)

    def _command_for(self) -> tuple[list[float], list[float], list[float]]:
        """``(q_from, q_to - q_from, (q_to - q_from) / dt)`` as float lists, worked out once
        per command rather than on every substep.

        Each of ``_q_from`` and ``_q_to`` is replaced, never changed in place, whenever the
        command changes, so the pair of objects identifies the command. Float arithmetic
        element by element gives numpy's elementwise results exactly.
        """
        q_from, q_to = self._line[0] if self._line else (self._q_from, self._q_to)
        key = self._command_of
        if key is None or key[0] is not q_from or key[1] is not q_to:
            start = q_from.tolist()
            change = [b - a for a, b in zip(start, q_to.tolist(), strict=True)]
            dt = self._dt
            self._command = (start, change, [d / dt for d in change])
            self._command_of = (q_from, q_to)
        return self._command

    def _send(self, q: NDArray[np.float64], qd: NDArray[np.float64]) -> None:
        self._send_lists(q.tolist(), qd.tolist())

    def _send_lists(self, q: list[float], qd: list[float]) -> None:
        """Position control to ``q`` (rad) with ``qd`` (rad/s) feed-forward, every arm joint in
        one call; the gain lists are built once."""
        position_gains, velocity_gains = self._gains
        self._p.setJointMotorControlArray(
            self._body,
            self._joints,
            self._position_control,
            targetPositions=q,
            targetVelocities=qd,
            forces=self._effort,
            positionGains=position_gains,
            velocityGains=velocity_gains,
        )

    # --- force mode ----------------------------------------------------------------------

    def applied_wrench(self) -> NDArray[np.float64]:
        """The wrench the TCP applies to the environment (N, N*m about the TCP, base frame),
        from the sensor; the quantity :meth:`force_mode` regulates."""
        assert self._ft is not None
        w = self._ft.wrench()
        force_tool, torque_sensor = w[:3], w[3:]
        # Environment's moment about the TCP: T_tcp = T_sensor + (sensor - tcp) x F.
        torque_tool = torque_sensor + np.cross(np.array([0.0, 0.0, -TCP_Z]), force_tool)
        rotation = self.tool_pose().rotation
        return -np.concatenate([rotation @ force_tool, rotation @ torque_tool])

    def _update_virtual(self) -> None:
        """Admittance: move the virtual target along the selected axes (once per step)."""
        assert self._virtual is not None
        sel, cmd, limit = self._force["selection"], self._force["wrench"], self._force["speed"]
        velocity = np.clip(ADMITTANCE_GAIN * (cmd - self.applied_wrench()), -limit, limit)
        velocity[~sel] = 0.0
        v = self._virtual
        rotation = rotvec_to_matrix(velocity[3:] * self._dt) @ v.rotation
        self._virtual = Pose(v.position + velocity[:3] * self._dt, rotation)

    def _apply_impedance(self) -> None:
        """Torques: gravity and Coriolis compensation plus a spring-damper to the target."""
        assert self._virtual is not None
        movable, arm_cols = self._movable
        states = self._p.getJointStates(self._body, movable)
        q_all = [s[0] for s in states]
        qd_all = [s[1] for s in states]
        q = np.array([q_all[i] for i in arm_cols])
        qd = np.array([qd_all[i] for i in arm_cols])
        bias = self._p.calculateInverseDynamics(self._body, q_all, qd_all, [0.0] * len(movable))
        jac, here, here_rotation = jacobian_frame(q)
        twist = jac @ qd
        v = self._virtual
        error = np.array(frame_error_list(v.position, v.rotation, here, here_rotation))
        wrench = FORCE_STIFFNESS * error - FORCE_DAMPING * twist
        tau = np.array([bias[i] for i in arm_cols]) + jac.T @ wrench
        tau = np.clip(tau, -np.asarray(self._effort), self._effort)
        self._q_to = q
        self._p.setJointMotorControlArray(
            self._body, self._joints, self._torque_control, forces=tau.tolist()
        )
