"""A hollow part of the catalogue as one dynamic PyBullet body.

The part is built from flat boxes so that every contact the pivot relies on is a box-box contact
(Bullet's exact box-box detector, no GJK margin rounding): a round tube is ``N`` staves around the
hole, a rectangular one four plates; a part with one open end also gets a bottom at its closed end.
Geometry, units and frames:

* Part frame: origin at the centroid of the ``length x outer x outer`` envelope, ``+x`` along the
  axis towards the open end (the closed end of a cup or bottle is at ``-x``). All lengths in m.
* Round section: stave ``k`` has its outward normal at ``2 pi k / N`` about ``+x`` from ``-z``,
  its inner face tangent to the hole circle (``hole / 2``) and its outer face at ``outer / 2``.
  The union is exactly the region between two regular ``N``-gons whose inscribed circles have
  diameters ``hole`` and ``outer``: a finger sees the free diameter ``hole`` and the floor sees the
  envelope ``outer``. Stave 0 faces ``-z``, so a part lying with an identity roll rests on a flat
  face with its centre ``outer / 2`` above the floor.
* Mass (kg) and inertia are those of the ideal thick-walled tube (plus its bottom disc, same wall
  material, for ``open_ends == 1``), set explicitly; PyBullet's default would be a box's.

Nothing here moves a part after :func:`spawn_part`: the cell's rule is that only physics does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from drivers.parts import Part
from drivers.pose import Pose, rot_x, rot_y, rot_z
from sim.world import SimWorld, matrix_from_quaternion

#: PyBullet keeps only the first 16 child shapes of a shape array.
MAX_CHILD_SHAPES = 16
#: Default number of staves for a round section (a multiple of 4: flat faces at +-y and +-z).
DEFAULT_STAVES = 12
#: Upper bound of the collision margin (m): well inside a 3 mm wall.
MAX_COLLISION_MARGIN = 0.0005


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


def _boxes(part: Part, staves: int) -> list[_Box]:
    """The child boxes of the part, in the part frame."""
    half_l = 0.5 * part.length
    t = wall_thickness(part)
    r_in, r_out = 0.5 * part.hole, 0.5 * part.outer
    boxes: list[_Box] = []
    if part.hole_shape == "circle":
        # Tangential width that closes the outer polygon; the staves then overlap near the hole,
        # which is harmless inside one body, and nothing reaches inside the hole circle.
        half_w = r_out * math.tan(math.pi / staves)
        for k in range(staves):
            theta = 2.0 * math.pi * k / staves - 0.5 * math.pi
            rot = rot_x(theta)  # local y -> outward normal (0, cos, sin); stave 0 faces -z
            centre = rot @ np.array([0.0, 0.5 * (r_in + r_out), 0.0])
            boxes.append(_Box((half_l, 0.5 * t, half_w), centre, rot))
    else:
        eye = np.eye(3)
        for s in (-1.0, 1.0):
            # Plates facing +-z span the full outer side; those facing +-y fill between them.
            off = s * (r_out - 0.5 * t)
            boxes.append(_Box((half_l, r_out, 0.5 * t), np.array([0.0, 0.0, off]), eye))
            boxes.append(_Box((half_l, 0.5 * t, r_in), np.array([0.0, off, 0.0]), eye))
    return boxes


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

    Round: the outer ``N``-gon (corners at ``outer / 2 / cos(pi / N)``) at both ends; rectangular:
    the eight corners. The lowest point of the part is always one of these.
    """
    half_l, r_out = 0.5 * part.length, 0.5 * part.outer
    if part.hole_shape == "circle":
        rc = r_out / math.cos(math.pi / staves)
        ang = 2.0 * math.pi * (np.arange(staves) + 0.5) / staves - 0.5 * math.pi
        ring = np.stack([np.cos(ang), np.sin(ang)], axis=1) * rc
    else:
        ring = np.array([[1, 1], [1, -1], [-1, 1], [-1, -1]], float) * r_out
    ends = [np.column_stack([np.full(len(ring), s * half_l), ring]) for s in (-1.0, 1.0)]
    return np.vstack(ends)


def lying_pose(part: Part, x: float, y: float, yaw: float, floor_z: float = 0.0) -> Pose:
    """Pose of ``part`` resting on a floor at height ``floor_z`` (m), axis horizontal at ``yaw``.

    The part's ``+x`` axis points along ``(cos yaw, sin yaw, 0)``; a flat stave or plate faces
    down, so the centre is ``outer / 2`` above the floor.
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


def spawn_part(
    world: SimWorld,
    part: Part,
    pose: Pose,
    lateral_friction: float = 1.0,
    *,
    staves: int = DEFAULT_STAVES,
    rolling_friction: float = 1e-4,
    spinning_friction: float = 1e-3,
    rgba: tuple[float, float, float, float] = (0.70, 0.72, 0.75, 1.0),
    sleep_threshold: float | None = None,
) -> PartBody:
    """Create ``part`` as one dynamic body with its part frame at ``pose`` (world, m).

    ``lateral_friction`` is the part's own coefficient; PyBullet multiplies it with the other
    body's, so the cell keeps 1.0 here and puts the per-contact values on fingers and floor.
    ``rolling_friction`` / ``spinning_friction`` (m) are small on purpose: the part must pivot
    freely about its floor contact. Bullet combines them as ``r_part * mu_other + r_other *
    mu_part``, so with fixtures at 0 the effective value is this one times the floor's friction.
    ``staves`` (round sections only) must leave room for the bottom within 16 child shapes.
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
    boxes = _boxes(part, staves)
    types = [p.GEOM_BOX] * len(boxes)
    half_extents = [list(b.half_extents) for b in boxes]
    radii = [0.0] * len(boxes)
    lengths = [0.0] * len(boxes)
    positions = [b.position.tolist() for b in boxes]
    orientations = [Pose(rotation=b.rotation).quaternion.tolist() for b in boxes]
    bottom = _bottom(part)
    if bottom is not None:
        centre, t_b = bottom
        if part.hole_shape == "circle":
            # A disc reaching half-way into the staves: closes the hole, stays inside the envelope.
            types.append(p.GEOM_CYLINDER)
            half_extents.append([0.0, 0.0, 0.0])
            radii.append(0.25 * (part.hole + part.outer))
            lengths.append(t_b)
            orientations.append(Pose(rotation=rot_y(0.5 * math.pi)).quaternion.tolist())
        else:
            types.append(p.GEOM_BOX)
            half_extents.append([0.5 * t_b, 0.5 * part.hole, 0.5 * part.hole])
            radii.append(0.0)
            lengths.append(0.0)
            orientations.append([0.0, 0.0, 0.0, 1.0])
        positions.append(centre.tolist())
    if len(types) > MAX_CHILD_SHAPES:
        raise ValueError(f"{len(types)} child shapes; PyBullet keeps only {MAX_CHILD_SHAPES}")

    collision = p.createCollisionShapeArray(
        shapeTypes=types,
        halfExtents=half_extents,
        radii=radii,
        lengths=lengths,
        collisionFramePositions=positions,
        collisionFrameOrientations=orientations,
    )
    visual = p.createVisualShapeArray(
        shapeTypes=types,
        halfExtents=half_extents,
        radii=radii,
        lengths=lengths,
        visualFramePositions=positions,
        visualFrameOrientations=orientations,
    )
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
    margin = min(MAX_COLLISION_MARGIN, 0.25 * wall_thickness(part))
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
