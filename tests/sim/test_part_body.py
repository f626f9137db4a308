"""The part as a PyBullet body: it lies as the mechanics assume, its hole is free, mass is set."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cell.catalogue import load_catalogue
from drivers.pose import Pose, rot_x
from sim.cell_layout import FLOOR_ROLLING
from sim.part_body import (
    ARC_SEGMENTS,
    hull_vertices,
    lying_pose,
    mass_properties,
    spawn_part,
    upright_pose,
)
from sim.world import SimWorld

CATALOGUE = load_catalogue()


def _floor(world: SimWorld, friction: float = 0.4) -> int:
    """A 2 m x 2 m box floor with its top at z = 0 (a plane does not collide with compounds),
    rolling like the cell's floor."""
    p = world.p
    shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=[1.0, 1.0, 0.05])
    floor = p.createMultiBody(0.0, shape, basePosition=[0.0, 0.0, -0.05])
    p.changeDynamics(floor, -1, lateralFriction=friction, rollingFriction=FLOOR_ROLLING)
    return floor


def _lifted(pose: Pose, dz: float) -> Pose:
    return Pose(pose.position + np.array([0.0, 0.0, dz]), pose.rotation)


@pytest.mark.parametrize("name", list(CATALOGUE.parts))
def test_every_part_comes_to_rest_lying(name: str) -> None:
    part = CATALOGUE.get(name)
    with SimWorld(seed=1) as world:
        _floor(world)
        body = spawn_part(world, part, _lifted(lying_pose(part, 0.1, -0.05, 0.7), 0.001))
        for _ in range(125):  # 1 s
            world.step()
        pose = body.pose()
        assert abs(body.axis()[2]) < math.sin(math.radians(2.0))
        assert pose.position[2] == pytest.approx(0.5 * part.outer, abs=0.0015)
        assert body.lowest_z() == pytest.approx(0.0, abs=0.0015)
        lin, ang = body.velocity()
        assert np.linalg.norm(lin) < 0.01 and np.linalg.norm(ang) < 0.1


@pytest.mark.parametrize("name", ["bushing", "medicine_bottle", "cookie_can"])
def test_a_round_part_rolls_down_a_floor_tilted_2_deg_and_rests_on_a_level_one(name: str) -> None:
    part = CATALOGUE.get(name)
    for tilt_deg, rolls in ((2.0, True), (0.0, False)):
        with SimWorld(seed=1) as world:
            g = world.settings.gravity
            tilt = math.radians(tilt_deg)
            world.p.setGravity(0.0, g * math.sin(tilt), -g * math.cos(tilt))  # downhill is +y
            _floor(world)
            start = _lifted(lying_pose(part, 0.0, 0.0, 0.0), 0.001)
            body = spawn_part(world, part, start)
            for _ in range(250):  # 2 s
                world.step()
            travelled = body.pose().position[1] - start.position[1]
            turned = math.acos(float(np.clip(body.pose().rotation[2, 2], -1.0, 1.0)))
            if rolls:  # rolled, not slid: the travel is the turn times the radius
                assert travelled > 0.1
                assert abs(body.axis()[2]) < 0.01
                assert body.velocity()[1][0] < -1.0  # turning about its axis: rolling to +y
            else:
                assert abs(travelled) < 0.0005 and turned < 0.01
            assert body.pose().position[2] == pytest.approx(0.5 * part.outer, abs=0.001)


@pytest.mark.parametrize("name", ["bushing", "medicine_bottle", "cookie_can", "plastic_cup"])
def test_a_round_part_left_lying_on_a_level_floor_comes_to_rest(name: str) -> None:
    # Real round parts left lying on a level floor stay put. The twin lays them on an edge of the
    # polygon, balanced, and the solver's jitter tips a can or the cup off it; with the floor's
    # rolling resistance (FLOOR_ROLLING) it settles on a flat within a few mm (with the part's
    # share alone the roll grew instead and took the cup 14-137 mm away).
    part = CATALOGUE.get(name)
    with SimWorld(seed=1) as world:
        _floor(world, friction=0.35)
        start = _lifted(lying_pose(part, 0.0, 0.0, -0.04), 0.0005)
        body = spawn_part(world, part, start)
        for _ in range(1875):  # 15 s
            world.step()
        settled = body.pose().position.copy()
        for _ in range(625):  # 5 s more
            world.step()
        moved = np.linalg.norm(body.pose().position[:2] - start.position[:2])
        still = np.linalg.norm(body.pose().position[:2] - settled[:2])
        turned = math.acos(float(np.clip(body.pose().rotation[2, 2], -1.0, 1.0)))
        assert moved < 0.005 and turned < math.radians(10.0)  # a few of the 144 flats
        assert still < 0.0005


def _probe(world: SimWorld, width: float, thickness: float = 0.008, length: float = 0.03) -> int:
    """A static (kinematic) finger-like box, moved only by the test; the part is never moved."""
    p = world.p
    half = [0.5 * length, 0.5 * width, 0.5 * thickness]
    shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=half)
    return p.createMultiBody(0.0, shape, basePosition=[0.0, 0.0, 1.0])


