"""The tree as BehaviorTree.CPP v4 XML, and back: Groot2 opens, draws and edits our trees.

Why the YAML node spec and not the built tree: the builder wraps every motion leaf in a timeout
inside a force-torque guard from the leaf's own ``timeout_s`` / ``max_force_n`` /
``max_torque_nm``. Writing the spec keeps those limits as the leaf's ports, so a tree edited in
Groot2 comes back as the same YAML and is built -- and guarded -- the same way; a guard can never
be lost by an edit in the editor.

Mapping: ``sequence`` and ``selector`` (both with memory in py_trees) are BehaviorTree.CPP's own
``Sequence`` and ``Fallback``, which resume the running child the same way and which Groot2
already knows. Every other type is a node of this project, declared in ``<TreeNodesModel>`` with
its parameters as input ports (type, default, and the registry's doc as the description), so
Groot2's palette offers it with the right fields. Port values are the YAML's values, SI units as
the key names say.

Reading accepts what Groot2 writes: the compact form (``<Grasp .../>``) and the explicit one
(``<Action ID="Grasp" .../>``), several ``<BehaviorTree>`` with ``main_tree_to_execute``, and
``<SubTree ID=.../>`` references, which are inlined. Everything else -- an unknown node, port or
attribute, a blackboard reference ``{key}``, a script pre/post condition -- is an error naming the
file, the line and the reason.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

from trees.registry import MOTION, NAME, REGISTRY, Param, section_params
from trees.yaml_lines import ConfigError

BUILTIN = frozenset({"Sequence", "Fallback"})


def btcpp_ids() -> dict[str, tuple[str, str]]:
    """Registry type -> (BehaviorTree.CPP node ID, its model category), as each node declares
    it (:attr:`trees.node_type.NodeType.btcpp`); read when asked, so a node declared after this
    module was imported is in it."""
    return {kind: nt.btcpp for kind, nt in REGISTRY.items()}


def _by_id() -> dict[str, str]:
    return {xml_id: kind for kind, (xml_id, _) in btcpp_ids().items()}
_CATEGORIES = frozenset({"Action", "Condition", "Control", "Decorator"})
_CPP_TYPES = {bool: "bool", int: "int", float: "double", str: "std::string"}
#: the words BehaviorTree.CPP reads as a bool port's values
_BOOLS = {"true": True, "false": False, "1": True, "0": False}
TREE_ID = "CellTree"


class BtcppError(ConfigError):
    """An XML tree the cell refuses: ``file:line: reason`` (exit status 2)."""


def _text(value: Any) -> str:
    """A port value as BehaviorTree.CPP reads it: whole floats without ``.0``, so ``20`` in the
    YAML stays ``20`` both ways."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float) and value.is_integer():
        return str(int(value))
    return str(value)


def _params(kind: str) -> dict[str, Param]:
    return REGISTRY[kind].all_params()


# ----------------------------------------------------------------------------------- writing
def to_xml(
    spec: Any,
    defaults: dict[str, float] | None = None,
    section_defaults: dict[str, dict[str, float]] | None = None,
    tree_id: str = TREE_ID,
    source: str = "",
) -> str:
    """``spec`` (a YAML node spec the registry accepts) as a BehaviorTree.CPP v4 document.

    ``defaults``: the safety section's ``timeout_s``, ``max_force_n`` and ``max_torque_nm``;
    ``section_defaults``: each ``skills:`` section's configured values -- the ports' defaults in
    the model, i.e. what a leaf gets when the port is left empty.
    """
    root = ET.Element("root", {"BTCPP_format": "4", "main_tree_to_execute": tree_id})
    if source:
        # An XML comment may not hold "--": the command is named in words.
        note = f" the cell's tree from {source}; `cell tree` with from-btcpp reads it back "
        root.append(ET.Comment(note.replace("--", "-")))
    bt = ET.SubElement(root, "BehaviorTree", {"ID": tree_id})
    bt.append(_element(spec))
    model = ET.SubElement(root, "TreeNodesModel")
    for kind, (xml_id, category) in btcpp_ids().items():
        if xml_id in BUILTIN:
            continue
        node = ET.SubElement(model, category, {"ID": xml_id})
        for key, p in _params(kind).items():
            attrs = {"name": key, "type": _CPP_TYPES[_kind_of(p)]}
            value = _default_of(kind, key, defaults or {}, section_defaults or {})
            if value is not None:
                attrs["default"] = _text(value)
            port = ET.SubElement(node, "input_port", attrs)
            port.text = p.doc or None
    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def _kind_of(p: Param) -> type:
    kinds = p.kind if isinstance(p.kind, tuple) else (p.kind,)
    return kinds[0]


