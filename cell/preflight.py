"""Every output a command will write is checked before the command does any work.

Why: a run of the twin takes minutes and a run of the real cell moves a robot; finding only at
the end that the JSON report, the GIF or the picture folder cannot be written wastes the run (on
hardware, a whole job). So :func:`check_outputs` runs between argument parsing and the command:
each output path named on the command line must be writable -- the file itself when it exists,
else the nearest existing folder above it -- and an output the configuration names (the tick
log, the state file, the journal) is checked by :func:`check_config_outputs` before any device
or twin is opened. A failure is one line naming the option (or the key) and the path, exit 2.

Whether a folder takes files is found out by creating a probe file in it and removing it at
once, not by ``os.access``: as root (containers, CI) ``os.access`` says yes to ``/proc`` and to
read-only mounts, and the run found out only when it wrote. Nothing else is created here: a
folder that does not exist yet is made by the command when it writes, so a refused command
leaves no trace.
"""

from __future__ import annotations

import argparse
import os
import tempfile
from collections.abc import Iterable
from pathlib import Path
from typing import Literal

from cell.errors import UserError

Kind = Literal["file", "dir"]

#: The outputs each command writes, by its argparse ``dest``: a file or a folder. A command
#: missing here writes nothing but stdout (tests/cell/test_preflight.py checks that every
#: command is either listed here or in :data:`NO_OUTPUTS`).
OUTPUTS: dict[str, tuple[tuple[str, Kind], ...]] = {
    "analyze": (("out", "dir"), ("json", "file")),
    "plan": (("json", "file"),),
    "pivot": (("record", "file"), ("json", "file")),
    "sweep": (("out", "dir"),),
    "calibrate": (("cell", "file"),),  # the layout file it updates
    "perceive": (("json", "file"), ("save_failures", "dir")),
    "train-perception": (("out", "file"),),
    "compare": (("json", "file"),),
    "sim": (("json", "file"), ("record", "file"), ("trace", "file")),
    "run": (("json", "file"),),
    "tree": (("out", "dir"),),
    "check-hardware": (("json", "file"),),
    "schema": (("out", "file"),),
    "soak": (("json", "file"),),
    "init": (("dir", "dir"),),
    "emulate": (("report", "file"), ("trace", "file")),
}

#: Commands that write nothing but their output on the terminal.
NO_OUTPUTS = frozenset({"check-tilt", "replay"})


def _option(dest: str) -> str:
    return "DIR" if dest == "dir" else "--" + dest.replace("_", "-")


def _takes_files(folder: Path) -> str | None:
    """Why no file can be created in ``folder`` (a probe file made and removed), or None."""
    try:
        fd, name = tempfile.mkstemp(prefix=".cell-probe-", dir=folder)
    except OSError as e:
        return f"cannot create files in {folder} ({e.strerror or type(e).__name__})"
    os.close(fd)
    os.unlink(name)
    return None


def writable_problem(path: Path, kind: Kind) -> str | None:
    """Why ``path`` cannot be written as a ``kind``, or None when it can."""
    if path.exists():
        if kind == "file" and path.is_dir():
            return "is a folder, need a file"
        if kind == "dir" and not path.is_dir():
            return "is a file, need a folder"
        if kind == "file":
            try:  # opened to append and closed: its content and time stamps stay
                with open(path, "ab"):
                    pass
            except OSError as e:
                return f"cannot open it for writing ({e.strerror or type(e).__name__})"
        return _takes_files(path if kind == "dir" else path.parent)
    above = path.parent
    while not above.exists() and above != above.parent:
        above = above.parent
    if not above.is_dir():
        return f"{above} is a file, not a folder"
    return _takes_files(above)


def check_path(path: Path | str, kind: Kind, name: str) -> None:
    """Raise a :class:`UserError` naming ``name`` (an option or a key) and ``path`` when it
    cannot be written."""
    why = writable_problem(Path(path), kind)
    if why is not None:
        raise UserError(f"{name} {path}: cannot write: {why}")


def check_outputs(command: str, args: argparse.Namespace) -> None:
    """Check every output path of ``command`` given in ``args`` (see :data:`OUTPUTS`)."""
    for dest, kind in OUTPUTS.get(command, ()):
        value = getattr(args, dest, None)
        if value is None:
            continue
        check_path(Path(value), kind, _option(dest))


def check_config_outputs(
    config: object, keys: Iterable[str] = ("tick_log", "state_file", "journal")
) -> None:
    """Check the outputs a validated configuration names in its ``log`` section."""
    log = config.log  # type: ignore[attr-defined]
    for key in keys:
        value = getattr(log, key, None)
        if value is not None:
            check_path(Path(value), "file", f"log.{key}")


__all__ = ["NO_OUTPUTS", "OUTPUTS", "check_config_outputs", "check_outputs", "check_path"]
