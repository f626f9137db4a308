"""What every command writes the same way: its ``--json`` file and a configuration's errors.

Why a module of its own: the production commands (``cell/cli.py``, ``cell/cell_cmds.py``) and the
experiments (``lab/``) all write their JSON and report a configuration that fails
validation in one form, which scripts rely on; keeping that here lets each command module stay
thin and none of them reach into another's private helpers. It imports no other command, so any
command can use it without loading the rest.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from cell.errors import UserError
from trees.yaml_lines import ConfigError


def write_json(path: Path, payload: Any) -> None:
    """Write ``payload`` to ``path`` as indented JSON, creating its folder; a file that cannot be
    written is the user's error (one line naming it), not a traceback."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(payload, indent=1) + "\n", encoding="utf-8")
    except OSError as exc:
        raise UserError(f"cannot write {path}: {exc.strerror}") from None


def report_config_error(exc: ConfigError, command: str) -> int:
    """Print a configuration's errors as ``cell COMMAND: error: FILE:LINE: KEY: reason`` lines
    on stderr and give the exit status for them (2, as for every user error)."""
    for line in str(exc).splitlines():
        print(f"cell {command}: error: {line}", file=sys.stderr)
    return 2


__all__ = ["report_config_error", "write_json"]