def _default_of(
    kind: str, key: str, defaults: dict[str, float], sections: dict[str, dict[str, float]]
) -> float | None:
    if key in MOTION:
        return defaults.get(key)
    section = REGISTRY[kind].section
    if section is not None:
        return sections.get(section, {}).get(key)
    return None


def _element(spec: dict[str, Any]) -> ET.Element:
    kind = spec["type"]
    xml_id, _ = REGISTRY[kind].btcpp
    attrs = {k: _text(v) for k, v in spec.items() if k not in ("type", "child", "children")}
    el = ET.Element(xml_id, attrs)
    for child in spec.get("children", []) or []:
        el.append(_element(child))
    if "child" in spec:
        el.append(_element(spec["child"]))
    return el


def write_xml(path: Path, spec: Any, **kwargs: Any) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(to_xml(spec, **kwargs), encoding="utf-8")
    return path


# ----------------------------------------------------------------------------------- reading
def _parse_lined(text: str, source: str) -> tuple[ET.Element, dict[int, int]]:
    """The document and the line of each element (by ``id``): errors point at the line."""
    from xml.parsers import expat

    lines: dict[int, int] = {}
    builder = ET.TreeBuilder()
    parser = expat.ParserCreate()

    def start(tag: str, attrs: dict[str, str]) -> None:
        lines[id(builder.start(tag, attrs))] = parser.CurrentLineNumber

    parser.StartElementHandler = start
    parser.EndElementHandler = builder.end
    parser.CharacterDataHandler = builder.data
    try:
        parser.Parse(text, True)
    except expat.ExpatError as exc:
        raise BtcppError(
            source, exc.lineno, "", f"not well-formed XML: {expat.ErrorString(exc.code)}"
        ) from None
    return builder.close(), lines


def from_xml(text: str, source: str) -> dict[str, Any]:
    """The YAML node spec of a BehaviorTree.CPP v4 document's main tree.

    Values are checked against the registry (type and range), as the YAML's are.
    """
    root, lines = _parse_lined(text, source)

    def err(el: ET.Element | None, reason: str) -> BtcppError:
        return BtcppError(source, lines.get(id(el)) if el is not None else None, "", reason)

    if root.tag != "root":
        raise err(root, f"the document's element is <{root.tag}>, expected <root>")
    fmt = root.get("BTCPP_format")
    if fmt != "4":
        raise err(root, f"BTCPP_format is {fmt!r}; this reads BehaviorTree.CPP v4 files ('4')")
    trees = {el.get("ID"): el for el in root.findall("BehaviorTree")}
    if not trees:
        raise err(root, "no <BehaviorTree> in the file")
    if None in trees:
        raise err(trees[None], "a <BehaviorTree> without an ID")
    main = root.get("main_tree_to_execute")
    if main is None:
        if len(trees) > 1:
            raise err(
                root,
                f"several trees ({', '.join(map(str, trees))}) and no "
                "main_tree_to_execute to choose one",
            )
        main = next(iter(trees))
    if main not in trees:
        raise err(
            root,
            f"main_tree_to_execute {main!r} is not one of the trees: {', '.join(map(str, trees))}",
        )

    def tree_body(tree_id: str, stack: tuple[str, ...], at: ET.Element) -> dict[str, Any]:
        if tree_id in stack:
            raise err(at, f"SubTree {tree_id!r} includes itself ({' -> '.join(stack)})")
        bt = trees[tree_id]
        kids = list(bt)
        if len(kids) != 1:
            raise err(
                bt, f"<BehaviorTree ID={tree_id!r}> must hold exactly one node, holds {len(kids)}"
            )
        return node(kids[0], (*stack, tree_id))

    def node(el: ET.Element, stack: tuple[str, ...]) -> dict[str, Any]:
        attrs = dict(el.attrib)
        if el.tag in _CATEGORIES or el.tag == "SubTree":
            xml_id = attrs.pop("ID", None)
            if xml_id is None:
                raise err(el, f"<{el.tag}> without an ID")
            if el.tag == "SubTree":
                extra = sorted(k for k in attrs if k != "name" and k != "_autoremap")
                if extra or list(el):
                    raise err(
                        el,
                        f"SubTree {xml_id!r}: port remapping ({', '.join(extra)}) "
                        "is not supported; the cell's nodes take values, not blackboard "
                        "entries",
                    )
                if xml_id not in trees:
                    raise err(el, f"SubTree {xml_id!r}: no <BehaviorTree> with that ID")
                return tree_body(xml_id, stack, el)
        else:
            xml_id = el.tag
        by_id = _by_id()
        kind = by_id.get(xml_id)
        if kind is None:
            valid = ", ".join(by_id)
            raise err(el, f"unknown node {xml_id!r}; the cell's nodes: {valid}")
        nt = REGISTRY[kind]
        allowed = dict(NAME) | nt.all_params()
        spec: dict[str, Any] = {"type": kind}
        for key, raw in attrs.items():
            if key not in allowed:
                what = "a script pre/post condition" if key.startswith("_") else "a port"
                valid = ", ".join(allowed)
                raise err(el, f"<{xml_id}>: {what} {key!r} the cell does not know; valid: {valid}")
            spec[key] = _value(el, xml_id, key, raw, allowed[key], err)
        for key, p in allowed.items():
            if p.required and key not in spec:
                raise err(el, f"<{xml_id}> needs {key!r} ({p.doc or _kind_of(p).__name__})")
        kids = [c for c in el if isinstance(c.tag, str)]
        if nt.kind == "composite":
            if not kids:
                raise err(el, f"<{xml_id}> needs at least one child")
            spec["children"] = [node(c, stack) for c in kids]
        elif nt.kind == "decorator":
            if len(kids) != 1:
                raise err(el, f"<{xml_id}> is a decorator: exactly one child, got {len(kids)}")
            spec["child"] = node(kids[0], stack)
        elif kids:
            raise err(el, f"<{xml_id}> is a leaf and takes no children")
        return spec

    return tree_body(main, (), root)


