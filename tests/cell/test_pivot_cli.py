"""``cell pivot``: the contract form, its JSON, and bad input (exit 2, one line, no motion)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

import lab.pivot_run
from cell.cli import main


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def no_simulation(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Fail the test if a trial is started: bad input must be refused before any motion."""
    started: list[int] = []

    def trap(*args, **kwargs):
        started.append(1)
        raise AssertionError("a trial was simulated")

    monkeypatch.setattr(lab.pivot_run, "run_trial", trap)
    return started


def test_contract_form_writes_the_summary(tmp_path: Path, capsys) -> None:
    out_json = tmp_path / "r.json"
    code, out, err = run_cli(
        ["pivot", "--part", "bushing", "--trials", "1", "--seed", "11", "--json", str(out_json)],
        capsys,
    )
    assert code == 0, err
    data = json.loads(out_json.read_text())
    assert data["part"] == "bushing" and data["trials"] == 1
    trial = data["per_trial"][0]
    # the form, whatever the one trial's outcome (a success rate is measured, not tested here)
    assert data["successes"] == int(trial["success"])
    assert (trial["failure"] is None) == trial["success"]
    lo, hi = data["wilson95"]
    assert 0.0 <= lo < hi <= 1.0
    assert {"seed", "tilt_deg", "height_m", "true_pose", "frictions", "mass"} <= set(trial)
    assert data["plan"]["l_a"] == pytest.approx(0.9)
    assert data["gripper"] == "robotiq_2f85" and data["ideal"] is False
    assert data["pose_source"] == "camera"
    assert set(trial["peak_force_n"]) == {"grasp", "tilt", "align", "lift"}
    assert trial["peak_force_n"]["grasp"] > 20.0  # S pressed as the 20 N pinch needs
    assert {"shove_mm", "grip_force_n", "draws"} <= set(trial)
    assert f"{data['successes']}/1" in out and "Wilson" in out
    assert "1/1" in err  # the progress bar


def test_mu_ground_is_used_exactly(tmp_path: Path, capsys, monkeypatch) -> None:
    seen = []
    real = lab.pivot_run.run_trial

    def spy(setup, seed, **kw):
        seen.append(setup.mu_ground)
        return real(setup, seed, **kw)

    monkeypatch.setattr(lab.pivot_run, "run_trial", spy)
    out_json = tmp_path / "r.json"
    args = ["pivot", "--part", "bushing", "--trials", "1", "--seed", "11", "--mu-ground", "0.7"]
    code, _, err = run_cli([*args, "--json", str(out_json)], capsys)
    assert code == 0, err
    assert seen == [0.7]
    assert json.loads(out_json.read_text())["per_trial"][0]["frictions"]["G"] == 0.7


def test_mu_pad_is_used_exactly_at_s_and_h(tmp_path: Path, capsys) -> None:
    out_json = tmp_path / "r.json"
    args = ["pivot", "--part", "bushing", "--trials", "1", "--seed", "11", "--mu-pad", "0.3"]
    code, _, err = run_cli([*args, "--json", str(out_json)], capsys)
    assert code == 0, err
    report = json.loads(out_json.read_text())
    assert report["mu_pad"] == 0.3
    trial = report["per_trial"][0]
    assert trial["frictions"]["S"] == trial["frictions"]["H"] == 0.3
    assert trial["draws"]["mu_s"] == trial["draws"]["mu_h"] == 0.3


@pytest.mark.parametrize(
    ("part", "words"),
    [
        ("no_such_part", ["unknown part 'no_such_part'", "parts.yaml"]),
        ("mounting_rail", ["parts.mounting_rail", "hole narrower than the finger"]),
        ("water_bottle", ["parts.water_bottle", "deformable"]),
    ],
)
def test_parts_that_cannot_be_pivoted_are_refused(
    part: str, words: list[str], tmp_path: Path, capsys, no_simulation
) -> None:
    code, out, err = run_cli(
        ["pivot", "--part", part, "--trials", "2", "--seed", "0", "--json", str(tmp_path / "r")],
        capsys,
    )
    assert code == 2
    assert all(w in err for w in words), err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "r").exists()


