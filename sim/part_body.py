"""A hollow part of the catalogue as one dynamic PyBullet body.

A rectangular part is four flat plates (boxes: Bullet's exact box-box detector, no GJK margin
rounding); a part with one open end also gets a bottom at its closed end. A round part is round:
``N`` convex staves around the hole, each with a flat inner face (so a finger in the hole meets
a plane, as on the rectangular parts) and an outer face that follows the outer circle in
:data:`ARC_SEGMENTS` flats, so the part rolls on a floor tilted 2 deg as a real tube does.
Geometry, units and frames:

* Part frame: origin at the centroid of the ``length x outer x outer`` envelope, ``+x`` along the
  axis towards the open end (the closed end of a cup or bottle is at ``-x``). All lengths in m.
* Round section: stave ``k`` is centred on the outward direction ``2 pi k / N`` about ``+x`` from
  ``-z``; its inner face is tangent to the hole circle (``hole / 2``), its outer face lies on the
  circle ``outer / 2``. A finger sees the free diameter ``hole`` and the floor the envelope
  ``outer``. Bullet inflates a convex hull by its collision margin, so each hull is built that
  margin inside the surface it stands for: the surfaces the contacts meet are where the
  dimensions say, with edges rounded by the margin.
* Mass (kg) and inertia are those of the ideal thick-walled tube (plus its bottom disc, same wall
  material, for ``open_ends == 1``), set explicitly; PyBullet's default would be a box's.

Nothing here moves a part after :func:`spawn_part`: the cell's rule is that only physics does.
"""

from __future__ import annotations

import atexit
import functools
import hashlib
import math
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from drivers.parts import Part
from drivers.pose import Pose, rot_y, rot_z
from sim.world import SimWorld, matrix_from_quaternion

#: PyBullet keeps only the first 16 child shapes of a shape array.
MAX_CHILD_SHAPES = 16
#: Default number of staves for a round section (a multiple of 4: the hole's flat faces at +-y
#: and +-z, where the fingers meet it).
DEFAULT_STAVES = 12
#: Flats per stave on the outer circle: 12 x 12 = a 144-gon, whose flats tilt 1.25 deg from one to
#: the next (under the 2 deg a part must roll on) and stay within 0.01 mm of a 34 mm circle.
#: Even, so an edge, not a flat, lies at the middle of stave 0, which faces down in
#: :func:`lying_pose`: a part is laid balanced on that edge, and in some trial worlds the
#: solver's jitter grows until it rolls off by itself (``bench/parts_at_rest.py``). 13 halved
#: those rolls but did not end them and cost the pivot trials elsewhere (docs/pivot_in_hand.md).
ARC_SEGMENTS = 12
#: Sides of the polygon standing for a round part's bottom disc.
BOTTOM_SIDES = 48
#: Upper bound of the collision margin (m). Bullet rounds each hull's edges by its margin, so two
#: staves meet in a notch as deep as the margin is wide; a pad pressed onto a seam sinks into it
#: and the rounded edges push back sideways. At 0.5 mm such a contact held a 2F-85's pads shut
#: against their 100 N opening force in a packing let go (the twin measured 150 N on it);
#: at 0.1 mm it did not recur.
MAX_COLLISION_MARGIN = 0.0001


@dataclass(frozen=True)
class MassProperties:
    """Mass (kg), centre of mass in the part frame (m) and principal inertia there (kg m^2)."""

    mass: float
    com: NDArray[np.float64]
    inertia: NDArray[np.float64]


@dataclass(frozen=True)
class _Box:
    """One child box: half extents (m) and its pose in the part frame."""

    half_extents: tuple[float, float, float]
    position: NDArray[np.float64]
    rotation: NDArray[np.float64]


def wall_thickness(part: Part) -> float:
    """Radial wall thickness ``(outer - hole) / 2`` (m); also the bottom's thickness."""
    return 0.5 * (part.outer - part.hole)


