"""Every command refuses an output it cannot write, and every malformed input, before it starts:
exit 2, one line naming the option (or key) and the path, no traceback, nothing written."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from cell.cli import build_parser
from cell.preflight import NO_OUTPUTS, OUTPUTS, writable_problem

from .test_cli import assert_user_error, run_cli

HW_CONFIG = "cell:\n  backend: hw\n"

#: A command line for each command whose outputs are all the placeholder ``{X}``, ``{J}``
#: (a writable JSON path) or ``{D}`` (a writable folder); otherwise valid.
VALID: dict[str, list[str]] = {
    "analyze": ["analyze", "--grid", "5", "--out", "{D}", "--json", "{J}"],
    "plan": ["plan", "--part", "bushing", "--json", "{J}"],
    "pivot": ["pivot", "--part", "bushing", "--trials", "1", "--json", "{J}", "--record", "{G}"],
    "sweep": ["sweep", "--part", "bushing", "--trials", "1", "--out", "{D}"],
    "calibrate": ["calibrate", "--cell", "{Y}"],
    "perceive": [
        "perceive",
        "--scenes",
        "1",
        "--seed",
        "0",
        "--json",
        "{J}",
        "--save-failures",
        "{D}",
    ],
    "train-perception": ["train-perception", "--scenes", "2", "--epochs", "1", "--out", "{W}"],
    "compare": ["compare", "--part", "bushing", "--trials", "1", "--json", "{J}"],
    "sim": ["sim", "--cycles", "1", "--json", "{J}", "--record", "{G}", "--trace", "{C}"],
    "run": ["run", "--config", "{HW}", "--json", "{J}"],
    "tree": ["tree", "--out", "{D}"],
    "check-hardware": ["check-hardware", "--config", "{HW}", "--json", "{J}"],
    "schema": ["schema", "--out", "{J}"],
    "soak": ["soak", "--cycles", "1", "--json", "{J}"],
    "init": ["init", "{D}"],
    "emulate": ["emulate", "--report", "{J}", "--trace", "{C}"],
}
SUFFIX = {
    "{J}": "x.json", "{G}": "x.gif", "{C}": "x.csv", "{D}": "folder", "{Y}": "layout.yaml",
    "{W}": "w.pt",
}


def _commands() -> list[str]:
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    return sorted(sub.choices)


def test_every_command_says_what_it_writes() -> None:
    for command in _commands():
        assert command in OUTPUTS or command in NO_OUTPUTS, (
            f"cell {command}: list its output options in cell/preflight.py OUTPUTS "
            "(or NO_OUTPUTS when it writes only to the terminal)"
        )


def _cases() -> list[tuple[str, str]]:
    return [(c, dest) for c, outs in sorted(OUTPUTS.items()) for dest, _ in outs]


def _snapshot(root: Path) -> set[Path]:
    return {p for p in root.rglob("*")}


@pytest.mark.parametrize(("command", "dest"), _cases())
def test_an_unwritable_output_is_refused_before_anything_starts(
    command: str,
    dest: str,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.chdir(tmp_path)  # a default output (out/...) would land here too
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder\n")
    hw = tmp_path / "hw.yaml"
    hw.write_text(HW_CONFIG)
    argv = [a.replace("{HW}", str(hw)) for a in VALID[command]]
    option = "DIR" if dest == "dir" else "--" + dest.replace("_", "-")
    index = 1 if dest == "dir" else argv.index(option) + 1
    bad = blocker / SUFFIX.get(argv[index], "x")
    argv[index] = str(bad)
    for i, a in enumerate(argv):  # the other outputs: writable places
        if a in SUFFIX:
            argv[i] = str(tmp_path / "ok" / SUFFIX[a])
    before = _snapshot(tmp_path)
    code, out, err = run_cli(argv, capsys)
    assert_user_error(code, out, err, command, option, str(bad), "is a file, not a folder")
    assert _snapshot(tmp_path) == before, "the refused command wrote something"


def test_writable_problem_reasons(tmp_path: Path) -> None:
    (tmp_path / "f").write_text("")
    assert writable_problem(tmp_path / "new" / "deeper" / "x.json", "file") is None
    assert writable_problem(tmp_path, "dir") is None
    assert writable_problem(tmp_path, "file") == "is a folder, need a file"
    assert writable_problem(tmp_path / "f", "dir") == "is a file, need a folder"
    if os.geteuid() != 0:  # root may write anywhere: a read-only folder only stops others
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o500)
        try:
            assert "cannot create files" in str(writable_problem(ro / "x.json", "file"))
        finally:
            ro.chmod(0o700)


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux's /proc")
def test_a_folder_that_takes_no_files_is_refused_even_as_root() -> None:
    """os.access says yes to /proc as root; the probe file finds out the truth."""
    assert "cannot create files in /proc" in str(writable_problem(Path("/proc/x.json"), "file"))
    assert "cannot create files in /proc" in str(writable_problem(Path("/proc/x"), "dir"))
    assert "cannot create files in /proc" in str(writable_problem(Path("/proc/a/b.gif"), "file"))


def test_the_probe_leaves_no_trace(tmp_path: Path) -> None:
    kept = tmp_path / "report.json"
    kept.write_text("{}")
    os.utime(kept, (1_000_000, 1_000_000))
    before = _snapshot(tmp_path)
    assert writable_problem(kept, "file") is None
    assert writable_problem(tmp_path / "new" / "x.gif", "file") is None
    assert writable_problem(tmp_path, "dir") is None
    assert _snapshot(tmp_path) == before
    assert kept.read_text() == "{}" and kept.stat().st_mtime == 1_000_000


def test_a_configured_log_that_cannot_be_written_stops_sim_before_the_twin(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "a_file").write_text("")
    for key in ("tick_log", "state_file", "journal"):
        cfg = tmp_path / f"{key}.yaml"
        paths = {
            k: str(tmp_path / "logs" / f"{k}.out") for k in ("tick_log", "state_file", "journal")
        }
        paths[key] = str(tmp_path / "a_file" / "x")
        cfg.write_text("log:\n" + "".join(f"  {k}: {v}\n" for k, v in paths.items()))
        before = _snapshot(tmp_path)
        code, out, err = run_cli(["sim", "--config", str(cfg), "--cycles", "1"], capsys)
        assert_user_error(code, out, err, "sim", f"log.{key}", paths[key])
        assert _snapshot(tmp_path) == before


# --- malformed inputs ---------------------------------------------------------------------

BAD_LAYOUT = "bin_center: [0.4\n"  # YAML cut off inside a list
BAD_CATALOGUE = "parts:\n  bushing:\n    outer: abc\n"
BAD_CONFIG = "cell:\n  control_hz: abc\n"

MALFORMED: list[tuple[str, list[str], str]] = [
    # (command, argv with {F} for the malformed file, its kind)
    *[
        (c, [c, *extra, "--cell", "{F}"], "layout")
        for c, extra in (
            ("pivot", ["--part", "bushing", "--trials", "1", "--json", "{J}"]),
            ("compare", ["--part", "bushing", "--trials", "1"]),
            ("sweep", ["--part", "bushing", "--trials", "1", "--out", "{D}"]),
            ("perceive", ["--scenes", "1", "--seed", "0", "--json", "{J}"]),
            ("calibrate", []),
        )
    ],
    *[
        (c, [c, *extra, "--catalogue", "{F}"], "catalogue")
        for c, extra in (
            ("analyze", ["--grid", "5", "--out", "{D}"]),
            ("plan", ["--part", "bushing"]),
            ("check-tilt", ["--la", "0.9", "--alpha", "0.3"]),
            ("pivot", ["--part", "bushing", "--trials", "1", "--json", "{J}"]),
            ("compare", ["--part", "bushing", "--trials", "1"]),
            ("sweep", ["--part", "bushing", "--trials", "1", "--out", "{D}"]),
            ("perceive", ["--scenes", "1", "--seed", "0", "--json", "{J}"]),
        )
    ],
    *[
        (c, [c, *extra, "--config", "{F}"], "config")
        for c, extra in (
            ("sim", ["--cycles", "1"]),
            ("run", []),
            ("tree", ["--out", "{D}"]),
            ("soak", ["--cycles", "1"]),
            ("check-hardware", []),
            ("pivot", ["--part", "bushing", "--trials", "1", "--json", "{J}"]),
        )
    ],
    ("replay", ["replay", "{F}"], "log"),
    ("replay", ["replay", "{F}"], "binary"),
    ("replay", ["replay", "{F}"], "array-log"),
    ("replay", ["replay", "{F}"], "other-json"),
    (
        "perceive",
        [
            "perceive",
            "--scenes",
            "1",
            "--seed",
            "0",
            "--json",
            "{J}",
            "--pipeline",
            "learned",
            "--weights",
            "{F}",
        ],
        "binary",
    ),
]
CONTENT = {
    "layout": BAD_LAYOUT.encode(),
    "catalogue": BAD_CATALOGUE.encode(),
    "config": BAD_CONFIG.encode(),
    "log": b'{"tick": 1, "t": 0.0}\nnot json\n',
    "binary": bytes(range(256)) * 4,
    "array-log": b"[1, 2, 3]\n",
    "other-json": b'{"name": "x", "version": 2}\n',
}


@pytest.mark.parametrize(
    ("command", "argv", "kind"), MALFORMED, ids=[f"{c}-{k}" for c, _, k in MALFORMED]
)
def test_a_malformed_input_is_refused_in_one_line_naming_the_file(
    command: str,
    argv: list[str],
    kind: str,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.chdir(tmp_path)
    bad = tmp_path / f"bad_{kind}.input"
    bad.write_bytes(CONTENT[kind])
    subs = {"{F}": str(bad), "{J}": str(tmp_path / "o" / "x.json"), "{D}": str(tmp_path / "d")}
    before = _snapshot(tmp_path)
    code, out, err = run_cli([subs.get(a, a) for a in argv], capsys)
    assert_user_error(code, out, err, command, str(bad))
    assert _snapshot(tmp_path) == before, "the refused command wrote something"


def test_unwritable_json_of_sim_fails_in_a_real_interpreter_in_seconds(tmp_path: Path) -> None:
    """Through ``python -m cell.cli``: no traceback, and no run (the journal is not opened)."""
    (tmp_path / "a_file").write_text("")
    r = subprocess.run(
        [sys.executable, "-m", "cell.cli", "sim", "--json", str(tmp_path / "a_file" / "x.json")],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert_user_error(r.returncode, r.stdout, r.stderr, "sim", "--json")
    assert not (tmp_path / "out").exists()


def test_a_trace_into_a_folder_not_made_yet_makes_it(tmp_path: Path) -> None:
    """As ``--json`` and ``--record`` do: the up-front check lets such a path through, so the
    writer must make the folder (it once failed after the twin had opened)."""
    from sim.trace import HEADER, TwinTrace

    class World:
        def after_step(self, callback: object) -> None:
            self.callback = callback

    path = tmp_path / "new" / "dir" / "trace.csv"
    trace = TwinTrace(path, World(), robot=None)
    trace.close()
    assert path.read_text() == HEADER + "\n"


def test_a_write_that_fails_late_is_one_line_and_exit_2(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import cell.cli as cli

    parser = cli.build_parser()

    def failing(args: object) -> int:
        raise OSError(28, "No space left on device", "/data/run.json")

    real_parse = parser.parse_args

    def parse(argv: list[str] | None = None) -> object:
        args = real_parse(argv)
        args.func = failing
        return args

    monkeypatch.setattr(parser, "parse_args", parse)
    monkeypatch.setattr(cli, "build_parser", lambda: parser)
    assert cli.main(["plan", "--part", "bushing"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["cell plan: error: /data/run.json: cannot write: No space left on device"]


def test_an_os_error_without_a_file_is_not_called_a_write(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A device's broken link is an OSError too, but it is not an output: it keeps its own
    reporting, never the bad-input exit code."""
    import cell.cli as cli

    parser = cli.build_parser()
    real_parse = parser.parse_args

    def parse(argv: list[str] | None = None) -> object:
        args = real_parse(argv)
        args.func = lambda a: (_ for _ in ()).throw(ConnectionResetError(104, "reset"))
        return args

    monkeypatch.setattr(parser, "parse_args", parse)
    monkeypatch.setattr(cli, "build_parser", lambda: parser)
    with pytest.raises(ConnectionResetError):
        cli.main(["plan", "--part", "bushing"])


def test_a_catalogue_that_is_not_there_is_named_at_its_key(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The file that names the catalogue and the line of its key, not only the missing path."""
    config = tmp_path / "cell.yaml"
    config.write_text("cell:\n  name: x\n  catalogue: partz.yaml\n")
    code, out, err = run_cli(["sim", "--config", str(config), "--cycles", "1"], capsys)
    assert_user_error(code, out, err, "sim", "cell.yaml:3", "cell.catalogue", "partz.yaml",
                      "no such file")
