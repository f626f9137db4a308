"""The YAML task configuration and trees from YAML: accepted, and refused with file/line/key."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from cell.assemble import prepare
from cell.config import config_from_text, default_config_path, load_config, schema
from tests.addresses import quiet_host
from trees.registry import REGISTRY
from trees.yaml_lines import ConfigError


def _prepare(text: str, tmp_path: Path):
    path = tmp_path / "cell.yaml"
    path.write_text(text, encoding="utf-8")
    config, doc = load_config(path)
    return prepare(config, doc)


def _error(text: str, tmp_path: Path) -> ConfigError:
    with pytest.raises(ConfigError) as info:
        _prepare(text, tmp_path)
    return info.value


def test_the_shipped_example_validates_and_builds_its_tree() -> None:
    config, doc = load_config(default_config_path())
    prep = prepare(config, doc)
    assert config.cell.backend == "sim" and config.workflow.part == "bushing"
    names = [n.name for n in prep.root.iterate()]
    for leaf in (
        "perceive",
        "plan pick",
        "grasp",
        "tilt",
        "align",
        "feed slot",
        "wait machining",
        "pick from slot",
        "pack in box",
        "go home",
        "put back",
    ):
        assert leaf in names
    # Every motion leaf sits under a timeout under an FT guard.
    assert "grasp timeout" in names and "grasp ft guard" in names
    assert len(prep.geometry.tray_places) >= 10


@pytest.mark.parametrize(
    ("text", "line", "key", "words"),
    [
        ("workflow:\n  cycles: 0\n", 2, "workflow.cycles", "greater than or equal to 1"),
        ("workflow:\n  cyclez: 3\n", 2, "workflow.cyclez", "unknown key; valid keys: part"),
        ("safety:\n  ft_abort_force_n: 5000\n", 2, "safety.ft_abort_force_n", "less than"),
        (
            "workflow:\n  machining_time_s: '5 s'\n",
            2,
            "workflow.machining_time_s",
            "expected a number, got the text '5 s'",
        ),
        ("cell:\n  backend: robot\n", 2, "cell.backend", "'sim' or 'hw'"),
        ("bin:\n  parts: true\n", 2, "bin.parts", "integer"),
        ("\n\nworkflow:\n  part: teapot\n", 4, "workflow.part", "unknown part 'teapot'"),
        ("workflow:\n  part: mounting_rail\n", 2, "workflow.part", "not pivotable"),
        ("cell:\n  layout:\n    bin_center: [0.0, 0.0]\n", 3, "cell.layout.bin_center", "robot"),
        ("cell:\n  layout:\n    tray_center: [0.1, -0.95]\n", 3, "cell.layout.tray_center", ""),
        (
            "devices:\n  arm:\n    home_joints_deg: [0, 0, 0, 0, 0, 999]\n",
            3,
            "devices.arm.home_joints_deg",
            "outside the UR5",
        ),
        (
            "devices:\n  camera:\n    stream: localhost\n",
            3,
            "devices.camera.stream",
            "not host:port",
        ),
    ],
)
def test_bad_values_name_file_line_and_key(tmp_path, text, line, key, words) -> None:
    err = _error(text, tmp_path)
    assert err.source.endswith("cell.yaml")
    assert err.line == line, str(err)
    assert err.key == key, str(err)
    assert words in str(err)


def test_broken_yaml_and_duplicate_keys_are_refused_with_their_line(tmp_path) -> None:
    err = _error("workflow:\n  cycles: [1, 2\n", tmp_path)
    assert "not valid YAML" in str(err) and err.line is not None
    err = _error("workflow:\n  cycles: 1\n  cycles: 2\n", tmp_path)
    assert "duplicate key 'cycles'" in str(err) and err.line == 3


TREE = """\
tree:
  type: sequence
  children:
    - {type: perceive, timeout_s: 10}
    - {type: grasp}