def _boxes(part: Part) -> list[_Box]:
    """The child boxes of a rectangular part, in the part frame."""
    half_l = 0.5 * part.length
    t = wall_thickness(part)
    r_in, r_out = 0.5 * part.hole, 0.5 * part.outer
    boxes: list[_Box] = []
    eye = np.eye(3)
    for s in (-1.0, 1.0):
        # Plates facing +-z span the full outer side; those facing +-y fill between them.
        off = s * (r_out - 0.5 * t)
        boxes.append(_Box((half_l, r_out, 0.5 * t), np.array([0.0, 0.0, off]), eye))
        boxes.append(_Box((half_l, 0.5 * t, r_in), np.array([0.0, off, 0.0]), eye))
    return boxes


def _prism(section: NDArray[np.float64], x0: float, x1: float) -> NDArray[np.float64]:
    """Vertices (n, 3) of a prism along ``x`` from ``x0`` to ``x1`` over a convex ``(y, z)``
    polygon (n / 2, 2) given counter-clockwise: first the ``x0`` end, then the ``x1`` end."""
    n = len(section)
    return np.vstack(
        [np.column_stack([np.full(n, x0), section]), np.column_stack([np.full(n, x1), section])]
    )


def round_pieces(
    part: Part, staves: int = DEFAULT_STAVES, margin: float = 0.0
) -> list[NDArray[np.float64]]:
    """The convex pieces of a round part (each a prism's vertices, see :func:`_prism`), built
    ``margin`` inside the surfaces they stand for: the staves, then the bottom if it has one."""
    half_l = 0.5 * part.length - margin
    r_in, r_out = 0.5 * part.hole + margin, 0.5 * part.outer - margin
    step = 2.0 * math.pi / staves
    r_corner = r_in / math.cos(0.5 * step)  # the hole polygon's corners
    pieces = []
    for k in range(staves):
        a0 = step * k - 0.5 * math.pi - 0.5 * step
        a1 = a0 + step
        arc = np.linspace(a0, a1, ARC_SEGMENTS + 1)
        ring = [(r_corner * math.cos(a0), r_corner * math.sin(a0))]
        ring += [(r_out * math.cos(a), r_out * math.sin(a)) for a in arc]
        ring.append((r_corner * math.cos(a1), r_corner * math.sin(a1)))
        # Counter-clockwise about +x in (y, z): inner corner a0, out along the arc, back in at a1.
        pieces.append(_prism(np.array(ring), -half_l, half_l))
    bottom = _bottom(part)
    if bottom is not None:
        centre, t_b = bottom
        # A disc reaching half-way into the staves: closes the hole, stays inside the envelope.
        r_b = 0.25 * (part.hole + part.outer) - margin
        ang = 2.0 * math.pi * np.arange(BOTTOM_SIDES) / BOTTOM_SIDES
        disc = np.column_stack([np.cos(ang), np.sin(ang)]) * r_b
        half_t = 0.5 * t_b - margin
        pieces.append(_prism(disc, centre[0] - half_t, centre[0] + half_t))
    return pieces


def _obj_text(pieces: list[NDArray[np.float64]]) -> str:
    """A Wavefront OBJ with one object per convex piece (PyBullet makes each a convex hull of a
    compound) and outward-wound faces (the camera renders it)."""
    lines: list[str] = []
    base = 1
    for i, verts in enumerate(pieces):
        n = len(verts) // 2
        lines.append(f"o piece{i}")
        lines += [f"v {x:.9f} {y:.9f} {z:.9f}" for x, y, z in verts]
        lo = [base + j for j in range(n)]
        hi = [base + n + j for j in range(n)]
        # The x0 end faces -x: its counter-clockwise (y, z) ring reversed; the x1 end as given.
        lines += [f"f {lo[0]} {lo[j + 1]} {lo[j]}" for j in range(1, n - 1)]
        lines += [f"f {hi[0]} {hi[j]} {hi[j + 1]}" for j in range(1, n - 1)]
        for j in range(n):
            a, b = j, (j + 1) % n
            lines.append(f"f {lo[a]} {lo[b]} {hi[b]} {hi[a]}")
        base += 2 * n
    return "\n".join(lines) + "\n"


_MESH_DIR: Path | None = None


