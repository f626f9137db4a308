"""The PyBullet world of the twin: one physics client, its settings, and the simulation clock.

Every sim device gets the :class:`SimWorld` it lives in. The control loop calls :meth:`step`
once per control period (8 ms at 125 Hz, like a CB3 UR5's RTDE); the world runs the physics
substeps and lets devices act before each substep (force-limited fingers, sensor sampling).

Physics settings and why (measured for this cell; see docs/design.md):
* 250 Hz physics, 2 substeps per control step: fine enough for stable finger-part contacts.
* 100 solver iterations: with fewer the part creeps in the pinch during a lift.
* Deterministic: one seeded ``numpy`` generator feeds every random choice of the twin.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import inspect
import math
import os
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray


def _flush_c_stdio() -> None:
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):  # no C library to flush (not glibc-like)
        pass


@contextlib.contextmanager
def _quiet(fds: tuple[int, ...] = (1, 2)) -> Iterator[None]:
    """Silence the C library's output on the file descriptors ``fds`` for the block."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved: list[tuple[int, int]] = []
    try:
        with open(os.devnull, "wb") as null:
            for fd in fds:
                try:
                    saved.append((fd, os.dup(fd)))
                    os.dup2(null.fileno(), fd)
                except OSError:  # not a real descriptor (captured output): leave it
                    pass
            try:
                yield
            finally:
                _flush_c_stdio()  # what C buffered goes to /dev/null, not out at exit
                for fd, copy in saved:
                    os.dup2(copy, fd)
    finally:
        for _, copy in saved:
            os.close(copy)


with _quiet():  # its import prints its build time
    import pybullet
    import pybullet_data
    from pybullet_utils.bullet_client import BulletClient


def matrix_from_quaternion(quat: ArrayLike) -> NDArray[np.float64]:
    """The 3x3 rotation matrix of a PyBullet ``(x, y, z, w)`` quaternion (normalised first).

    Bit for bit what ``scipy.spatial.transform.Rotation.from_quat(quat).as_matrix()`` returns,
    and so what :meth:`drivers.pose.Pose.from_quaternion` builds: the same operations in the same
    order (checked equal on 200 000 random quaternions, unit and not). Why not SciPy: its
    ``Rotation`` costs about 70 us a call in array-API dispatch, and the twin converts several
    poses every control step (the judge's watch, the pad tips); this costs about 3 us.
    """
    x, y, z, w = quat
    x, y, z, w = float(x), float(y), float(z), float(w)
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if norm == 0.0:
        raise ValueError("found zero norm quaternion")
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    x2, y2, z2, w2 = x * x, y * y, z * z, w * w
    xy, zw, xz, yw, yz, xw = x * y, z * w, x * z, y * w, y * z, x * w
    return np.array(
        [
            [x2 - y2 - z2 + w2, 2 * (xy - zw), 2 * (xz + yw)],
            [2 * (xy + zw), -x2 + y2 - z2 + w2, 2 * (yz - xw)],
            [2 * (xz - yw), 2 * (yz + xw), -x2 - y2 + z2 + w2],
        ]
    )


def _bind_functions(client: BulletClient) -> None:
    """Give ``client`` every PyBullet function bound to its physics client, once.

    ``BulletClient`` looks each one up in ``__getattr__`` and wraps it in a new
    ``functools.partial`` on every access -- a few microseconds, and the twin's devices and judge
    call PyBullet 15 to 20 times per control step. The same partials, made once and kept on the
    instance, where attribute lookup finds them before ``__getattr__``. ``disconnect`` is left to
    ``__getattr__``, which marks the client closed when it hands it out.
    """
    for name in dir(pybullet):
        if name.startswith("_") or name == "disconnect":
            continue
        attribute = getattr(pybullet, name)
        if inspect.isbuiltin(attribute):
            client.__dict__[name] = functools.partial(attribute, physicsClientId=client._client)


@dataclass(frozen=True)
class PhysicsSettings:
    control_hz: float = 125.0
    substeps: int = 2
    solver_iterations: int = 100
    #: The solver stops iterating once its residual is below this. PyBullet's default (1e-7)
    #: spends all 100 iterations on nearly every step; 1e-5 is about 1.3x faster with the same
    #: pivot outcomes. 1e-4 was 1.6x faster but let friction-held contacts creep: the bushing
    #: at mu_G = 0.2 fell from 20/20 to 8/20.
    solver_residual: float = 1e-5
    gravity: float = 9.81

    @property
    def physics_dt(self) -> float:
        return 1.0 / (self.control_hz * self.substeps)

    @property
    def control_dt(self) -> float:
        return 1.0 / self.control_hz


class SimClock:
    """Simulation time (s), advanced only by :meth:`SimWorld.step`."""

    def __init__(self) -> None:
        self._t = 0.0

    def now(self) -> float:
        return self._t

    def _advance(self, dt: float) -> None:
        self._t += dt


class SimWorld:
    """A headless (DIRECT) PyBullet client with the cell's physics settings."""

    def __init__(
        self, seed: int = 0, settings: PhysicsSettings | None = None, gui: bool = False
    ) -> None:
        self.settings = settings or PhysicsSettings()
        with _quiet((1,)):  # PyBullet's C code prints "argv[0]=" on every connect
            self.p = BulletClient(connection_mode=pybullet.GUI if gui else pybullet.DIRECT)
        self.p.setAdditionalSearchPath(pybullet_data.getDataPath())
        self.p.setGravity(0.0, 0.0, -self.settings.gravity)
        self.p.setPhysicsEngineParameter(
            fixedTimeStep=self.settings.physics_dt,
            numSolverIterations=self.settings.solver_iterations,
            solverResidualThreshold=self.settings.solver_residual,
            deterministicOverlappingPairs=1,
        )
        _bind_functions(self.p)
        self.rng = np.random.default_rng(seed)
        self.clock = SimClock()
        self._before_step: list[Callable[[], None]] = []
        self._before_substep: list[Callable[[], None]] = []
        self._after_step: list[Callable[[], None]] = []
        self.steps = 0

    def before_step(self, fn: Callable[[], None]) -> None:
        """Call ``fn`` once at the start of every control step (motion targets, IK)."""
        self._before_step.append(fn)

    def before_substep(self, fn: Callable[[], None]) -> None:
        """Call ``fn`` before every physics substep (device actuation)."""
        self._before_substep.append(fn)

    def after_step(self, fn: Callable[[], None]) -> None:
        """Call ``fn`` after every control step (sensor sampling)."""
        self._after_step.append(fn)

    def step(self) -> None:
        """Advance one control period."""
        for fn in self._before_step:
            fn()
        settings = self.settings
        dt = settings.physics_dt
        for _ in range(settings.substeps):
            for fn in self._before_substep:
                fn()
            self.p.stepSimulation()
            self.clock._advance(dt)
        self.steps += 1
        for fn in self._after_step:
            fn()

    def close(self) -> None:
        try:
            self.p.disconnect()
        except pybullet.error:
            pass

    def __enter__(self) -> SimWorld:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
