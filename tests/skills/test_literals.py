"""No skill module holds a number that is not declared.

A number a motion uses comes from the part's geometry, the plan, a declared parameter (``si()``:
unit, range, why; configurable) or a named module constant with its doc comment (a fact of the
device or of mathematics). So this check walks every module under skills/ and fails on a numeric
literal anywhere else -- including a factor on a declared parameter (``2 * approach_speed``) and
an index other than 0, 1 and -1 (``wrench[2]``: name it, skills/axes.py).

What counts as declared:
- 0, 1 and -1 (as indices, signs and identities);
- a field default in a class body (a parameter dataclass; ``si()``/``guard_field()`` arguments);
- the value of a module-level UPPER_CASE constant with a ``#:`` comment above it or after it;
- an exponent (``x**2``), a dimension given to an array constructor (``np.zeros(3)``);
- a line marked ``# exact: <why>``: exact mathematics (half of a diameter), not a choice.
"""

from __future__ import annotations

import ast
import pathlib
import textwrap

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
SKILLS = ROOT / "skills"
ALLOWED = {0, 1, -1}
#: calls whose numeric arguments are declarations or array dimensions
DECLARING_CALLS = {"si", "guard_field", "field"}
SHAPE_CALLS = {"zeros", "ones", "empty", "eye", "identity", "full", "reshape", "broadcast_to"}
EXACT = "# exact:"


def _parented(tree: ast.AST) -> None:
    for node in ast.walk(tree):
        for child in ast.iter_child_nodes(node):
            child._parent = node  # type: ignore[attr-defined]


def _call_name(call: ast.Call) -> str:
    f = call.func
    return f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else ""


def _documented(lines: list[str], stmt: ast.stmt) -> bool:
    """A module constant's ``#:`` comment: after it on its line, or on the line(s) above it."""
    if "#:" in lines[stmt.lineno - 1]:
        return True
    k = stmt.lineno - 2
    return k >= 0 and lines[k].lstrip().startswith("#")


def _declared(node: ast.AST, lines: list[str]) -> bool:
    line = lines[node.lineno - 1]  # type: ignore[attr-defined]
    if EXACT in line and line.split(EXACT, 1)[1].strip():
        return True
    child = node
    while hasattr(child, "_parent"):
        parent = child._parent  # type: ignore[attr-defined]
        if isinstance(parent, (ast.JoinedStr, ast.FormattedValue)):
            return True
        is_pow = isinstance(parent, ast.BinOp) and isinstance(parent.op, ast.Pow)
        if is_pow and parent.right is child:
            return True
        if isinstance(parent, ast.Call):
            name = _call_name(parent)
            if name in DECLARING_CALLS:
                return True
            if name in SHAPE_CALLS and child is not parent.func:
                return True
        if isinstance(parent, (ast.Assign, ast.AnnAssign)):
            scope = getattr(parent, "_parent", None)
            if isinstance(scope, ast.ClassDef):
                return True
            targets = parent.targets if isinstance(parent, ast.Assign) else [parent.target]
            names = [n for t in targets
                     for n in (t.elts if isinstance(t, ast.Tuple) else [t])]
            if isinstance(scope, ast.Module) and all(
                isinstance(n, ast.Name) and n.id.isupper() for n in names
            ):
                return _documented(lines, parent)
            return False
        if isinstance(parent, (ast.stmt, ast.Module)):
            return False
        child = parent
    return False


def undeclared(source: str, path: str = "<source>") -> list[str]:
    """``path:line: value  code`` for each undeclared numeric literal of ``source``."""
    lines = source.splitlines()
    tree = ast.parse(source)
    _parented(tree)
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Constant) or isinstance(node.value, bool):
            continue
        if not isinstance(node.value, (int, float)):
            continue
        value = node.value
        parent = node._parent  # type: ignore[attr-defined]
        if isinstance(parent, ast.UnaryOp) and isinstance(parent.op, ast.USub):
            value = -value
        if value in ALLOWED or _declared(node, lines):
            continue
        found.append(f"{path}:{node.lineno}: {value!r}  {lines[node.lineno - 1].strip()}")
    return sorted(found)


def test_no_skill_module_holds_an_undeclared_number() -> None:
    found: list[str] = []
    for path in sorted(SKILLS.rglob("*.py")):
        found += undeclared(path.read_text(), str(path.relative_to(ROOT)))
    assert not found, (
        f"{len(found)} undeclared numbers in skills/ (declare each: si(), a documented "
        "module constant, skills/axes.py, or '# exact: why'):\n" + "\n".join(found[:80])
    )


@pytest.mark.parametrize(
    "code",
    [
        "def f(p):\n    return 2 * p.approach_speed\n",
        "def f(p):\n    return 0.5 * p.approach_speed\n",
        "def f(w):\n    return w[2]\n",
        "def f(w):\n    return w[:2]\n",
        "def f(g):\n    g.close(speed=0.02, settle=0.3)\n",
        "def f(x, settle=0.3):\n    return x\n",
        "LIMIT = 40.0\n",  # a constant without its doc comment
        "def f(d):\n    return d / 2  # exact:\n",  # a mark without a reason
        "limit = 40.0  #: N\n",  # not a constant's name
    ],
)
def test_the_check_finds_an_undeclared_number(code: str) -> None:
    assert undeclared(code), code


@pytest.mark.parametrize(
    "code",
    [
        "def f(w):\n    return -w[0] + w[-1] * 1.0\n",
        "#: N, the pinch of a regrasp\nPINCH = 40.0\n",
        "PINCH = 40.0  #: N, the pinch of a regrasp\n",
        "class P:\n    speed: float = si(0.02, 'm/s', 0.001, 0.1, 'why')\n",
        "import numpy as np\nv = np.zeros(3)\n",
        "def f(r):\n    return r**2\n",
        "def f(d):\n    return d / 2  # exact: a radius is half the diameter\n",
        "def f(x):\n    return f'{x:.3f}'\n",
    ],
)
def test_the_check_lets_a_declared_number_pass(code: str) -> None:
    assert not undeclared(textwrap.dedent(code)), code
