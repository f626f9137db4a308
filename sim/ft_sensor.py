"""The twin's wrist force-torque sensor at ``ft_joint``, FT300-like.

Sign and frame convention (the :class:`drivers.ft_sensor.ForceTorqueSensor` contract, "the load
the tool puts on the sensor"):

* Axes are the tool frame's (``tool0``: z = approach, out of the flange towards the fingertips;
  x = the closing axis, ``finger_a`` on +x). Torques are about the sensor origin, which is the
  flange centre, :data:`sim.robot_model.TCP_Z` (m) behind the TCP on the tool z axis.
* The force is the one the tool (puck, gripper, fingers and whatever they hold or touch) exerts
  on the sensor. Hanging still with the tool pointing down, the raw reading is ``+m g`` along tool
  z (the tool pulls away from the flange). Pressing the fingertips down onto a floor, the floor
  pushes the tool back towards the flange: after :meth:`bias`, **Fz is negative**, about minus the
  pressing force. In general, after a bias at rest, the reading is the external wrench that the
  environment applies to the tool (quasi-statically); the force the tool applies to the
  environment is its negative.

The load is computed by Newton-Euler on the links below the sensor (puck, gripper, carriages,
pads): their weight, every contact force on them (PyBullet's contact points, normal and both
friction directions) and their mass times the tool's acceleration (the sensor link's velocity
differenced over a control step; the pads' own small motions and their motors' numerical jitter
left out), torques about the joint origin; the links' rotational inertia is left out (the tool
turns slowly). PyBullet's own joint reaction (``enableJointForceTorqueSensor``) is not
used: in the cell's slot feed it read a bushing hanging in the hole grasp (1.53 N) as
0.6-0.9 N, and a part left in the slot lost only 0.4 N of the reading (the check failed a feed
that had worked) -- what the pads' lift joints carry on their motors and limits does not all
reach it. The contact forces on the tool's links are what the pads carry, wherever it goes.

Realism: by default one sample per control step (125 Hz), Gaussian noise of 0.1 N and 0.003
N*m per axis, and a constant random offset of a few newtons that :meth:`bias` removes, as on the
real sensor after power-up. :meth:`SimForceTorqueSensor.configure` makes it an FT300 (what the
pivot trials do, :mod:`sim.uncertainty`): a stream at 100 Hz whose newest sample is held between
frames (the 125 Hz control loop sees a new one in four steps of five), values rounded to the
stream's 0.01 N and 0.001 N*m, and the noise of the unit. The arm's own protective stop does not
go through the FT300 (a UR watches its joints): :meth:`sampled_true_load` is the load at every
control step.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np
from numpy.typing import NDArray

from drivers.limit_guard import LimitGuard
from sim.world import SimWorld

FORCE_NOISE = 0.1  #: N, standard deviation per force axis
TORQUE_NOISE = 0.003  #: N*m, standard deviation per torque axis
FORCE_OFFSET = 3.0  #: N, the power-up offset is uniform in +-this per force axis
TORQUE_OFFSET = 0.1  #: N*m, the power-up offset is uniform in +-this per torque axis
BIAS_SAMPLES = 8  #: samples averaged by bias() (64 ms at 125 Hz, 80 ms at 100 Hz): a quieter zero


def _cross(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Row-wise cross product of (n, 3) arrays, as ``np.cross`` computes it (bit for bit) without
    its axis handling, which cost more than the products at the twin's every step."""
    out = np.empty_like(a)
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out


