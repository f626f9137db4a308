"""The optional parts of the install, and the one message a command gives when one is missing.

Why extras: the core (`cell sim`, `plan`, `pivot`, `tree`, `soak`, `perceive`, ...) needs
neither torch (about 1 GB, for training the learned perception; its inference runs the ONNX
export through OpenCV) nor Ray (for `cell sweep`); installing them for everyone made the install
take minutes and gigabytes. The commands that need them ask here
first, so a missing one is a line saying what to install (exit 2), not a traceback.
"""

from __future__ import annotations

import importlib.util

from cell.errors import UserError

#: module -> (the extra that installs it, what needs it)
EXTRAS: dict[str, tuple[str, str]] = {
    "torch": ("learned", "cell train-perception (training the learned perception)"),
    "onnx": ("learned", "cell train-perception (the export of the learned perception to ONNX)"),
    "ray": ("sweep", "cell sweep (parallel trials on Ray)"),
}


def available(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):  # a module set to None in sys.modules, a broken install
        return False


def require(module: str, what: str | None = None) -> None:
    """Raise a :class:`UserError` naming the extra to install when ``module`` is missing."""
    if available(module):
        return
    extra, needs = EXTRAS[module]
    raise UserError(
        f"{what or needs} needs {module}, which is not installed: "
        f'pip install "pivot-cell[{extra}]" (or -e ".[{extra}]" in a checkout)'
    )


__all__ = ["EXTRAS", "available", "require"]
