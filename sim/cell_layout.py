"""The static cell of the twin: floor, bin, machine with its slot, and the tray to pack into.

:class:`CellLayout` is a plain, validated parameter object (SI units, metres; all positions in the
robot-base frame, which is also the world frame of the twin: base at the origin, ``z`` up, the bin
in front on ``+x``). Every fixture is axis-aligned and built from boxes only, so all contacts with
parts are box-box contacts. :func:`build_cell` turns a layout into static PyBullet bodies.

Heights: the floor's top is ``z = 0`` and is also the bin's floor (the bin is four walls standing
on it, so a part in the bin touches the floor and the floor friction ``mu_G`` applies). The tray has
its own bottom plate. The machine is a block of ``machine_size[2]`` with a square pocket (the slot)
of side ``slot_width = slot_part_outer + slot_clearance`` and depth ``slot_depth`` in the middle of
its top, into which a part is fed standing upright.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
import yaml
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from drivers.pose import Pose
from sim.world import SimWorld

#: The thinnest wall (m) the machine block may keep around its slot.
MIN_MACHINE_WALL = 0.005

_Rect = tuple[float, float, float, float]  # xmin, xmax, ymin, ymax (m)
#: Fields besides the ``*_center`` ones that are not sizes: no ``> 0`` check (the camera mount
#: may be anywhere; the clearance and keep-out radius have their own checks).
_NOT_SIZES = ("slot_clearance", "robot_keepout_radius", "camera_xyz", "camera_rpy")


@dataclass(frozen=True)
class CellLayout:
    """The cell's fixtures (m). Keys of :meth:`from_dict` are these field names.

    ``floor_size`` (x, y) and ``floor_thickness``: a floor box centred on the base, top at z = 0.
    ``bin_center`` (x, y), ``bin_inner_size`` (x, y), ``bin_wall_height``,
    ``bin_wall_thickness``: the bin's walls stand on the floor around the inner size.
    ``machine_center`` (x, y), ``machine_size`` (x, y, height): the machine block on the floor.
    ``slot_part_outer``: outer size ``D`` of the part the slot is made for (the bushing's 34 mm);
    ``slot_clearance``: ``slot_width - D`` (5 mm: 2.5 mm each side); ``slot_depth``: pocket depth.
    ``tray_center`` (x, y), ``tray_inner_size`` (x, y), ``tray_wall_height``,
    ``tray_wall_thickness``, ``tray_floor_thickness``: the open box parts are packed into
    (by default 4 x 3 bushings standing upright, pushed together: :meth:`packing_places`).
    ``robot_keepout_radius``: no fixture may come closer than this to the base axis.
    ``camera_xyz`` (m) and ``camera_rpy`` (rad): the eye-in-hand camera's mount, the pose of its
    optical frame (``z`` forward, ``x`` right, ``y`` down) in the tool frame: position, and
    roll-pitch-yaw as fixed-axis (extrinsic) rotations about the tool's ``x``, then ``y``, then
    ``z``, i.e. ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (scipy ``Rotation.from_euler("xyz", rpy)``).
    The defaults are :func:`sim.camera.default_tool_T_camera`; ``cell calibrate`` writes measured
    values. Any finite numbers are accepted (they are not sizes).
    """

    floor_size: tuple[float, float] = (2.0, 2.0)
    floor_thickness: float = 0.05
    bin_center: tuple[float, float] = (0.47, 0.0)
    bin_inner_size: tuple[float, float] = (0.50, 0.32)
    bin_wall_height: float = 0.08
    bin_wall_thickness: float = 0.005
    machine_center: tuple[float, float] = (0.10, 0.45)
    machine_size: tuple[float, float, float] = (0.16, 0.16, 0.10)
    slot_part_outer: float = 0.034
    slot_clearance: float = 0.005
    slot_depth: float = 0.04
    tray_center: tuple[float, float] = (0.10, -0.45)
    tray_inner_size: tuple[float, float] = (0.155, 0.12)
    tray_wall_height: float = 0.05
    tray_wall_thickness: float = 0.005
    tray_floor_thickness: float = 0.005
    robot_keepout_radius: float = 0.10
    camera_xyz: tuple[float, float, float] = (0.0, -0.08, -0.05)
    camera_rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)

    # ----------------------------------------------------------------- derived geometry (m)
    @property
    def slot_width(self) -> float:
        """Side of the square slot pocket (m)."""
        return self.slot_part_outer + self.slot_clearance

    @property
    def machine_top_z(self) -> float:
        """Height of the machine's top surface (m)."""
        return self.machine_size[2]

    @property
    def slot_floor_z(self) -> float:
        """Height of the slot pocket's bottom (m)."""
        return self.machine_size[2] - self.slot_depth

    @property
    def slot_center(self) -> NDArray[np.float64]:
        """Centre of the slot's bottom face (m, world)."""
        return np.array([*self.machine_center, self.slot_floor_z])

    @property
    def bin_floor_z(self) -> float:
        """Height of the surface parts lie on in the bin (m): the cell floor."""
        return 0.0

    @property
    def tray_floor_z(self) -> float:
        """Height of the tray's inner bottom (m)."""
        return self.tray_floor_thickness

    def tool_T_camera(self) -> Pose:
        """The camera mount (:attr:`camera_xyz`, :attr:`camera_rpy`) as a pose in the tool frame."""
        return Pose(
            np.array(self.camera_xyz, float),
            Rotation.from_euler("xyz", self.camera_rpy).as_matrix(),
        )

    def bin_interior(self) -> _Rect:
        """``(xmin, xmax, ymin, ymax)`` of the bin's free inside (m)."""
        return _rect(self.bin_center, self.bin_inner_size, 0.0)

    def tray_interior(self) -> _Rect:
        """``(xmin, xmax, ymin, ymax)`` of the tray's free inside (m)."""
        return _rect(self.tray_center, self.tray_inner_size, 0.0)

    def packing_places(self, part_outer: float | None = None) -> NDArray[np.float64]:
        """Where :class:`skills.packing.PackInBox` puts parts of diameter ``part_outer`` (m;
        default ``slot_part_outer``), in packing order: ``(n, 3)`` bottom centres on the tray
        floor, the first in the ``+x, +y`` corner (see :func:`skills.packing.tray_places`)."""
        from skills.packing import tray_places

        outer = self.slot_part_outer if part_outer is None else part_outer
        return tray_places(self.tray_interior(), self.tray_floor_z, outer)

    def tray_places(self, nx: int = 3, ny: int = 2) -> NDArray[np.float64]:
        """Centres (m, world, on the tray floor) of an ``nx`` x ``ny`` grid filling the tray
        evenly (not a packing order; for packing see :meth:`packing_places`)."""
        (x0, x1, y0, y1) = _rect(self.tray_center, self.tray_inner_size, 0.0)
        xs = x0 + (np.arange(nx) + 0.5) * (x1 - x0) / nx
        ys = y0 + (np.arange(ny) + 0.5) * (y1 - y0) / ny
        return np.array([[x, y, self.tray_floor_z] for y in ys for x in xs])

    def footprints(self) -> dict[str, tuple[_Rect, str]]:
        """Outer footprint of each fixture and the fields that set it, for overlap checks."""
        return {
            "bin": (
                _rect(self.bin_center, self.bin_inner_size, self.bin_wall_thickness),
                "bin_center, bin_inner_size, bin_wall_thickness",
            ),
            "machine": (
                _rect(self.machine_center, self.machine_size[:2], 0.0),
                "machine_center, machine_size",
            ),
            "tray": (
                _rect(self.tray_center, self.tray_inner_size, self.tray_wall_thickness),
                "tray_center, tray_inner_size, tray_wall_thickness",
            ),
        }

    # ----------------------------------------------------------------------- validation
    def validate(self) -> CellLayout:
        """Raise ``ValueError("<field>: <reason>")`` for a layout that cannot be built.

        Checks: finite numbers, positive sizes, a non-negative slot clearance, a slot that fits
        in the machine with walls left, fixtures inside the floor, clear of the robot base and
        not overlapping each other. Returns ``self`` so it chains.
        """
        for f in fields(self):
            value = getattr(self, f.name)
            values = value if isinstance(value, tuple) else (value,)
            if not all(math.isfinite(v) for v in values):
                raise ValueError(f"{f.name}: must be finite, got {value!r}")
            if f.name.endswith("_center") or f.name in _NOT_SIZES:
                continue
            if any(v <= 0 for v in values):
                raise ValueError(f"{f.name}: sizes must be > 0 m, got {value!r}")
        if self.slot_clearance < 0:
            raise ValueError(
                f"slot_clearance: must be >= 0 m (the slot must admit the part), "
                f"got {self.slot_clearance:g}"
            )
        if self.robot_keepout_radius < 0:
            raise ValueError(
                f"robot_keepout_radius: must be >= 0 m, got {self.robot_keepout_radius}"
            )
        if self.slot_width + 2 * MIN_MACHINE_WALL > min(self.machine_size[:2]):
            raise ValueError(
                f"machine_size: {self.machine_size[0]:g} x {self.machine_size[1]:g} m leaves less "
                f"than {MIN_MACHINE_WALL:g} m of wall around the {self.slot_width:g} m slot "
                f"(slot_part_outer + slot_clearance)"
            )
        if self.slot_depth >= self.machine_size[2]:
            raise ValueError(
                f"slot_depth: {self.slot_depth:g} m must be less than the machine height "
                f"{self.machine_size[2]:g} m (machine_size)"
            )
        prints = self.footprints()
        fx, fy = 0.5 * self.floor_size[0], 0.5 * self.floor_size[1]
        for name, ((x0, x1, y0, y1), keys) in prints.items():
            if x0 < -fx or x1 > fx or y0 < -fy or y1 > fy:
                raise ValueError(f"{keys.split(',')[0]}: {name} ({keys}) is off the floor_size")
            nx, ny = min(max(0.0, x0), x1), min(max(0.0, y0), y1)  # nearest point to the base
            if math.hypot(nx, ny) < self.robot_keepout_radius:
                raise ValueError(
                    f"{keys.split(',')[0]}: {name} ({keys}) comes within "
                    f"robot_keepout_radius {self.robot_keepout_radius:g} m of the robot base"
                )
        names = list(prints)
        for i, a in enumerate(names):
            for b in names[i + 1 :]:
                (ra, ka), (rb, kb) = prints[a], prints[b]
                if ra[0] < rb[1] and rb[0] < ra[1] and ra[2] < rb[3] and rb[2] < ra[3]:
                    raise ValueError(f"{ka.split(',')[0]}: {a} ({ka}) overlaps {b} ({kb})")
        return self

    # ----------------------------------------------------------------------- from data
    @classmethod
    def from_dict(cls, data: Mapping[str, object], source: str = "<layout>") -> CellLayout:
        """A validated layout from a mapping of field names to numbers or lists (metres).

        Missing keys keep their defaults. Every error reads ``source: key: reason``.
        """
        if not isinstance(data, Mapping):
            raise ValueError(f"{source}: expected a mapping of layout keys, got {data!r}")
        defaults = cls()
        known = {f.name: f for f in fields(cls)}
        values: dict[str, object] = {}
        for key, raw in data.items():
            if key not in known:
                raise ValueError(f"{source}: {key}: unknown key; valid keys: {', '.join(known)}")
            default = getattr(defaults, key)
            if isinstance(default, tuple):
                if not isinstance(raw, list | tuple) or len(raw) != len(default):
                    raise ValueError(
                        f"{source}: {key}: expected a list of {len(default)} numbers "
                        f"({_unit(key)}), "
                        f"got {raw!r}"
                    )
                values[key] = tuple(_number(source, key, v) for v in raw)
            else:
                values[key] = _number(source, key, raw)
        layout = cls(**values)  # type: ignore[arg-type]
        try:
            return layout.validate()
        except ValueError as exc:
            raise ValueError(f"{source}: {exc}") from None

    @classmethod
    def from_yaml(cls, path: str | Path) -> CellLayout:
        """Read a YAML file holding a mapping of layout keys (metres); errors name the file."""
        p = Path(path)
        try:
            data = yaml.safe_load(p.read_text(encoding="utf-8"))
        except OSError as exc:
            raise ValueError(f"{p}: cannot read the cell layout: {exc.strerror}") from None
        except yaml.YAMLError as exc:
            raise ValueError(f"{p}: not valid YAML: {exc}") from None
        return cls.from_dict(data if data is not None else {}, source=str(p))


def _unit(key: str) -> str:
    return "rad" if key == "camera_rpy" else "m"


def _number(source: str, key: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{source}: {key}: expected a finite number ({_unit(key)}), got {value!r}")
    return float(value)


def _rect(center: tuple[float, ...], inner: tuple[float, ...], wall: float) -> _Rect:
    hx, hy = 0.5 * inner[0] + wall, 0.5 * inner[1] + wall
    return (center[0] - hx, center[0] + hx, center[1] - hy, center[1] + hy)


@dataclass(frozen=True)
class CellBodies:
    """PyBullet ids of the static fixtures."""

    floor: int
    bin: int
    machine: int
    tray: int

    def all(self) -> tuple[int, ...]:
        return (self.floor, self.bin, self.machine, self.tray)


def _static_boxes(
    world: SimWorld,
    boxes: list[tuple[tuple[float, float, float], tuple[float, float, float]]],
    base: tuple[float, float, float],
    friction: float,
    rgba: tuple[float, float, float, float],
) -> int:
    """One static body of axis-aligned boxes ``(half_extents, centre offset)`` around ``base``."""
    p = world.p
    kwargs = {
        "shapeTypes": [p.GEOM_BOX] * len(boxes),
        "halfExtents": [list(h) for h, _ in boxes],
    }
    collision = p.createCollisionShapeArray(
        **kwargs, collisionFramePositions=[list(c) for _, c in boxes]
    )
    visual = p.createVisualShapeArray(**kwargs, visualFramePositions=[list(c) for _, c in boxes])
    body = p.createMultiBody(
        baseMass=0.0,
        baseCollisionShapeIndex=collision,
        baseVisualShapeIndex=visual,
        basePosition=list(base),
    )
    p.changeDynamics(body, -1, lateralFriction=friction, restitution=0.0)
    p.changeVisualShape(body, -1, rgbaColor=list(rgba))
    return body


def _walls(
    inner: tuple[float, float], height: float, thickness: float, z0: float
) -> list[tuple[tuple[float, float, float], tuple[float, float, float]]]:
    """Four walls around an ``inner`` (x, y) rectangle, from ``z0`` up by ``height`` (m)."""
    ix, iy = 0.5 * inner[0], 0.5 * inner[1]
    hz, zc = 0.5 * height, z0 + 0.5 * height
    t = 0.5 * thickness
    return [
        ((t, iy + thickness, hz), (ix + t, 0.0, zc)),
        ((t, iy + thickness, hz), (-ix - t, 0.0, zc)),
        ((ix, t, hz), (0.0, iy + t, zc)),
        ((ix, t, hz), (0.0, -iy - t, zc)),
    ]


def build_cell(
    world: SimWorld,
    layout: CellLayout | None = None,
    floor_friction: float = 0.4,
    fixture_friction: float = 0.5,
) -> CellBodies:
    """Create the fixtures of ``layout`` (validated first) as static bodies.

    ``floor_friction`` is the floor's own coefficient; PyBullet multiplies it with the part's, so
    with parts at 1.0 it is the part-floor ``mu_G`` of the paper. ``fixture_friction`` is used for
    the bin, machine and tray.
    """
    layout = (layout or CellLayout()).validate()
    if floor_friction < 0 or fixture_friction < 0:
        raise ValueError("friction coefficients must be >= 0")
    ft = layout.floor_thickness
    floor = _static_boxes(
        world,
        [((0.5 * layout.floor_size[0], 0.5 * layout.floor_size[1], 0.5 * ft), (0.0, 0.0, 0.0))],
        (0.0, 0.0, -0.5 * ft),
        floor_friction,
        (0.55, 0.55, 0.52, 1.0),
    )
    bin_ = _static_boxes(
        world,
        _walls(layout.bin_inner_size, layout.bin_wall_height, layout.bin_wall_thickness, 0.0),
        (*layout.bin_center, 0.0),
        fixture_friction,
        (0.20, 0.35, 0.65, 1.0),
    )
    sx, sy, h = layout.machine_size
    w, base_h = layout.slot_width, layout.slot_floor_z
    dz, zc = 0.5 * layout.slot_depth, base_h + 0.5 * layout.slot_depth
    side_x = 0.5 * (sx - w)  # wall thickness along x on each side of the pocket
    side_y = 0.5 * (sy - w)
    machine = _static_boxes(
        world,
        [
            ((0.5 * sx, 0.5 * sy, 0.5 * base_h), (0.0, 0.0, 0.5 * base_h)),
            ((0.5 * side_x, 0.5 * sy, dz), (0.5 * (w + side_x), 0.0, zc)),
            ((0.5 * side_x, 0.5 * sy, dz), (-0.5 * (w + side_x), 0.0, zc)),
            ((0.5 * w, 0.5 * side_y, dz), (0.0, 0.5 * (w + side_y), zc)),
            ((0.5 * w, 0.5 * side_y, dz), (0.0, -0.5 * (w + side_y), zc)),
        ],
        (*layout.machine_center, 0.0),
        fixture_friction,
        (0.30, 0.30, 0.33, 1.0),
    )
    tf = layout.tray_floor_thickness
    ti = layout.tray_inner_size
    tray_boxes = _walls(ti, layout.tray_wall_height, layout.tray_wall_thickness, 0.0)
    tray_boxes.append(((0.5 * ti[0], 0.5 * ti[1], 0.5 * tf), (0.0, 0.0, 0.5 * tf)))
    tray = _static_boxes(
        world, tray_boxes, (*layout.tray_center, 0.0), fixture_friction, (0.60, 0.45, 0.25, 1.0)
    )
    return CellBodies(floor=floor, bin=bin_, machine=machine, tray=tray)