def test_forcing_the_rail_is_still_refused_its_finger_cannot_enter(
    tmp_path: Path, capsys, no_simulation
) -> None:
    code, _, err = run_cli(
        ["pivot", "--part", "mounting_rail", "--force", "--json", str(tmp_path / "r")], capsys
    )
    assert code == 2 and "hole_mm" in err and "not even with --force" in err


def _cell(tmp_path: Path, data: dict) -> Path:
    path = tmp_path / "cell.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.parametrize(
    ("layout", "words"),
    [
        ({"bin_center": [0.10, 0.40]}, ["bin_center", "overlaps machine"]),
        (
            {"floor_size": [3.0, 3.0], "bin_center": [1.2, 0.0]},
            ["bin_center", "out of the UR5's reach"],
        ),
        ({"bin_inner_size": [0.12, 0.3]}, ["bin_center", "outside the bin"]),
        ({"bin_wall_height": "high"}, ["bin_wall_height", "expected a finite number"]),
        ({"no_such_key": 1}, ["no_such_key", "unknown key"]),
    ],
)
def test_bad_cell_yaml_is_refused_naming_file_and_key(
    layout: dict, words: list[str], tmp_path: Path, capsys, no_simulation
) -> None:
    path = _cell(tmp_path, layout)
    code, _, err = run_cli(
        ["pivot", "--part", "bushing", "--cell", str(path), "--json", str(tmp_path / "r")], capsys
    )
    assert code == 2, err
    assert str(path) in err and all(w in err for w in words), err


@pytest.mark.parametrize(
    ("extra", "word"),
    [
        (["--trials", "0"], "--trials"),
        (["--mu-ground", "-1"], "--mu-ground"),
        (["--mu-pad", "nan"], "--mu-pad"),
        (["--record", "x.mp4"], "--record"),
        (["--la", "0.5"], "--la/--alpha"),
    ],
)
def test_bad_options_are_refused(extra, word, tmp_path: Path, capsys, no_simulation) -> None:
    code, _, err = run_cli(
        ["pivot", "--part", "bushing", *extra, "--json", str(tmp_path / "r")], capsys
    )
    assert code == 2 and word in err, err


# --- --config and --set: the whole configuration reaches the trials --------------------------
def _fake_result(setup, seed: int):
    """A trial's result without simulating it (what the command does with the setup is tested,
    not the physics)."""
    from lab.pivot_run import TrialResult

    return TrialResult(
        seed=seed, success=True, failure=None, phase="done", tilt_deg=0.0, height_m=0.05,
        sim_time=1.0, wall_time=0.1, true_pose={"x": 0.0, "y": 0.0, "yaw": 0.0},
        frictions={"S": 0.2, "H": 0.4, "G": setup.mu_ground or 0.4}, mass=0.05,
    )


@pytest.fixture
def setups(monkeypatch: pytest.MonkeyPatch) -> list:
    """The setups the trials get; no trial is simulated."""
    seen: list = []

    def spy(setup, seed, **kw):
        seen.append(setup)
        return _fake_result(setup, seed)

    monkeypatch.setattr(lab.pivot_run, "run_trial", spy)
    return seen