def _value(el: ET.Element, xml_id: str, key: str, raw: str, p: Param, err: Any) -> Any:
    if raw.startswith("{") and raw.endswith("}"):
        raise err(
            el, f"<{xml_id}> {key}={raw!r}: blackboard references are not supported; give the value"
        )
    kind = _kind_of(p)
    if kind is bool:
        if raw.lower() not in _BOOLS:
            raise err(el, f"<{xml_id}> {key}={raw!r}: expected true or false")
        return _BOOLS[raw.lower()]
    try:
        value: Any = kind(raw) if kind is not int else int(raw, 10)
    except ValueError:
        raise err(el, f"<{xml_id}> {key}={raw!r}: expected {kind.__name__}") from None
    if kind is float and value.is_integer():
        value = int(value)  # reads as the YAML wrote it; the builder takes an int as a float
    if p.low is not None and value < p.low or p.high is not None and value > p.high:
        raise err(el, f"<{xml_id}> {key}={raw!r}: must lie in [{p.low:g}, {p.high:g}]")
    return value


def read_xml(path: Path) -> dict[str, Any]:
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise BtcppError(str(path), None, "", f"cannot read: {exc.strerror}") from None
    return from_xml(text, str(path))


def to_yaml(spec: dict[str, Any], source: str = "") -> str:
    """The node spec as the YAML a cell's ``tree: {file: ...}`` reads: ``type`` and ``name``
    first, the children last, as the shipped trees are written."""
    import yaml

    def ordered(s: dict[str, Any]) -> dict[str, Any]:
        head = {k: s[k] for k in ("type", "name") if k in s}
        body = {k: v for k, v in s.items() if k not in ("type", "name", "child", "children")}
        out = head | body
        if "children" in s:
            out["children"] = [ordered(c) for c in s["children"]]
        if "child" in s:
            out["child"] = ordered(s["child"])
        return out

    header = f"# read by `cell tree --from-btcpp` from {source}\n" if source else ""
    return header + yaml.safe_dump(ordered(spec), sort_keys=False, width=100)


__all__ = [
    "btcpp_ids",
    "BtcppError",
    "from_xml",
    "read_xml",
    "section_params",
    "to_xml",
    "to_yaml",
    "write_xml",
]
