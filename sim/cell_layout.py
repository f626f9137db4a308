"""The static cell of the twin: floor, bin, machine with its slot, and the tray to pack into.

:func:`build_cell` turns a :class:`drivers.layout.CellLayout` (the cell's validated description,
shared with the hardware path) into static PyBullet bodies. Every fixture is axis-aligned and
built from boxes only, so all contacts with parts are box-box contacts. The bin is four walls
standing on the floor (a part in the bin touches the floor, so the floor friction ``mu_G``
applies); the tray has its own bottom plate; the machine is a block with a square pocket (the
slot) in the middle of its top.
"""

from __future__ import annotations

from dataclasses import dataclass

from drivers.layout import CellLayout
from sim.world import SimWorld

#: m, the floor's rolling friction. Bullet combines a contact's as ``r_part * mu_floor +
#: r_floor * mu_part`` (parts at mu 1.0, ``spawn_part``'s 5e-4): 0.33-0.5 mm for a part lying in
#: the bin on the cell's floors (mu_G 0.25-0.6), a hard part on a plastic floor. A round part is
#: laid balanced on an edge of its 144-gon and the solver's jitter tips some off it; with the
#: part's share alone (0.1-0.3 mm) the roll then grew on its own in some trial worlds (the cup
#: up to 137 mm, a 200 g jar 36 mm within 6 s), with this they settle on a flat a few mm on. The
#: floor's, not the part's: the part's own value also acts at the fingers, where the paper's
#: contacts turn freely. Below 0.6 mm, so a bushing still rolls down a floor tilted 2 deg.
FLOOR_ROLLING = 2e-4


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
    rolling: float = 0.0,
) -> int:
    """One static body of axis-aligned boxes ``(half_extents, centre offset)`` around ``base``;
    ``rolling``: its rolling friction (m), see :func:`build_cell`."""
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
    p.changeDynamics(body, -1, lateralFriction=friction, restitution=0.0, rollingFriction=rolling)
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
    z_offset: float = 0.0,
    floor_rolling: float = FLOOR_ROLLING,
) -> CellBodies:
    """Create the fixtures of ``layout`` (validated first) as static bodies.

    ``floor_friction`` is the floor's own coefficient; PyBullet multiplies it with the part's, so
    with parts at 1.0 it is the part-floor ``mu_G`` of the paper. ``fixture_friction`` is used for
    the bin, machine and tray. ``z_offset`` (m) raises every fixture above where the layout puts
    it: the cell's true height against the configured one (:mod:`sim.uncertainty`).
    ``floor_rolling`` (m) is the floor's rolling friction, the resistance a part lying in the bin
    meets when it rolls (:data:`FLOOR_ROLLING`).
    """
    layout = (layout or CellLayout()).validate()
    if floor_friction < 0 or fixture_friction < 0 or floor_rolling < 0:
        raise ValueError("friction coefficients must be >= 0")
    ft = layout.floor_thickness
    floor = _static_boxes(
        world,
        [((0.5 * layout.floor_size[0], 0.5 * layout.floor_size[1], 0.5 * ft), (0.0, 0.0, 0.0))],
        (0.0, 0.0, z_offset - 0.5 * ft),
        floor_friction,
        (0.55, 0.55, 0.52, 1.0),
        floor_rolling,
    )
    bin_ = _static_boxes(
        world,
        _walls(layout.bin_inner_size, layout.bin_wall_height, layout.bin_wall_thickness, 0.0),
        (*layout.bin_center, z_offset),
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
        (*layout.machine_center, z_offset),
        fixture_friction,
        (0.30, 0.30, 0.33, 1.0),
    )
    tf = layout.tray_floor_thickness
    ti = layout.tray_inner_size
    tray_boxes = _walls(ti, layout.tray_wall_height, layout.tray_wall_thickness, 0.0)
    tray_boxes.append(((0.5 * ti[0], 0.5 * ti[1], 0.5 * tf), (0.0, 0.0, 0.5 * tf)))
    tray = _static_boxes(
        world, tray_boxes, (*layout.tray_center, z_offset), fixture_friction,
        (0.60, 0.45, 0.25, 1.0),
    )
    return CellBodies(floor=floor, bin=bin_, machine=machine, tray=tray)
