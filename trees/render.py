"""Pictures of a tree: DOT (py_trees' own) and a PNG drawn with matplotlib.

The PNG does not need Graphviz: cells and CI machines rarely have the ``dot`` binary, and a tree
picture an integrator cannot produce is no help. Where ``dot`` exists, run it on the .dot file
for the classic look.
"""

from __future__ import annotations

from pathlib import Path

import py_trees
from py_trees.behaviour import Behaviour

_COLOURS = {
    "Sequence": "#ffb84d",
    "Selector": "#7fe5f0",
    "Parallel": "#ffd700",
    "Guard": "#f4a6a6",  # FT guard and timeout: the safety limits
    "Decorator": "#dddddd",  # retry, cycles, stop on failure
    "Condition": "#d7b8f3",
    "Leaf": "#9be39b",  # an action
}
_LEGEND = (
    ("Sequence", "sequence (all in turn)"),
    ("Selector", "selector (first that succeeds)"),
    ("Parallel", "parallel"),
    ("Guard", "FT guard / timeout (limits)"),
    ("Decorator", "retry / cycles / stop"),
    ("Condition", "condition (checks, never moves)"),
    ("Leaf", "action"),
)


def _kind(node: Behaviour) -> str:
    if isinstance(node, py_trees.composites.Sequence):
        return "Sequence"
    if isinstance(node, py_trees.composites.Selector):
        return "Selector"
    if isinstance(node, py_trees.composites.Parallel):
        return "Parallel"
    if isinstance(node, py_trees.decorators.Decorator):
        from trees.decorators import FTGuard, Timeout

        return "Guard" if isinstance(node, FTGuard | Timeout) else "Decorator"
    if isinstance(node, _condition_leaves()):
        return "Condition"
    return "Leaf"


def _condition_leaves() -> tuple[type[Behaviour], ...]:
    """The leaf classes whose node type BehaviorTree.CPP's model declares a Condition: one list
    for the picture and the Groot2 export, so a new check is drawn as one without a second edit."""
    from trees.btcpp import btcpp_ids
    from trees.registry import REGISTRY

    return tuple(
        leaf
        for kind, (_, category) in btcpp_ids().items()
        if category == "Condition" and (leaf := REGISTRY[kind].leaf) is not None
    )


def _label(node: Behaviour) -> str:
    """A node's name, and the parameters that decide what it does: a guard's force and torque,
    a timeout's seconds, a retry's attempts and pause, the cycles' count, a stop's reason
    (safety and persistence are in the picture, not only in the YAML)."""
    from trees.decorators import Cycles, FTGuard, Retry, StopOnFailure, Timeout

    name = node.name.replace(" ", "\n", 1) if len(node.name) > 14 else node.name
    if isinstance(node, FTGuard):
        return f"{name}\n{node.max_force:g} N, {node.max_torque:g} N*m"
    if isinstance(node, Timeout):
        return f"{name}\n{node.seconds:g} s"
    if isinstance(node, Retry):
        pause = f", pause {node.pause_s:g} s" if node.pause_s else ""
        return f"{name}\n{node.attempts} attempts{pause}"
    if isinstance(node, Cycles):
        count = getattr(getattr(node, "ctx", None), "limits", None)
        return f"{name}\n{count.cycles} cycles" if count is not None else name
    if isinstance(node, StopOnFailure) and node.reason:
        reason = node.reason if len(node.reason) <= 28 else node.reason[:27] + "..."
        return f"{name}\n{reason}"
    return name


def limits_table(root: Behaviour) -> list[str]:
    """One line per guarded motion leaf: its abort force and torque and its timeout."""
    from trees.decorators import FTGuard, Timeout, leaf_name

    lines = []
    for node in root.iterate():
        if isinstance(node, FTGuard):
            inner = node.decorated
            seconds = f", {inner.seconds:g} s" if isinstance(inner, Timeout) else ""
            lines.append(
                f"{leaf_name(node)}: {node.max_force:g} N, {node.max_torque:g} N*m{seconds}"
            )
    return lines


def write_pictures(root: Behaviour, out: Path) -> tuple[Path, Path]:
    out.mkdir(parents=True, exist_ok=True)
    dot_path = out / "tree.dot"
    graph = py_trees.display.dot_tree(root, collapse_decorators=False)
    dot_path.write_text(graph.to_string(), encoding="utf-8")
    png_path = out / "tree.png"
    _draw_png(root, png_path)
    return dot_path, png_path


def _draw_png(root: Behaviour, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    # Layout: leaves get consecutive x slots; a parent sits over the middle of its children.
    pos: dict[int, tuple[float, int]] = {}
    slot = [0]

    def place(node: Behaviour, depth: int) -> float:
        kids = list(node.children)
        if not kids:
            x = float(slot[0])
            slot[0] += 1
        else:
            xs = [place(c, depth + 1) for c in kids]
            x = 0.5 * (xs[0] + xs[-1])
        pos[id(node)] = (x, depth)
        return x

    place(root, 0)
    depth = max(d for _, d in pos.values()) + 1
    fig, ax = plt.subplots(figsize=(max(8, 1.5 * slot[0]), 1.1 * depth + 1))
    for node in root.iterate():
        x, d = pos[id(node)]
        for c in node.children:
            cx, cd = pos[id(c)]
            ax.plot([x, cx], [-d, -cd], color="#888888", lw=0.8, zorder=1)
    for node in root.iterate():
        x, d = pos[id(node)]
        kind = _kind(node)
        colour = _COLOURS.get(kind, _COLOURS["Leaf"])
        ax.text(
            x,
            -d,
            _label(node),
            ha="center",
            va="center",
            fontsize=7,
            zorder=2,
            bbox={"boxstyle": "round,pad=0.3", "fc": colour, "ec": "#333333", "lw": 0.6},
        )
    ax.set_xlim(-1, slot[0])
    ax.set_ylim(-depth, 0.7)
    ax.axis("off")
    from matplotlib.patches import Patch

    ax.legend(
        handles=[Patch(fc=_COLOURS[k], ec="#333333", lw=0.6, label=t) for k, t in _LEGEND],
        loc="upper left",
        fontsize=7,
        frameon=False,
        ncol=len(_LEGEND),
    )
    ax.set_title(f"behaviour tree: {root.name}", fontsize=9, loc="left")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
