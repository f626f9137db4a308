"""Fault injection in the twin: wrappers around the cell's devices that fail the way real ones do.

Why wrappers: the tree and the skills only know the device interfaces (:mod:`drivers`), so a
fault injected behind those interfaces exercises exactly the code a real fault would, and the
twin's physics stays honest -- a dropped part falls because the jaws open, a slipping part slips
because the finger friction drops; nothing is teleported or welded.

Every fault has a rate: the probability that it happens at one *opportunity* of its kind, drawn
from one seeded generator (same seed and the same calls: the same faults):

* ``missed_grasp`` -- each ``gripper.close()``: the close is not executed (once).
* ``slip_in_tilt`` -- each Tilt (the tool has turned 3 deg since a light pinch, <= 5 N, closed on
  a part): 0-1.5 s later the finger friction drops to 0.02 for 0.3-0.8 s, then comes back.
* ``drop_in_transit`` -- each carry between stations (a part in a firm grasp, >= 10 N, the TCP
  leaving the bin, the machine and the box, each grown by 3 cm): the jaws open 0.1-0.8 s later,
  if the part is still in transit then (else at the next tick it is); the part falls.
* ``ft_spike`` -- each arm motion command: 0-0.5 s later the wrench reads 150-300 N more on one
  force axis for 1-3 samples.
* ``camera_lost`` -- each ``camera.capture()``: it raises ``TimeoutError``.
* ``camera_invalid`` -- each capture that was not lost: the depth image is all zero (invalid).
* ``gripper_fault`` -- each gripper command (open or close): it is not executed and ``fault()``
  reports a code for 0.3-2 s; commands meanwhile are not executed either.
* ``protective_stop`` -- each arm motion command: 0-0.5 s later (or as soon as the arm moves)
  the arm stops and reports FAULT with ``protective_stop=True`` and refuses servo targets until
  the next motion command, as a UR5 (and :mod:`sim.arm`) does.
* ``link_lost`` -- each arm motion command: 0-0.5 s later the FT sensor raises ``DeviceError``
  for 5-50 samples.

"Arm motion command": ``move_to``, ``move_path``, ``move_joints``, ``force_mode`` (a servo stream
is one motion, not one per tick). A fault drawn while one of the same kind is still pending is not
drawn again. :attr:`FaultInjector.drawn` counts the draws that hit, :attr:`FaultInjector.injected`
the faults that took effect (a protective stop waits for the arm to move; a drop waits until the
part is in transit and is dropped if the part is set down first).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from drivers.arm import Arm, ArmStatus, MotionState
from drivers.camera import Camera, Frame, Intrinsics
from drivers.clock import Clock
from drivers.devices import Devices
from drivers.ft_sensor import ForceTorqueSensor
from drivers.gripper import Gripper
from drivers.health import DeviceError
from drivers.pose import Pose

FAULT_NAMES: tuple[str, ...] = (
    "missed_grasp",
    "slip_in_tilt",
    "drop_in_transit",
    "ft_spike",
    "camera_lost",
    "camera_invalid",
    "gripper_fault",
    "protective_stop",
    "link_lost",
)

#: ``--faults default``: about one fault every two cycles of the bushing cell, each kind seen
#: within a few dozen cycles (a cycle has about 40 arm motion commands, 6 gripper commands,
#: 3 closes, 4 captures, 1 Tilt and 2 carries between stations).
DEFAULT_RATES: dict[str, float] = {
    "missed_grasp": 0.03,
    "slip_in_tilt": 0.05,
    "drop_in_transit": 0.01,
    "ft_spike": 0.002,
    "camera_lost": 0.02,
    "camera_invalid": 0.01,
    "gripper_fault": 0.005,
    "protective_stop": 0.002,
    "link_lost": 0.001,
}

SLIP_FRICTION = 0.02  #: finger friction while a part slips in the Tilt
LIGHT_PINCH = 5.0  #: N per finger: a close this light is the pivot's grasp (Grasp, Tilt)
HOLD_PINCH = 10.0  #: N per finger: a close this firm is the hole grasp that carries a part
TILT_TURN = math.radians(3.0)  #: rad the tool turns from the close that starts a Tilt
SPIKE_FORCE = (150.0, 300.0)  #: N added on one force axis by an FT spike
GRIPPER_FAULT_CODE = "0x07: gripper fault (injected: e.g. an overcurrent on the finger motor)"


def no_faults() -> dict[str, float]:
    """Every rate zero: the wrappers pass everything through."""
    return dict.fromkeys(FAULT_NAMES, 0.0)


def check_rates(rates: Mapping[str, float]) -> dict[str, float]:
    """Validated rates (every fault named, missing ones 0). ``ValueError`` names the bad key."""
    out = no_faults()
    for name, rate in rates.items():
        if name not in FAULT_NAMES:
            raise ValueError(f"unknown fault {name!r}; valid faults: {', '.join(FAULT_NAMES)}")
        if not (isinstance(rate, int | float) and 0.0 <= float(rate) <= 1.0):
            raise ValueError(f"faults.rates.{name}: the rate must be in [0, 1], got {rate!r}")
        out[name] = float(rate)
    return out


Rect = tuple[float, float, float, float]


@dataclass(frozen=True)
class TwinHooks:
    """What the injector needs of the twin beyond the device interfaces (all optional: without
    them the faults that need them are never drawn).

    ``set_friction(mu_a, mu_b)`` sets the finger friction; ``friction`` is the cell's own pair,
    restored after a slip. ``stations`` are (xmin, xmax, ymin, ymax) rectangles (m, base frame):
    outside all of them a carried part is in transit.
    """

    set_friction: Callable[[float, float], None] | None = None
    friction: tuple[float, float] = (0.2, 0.4)
    stations: tuple[Rect, ...] = ()


class FaultInjector:
    """One seeded source of faults for a cell's devices; :meth:`wrap` gives the faulty devices.

    :meth:`tick` must run once per control step after the physics (the twin registers it with
    ``world.after_step``; a test calls it by hand): it fires what was scheduled and watches for
    Tilts and carries.
    """

    def __init__(
        self,
        rates: Mapping[str, float],
        seed: int,
        clock: Clock,
        control_dt: float = 1.0 / 125.0,
        hooks: TwinHooks | None = None,
    ) -> None:
        self.rates = check_rates(rates)
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self.clock = clock
        self.dt = control_dt
        self.hooks = hooks or TwinHooks()
        self.opportunities: Counter[str] = Counter()
        self.drawn: Counter[str] = Counter()
        self.injected: Counter[str] = Counter()
        #: Every fault that took effect: ``{"fault", "t", "step", ...}``.
        self.log: list[dict[str, Any]] = []
        self.step = 0
        self._forced: Counter[str] = Counter()
        self.arm: FaultyArm | None = None
        self.gripper: FaultyGripper | None = None
        self.ft: FaultyFT | None = None
        self.camera: FaultyCamera | None = None
        self.reset()

    # -- the wrapped devices ---------------------------------------------------------------
    def wrap(self, devices: Devices) -> Devices:
        """The same devices behind the fault wrappers (the clock is not wrapped)."""
        self.arm = FaultyArm(devices.arm, self)
        self.gripper = FaultyGripper(devices.gripper, self)
        self.ft = FaultyFT(devices.ft, self)
        self.camera = FaultyCamera(devices.camera, self) if devices.camera is not None else None
        return Devices(self.arm, self.gripper, self.ft, devices.clock, self.camera)

    def reset(self) -> None:
        """Clear every pending and active fault (a person reset the cell): the friction comes
        back, the FT link and the gripper answer again, a protective stop is unlocked."""
        if getattr(self, "_slip_until", None) is not None and self.hooks.set_friction:
            self.hooks.set_friction(*self.hooks.friction)
        self._pending: dict[str, int] = {}  # fault -> control step at which it fires
        self._spike: tuple[int, NDArray[np.float64]] | None = None  # until step, wrench added
        self._lost_until: int | None = None
        self._lost_since = 0.0
        self._gripper_fault_until: float | None = None
        self._slip_until: int | None = None
        self._close_force: float | None = None  # force of the last executed close (N)
        self._close_rotation: NDArray[np.float64] | None = None  # tool rotation at that close
        self._tilt_seen = False
        self._in_transit = False
        if self.arm is not None:
            self.arm.protective = None

    # -- drawing ---------------------------------------------------------------------------
    def force(self, name: str, count: int = 1) -> None:
        """The next ``count`` opportunities of ``name`` hit whatever its rate (for tests that
        need one fault at a known moment)."""
        check_rates({name: 0.0})
        self._forced[name] += count

    def draw(self, name: str) -> bool:
        """One opportunity for ``name``: True when the fault happens (one uniform draw each)."""
        self.opportunities[name] += 1
        hit = bool(self.rng.random() < self.rates[name])
        if self._forced[name] > 0:
            self._forced[name] -= 1
            hit = True
        if hit:
            self.drawn[name] += 1
        return hit

    def _record(self, name: str, **data: Any) -> None:
        self.injected[name] += 1
        self.log.append({"fault": name, "t": round(self.clock.now(), 3), "step": self.step, **data})

    def _schedule(self, name: str, max_delay_s: float) -> None:
        if name in self._pending or not self.draw(name):
            return
        self._pending[name] = self.step + 1 + int(self.rng.integers(0, int(max_delay_s / self.dt)))

    # -- opportunities the wrappers report -------------------------------------------------
    def on_arm_command(self) -> None:
        for name in ("ft_spike", "protective_stop", "link_lost"):
            self._schedule(name, 0.5)

    def on_close_executed(self, force: float) -> None:
        self._close_force = force
        self._tilt_seen = False
        self._in_transit = False
        if self.arm is not None:
            self._close_rotation = self.arm.inner.tool_pose().rotation
        self._pending.pop("drop_in_transit", None)

    def on_open_executed(self) -> None:
        self._close_force = None
        self._close_rotation = None
        self._pending.pop("drop_in_transit", None)
        self._pending.pop("slip_in_tilt", None)

    def gripper_faulted(self) -> bool:
        return self._gripper_fault_until is not None

    def link_lost(self) -> bool:
        return self._lost_until is not None

    def spike(self) -> NDArray[np.float64] | None:
        return None if self._spike is None else self._spike[1]

    # -- once per control step -------------------------------------------------------------
    def tick(self) -> None:
        """After each control step: fire what is due, end what is over, watch Tilts and carries."""
        self.step += 1
        now = self.clock.now()
        if self._spike is not None and self.step >= self._spike[0]:
            self._spike = None
        if self._lost_until is not None and self.step >= self._lost_until:
            self._lost_until = None
        if self._gripper_fault_until is not None and now >= self._gripper_fault_until:
            self._gripper_fault_until = None
        if self._slip_until is not None and self.step >= self._slip_until:
            self._slip_until = None
            if self.hooks.set_friction is not None:
                self.hooks.set_friction(*self.hooks.friction)
        due = [n for n, s in self._pending.items() if self.step >= s]
        for name in due:
            self._fire(name)
        self._watch_tilt()
        self._watch_transit()

    def _fire(self, name: str) -> None:
        rng = self.rng
        if name == "ft_spike":
            samples = int(rng.integers(1, 4))
            w = np.zeros(6)
            w[int(rng.integers(0, 3))] = float(rng.choice([-1.0, 1.0]) * rng.uniform(*SPIKE_FORCE))
            self._spike = (self.step + samples, w)
            self._record(name, samples=samples, force_n=round(float(np.abs(w).max()), 1))
        elif name == "link_lost":
            samples = int(rng.integers(5, 51))
            self._lost_until = self.step + samples
            self._lost_since = self.clock.now()
            self._record(name, samples=samples)
        elif name == "protective_stop":
            arm = self.arm
            if arm is None or arm.inner.status().state is not MotionState.MOVING:
                return  # waits (pending) until the arm moves
            arm.inner.stop()
            arm.protective = "protective stop: injected (a simulated collision)"
            self._record(name)
        elif name == "slip_in_tilt":
            if self._close_force is None or self.hooks.set_friction is None:
                self._pending.pop(name)
                return
            samples = int(rng.integers(int(0.3 / self.dt), int(0.8 / self.dt) + 1))
            self.hooks.set_friction(SLIP_FRICTION, SLIP_FRICTION)
            self._slip_until = self.step + samples
            self._record(name, seconds=round(samples * self.dt, 3))
        elif name == "drop_in_transit":
            if not self._in_transit:
                return  # waits until the part is between stations again
            assert self.gripper is not None
            self.gripper.inner.open()
            self.on_open_executed()
            self._record(name)
        self._pending.pop(name, None)

    def _holding(self, light: bool) -> bool:
        f = self._close_force
        if f is None or self.gripper is None or not self.gripper.inner.object_detected():
            return False
        return f <= LIGHT_PINCH if light else f >= HOLD_PINCH

    def _watch_tilt(self) -> None:
        if self._tilt_seen or self._close_rotation is None or self.arm is None:
            return
        if self.hooks.set_friction is None or not self._holding(light=True):
            return
        r = self.arm.inner.tool_pose().rotation
        cos = (np.trace(self._close_rotation.T @ r) - 1.0) / 2.0
        if math.acos(min(1.0, max(-1.0, cos))) > TILT_TURN:
            self._tilt_seen = True
            self._schedule("slip_in_tilt", 1.5)

    def _watch_transit(self) -> None:
        if not self.hooks.stations or self.arm is None or not self._holding(light=False):
            self._in_transit = False
            if "drop_in_transit" in self._pending and self._close_force is None:
                self._pending.pop("drop_in_transit")
            return
        x, y = self.arm.inner.tool_pose().position[:2]
        inside = any(x0 <= x <= x1 and y0 <= y <= y1 for x0, x1, y0, y1 in self.hooks.stations)
        entering = not inside and not self._in_transit
        self._in_transit = not inside
        if entering:
            self._pending.pop("drop_in_transit", None)
            if self.draw("drop_in_transit"):
                delay = int(self.rng.integers(int(0.1 / self.dt), int(0.8 / self.dt) + 1))
                self._pending["drop_in_transit"] = self.step + delay

    def summary(self) -> dict[str, Any]:
        """Rates, opportunities, draws and injected faults, for a report."""
        return {
            "seed": self.seed,
            "rates": dict(self.rates),
            "opportunities": {n: self.opportunities[n] for n in FAULT_NAMES},
            "drawn": {n: self.drawn[n] for n in FAULT_NAMES},
            "injected": {n: self.injected[n] for n in FAULT_NAMES},
        }


# ---------------------------------------------------------------------------- the wrappers
class FaultyArm:
    """:class:`drivers.arm.Arm` with injected protective stops (and the opportunities for the
    FT spike and the link loss, which a motion is when they matter)."""

    def __init__(self, inner: Arm, injector: FaultInjector) -> None:
        self.inner, self.injector = inner, injector
        #: The message of an injected protective stop in force, or None.
        self.protective: str | None = None

    def _command(self) -> None:
        self.protective = None  # a new motion command unlocks it, as on the UR5 (and the twin)
        self.injector.on_arm_command()

    def tool_pose(self) -> Pose:
        return self.inner.tool_pose()

    def joint_positions(self) -> NDArray[np.float64]:
        return self.inner.joint_positions()

    def move_path(self, waypoints: Sequence[Pose], speed: float, acceleration: float) -> None:
        self._command()
        self.inner.move_path(waypoints, speed, acceleration)

    def move_to(self, pose: Pose, speed: float, acceleration: float) -> None:
        self._command()
        self.inner.move_to(pose, speed, acceleration)

    def move_joints(self, q: Sequence[float], speed: float, acceleration: float) -> None:
        self._command()
        self.inner.move_joints(q, speed, acceleration)

    def force_mode(
        self, selection: Sequence[bool], wrench: Sequence[float], speed_limits: Sequence[float]
    ) -> None:
        self._command()
        self.inner.force_mode(selection, wrench, speed_limits)

    def servo_lag(self) -> float:
        return self.inner.servo_lag()

    def servo(self, target: Pose) -> None:
        """A protectively stopped arm ignores servo targets (the controller refuses them)."""
        if self.protective is None:
            self.inner.servo(target)

    def stop(self) -> None:
        self.inner.stop()

    def status(self) -> ArmStatus:
        if self.protective is not None:
            return ArmStatus(MotionState.FAULT, self.protective, protective_stop=True)
        return self.inner.status()


class FaultyGripper:
    """:class:`drivers.gripper.Gripper` with missed closes and faults."""

    def __init__(self, inner: Gripper, injector: FaultInjector) -> None:
        self.inner, self.injector = inner, injector

    @property
    def stroke(self) -> float:  # type: ignore[override]
        return self.inner.stroke

    @property
    def finger_width(self) -> float:  # type: ignore[override]
        return self.inner.finger_width

    def _refused(self) -> bool:
        """True when the command is not executed: the gripper is faulted, or faults now."""
        inj = self.injector
        if inj.gripper_faulted():
            return True
        if inj.draw("gripper_fault"):
            inj._gripper_fault_until = inj.clock.now() + float(inj.rng.uniform(0.3, 2.0))
            inj._record("gripper_fault")
            return True
        return False

    def open(self, width: float | None = None, speed: float = 0.1) -> None:
        if self._refused():
            return
        self.inner.open(width, speed)
        self.injector.on_open_executed()

    def close(self, force: float, speed: float = 0.05, width: float = 0.0) -> None:
        if self._refused():
            return
        inj = self.injector
        if inj.draw("missed_grasp"):
            inj._record("missed_grasp", force_n=force)
            return
        self.inner.close(force, speed, width)
        inj.on_close_executed(force)

    def width(self) -> float:
        return self.inner.width()

    def moving(self) -> bool:
        return self.inner.moving()

    def object_detected(self) -> bool:
        return self.inner.object_detected()

    def tip_advance(self, width: float) -> float:
        return self.inner.tip_advance(width)

    def fault(self) -> str | None:
        if self.injector.gripper_faulted():
            return GRIPPER_FAULT_CODE
        return self.inner.fault()


class FaultyFT:
    """:class:`drivers.ft_sensor.ForceTorqueSensor` with spikes and a lost link."""

    def __init__(self, inner: ForceTorqueSensor, injector: FaultInjector) -> None:
        self.inner, self.injector = inner, injector
        #: the sensor's own limit guard: it sees the samples, not the spikes injected on reading
        #: (those the tick's guards catch)
        self.limits = getattr(inner, "limits", None)

    def _check_link(self) -> None:
        inj = self.injector
        if inj.link_lost():
            ms = 1e3 * (inj.clock.now() - inj._lost_since)
            raise DeviceError("FT300", "twin", f"no sample for {ms:.0f} ms (injected link loss)")

    def wrench(self) -> NDArray[np.float64]:
        self._check_link()
        w = self.inner.wrench()
        spike = self.injector.spike()
        return w if spike is None else w + spike

    def bias(self) -> None:
        self._check_link()
        self.inner.bias()

    def age(self) -> float:
        inj = self.injector
        if inj.link_lost():
            return float(inj.clock.now() - inj._lost_since)
        return self.inner.age()


class FaultyCamera:
    """:class:`drivers.camera.Camera` with lost frames and all-invalid depth."""

    def __init__(self, inner: Camera, injector: FaultInjector) -> None:
        self.inner, self.injector = inner, injector

    def intrinsics(self) -> Intrinsics:
        return self.inner.intrinsics()

    def tool_T_camera(self) -> Pose:
        return self.inner.tool_T_camera()

    def capture(self) -> Frame:
        inj = self.injector
        if inj.draw("camera_lost"):
            inj._record("camera_lost")
            raise TimeoutError("camera: no frame within 1000 ms (injected)")
        frame = self.inner.capture()
        if inj.draw("camera_invalid"):
            inj._record("camera_invalid")
            return Frame(frame.rgb, np.zeros_like(frame.depth), frame.stamp)
        return frame


def twin_injector(backend: Any, rates: Mapping[str, float], seed: int) -> FaultInjector:
    """An injector wired to a :class:`sim.cell_twin.SimCellBackend`: ticked after every physics
    step, finger friction through the twin's gripper, stations from the layout (each grown by
    3 cm: the TCP over a station's wall is still at that station)."""
    layout, robot, world = backend.layout, backend.robot, backend.world
    margin = 0.03

    def grow(r: Rect) -> Rect:
        return (r[0] - margin, r[1] + margin, r[2] - margin, r[3] + margin)

    mx, my = layout.machine_center
    sx, sy = layout.machine_size[0], layout.machine_size[1]
    stations = (
        grow(layout.bin_interior()),
        grow((mx - 0.5 * sx, mx + 0.5 * sx, my - 0.5 * sy, my + 0.5 * sy)),
        grow(layout.tray_interior()),
    )
    fr = backend.options.frictions
    hooks = TwinHooks(
        set_friction=robot.gripper.set_finger_friction,
        friction=(float(fr.mu_s), float(fr.mu_h)),
        stations=stations,
    )
    injector = FaultInjector(rates, seed, world.clock, world.settings.control_dt, hooks)
    world.after_step(injector.tick)
    return injector


__all__ = [
    "DEFAULT_RATES",
    "FAULT_NAMES",
    "FaultInjector",
    "FaultyArm",
    "FaultyCamera",
    "FaultyFT",
    "FaultyGripper",
    "TwinHooks",
    "check_rates",
    "no_faults",
    "twin_injector",
]
