"""The cell's uncertainty in a trial (sim/uncertainty.py): drawn from the trial's seed, off with
``--ideal``, and each error put into the twin where the real one arises -- the camera's mount,
the floor, the part's body, the FT300's stream, the arm's command lag."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from cell.catalogue import load_catalogue
from drivers.layout import CellLayout
from drivers.parts import Gripper
from drivers.pose import Pose
from drivers.ur5.kinematics import HOME_TCP, rotvec_to_matrix
from lab.pivot_cmd import build_setup, pivot_args
from lab.pivot_run import TrialSetup, open_trial_world
from sim.camera import SimCamera
from sim.cell_layout import build_cell
from sim.part_body import lying_pose, spawn_part
from sim.robot import SimRobot
from sim.scenes import look_down_pose
from sim.uncertainty import Draws, Uncertainty
from sim.world import SimWorld
from skills.mechanics.planner import plan_pivot
from skills.perception.bin_parts import detect_parts

BUSHING = load_catalogue().get("bushing")
#: the draws that are errors of a real cell; --ideal makes every one of them 0
ERRORS = (
    "hand_eye_x_mm", "hand_eye_y_mm", "hand_eye_z_mm", "hand_eye_rx_deg", "hand_eye_ry_deg",
    "hand_eye_rz_deg", "floor_dz_mm", "outer_dmm", "hole_dmm", "length_dmm", "lag_steps",
    "lag_ms", "ft_force_resolution_n", "ft_torque_resolution_nm",
)


@pytest.fixture(scope="module")
def setup() -> TrialSetup:
    return TrialSetup(part=BUSHING, plan=plan_pivot(BUSHING, Gripper()))


# --- the draws ------------------------------------------------------------------------------


def test_draws_are_the_seeds_and_plain_json() -> None:
    model = Uncertainty()
    a = model.draw(np.random.default_rng(42)).to_json()
    assert a == model.draw(np.random.default_rng(42)).to_json()
    assert a != model.draw(np.random.default_rng(43)).to_json()
    assert all(type(v) is float for v in a.values())
    assert json.loads(json.dumps(a)) == a
    # every error is drawn, within its range
    assert all(a[k] != 0.0 for k in ERRORS[:10])
    assert max(abs(a[k]) for k in ("hand_eye_x_mm", "hand_eye_y_mm", "hand_eye_z_mm")) <= 1.0
    assert max(abs(a[k]) for k in ("hand_eye_rx_deg", "hand_eye_ry_deg", "hand_eye_rz_deg")) <= 0.5
    assert abs(a["floor_dz_mm"]) <= 1.5
    assert a["lag_steps"] in (1.0, 2.0, 3.0) and a["lag_ms"] == pytest.approx(8.0 * a["lag_steps"])
    assert a["ft_rate_hz"] == 100.0


def test_the_ranges_are_covered_over_many_seeds() -> None:
    draws = [Uncertainty().draw(np.random.default_rng(s)) for s in range(400)]
    floors = [d.floor_dz_m for d in draws]
    assert min(floors) < -0.0013 and max(floors) > 0.0013
    assert {d.lag_steps for d in draws} == {1, 2, 3}
    mu_s = [d.mu_s for d in draws]
    assert min(mu_s) < 0.25 and max(mu_s) > 0.95
    mu_g = [d.mu_g for d in draws]
    assert 0.25 <= min(mu_g) < 0.3 and 0.55 < max(mu_g) <= 0.6


def test_ideal_draws_no_error_and_the_pose_as_before() -> None:
    for seed in range(20):
        d = Uncertainty.ideal().draw(np.random.default_rng(seed)).to_json()
        assert all(d[k] == 0.0 for k in ERRORS), d
        assert d["ft_rate_hz"] == 0.0  # a sample every control step, as the twin had
        assert (d["ft_force_noise_n"], d["ft_torque_noise_nm"]) == (0.1, 0.003)
        # The generator is used as before the model: frictions +-20 %, mass +-10 %, nothing
        # else, so the pose drawn next is the old one.
        old = np.random.default_rng(seed)
        mu = [v * (1.0 + old.uniform(-0.2, 0.2)) for v in (0.2, 0.4, 0.4)]
        assert [d["mu_s"], d["mu_h"], d["mu_g"]] == mu
        assert d["mass_scale"] == 1.0 + old.uniform(-0.1, 0.1)
    assert Uncertainty.ideal().is_ideal and not Uncertainty().is_ideal


def test_ideal_flag_reaches_the_setup() -> None:
    default = build_setup(pivot_args("bushing", 1, None, None, nominal=True))[0]
    ideal = build_setup(pivot_args("bushing", 1, None, None, nominal=True, ideal=True))[0]
    assert not default.uncertainty.is_ideal and default.uncertainty == Uncertainty()
    assert ideal.uncertainty.is_ideal


# --- in the twin ----------------------------------------------------------------------------


def test_a_trial_world_is_built_from_its_draws(setup: TrialSetup) -> None:
    tw = open_trial_world(setup, 7)
    try:
        d = tw.draws
        assert isinstance(d, Draws) and not d.ideal
        p = tw.world.p
        # the floor's top where the draw puts it, and the part lying on it
        top = p.getAABB(tw.cell.floor)[1][2]
        assert top == pytest.approx(d.floor_dz_m, abs=1e-9)
        assert tw.body.lowest_z() == pytest.approx(d.floor_dz_m, abs=0.0008)
        # the body is the part off by its tolerances and mass, not the catalogue's
        assert tw.body.part.outer == BUSHING.outer + d.outer_dm
        assert tw.body.part.hole == BUSHING.hole + d.hole_dm
        assert tw.body.part.length == BUSHING.length + d.length_dm
        assert p.getDynamicsInfo(tw.body.body_id, -1)[0] == pytest.approx(
            BUSHING.mass * d.mass_scale
        )
        # the camera is where the draw puts it; it reports the calibrated mount
        camera = tw.dev.camera
        assert isinstance(camera, SimCamera)
        calibrated = setup.layout.tool_T_camera()
        assert camera.tool_T_camera().distance(calibrated) == (0.0, 0.0)
        dp, dr = camera.true_tool_T_camera().distance(calibrated @ d.mount_error())
        assert dp < 1e-12 and dr < 1e-12
        assert tw.robot.arm.command_lag == d.lag_steps
        assert tw.frictions == {"S": d.mu_s, "H": d.mu_h, "G": d.mu_g}
        again = _drawn(setup, 7)
        assert again[0] == d and again[1] == tw.true_pose  # the seed's trial, again
        assert _drawn(setup, 8)[0] != d
    finally:
        tw.world.close()


def _drawn(setup: TrialSetup, seed: int) -> tuple[Draws | None, dict[str, float]]:
    """A trial world's draws and the part's true pose (the world closed at once)."""
    tw = open_trial_world(setup, seed)
    tw.world.close()
    return tw.draws, tw.true_pose


def _perceived_center(mount_error: Pose | None) -> tuple[np.ndarray, np.ndarray, Pose, Pose]:
    """The bushing lying in the bin seen from 0.5 m with the calibrated mount: where the
    perception puts its centre, where it is, the tool pose and the calibrated mount."""
    layout = CellLayout()
    mount = layout.tool_T_camera()
    with SimWorld(seed=5) as world:
        build_cell(world, layout)
        x, y = layout.bin_center[0], layout.bin_center[1]
        body = spawn_part(world, BUSHING, lying_pose(BUSHING, x, y, 0.3))
        for _ in range(40):
            world.step()
        tool = look_down_pose((x, y), 0.5, mount)
        camera = SimCamera(world, lambda: tool, mount, noise=None, mount_error=mount_error)
        frame = camera.capture()
        # the perception computes with the calibrated mount, as a real cell does
        found = detect_parts(
            frame, camera.intrinsics(), tool @ camera.tool_T_camera(), [BUSHING],
            layout.bin_interior(),
        )
        assert len(found) == 1
        return np.asarray(found[0].center, float), body.pose().position.copy(), tool, mount


def test_the_hand_eye_error_moves_the_perceived_pose() -> None:
    error = Pose(np.array([0.001, 0.0, 0.0]), rotvec_to_matrix([math.radians(0.5), 0.0, 0.0]))
    seen, true, tool, mount = _perceived_center(None)
    assert np.linalg.norm(seen[:2] - true[:2]) < 0.0015  # without the error: where it lies
    seen_off, true_off, _, _ = _perceived_center(error)
    assert np.allclose(true_off, true)
    moved = seen_off[:2] - seen[:2]
    # The camera really sits at mount @ error: a point X is seen where the calibrated mount
    # puts what the true camera sees, tool @ mount @ error^-1 @ mount^-1 @ tool^-1 @ X.
    shift = tool @ mount @ error.inverse() @ mount.inverse() @ tool.inverse()
    predicted = shift.transform(true)[:2] - true[:2]
    assert np.linalg.norm(predicted) > 0.004  # 0.5 deg at 0.5 m, and the 1 mm
    assert np.linalg.norm(moved) > 0.003
    assert np.linalg.norm(moved - predicted) < 0.0015


def _changes(readings: list[np.ndarray]) -> int:
    """How many times the reading changed from one control step to the next."""
    return sum(not np.array_equal(a, b) for a, b in zip(readings[:-1], readings[1:], strict=True))


def test_the_ft_sensor_streams_at_100_hz_in_counts() -> None:
    with SimWorld(seed=2) as world:
        robot = SimRobot(world)
        ft = robot.ft
        readings = []
        for _ in range(125):  # 1 s as built: a sample every control step
            world.step()
            readings.append(ft.wrench().copy())
        changes = _changes(readings)
        assert changes == 124
        ft.configure(100.0, 0.1, 0.005, 0.01, 0.001)
        readings, ages = [], []
        for _ in range(250):  # 2 s at 100 Hz, held between samples
            world.step()
            readings.append(ft.wrench().copy())
            ages.append(ft.age())
        changes = _changes(readings)
        assert changes == pytest.approx(200, abs=1)
        assert max(ages) == pytest.approx(0.008, abs=1e-9)  # held one control step at most
        counts = np.asarray(readings) / np.array([0.01] * 3 + [0.001] * 3)
        assert np.allclose(counts, np.round(counts), atol=1e-6)  # the stream's resolution


def _joint_trace(lag: int) -> np.ndarray:
    """Joint angles every control step after a 5 cm move is commanded from rest."""
    with SimWorld(seed=4) as world:
        robot = SimRobot(world)
        robot.arm.set_command_lag(lag)
        for _ in range(60):  # come to rest
            world.step()
        goal = Pose(HOME_TCP.position + np.array([0.05, 0.0, 0.0]), HOME_TCP.rotation)
        robot.arm.move_to(goal, 0.2, 2.0)
        trace = []
        for _ in range(60):
            world.step()
            trace.append(robot.arm.joint_positions())
        return np.asarray(trace)


@pytest.mark.parametrize("lag", [1, 3])
def test_the_arm_lag_delays_the_motion_by_the_drawn_steps(lag: int) -> None:
    now, late = _joint_trace(0), _joint_trace(lag)
    assert np.max(np.abs(now[-1] - now[0])) > 0.01  # it moved

    def off(shift: int) -> float:
        return float(np.max(np.abs(late[shift:] - now[: len(now) - shift])))

    # the lagged arm does what the prompt one did, ``lag`` control steps later ...
    assert off(lag) < 1e-6
    # ... and not one step sooner or later
    assert off(lag - 1) > 1e-4 and off(lag + 1) > 1e-4


def test_ideal_trial_world_has_no_error(setup: TrialSetup) -> None:
    ideal = dataclasses.replace(setup, uncertainty=Uncertainty.ideal())
    tw = open_trial_world(ideal, 7)
    try:
        d = tw.draws
        assert d is not None and d.ideal
        assert all(v == 0.0 for k, v in d.to_json().items() if k in ERRORS)
        assert tw.world.p.getAABB(tw.cell.floor)[1][2] == pytest.approx(0.0, abs=1e-12)
        assert tw.body.part == dataclasses.replace(BUSHING, mass=BUSHING.mass * d.mass_scale)
        assert tw.robot.arm.command_lag == 0
        # the uncertainty comes from a child generator: the seed's pose is the same either way
        assert tw.true_pose == _drawn(setup, 7)[1]
    finally:
        tw.world.close()
