"""The cell's layout: floor, bin, machine with its slot, the tray to pack into, the camera mount.

:class:`CellLayout` is a plain, validated parameter object (SI units, metres; all positions in the
robot-base frame, which is also the world frame of the twin: base at the origin, ``z`` up, the bin
in front on ``+x``). Every fixture is axis-aligned and made of boxes only.

Why here, in the bottom layer: the hardware path validates a configuration's layout, derives
the workflow's geometry from it and reads the camera mount from it, and the twin builds its
fixtures from the same object (:func:`sim.cell_layout.build_cell`); neither may need the other,
and the hardware path must run without PyBullet.

Heights: the floor's top is ``z = 0`` and is also the bin's floor (the bin is four walls standing
on it, so a part in the bin touches the floor and the floor friction ``mu_G`` applies). The tray has
its own bottom plate. The machine is a block of ``machine_size[2]`` with a square pocket (the slot)
of side ``slot_width = slot_part_outer + slot_clearance`` and depth ``slot_depth`` in the middle of
its top, into which a part is fed standing upright.

Packing order (:func:`tray_places`): the first part into the ``+x, +y`` corner of the tray, then
along the ``+y`` wall towards ``-x``, then the next row, so that each new part is pushed into a
corner made of walls and parts already packed (:class:`skills.packing.PackInBox`).
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

#: The thinnest wall (m) the machine block may keep around its slot.
MIN_MACHINE_WALL = 0.005

_Rect = tuple[float, float, float, float]  # xmin, xmax, ymin, ymax (m)
#: Fields besides the ``*_center`` ones that are not sizes: no ``> 0`` check (the camera mount
#: may be anywhere; the clearance and keep-out radius have their own checks).
_NOT_SIZES = ("slot_clearance", "robot_keepout_radius", "camera_xyz", "camera_rpy")


def tray_places(
    tray_roi: tuple[float, float, float, float],
    floor_z: float,
    outer: float,
    margin: float = 0.0015,
    trailing: float = 0.012,
) -> NDArray[np.float64]:
    """Places (x, y, floor z; m) of upright parts of diameter ``outer`` in packing order.

    ``tray_roi``: ``(xmin, xmax, ymin, ymax)`` of the box's inside. A square grid of pitch
    ``outer + margin`` from the ``+x, +y`` corner: row by row along ``-x``, rows towards ``-y``.
    ``margin`` covers parts a little wider than nominal (the place is where the part is set
    down from, the pushes find where it really goes); ``trailing`` (m) is kept free along the
    ``-x`` and ``-y`` walls for the set-down offset and the outer finger beside the last part.
    """
    x0, x1, y0, y1 = tray_roi
    pitch = outer + margin
    nx = int((x1 - x0 - trailing) // pitch)
    ny = int((y1 - y0 - trailing) // pitch)
    half = 0.5 * pitch
    return np.array(
        [[x1 - half - i * pitch, y1 - half - j * pitch, floor_z] for j in range(ny)
         for i in range(nx)],
        float,
    ).reshape(-1, 3)


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
        floor, the first in the ``+x, +y`` corner (see :func:`tray_places`)."""
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
        except yaml.MarkedYAMLError as exc:
            mark = exc.problem_mark or exc.context_mark
            where = f"{p}:{mark.line + 1}" if mark is not None else str(p)
            raise ValueError(f"{where}: not valid YAML: {exc.problem or exc.context}") from None
        except (yaml.YAMLError, UnicodeDecodeError) as exc:
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


__all__ = ["MIN_MACHINE_WALL", "CellLayout", "tray_places"]