@functools.lru_cache(maxsize=64)
def _round_mesh_file(part: Part, staves: int, margin: float) -> str:
    """Path of an OBJ holding the part's :func:`round_pieces`, written once per process into a
    private temporary folder (PyBullet reads meshes only from files); named by content, so a
    part's file is reused and two parts never share one. Cached: a bin fill spawns the same
    part many times, and each spawn would build and hash the same text again."""
    global _MESH_DIR
    if _MESH_DIR is None:
        _MESH_DIR = Path(tempfile.mkdtemp(prefix="pivot-cell-parts-"))
        atexit.register(shutil.rmtree, _MESH_DIR, True)
    text = _obj_text(round_pieces(part, staves, margin))
    path = _MESH_DIR / f"{hashlib.sha1(text.encode()).hexdigest()[:16]}.obj"
    if not path.exists():
        path.write_text(text)
    return str(path)


def _bottom(part: Part) -> tuple[NDArray[np.float64], float] | None:
    """Centre (m, part frame) and thickness (m) of the closed end, or ``None`` for a tube."""
    if part.open_ends == 2:
        return None
    t = wall_thickness(part)
    return np.array([-0.5 * part.length + 0.5 * t, 0.0, 0.0]), t


def mass_properties(part: Part) -> MassProperties:
    """Ideal thick-walled tube (round: annulus, rectangular: square ring) plus its bottom.

    The tube wall and the bottom are one material, so the bottom's share of ``part.mass`` is its
    share of the volume; the centre of mass moves towards the closed end accordingly.
    """
    length, r_in, r_out = part.length, 0.5 * part.hole, 0.5 * part.outer
    round_ = part.hole_shape == "circle"
    area_tube = math.pi * (r_out**2 - r_in**2) if round_ else part.outer**2 - part.hole**2
    area_bottom = math.pi * r_in**2 if round_ else part.hole**2
    bottom = _bottom(part)
    t_b = bottom[1] if bottom is not None else 0.0
    v_tube, v_bottom = area_tube * length, area_bottom * t_b
    m_tube = part.mass * v_tube / (v_tube + v_bottom)
    m_bottom = part.mass - m_tube
    x_bottom = bottom[0][0] if bottom is not None else 0.0
    x_com = m_bottom * x_bottom / part.mass

    if round_:
        sq = r_out**2 + r_in**2
        ix = 0.5 * m_tube * sq + 0.5 * m_bottom * r_in**2
        iy_tube = m_tube * (3.0 * sq + length**2) / 12.0
        iy_bottom = m_bottom * (3.0 * r_in**2 + t_b**2) / 12.0
    else:
        sq = part.outer**2 + part.hole**2
        ix = m_tube * sq / 6.0 + m_bottom * part.hole**2 / 6.0
        iy_tube = m_tube * (sq + length**2) / 12.0
        iy_bottom = m_bottom * (part.hole**2 + t_b**2) / 12.0
    iy = iy_tube + m_tube * x_com**2 + iy_bottom + m_bottom * (x_bottom - x_com) ** 2
    return MassProperties(part.mass, np.array([x_com, 0.0, 0.0]), np.array([ix, iy, iy]))


def hull_vertices(part: Part, staves: int = DEFAULT_STAVES) -> NDArray[np.float64]:
    """Vertices of the outer envelope in the part frame (m), shape (n, 3).

    Round: the outer circle's ``N x`` :data:`ARC_SEGMENTS` corners at both ends; rectangular: the
    eight corners. The lowest point of the part is always one of these.
    """
    half_l, r_out = 0.5 * part.length, 0.5 * part.outer
    if part.hole_shape == "circle":
        n = staves * ARC_SEGMENTS
        ang = 2.0 * math.pi * np.arange(n) / n - 0.5 * math.pi - math.pi / staves
        ring = np.stack([np.cos(ang), np.sin(ang)], axis=1) * r_out
    else:
        ring = np.array([[1, 1], [1, -1], [-1, 1], [-1, -1]], float) * r_out
    ends = [np.column_stack([np.full(len(ring), s * half_l), ring]) for s in (-1.0, 1.0)]
    return np.vstack(ends)


