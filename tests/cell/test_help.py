"""The help a new user reads: commands grouped with `cell sim` first, every command's --help with
an example and its exit codes, defaults written one way, and the consistent option names (the
old spellings still accepted)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from cell.cli import build_parser, main
from cell.help import GROUPS

from .test_cli import run_cli


def _commands() -> list[str]:
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    return sorted(sub.choices)


def _help(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    with pytest.raises(SystemExit) as info:
        main([*argv, "--help"])
    assert info.value.code == 0
    return capsys.readouterr().out


def test_top_level_help_groups_the_commands_and_starts_with_sim(
    capsys: pytest.CaptureFixture[str],
) -> None:
    out = _help([], capsys)
    assert "start here: `cell sim`" in out
    positions = [out.index(f"{title}:\n") for title, _ in GROUPS]
    assert positions == sorted(positions)
    for command in _commands():  # every command listed once, under a group
        assert len(re.findall(rf"^  {re.escape(command)} ", out, flags=re.M)) == 1, command
    assert out.index("  sim ") < out.index("  analyze ")


@pytest.mark.parametrize("command", _commands())
def test_every_command_help_has_an_example_and_exit_codes(
    command: str, capsys: pytest.CaptureFixture[str]
) -> None:
    out = _help([command], capsys)
    assert re.search(r"^examples?:\n  cell ", out, flags=re.M), out
    assert "exit status:\n  0 " in out and "\n  2 bad input" in out
    assert not re.search(r"\(default [^:]", out), "a default not written as (default: X)"
    # A default given in the old "(0.4)" form is not repeated as "(0.4) (default: 0.4)".
    assert not re.search(r"\(([^()]+)\) \(default: \1\)", out)


def test_defaults_are_shown_one_way(capsys: pytest.CaptureFixture[str]) -> None:
    out = " ".join(_help(["analyze"], capsys).split())
    for shown in ("(default: bushing)", "(default: 0.2)", "(default: 91)", "(default: out)"):
        assert shown in out, shown


def test_the_layout_option_and_its_old_spelling(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "layout.yaml"
    bad.write_text("no_such_key: 1\n")
    for spelling in ("--layout", "--cell"):
        code, _, err = run_cli(["compare", "--part", "bushing", spelling, str(bad)], capsys)
        assert code == 2 and "no_such_key: unknown key" in err, err


def test_workers_and_jobs_are_one_option(capsys: pytest.CaptureFixture[str]) -> None:
    parser = build_parser()
    for spelling in ("--workers", "--jobs"):
        args = parser.parse_args(["pivot", "--part", "bushing", "--json", "x", spelling, "3"])
        assert args.jobs == 3
    code, _, err = run_cli(["pivot", "--part", "bushing", "--json", "x", "--workers", "0"], capsys)
    assert code == 2 and "--workers" in err


def test_schema_json_and_out_write_the_same_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for spelling in ("--json", "--out"):
        path = tmp_path / f"{spelling[2:]}.json"
        code, _, err = run_cli(["schema", spelling, str(path)], capsys)
        assert code == 0, err
        assert "properties" in json.loads(path.read_text())