def test_set_reaches_the_trials_pivot_params(tmp_path: Path, capsys, setups) -> None:
    from skills.pivot import PivotParams

    out_json = tmp_path / "r.json"
    argv = ["pivot", "--part", "bushing", "--trials", "1", "--json", str(out_json)]
    code, _, err = run_cli([*argv, "--set", "skills.pivot.approach_speed_m_s=0.07"], capsys)
    assert code == 0, err
    params = PivotParams(l_a=0.9, alpha=0.3, **setups[0].params)
    assert params.approach_speed == 0.07
    assert PivotParams(l_a=0.9, alpha=0.3).approach_speed != 0.07  # the test can fail
    # On top of a file: the --set wins over the file's value, the file's other keys stay.
    path = _cell(tmp_path, {"skills": {"pivot": {"approach_speed_m_s": 0.1,
                                                 "tilt_speed_m_s": 0.015}}})
    code, _, err = run_cli(
        [*argv, "--config", str(path), "--set", "skills.pivot.approach_speed_m_s=0.07",
         "--set", "safety.ft_abort_force_n=60"],
        capsys,
    )
    assert code == 0, err
    over = setups[1].params
    assert over["approach_speed"] == 0.07 and over["tilt_speed"] == 0.015
    assert over["guard"].max_force == 60.0


@pytest.mark.parametrize(
    ("sets", "words"),
    [
        (["skills.pivot.no_such_key=1"], ["--set skills.pivot.no_such_key=1",
                                          "skills.pivot.no_such_key: unknown key"]),
        (["skills.pivot.approach_speed_m_s=fast"], ["skills.pivot.approach_speed_m_s",
                                                    "expected a number"]),
        (["sim.mu_ground=-1"], ["sim.mu_ground", "greater than 0"]),
        (["cell.layout.bin_wall_height=high"], ["cell.layout.bin_wall_height"]),
        (["safety"], ["--set safety", "expected KEY.PATH=VALUE"]),
    ],
)
def test_a_bad_set_exits_2_in_one_line_and_writes_nothing(
    sets: list[str], words: list[str], tmp_path: Path, capsys, no_simulation
) -> None:
    out_json = tmp_path / "r.json"
    argv = ["pivot", "--part", "bushing", "--json", str(out_json)]
    code, out, err = run_cli([*argv, *(a for s in sets for a in ("--set", s))], capsys)
    assert code == 2
    assert err.startswith("cell pivot: error: ") and all(w in err for w in words), err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not out_json.exists() and not no_simulation


def test_config_applies_mu_ground_and_the_sections_a_trial_uses(
    tmp_path: Path, capsys, monkeypatch
) -> None:
    """sim.mu_ground reaches the simulated floor; skills.perceive, skills.reposition, the safety
    limits, cell.control_hz and cell.layout reach the trial's setup."""
    seen = []
    real = lab.pivot_run.run_trial

    def spy(setup, seed, **kw):
        seen.append(setup)
        return real(setup, seed, **kw)

    monkeypatch.setattr(lab.pivot_run, "run_trial", spy)
    path = _cell(
        tmp_path,
        {
            "cell": {"control_hz": 100, "layout": {"bin_inner_size": [0.50, 0.44]}},
            "sim": {"mu_ground": 0.55},
            "safety": {"ft_abort_force_n": 70},
            "skills": {"perceive": {"speed_m_s": 0.4},
                       "reposition": {"drag_speed_m_s": 0.05}},
            "workflow": {"cycles": 3},  # no meaning for a trial: accepted, not used
        },
    )
    out_json = tmp_path / "r.json"
    argv = ["pivot", "--part", "bushing", "--trials", "1", "--seed", "11", "--nominal"]
    code, _, err = run_cli([*argv, "--config", str(path), "--json", str(out_json)], capsys)
    assert code == 0, err
    setup = seen[0]
    assert setup.mu_ground == 0.55
    assert setup.look.speed == 0.4 and setup.look.guard.max_force == 70.0
    assert setup.reposition.drag_speed == 0.05
    assert setup.params["guard"].max_force == 70.0
    assert tuple(setup.layout.bin_inner_size) == (0.50, 0.44)
    assert setup.physics.control_hz == 100.0 and setup.physics.physics_dt <= 1 / 250 + 1e-12
    data = json.loads(out_json.read_text())
    assert data["per_trial"][0]["frictions"]["G"] == 0.55  # the simulated floor's friction
    assert data["mu_ground"] == 0.55 and data["physics"]["control_hz"] == 100.0
    # --mu-ground on the command line wins over the file.
    code, _, err = run_cli(
        [*argv, "--config", str(path), "--mu-ground", "0.3", "--json", str(out_json)], capsys
    )
    assert code == 0, err
    assert seen[1].mu_ground == 0.3


