"""``--set KEY.PATH=VALUE`` (validated like the file, errors naming the --set), ``cell init DIR``
(a configuration, tree and catalogue that run as they are) and ``cell --version``."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from cell.cell_cmds import load_prepared
from cell.overrides import parse_set

from .test_cli import assert_user_error, run_cli


def test_parse_set_reads_the_value_as_yaml() -> None:
    assert parse_set("workflow.cycles=3").value == 3
    assert parse_set("workflow.cycles=3").path == ("workflow", "cycles")
    assert parse_set("cell.layout.bin_center=[0.5, 0.1]").value == [0.5, 0.1]
    assert parse_set("sim.realtime=true").value is True
    assert parse_set("cell.name=my cell").value == "my cell"
    assert parse_set("tree.children.2.type=x").path == ("tree", "children", 2, "type")


def test_set_changes_the_validated_configuration() -> None:
    prep = load_prepared(None, ["workflow.cycles=3", "safety.ft_abort_force_n=55", "sim.seed=7"])
    assert prep.config.workflow.cycles == 3
    assert prep.ctx.limits.cycles == 3
    assert prep.config.safety.ft_abort_force_n == 55
    assert prep.ctx.default_guard.max_force == 55
    assert prep.config.sim.seed == 7
    # A later --set of the same key wins.
    assert load_prepared(None, ["sim.seed=1", "sim.seed=2"]).config.sim.seed == 2


@pytest.mark.parametrize(
    ("setting", "words"),
    [
        ("workflow.cycles=abc", ("workflow.cycles", "expected a number")),
        ("workflow.cyclez=3", ("workflow.cyclez", "unknown key", "valid keys")),
        ("safety.ft_abort_force_n=-5", ("safety.ft_abort_force_n", "greater than 0")),
        ("cell.name.first=x", ("cell.name",)),
        ("cycles", ("expected KEY.PATH=VALUE",)),
        ("workflow.cycles=[1, 2", ("not valid YAML",)),
        ("tree.file=nowhere.yaml", ("tree.file", "no such tree file")),
    ],
)
@pytest.mark.parametrize("command", ["sim", "tree", "soak", "run"])
def test_a_bad_set_is_refused_naming_it(
    command: str,
    setting: str,
    words: tuple[str, ...],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.chdir(tmp_path)
    argv = [command, "--set", setting]
    if command == "run":
        cfg = tmp_path / "hw.yaml"
        cfg.write_text("cell:\n  backend: hw\n")
        argv += ["--config", str(cfg)]
    if command == "soak":
        argv += ["--cycles", "1"]
    code, out, err = run_cli(argv, capsys)
    assert_user_error(code, out, err, command, f"--set {setting}", *words)
    assert list(tmp_path.iterdir()) == ([tmp_path / "hw.yaml"] if command == "run" else [])


def test_set_reaches_the_tree(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run_cli(
        ["tree", "--out", str(tmp_path), "--set", "safety.ft_abort_force_n=42"], capsys
    )
    assert code == 0, err
    assert "42 N" in out  # the limits table: every leaf without its own force limit


def test_version(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run_cli(["--version"], capsys)
    assert code == 0
    assert out.startswith("cell ") and any(ch.isdigit() for ch in out)


def test_init_writes_three_files_that_refer_to_each_other(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "mycell"
    code, out, err = run_cli(["init", str(folder)], capsys)
    assert code == 0, err
    assert sorted(p.name for p in folder.iterdir()) == ["cell.yaml", "parts.yaml", "tree.yaml"]
    config = yaml.safe_load((folder / "cell.yaml").read_text())
    assert config["cell"]["catalogue"] == "parts.yaml"
    assert config["tree"] == {"file": "tree.yaml"}
    assert f"cell sim --config {folder / 'cell.yaml'}" in out
    # Refused the second time (nothing overwritten), allowed with --force.
    (folder / "tree.yaml").write_text("# mine\n" + (folder / "tree.yaml").read_text())
    code, out, err = run_cli(["init", str(folder)], capsys)
    assert_user_error(code, out, err, "init", "exists", "--force")
    assert (folder / "tree.yaml").read_text().startswith("# mine")
    code, _, err = run_cli(["init", str(folder), "--force"], capsys)
    assert code == 0, err
    assert not (folder / "tree.yaml").read_text().startswith("# mine")


def test_the_init_files_are_the_ones_the_cell_reads(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """An edit of the copied tree and catalogue shows in `cell tree`: the copies are used, not
    the shipped files."""
    folder = tmp_path / "c"
    assert run_cli(["init", str(folder)], capsys)[0] == 0
    tree = folder / "tree.yaml"
    tree.write_text(tree.read_text().replace("name: bushing machining", "name: my machining"))
    parts = yaml.safe_load((folder / "parts.yaml").read_text())
    parts["parts"]["my_bushing"] = dict(parts["parts"]["bushing"], length_mm=70)
    (folder / "parts.yaml").write_text(yaml.safe_dump(parts))
    code, out, err = run_cli(
        [
            "tree",
            "--config",
            str(folder / "cell.yaml"),
            "--out",
            str(tmp_path / "t"),
            "--set",
            "workflow.part=my_bushing",
        ],
        capsys,
    )
    assert code == 0, err
    assert "my machining" in out
    prep = load_prepared(folder / "cell.yaml", ["workflow.part=my_bushing"])
    assert prep.part.name == "my_bushing" and prep.part.length == pytest.approx(0.070)


def test_the_init_cell_runs_as_it_is_with_sets(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """`cell init` then `cell sim` on it, one cycle, with --set changing the bin and the logs:
    the twin packs a part and the logs land where the --set put them."""
    monkeypatch.chdir(tmp_path)
    assert run_cli(["init", "c"], capsys)[0] == 0
    code, out, err = run_cli(
        [
            "sim",
            "--config",
            "c/cell.yaml",
            "--cycles",
            "1",
            "--json",
            "r.json",
            "--quiet",
            "--set",
            "bin.parts=2",
            "--set",
            "workflow.machining_time_s=1",
            "--set",
            "log.tick_log=logs/ticks.jsonl",
        ],
        capsys,
    )
    assert code == 0, err
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["packed"] == 1 and report["parts"]["in_bin"] == 1
    assert (tmp_path / "logs" / "ticks.jsonl").stat().st_size > 0