class SimForceTorqueSensor:
    """Implements :class:`drivers.ft_sensor.ForceTorqueSensor` on a fixed joint of a body."""

    def __init__(self, world: SimWorld, body_id: int, joint_index: int) -> None:
        self._world = world
        self._p = world.p
        self._body = body_id
        self.joint = joint_index  #: the sensor's joint (its child link: the tool's first)
        # The links below the sensor: its child (a link's index is its joint's) and every
        # link after it in the chain (the tool is the chain's end: puck, gripper, pads, TCP).
        self._links = list(range(joint_index, self._p.getNumJoints(body_id)))
        self._link_set = frozenset(self._links)
        self._masses = np.array(
            [self._p.getDynamicsInfo(body_id, link)[0] for link in self._links], float
        )
        self._gravity = np.array([0.0, 0.0, -world.settings.gravity])
        self._last_v: NDArray[np.float64] | None = None  #: the sensor link's velocity last step
        self._last_t = 0.0
        self._cached: NDArray[np.float64] | None = None  #: the load at ``_cached_t``
        self._cached_t = -np.inf
        rng = world.rng
        self._offset = np.concatenate(
            [
                rng.uniform(-FORCE_OFFSET, FORCE_OFFSET, 3),
                rng.uniform(-TORQUE_OFFSET, TORQUE_OFFSET, 3),
            ]
        )
        self._sigma = np.array([FORCE_NOISE] * 3 + [TORQUE_NOISE] * 3)
        self._zero = np.zeros(6)
        self._newest = self._offset.copy()
        self._true = np.zeros(6)
        self._recent: deque[NDArray[np.float64]] = deque(maxlen=BIAS_SAMPLES)
        self._stamp = -np.inf
        self._period = 0.0  #: s between samples; 0: one every control step
        self._next = -np.inf  #: s (clock) of the next sample on the stream's grid
        self._resolution = np.zeros(6)  #: N, N*m per count; 0: not rounded
        #: the running motion's limits, checked against each sample as it is taken, as the
        #: FT300's reader does (:class:`drivers.limit_guard.LimitGuard`)
        self.limits = LimitGuard(world.clock.now)
        world.after_step(self.sample)

    def configure(
        self,
        rate_hz: float | None = None,
        force_noise: float = FORCE_NOISE,
        torque_noise: float = TORQUE_NOISE,
        force_resolution: float = 0.0,
        torque_resolution: float = 0.0,
    ) -> None:
        """The sensor's stream: ``rate_hz`` samples a second on a fixed grid of the clock,
        held between (None: one per control step), the noise's standard deviations (N, N*m per
        axis) and the resolution the values are rounded to (N, N*m; 0: not rounded). The
        defaults are the twin's sensor as built."""
        if rate_hz is not None and not rate_hz > 0.0:
            raise ValueError(f"rate_hz must be > 0 or None, got {rate_hz!r}")
        for name, value in (("force_noise", force_noise), ("torque_noise", torque_noise),
                            ("force_resolution", force_resolution),
                            ("torque_resolution", torque_resolution)):
            if not value >= 0.0:
                raise ValueError(f"{name} must be >= 0, got {value!r}")
        self._period = 0.0 if rate_hz is None else 1.0 / rate_hz
        self._next = -np.inf
        self._sigma = np.array([force_noise] * 3 + [torque_noise] * 3)
        self._resolution = np.array([force_resolution] * 3 + [torque_resolution] * 3)

    def true_load(self) -> NDArray[np.float64]:
        """The noiseless, offset-free load of the tool on the sensor now (N, N*m; tool frame).

        Newton-Euler on the links below the sensor (module doc): their weight, the contact
        forces on them, less their mass times the tool's acceleration (the sensor link's
        velocity differenced over a control step); torques about the joint origin. For tests
        and the twin's own controllers; skills use :meth:`wrench`.
        """
        now = self._world.clock.now()
        if self._cached is not None and now == self._cached_t:
            return self._cached.copy()  # once per step: a second difference would be over 0 s
        p, body = self._p, self._body
        states = p.getLinkStates(body, self._links, computeLinkVelocity=1)
        dt = now - self._last_t if self._last_v is not None else 0.0
        origin = np.asarray(states[0][4], float)
        rotation = np.asarray(p.getMatrixFromQuaternion(states[0][5]), float).reshape(3, 3)
        coms = np.array([st[0] for st in states], float)
        # The tool's acceleration is the sensor link's: the pads' carriages ride their motors,
        # whose numerical jitter (not a motion) would otherwise read as tens of newtons.
        velocity = np.asarray(states[0][6], float)
        acceleration = (
            (velocity - self._last_v) / dt if dt > 0.0 and self._last_v is not None
            else np.zeros(3)
        )
        self._last_v, self._last_t = velocity, now
        forces = self._masses[:, None] * (self._gravity - acceleration)[None, :]
        force = forces.sum(axis=0)
        torque = _cross(coms - origin, forces).sum(axis=0)
        mine = [c for c in p.getContactPoints(bodyA=body)
                if c[2] != body and c[3] in self._link_set]
        if mine:
            # On A: the normal force along the normal on B (it points towards A), friction
            # against its directions (PyBullet's convention, checked against a hanging part).
            # All contacts at once, summed row after row onto the links' load: the same
            # arithmetic in the same order as one contact at a time, a third of the time.
            c = np.array([(*x[5], *x[7], x[9], x[10], *x[11], x[12], *x[13]) for x in mine],
                         float)
            f = (c[:, 6:7] * c[:, 3:6] - c[:, 7:8] * c[:, 8:11]) - c[:, 11:12] * c[:, 12:15]
            force = np.add.reduce(np.vstack([force[None], f]), axis=0)
            torque = np.add.reduce(np.vstack([torque[None], _cross(c[:, 0:3] - origin, f)]),
                                   axis=0)
        self._cached = np.concatenate([rotation.T @ force, rotation.T @ torque])
        self._cached_t = now
        return self._cached.copy()

    def sampled_true_load(self) -> NDArray[np.float64]:
        """The noiseless load (N, N*m; tool frame) at the newest sample, without a new query."""
        return self._true

    def sample(self) -> None:
        """Called by the world after each control step: the load now, and a new reading when
        the stream's next sample is due (every step unless :meth:`configure` set a rate)."""
        self._true = self.true_load()
        now = self._world.clock.now()
        if self._period > 0.0:
            if now < self._next - 1e-9:
                return  # between two samples of the stream: the newest is held
            # The next sample on the grid of the period (a step covers at most one at 100 Hz).
            self._next = (math.floor(now / self._period + 1e-6) + 1) * self._period
        reading = self._true + self._offset + self._sigma * self._world.rng.standard_normal(6)
        if self._resolution.any():
            res = self._resolution
            reading = np.where(res > 0.0, np.round(reading / np.where(res > 0, res, 1.0)) * res,
                               reading)
        self._newest = reading
        self._recent.append(reading)
        self._stamp = now
        self.limits.feed(reading - self._zero, now)

    def wrench(self) -> NDArray[np.float64]:
        """Newest ``[Fx, Fy, Fz, Tx, Ty, Tz]`` (N, N*m) in the tool frame, bias removed."""
        return self._newest - self._zero

    def bias(self) -> None:
        """Zero the reading on the mean of the last :data:`BIAS_SAMPLES` samples (at rest)."""
        if self._recent:
            self._zero = np.mean(np.asarray(self._recent), axis=0)
        else:
            self._zero = self._newest.copy()

    def age(self) -> float:
        """Seconds (simulation time) since the newest sample; ``inf`` before the first."""
        return float(self._world.clock.now() - self._stamp)