def _contacts_along_axis(world: SimWorld, body, probe: int, roll: float) -> list[float]:
    """Signed distances (m) <= 0 met while the probe slides along the axis through the hole."""
    p = world.p
    part_pose = body.pose()
    half = 0.5 * body.part.length
    hits = []
    for x in np.arange(-half - 0.02, half + 0.02, 0.002):
        probe_pose = part_pose @ Pose(np.array([x, 0.0, 0.0]), rot_x(roll))
        p.resetBasePositionAndOrientation(probe, probe_pose.position, probe_pose.quaternion)
        hits += [c[8] for c in p.getClosestPoints(probe, body.body_id, distance=0.0)]
    return hits


@pytest.mark.parametrize("roll", [0.0, 0.13, math.pi / 4, math.pi / 2])
def test_a_20_mm_finger_slides_through_the_bushing_hole_and_30_mm_does_not(roll: float) -> None:
    part = CATALOGUE.get("bushing")  # hole 28 mm
    with SimWorld() as world:
        body = spawn_part(world, part, Pose(np.array([0.0, 0.0, 0.5]), rot_x(0.3)))
        assert _contacts_along_axis(world, body, _probe(world, 0.020), roll) == []
        assert len(_contacts_along_axis(world, body, _probe(world, 0.030), roll)) > 0


def test_a_finger_slides_through_the_rectangular_duct() -> None:
    part = CATALOGUE.get("wiring_duct")  # 57 mm square hole
    with SimWorld() as world:
        body = spawn_part(world, part, lying_pose(part, 0.0, 0.0, 0.4, floor_z=0.3))
        assert _contacts_along_axis(world, body, _probe(world, 0.050), 0.0) == []
        assert len(_contacts_along_axis(world, body, _probe(world, 0.060), 0.0)) > 0


def test_the_outer_envelope_is_the_outer_diameter() -> None:
    part = CATALOGUE.get("bushing")
    with SimWorld() as world:
        body = spawn_part(world, part, Pose(np.array([0.0, 0.0, 0.5])))
        p = world.p
        # A plate 0.5 mm below the envelope's flat face does not touch it; 0.5 mm inside does.
        for gap, touching in ((0.0005, False), (-0.0005, True)):
            shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.05, 0.05, 0.001])
            z = 0.5 - 0.5 * part.outer - 0.001 - gap
            plate = p.createMultiBody(0.0, shape, basePosition=[0.0, 0.0, z])
            assert bool(p.getClosestPoints(plate, body.body_id, distance=0.0)) is touching
            p.removeBody(plate)


@pytest.mark.parametrize("name", ["bushing", "medicine_bottle", "wiring_duct"])
def test_mass_and_inertia_are_the_thick_walled_tube(name: str) -> None:
    part = CATALOGUE.get(name)
    with SimWorld() as world:
        pose = Pose(np.array([0.2, 0.1, 0.3]), rot_x(0.4))
        body = spawn_part(world, part, pose)
        info = world.p.getDynamicsInfo(body.body_id, -1)
        expected = mass_properties(part)
        assert info[0] == pytest.approx(part.mass)
        assert np.allclose(info[2], expected.inertia, rtol=1e-9)
        assert np.allclose(info[3], expected.com, atol=1e-12)
        # The part frame is reported, not the centre of mass.
        dp, dr = body.pose().distance(pose)
        assert dp < 1e-9 and dr < 1e-9
    if name == "bushing":  # a tube: centred, I_x = m (R^2 + r^2) / 2
        r_out, r_in = 0.5 * part.outer, 0.5 * part.hole
        assert expected.com == pytest.approx([0.0, 0.0, 0.0])
        assert expected.inertia[0] == pytest.approx(0.5 * part.mass * (r_out**2 + r_in**2))
        assert expected.inertia[1] == pytest.approx(
            part.mass * (3 * (r_out**2 + r_in**2) + part.length**2) / 12
        )
    if name == "medicine_bottle":  # the bottom pulls the centre of mass to the closed (-x) end
        assert -0.5 * part.length < expected.com[0] < 0.0


def test_a_cup_stands_on_its_closed_end() -> None:
    part = CATALOGUE.get("plastic_cup")
    with SimWorld() as world:
        _floor(world)
        body = spawn_part(world, part, _lifted(upright_pose(part, 0.0, 0.0), 0.001))
        for _ in range(60):
            world.step()
        assert body.axis()[2] > math.cos(math.radians(1.0))
        assert body.lowest_z() == pytest.approx(0.0, abs=0.001)
        assert body.open_end_center()[2] == pytest.approx(part.length, abs=0.001)


def test_child_shape_count_is_within_pybullets_16() -> None:
    for part in CATALOGUE.parts.values():
        with SimWorld() as world:
            body = spawn_part(world, part, Pose(np.array([0.0, 0.0, 0.5])))
            n = len(world.p.getCollisionShapeData(body.body_id, -1))
            assert n == (12 if part.hole_shape == "circle" else 4) + (part.open_ends == 1)
    assert hull_vertices(CATALOGUE.get("bushing")).shape == (2 * 12 * ARC_SEGMENTS, 3)
    with SimWorld() as world, pytest.raises(ValueError, match="staves"):
        spawn_part(world, CATALOGUE.get("bushing"), Pose(), staves=16)