def lying_pose(part: Part, x: float, y: float, yaw: float, floor_z: float = 0.0) -> Pose:
    """Pose of ``part`` resting on a floor at height ``floor_z`` (m), axis horizontal at ``yaw``.

    The part's ``+x`` axis points along ``(cos yaw, sin yaw, 0)``; stave 0 or a plate faces
    down (a round part rests on the edge at stave 0's middle, see :data:`ARC_SEGMENTS`), so the
    centre is ``outer / 2`` above the floor.
    """
    return Pose(np.array([x, y, floor_z + 0.5 * part.outer]), rot_z(yaw))


def upright_pose(
    part: Part, x: float, y: float, floor_z: float = 0.0, open_up: bool = True
) -> Pose:
    """Pose of ``part`` standing on an end on a floor at ``floor_z`` (m), open end up by default."""
    rot = rot_y(-0.5 * math.pi) if open_up else rot_y(0.5 * math.pi)  # part +x -> world +z / -z
    return Pose(np.array([x, y, floor_z + 0.5 * part.length]), rot)


class PartBody:
    """A spawned part: its body id and read-only views of its state (m, rad, world frame)."""

    def __init__(
        self, world: SimWorld, part: Part, body_id: int, mass: MassProperties, staves: int
    ) -> None:
        self.world = world
        self.part = part
        self.body_id = body_id
        self.mass_properties = mass
        self.staves = staves
        self._com_T_part = Pose(-mass.com, np.eye(3))
        self._hull = hull_vertices(part, staves)

    def pose(self) -> Pose:
        """World pose of the part frame (PyBullet reports the centre of mass; this undoes it)."""
        return Pose(*self.frame())

    def frame(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(position, rotation)`` of :meth:`pose`, the same numbers without building a
        :class:`Pose`: the judge reads the part every control step, and each ``Pose`` costs more
        than the query. Computed as ``Pose.from_quaternion(pos, quat) @ com_T_part`` would."""
        pos, quat = self.world.p.getBasePositionAndOrientation(self.body_id)
        rotation = matrix_from_quaternion(quat)
        com = self._com_T_part
        return np.asarray(pos, float) + rotation @ com.position, rotation @ com.rotation

    def axis(self) -> NDArray[np.float64]:
        """Unit vector of the part's ``+x`` axis (towards the open end) in the world."""
        return self.pose().rotation[:, 0].copy()

    def open_end_center(self) -> NDArray[np.float64]:
        """World position (m) of the centre of the ``+x`` end face (the open end)."""
        return self.pose().transform([0.5 * self.part.length, 0.0, 0.0])

    def closed_end_center(self) -> NDArray[np.float64]:
        """World position (m) of the centre of the ``-x`` end face (closed for a cup)."""
        return self.pose().transform([-0.5 * self.part.length, 0.0, 0.0])

    def lowest_z(self) -> float:
        """Height (m) of the lowest point of the part's envelope."""
        return float(self.pose().transform(self._hull)[:, 2].min())

    def velocity(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Linear (m/s, of the centre of mass) and angular (rad/s) velocity in the world."""
        lin, ang = self.world.p.getBaseVelocity(self.body_id)
        return np.asarray(lin, float), np.asarray(ang, float)

    def tilt(self) -> float:
        """Angle (rad) between the axis and the floor plane: 0 lying, pi/2 upright."""
        return float(math.asin(min(1.0, abs(self.axis()[2]))))


def _box_shapes(world: SimWorld, part: Part) -> tuple[int, int]:
    """Collision and visual shape of a rectangular part: its plates and its bottom plate."""
    p = world.p
    boxes = _boxes(part)
    half_extents = [list(b.half_extents) for b in boxes]
    positions = [b.position.tolist() for b in boxes]
    orientations = [Pose(rotation=b.rotation).quaternion.tolist() for b in boxes]
    bottom = _bottom(part)
    if bottom is not None:
        centre, t_b = bottom
        half_extents.append([0.5 * t_b, 0.5 * part.hole, 0.5 * part.hole])
        positions.append(centre.tolist())
        orientations.append([0.0, 0.0, 0.0, 1.0])
    types = [p.GEOM_BOX] * len(half_extents)
    if len(types) > MAX_CHILD_SHAPES:
        raise ValueError(f"{len(types)} child shapes; PyBullet keeps only {MAX_CHILD_SHAPES}")
    collision = p.createCollisionShapeArray(
        shapeTypes=types,
        halfExtents=half_extents,
        collisionFramePositions=positions,
        collisionFrameOrientations=orientations,
    )
    visual = p.createVisualShapeArray(
        shapeTypes=types,
        halfExtents=half_extents,
        visualFramePositions=positions,
        visualFrameOrientations=orientations,
    )
    return collision, visual


def spawn_part(
    world: SimWorld,
    part: Part,
    pose: Pose,
    lateral_friction: float = 1.0,
    *,
    staves: int = DEFAULT_STAVES,
    rolling_friction: float = 5e-4,
    spinning_friction: float = 1e-3,
    rgba: tuple[float, float, float, float] = (0.70, 0.72, 0.75, 1.0),
    sleep_threshold: float | None = None,
) -> PartBody:
    """Create ``part`` as one dynamic body with its part frame at ``pose`` (world, m).

    ``lateral_friction`` is the part's own coefficient; PyBullet multiplies it with the other
    body's, so the cell keeps 1.0 here and puts the per-contact values on fingers and floor.
    ``rolling_friction`` / ``spinning_friction`` (m) are small on purpose: the part must pivot
    freely about its floor contact. Bullet combines them as ``r_part * mu_other + r_other *
    mu_part``, so with fixtures at 0 the effective value is this one times the other body's
    friction: 0.1-0.3 mm on the cell's floors (0.25-0.6), to which the floor adds its own
    (:data:`sim.cell_layout.FLOOR_ROLLING`). Under 0.05 mm the 144-gon's contact wanders and a
    round part left lying starts rolling by itself within seconds.
    ``staves`` (round sections only): the pieces around the hole, within 16 with the bottom.
    ``sleep_threshold``: let the part fall asleep once it moves slower than this (Bullet's
    velocity threshold, about m/s) -- a part left standing (packed in a box, in a slot) otherwise
    creeps about 1 mm a minute on the solver's jitter; contact with a moving body wakes it.
    None (default): never sleeps.
    """
    if part.hole_shape == "circle" and not (3 <= staves <= MAX_CHILD_SHAPES - 1):
        raise ValueError(f"staves must be in 3..{MAX_CHILD_SHAPES - 1}, got {staves}")
    if lateral_friction < 0 or rolling_friction < 0 or spinning_friction < 0:
        raise ValueError("friction coefficients must be >= 0")
    p = world.p
    margin = min(MAX_COLLISION_MARGIN, 0.25 * wall_thickness(part))
    if part.hole_shape == "circle":
        mesh = _round_mesh_file(part, staves, margin)
        collision = p.createCollisionShape(p.GEOM_MESH, fileName=mesh)
        visual = p.createVisualShape(p.GEOM_MESH, fileName=mesh)
    else:
        collision, visual = _box_shapes(world, part)
    mass = mass_properties(part)
    body = p.createMultiBody(
        baseMass=part.mass,
        baseCollisionShapeIndex=collision,
        baseVisualShapeIndex=visual,
        basePosition=pose.position.tolist(),
        baseOrientation=pose.quaternion.tolist(),
        baseInertialFramePosition=mass.com.tolist(),
    )
    if body < 0:
        raise RuntimeError(f"PyBullet could not create part {part.name!r}")
    p.changeDynamics(
        body,
        -1,
        localInertiaDiagonal=mass.inertia.tolist(),
        lateralFriction=lateral_friction,
        rollingFriction=rolling_friction,
        spinningFriction=spinning_friction,
        restitution=0.0,
        collisionMargin=margin,
    )
    if sleep_threshold is not None:
        p.changeDynamics(
            body,
            -1,
            activationState=p.ACTIVATION_STATE_ENABLE_SLEEPING,
            sleepThreshold=float(sleep_threshold),
        )
    p.changeVisualShape(body, -1, rgbaColor=list(rgba))
    return PartBody(world, part, body, mass, staves)