"""


def test_an_inline_tree_builds_with_guards_from_the_safety_defaults(tmp_path) -> None:
    prep = _prepare(TREE + "safety:\n  ft_abort_force_n: 42\n", tmp_path)
    guards = [n for n in prep.root.iterate() if n.name.endswith("ft guard")]
    assert [g.max_force for g in guards] == [42.0, 42.0]
    timeouts = {n.name: n.seconds for n in prep.root.iterate() if n.name.endswith("timeout")}
    assert timeouts == {"perceive timeout": 10.0, "grasp timeout": 30.0}


@pytest.mark.parametrize(
    ("tree", "line", "key", "words"),
    [
        (
            "    - {type: grasp2}\n",
            6,
            "tree.children[2].type",
            "unknown behaviour type 'grasp2'; valid types: sequence",
        ),
        (
            "    - {type: grasp, speed: 3}\n",
            6,
            "tree.children[2].speed",
            "unknown parameter of 'grasp'; valid: name, timeout_s",
        ),
        (
            "    - {type: retry, child: {type: grasp}}\n",
            6,
            "tree.children[2]",
            "'retry' needs 'attempts'",
        ),
        (
            "    - {type: retry, attempts: 0, child: {type: grasp}}\n",
            6,
            "tree.children[2].attempts",
            "must lie in [1, 100]",
        ),
        (
            "    - {type: grasp, timeout_s: '10 s'}\n",
            6,
            "tree.children[2].timeout_s",
            "unit is in the key's name",
        ),
        (
            "    - {type: sequence, children: []}\n",
            6,
            "tree.children[2].children",
            "non-empty list",
        ),
        ("    - {type: timeout, seconds: 3}\n", 6, "tree.children[2]", "needs a 'child'"),
        ("    - grasp\n", 6, "tree.children[2]", "a node must be a mapping"),
    ],
)
def test_tree_errors_name_the_line_the_key_and_the_choices(tmp_path, tree, line, key, words):
    err = _error(TREE + tree, tmp_path)
    assert (err.line, err.key) == (line, key), str(err)
    assert words in str(err)


def test_a_tree_file_is_read_relative_to_the_config_and_its_errors_name_it(tmp_path) -> None:
    (tmp_path / "my_tree.yaml").write_text("type: sequence\nchildren:\n  - {type: nope}\n")
    err = _error("tree:\n  file: my_tree.yaml\n", tmp_path)
    assert err.source.endswith("my_tree.yaml") and err.line == 3
    assert "unknown behaviour type 'nope'" in str(err)
    err = _error("tree:\n  file: missing.yaml\n", tmp_path)
    assert err.key == "tree.file" and "no such tree file" in str(err)


def test_schema_covers_every_section_and_the_registry_is_documented() -> None:
    s = schema()
    assert set(s["properties"]) == {
        "cell",
        "gripper",
        "sim",
        "devices",
        "workflow",
        "safety",
        "log",
        "tree",
        "faults",
        "skills",
        "bin",
        "emulate",
    }
    readme = (Path(__file__).resolve().parents[2] / "docs" / "configuration.md").read_text()
    for name in REGISTRY:
        assert f"`{name}`" in readme, f"behaviour type {name} is not in docs/configuration.md"
    from pydantic import BaseModel

    from cell.config import CellConfig

    def keys(model: type[BaseModel], prefix: str):  # type: ignore[no-untyped-def]
        for name, field in model.model_fields.items():
            ann = field.annotation
            if isinstance(ann, type) and issubclass(ann, BaseModel):
                yield from keys(ann, f"{prefix}{name}.")
            else:
                yield f"{prefix}{name}"

    for key in keys(CellConfig, ""):
        assert f"| `{key}` |" in readme, f"config key {key} is not in docs/configuration.md"
    from cell.config import skills_reference

    assert skills_reference() in readme, "docs/configuration.md's skills tables are stale"


def test_config_from_text_reports_all_problems_at_once() -> None:
    with pytest.raises(ConfigError) as info:
        config_from_text("workflow:\n  cycles: 0\n  machining_time_s: -1\n", "x.yaml")
    text = str(info.value)
    assert "x.yaml:2: workflow.cycles" in text and "x.yaml:3: workflow.machining_time_s" in text


def _cell(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "cell.cli", *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=120,
    )


def test_cli_bad_config_exits_2_without_traceback_or_device(tmp_path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("workflow:\n  cycles: -3\nlog:\n  tick_log: ticks.jsonl\n")
    r = _cell("sim", "--config", str(bad), "--json", str(tmp_path / "o.json"), cwd=tmp_path)
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    assert f"{bad}:2: workflow.cycles" in r.stderr
    # Nothing was opened: no tick log, no state, no summary.
    assert not (tmp_path / "ticks.jsonl").exists() and not (tmp_path / "o.json").exists()


def test_cli_run_refuses_the_sim_backend_and_devices_that_fail_their_checks(tmp_path) -> None:
    sim = tmp_path / "sim.yaml"
    sim.write_text("cell:\n  backend: sim\n")
    r = _cell("run", "--config", str(sim), cwd=tmp_path)
    assert r.returncode == 2 and "needs `backend: hw`" in r.stderr and "Traceback" not in r.stderr
    hw = tmp_path / "hw.yaml"
    hw.write_text(
        f"cell:\n  backend: hw\ndevices:\n  arm: {{host: {quiet_host()}}}\n"
        f"  gripper: {{port: {tmp_path}/no_tty0}}\n  ft: {{port: {tmp_path}/no_tty1}}\n"
        "skills:\n  pivot: {grip_force_n: 20, hold_force_n: 20}\n  slot: {hold_force_n: 20}\n"
    )
    r = _cell("run", "--config", str(hw), cwd=tmp_path)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "start-up checks failed, nothing moved" in r.stderr
    for device in (f"UR5 at {quiet_host()}:30004", "no_tty0", "no_tty1", "D435"):
        assert device in r.stderr, device


def test_cli_tree_prints_the_tree_and_writes_pictures(tmp_path) -> None:
    r = _cell("tree", "--out", str(tmp_path / "pics"), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "pick a part" in r.stdout and "feed slot ft guard" in r.stdout
    assert (tmp_path / "pics" / "tree.dot").read_text().startswith("digraph")
    assert (tmp_path / "pics" / "tree.png").stat().st_size > 10_000
    r = _cell("tree", "--types", cwd=tmp_path)
    assert "pack_in_box" in r.stdout


def test_cli_schema_is_json(tmp_path) -> None:
    r = _cell("schema", cwd=tmp_path)
    assert r.returncode == 0
    assert "workflow" in json.loads(r.stdout)["properties"]


def test_a_gripper_value_beyond_the_unit_is_refused_at_load(tmp_path) -> None:
    # The 2F-85 grips with 20 N at least and moves its fingers at 20-150 mm/s.
    err = _error("skills:\n  pivot:\n    grip_force_n: 2\n", tmp_path)
    assert err.key == "skills.pivot.grip_force_n" and err.line == 3
    assert "20..235 N" in err.reason and "robotiq_2f85" in err.reason
    err = _error("skills:\n  slot:\n    hold_force_n: 300\n", tmp_path)
    assert err.key == "skills.slot.hold_force_n"
    err = _error("skills:\n  pivot:\n    close_speed_m_s: 0.005\n", tmp_path)
    assert err.key == "skills.pivot.close_speed_m_s" and "0.02..0.15 m/s" in err.reason
    # a gentler gripper's description admits the gentle grip
    config, _ = config_from_text("gripper: gentle_wire\nskills:\n  pivot:\n    grip_force_n: 2\n")
    assert config.gripper == "gentle_wire"
    err = _error("gripper: no_such_gripper\n", tmp_path)
    assert err.key == "gripper" and "unknown gripper" in err.reason


def test_a_description_file_is_read_relative_to_the_configuration(tmp_path) -> None:
    src = Path(__file__).resolve().parents[2] / "drivers" / "data" / "grippers"
    text = (src / "robotiq_2f85.yaml").read_text().replace("[20.0, 235.0]", "[5.0, 235.0]")
    text = text.replace("name: robotiq_2f85", "name: soft_2f85")
    (tmp_path / "soft.yaml").write_text(text)
    cfg = tmp_path / "cell.yaml"
    cfg.write_text("gripper: soft.yaml\nskills:\n  pivot:\n    grip_force_n: 10\n")
    config, _ = load_config(cfg)  # 10 N is within this description's 5..235 N
    assert config.gripper == "soft.yaml"
    (tmp_path / "bad.yaml").write_text(text.replace("stroke_m: 0.085", "stroke_m: -1"))
    cfg.write_text("gripper: bad.yaml\n")
    with pytest.raises(ConfigError) as info:
        load_config(cfg)
    assert info.value.key == "gripper" and "stroke" in info.value.reason


def test_a_tree_node_asking_the_gripper_too_little_is_refused(tmp_path) -> None:
    cfg = tmp_path / "cell.yaml"
    cfg.write_text(
        "tree:\n  type: sequence\n  children:\n    - {type: tilt, grip_force_n: 5}\n"
    )
    config, doc = load_config(cfg)
    with pytest.raises(ConfigError) as info:
        prepare(config, doc)
    assert info.value.key.endswith("grip_force_n") and "20..235 N" in info.value.reason


@pytest.mark.parametrize("text", ["", "\n\n", "# only a comment\n"])
def test_an_empty_configuration_is_refused_and_braces_run_the_defaults(tmp_path, text) -> None:
    cfg = tmp_path / "cell.yaml"
    cfg.write_text(text)
    for command in (["tree", "--config", str(cfg)], ["sim", "--config", str(cfg)]):
        r = _cell(*command, cwd=tmp_path)
        assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
        assert f"{cfg}: the file is empty" in r.stderr and "`{}`" in r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cell.yaml"]  # nothing written
    cfg.write_text("{}\n")
    r = _cell("tree", "--config", str(cfg), "--out", str(tmp_path / "t"), cwd=tmp_path)
    assert r.returncode == 0, r.stderr


@pytest.mark.parametrize("value", ["-3", "0", "nan"])
def test_a_duration_that_is_not_positive_is_refused(tmp_path, value) -> None:
    r = _cell("sim", "--cycles", "1", f"--max-sim-time={value}", cwd=tmp_path)
    assert r.returncode == 2 and "--max-sim-time: must be > 0 s" in r.stderr, r.stderr
    assert list(tmp_path.iterdir()) == []