def test_a_config_without_mu_ground_keeps_the_perturbed_floor(
    tmp_path: Path, capsys, setups
) -> None:
    path = _cell(tmp_path, {"skills": {"pivot": {"tilt_speed_m_s": 0.015}}})
    argv = ["pivot", "--part", "bushing", "--trials", "1", "--json", str(tmp_path / "r.json")]
    code, _, err = run_cli([*argv, "--config", str(path)], capsys)
    assert code == 0, err
    assert setups[0].mu_ground is None and setups[0].physics.control_hz == 125.0


def test_per_trial_forces_and_shove_from_the_simulated_state(tmp_path: Path, capsys) -> None:
    """grip_force_n, peak_force_n, shove_mm and hook_depth_mm on one trial: measured,
    present, physical."""
    from skills.pivot import PivotParams

    out_json = tmp_path / "r.json"
    argv = ["pivot", "--part", "bushing", "--trials", "1", "--seed", "5"]
    code, _, err = run_cli([*argv, "--json", str(out_json)], capsys)
    assert code == 0, err
    data = json.loads(out_json.read_text())
    assert data["pose_source"] == "camera"
    trial = data["per_trial"][0]
    reached = {ph for ph, t in trial["phase_times_s"].items() if t > 0}
    assert {"grasp", "tilt"} <= reached, trial["failure"]
    peaks = trial["peak_force_n"]
    assert set(peaks) == {"grasp", "tilt", "align", "lift"}
    for phase, peak in peaks.items():
        assert (peak is None) == (phase not in reached), (phase, peak)
    defaults = PivotParams(l_a=0.9, alpha=0.3)
    # The Grasp felt S with touch_force and pressed it: the wrist saw at least that, and no
    # more than a multiple of the guard's limit.
    assert defaults.touch_force <= peaks["grasp"] < 2 * defaults.guard.max_force
    # The motors' force is capped by the commanded grip: between nothing and that.
    assert 0.5 < trial["grip_force_n"] <= defaults.grip_force + 0.5
    # The close moved the part a little (never centimetres), and it was measured.
    assert isinstance(trial["shove_mm"], float) and 0.0 <= trial["shove_mm"] < 10.0
    # A successful hole grasp has the inner pad's tip past the open end's face, within the
    # finger's reach (the judge's first sample after the close).
    if trial["success"]:
        assert 0.0 < trial["hook_depth_mm"] < 20.0


def test_a_configured_gripper_description_is_the_one_the_trials_run(tmp_path: Path, capsys) -> None:
    out_json = tmp_path / "r.json"
    args = ["pivot", "--part", "bushing", "--trials", "1", "--seed", "11", "--set",
            "gripper=gentle_wire", "--set", "skills.pivot.grip_force_n=2", "--json", str(out_json)]
    code, _, err = run_cli(args, capsys)
    assert code == 0, err
    data = json.loads(out_json.read_text())
    assert data["gripper"] == "gentle_wire"
    # the twin's fingers are that gripper's: the Tilt's grip stays within the 2 N it can apply
    # (a 2F-85 applies 20 N at least; its Tilt's median grip is 7-10 N)
    grip = data["per_trial"][0]["grip_force_n"]
    assert grip is not None and grip <= 2.0 + 0.5, grip
    # the 2F-85 refuses the same grip at load, before any trial
    args = ["pivot", "--part", "bushing", "--trials", "1", "--set",
            "skills.pivot.grip_force_n=2", "--json", str(tmp_path / "s.json")]
    code, _, err = run_cli(args, capsys)
    assert code == 2 and "20..235 N" in err and not (tmp_path / "s.json").exists()
