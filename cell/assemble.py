"""From a validated configuration to a runnable cell: geometry, part, plan, tree, backend.

Two stages on purpose. :func:`prepare` checks everything that needs no device -- the layout, the
part and its plan, every fixed pose against the UR5's reach, the tree file -- and builds the tree
against a context without devices; any problem is a :class:`ConfigError` naming file, line and
key. Only then does :func:`open_backend` create the twin or connect to the hardware, so a
configuration that fails validation never reaches a driver.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from py_trees.behaviour import Behaviour

from cell.catalogue import CatalogueError, load_catalogue
from cell.config import (
    CellConfig,
    check_tree_actuators,
    gripper_of,
    skill_settings,
    twin_servo,
)
from cell.reach import UR5_MODEL, reach_from, reach_from_or_home, ur5_reach
from cell.runner import Backend, CellState
from drivers.gripper_spec import GripperSpec
from drivers.layout import CellLayout
from drivers.parts import Gripper, Part
from drivers.pose import Pose
from skills.mechanics.contact import Frictions
from skills.mechanics.planner import PivotPlan, plan_pivot
from skills.motion import Guard
from skills.params import apply_config
from skills.perception.look import DOWN
from skills.pivot import PivotParams
from trees.context import CellContext, CellGeometry, WorkflowLimits
from trees.registry import build_root, resolve_tree_spec
from trees.yaml_lines import ConfigError, LinedDocument

DATA_DIR = Path(__file__).resolve().parent / "data"


@dataclass
class Prepared:
    config: CellConfig
    doc: LinedDocument
    layout: CellLayout
    part: Part
    catalogue: list[Part]
    plan: PivotPlan
    params: PivotParams
    geometry: CellGeometry
    ctx: CellContext
    root: Behaviour
    state: CellState
    gripper: GripperSpec  #: the configured gripper's description


def _layout(config: CellConfig, doc: LinedDocument) -> CellLayout:
    try:
        return CellLayout.from_dict(config.cell.layout, source="cell.layout")
    except ValueError as exc:
        text = str(exc).removeprefix("cell.layout: ")
        key, _, reason = text.partition(": ")
        path: tuple[str, ...] = (
            ("cell", "layout", key) if key in config.cell.layout else ("cell", "layout")
        )
        raise doc.error(path, reason if reason else text) from None


def geometry_from(
    layout: CellLayout, home_joints_deg: list[float], part_outer: float
) -> CellGeometry:
    x0, x1, y0, y1 = layout.bin_interior()
    tx0, tx1, ty0, ty1 = (
        layout.tray_center[0] - 0.5 * layout.tray_inner_size[0],
        layout.tray_center[0] + 0.5 * layout.tray_inner_size[0],
        layout.tray_center[1] - 0.5 * layout.tray_inner_size[1],
        layout.tray_center[1] + 0.5 * layout.tray_inner_size[1],
    )
    places = np.asarray(layout.packing_places(part_outer), float)
    return CellGeometry(
        bin_roi=(x0, x1, y0, y1),
        bin_view_xy=(float(layout.bin_center[0]), float(layout.bin_center[1])),
        bin_floor_z=float(layout.bin_floor_z),
        slot_center=np.asarray(layout.slot_center, float),
        slot_width=float(layout.slot_width),
        machine_top_z=float(layout.machine_top_z),
        tray_places=places,
        tray_roi=(tx0, tx1, ty0, ty1),
        tray_floor_z=float(layout.tray_floor_z),
        home_joints=np.radians(np.asarray(home_joints_deg, float)),
        bin_wall_height=float(layout.bin_wall_height),
        bin_wall_thickness=float(layout.bin_wall_thickness),
    )


def _check_reach(config: CellConfig, doc: LinedDocument, geometry: CellGeometry) -> None:
    """Every fixed pose the workflow visits must be inside the UR5's reach, tool down (the same
    kinematics as the twin's arm, and no simulator: `cell run` checks this before connecting)."""
    checks: list[tuple[tuple[str, ...], str, np.ndarray]] = [
        (
            ("cell", "layout", "machine_center"),
            "the pose over the slot",
            geometry.slot_center
            + np.array([0.0, 0.0, 0.15 + geometry.machine_top_z - geometry.slot_center[2]]),
        ),
    ]
    for i, place in enumerate(geometry.tray_places):
        checks.append(
            (
                ("cell", "layout", "tray_center"),
                f"box place {i}",
                place + np.array([0.0, 0.0, 0.12]),
            )
        )
    x0, x1, y0, y1 = geometry.bin_roi
    for x in (x0, x1):
        for y in (y0, y1):
            checks.append(
                (
                    ("cell", "layout", "bin_center"),
                    "a bin corner",
                    np.array([x, y, geometry.bin_floor_z + 0.10]),
                )
            )
    for path, what, position in checks:
        if ur5_reach([Pose(position, DOWN)]) is not None:
            p = position
            key = path if path[-1] in config.cell.layout or path[0] == "devices" else path[:2]
            raise doc.error(
                key,
                f"{what} at ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m is out of the UR5's reach",
            )


def prepare(config: CellConfig, doc: LinedDocument) -> Prepared:
    """Everything checked and the tree built; no device touched."""
    layout = _layout(config, doc)
    cat_path = config.cell.catalogue
    if cat_path is not None and not Path(cat_path).is_absolute():
        cat_path = str(Path(doc.source).resolve().parent / cat_path)
    if cat_path is not None and not Path(cat_path).is_file():  # this file's key names it
        raise doc.error(("cell", "catalogue"), f"{cat_path}: no such file")
    try:
        catalogue = load_catalogue(Path(cat_path) if cat_path else None)
    except CatalogueError as exc:  # the catalogue's own file and line, not this file's
        raise exc.as_config_error() from None
    except ValueError as exc:
        raise doc.error(("cell", "catalogue"), str(exc)) from None
    name = config.workflow.part
    if name not in catalogue.parts:
        raise doc.error(
            ("workflow", "part"),
            f"unknown part {name!r}; known parts: {', '.join(catalogue.parts)}",
        )
    part = catalogue.parts[name]
    spec = gripper_of(config, doc)
    # the planner's model of the configured gripper: the skills' clearance and finger too
    gripper = Gripper.from_spec(spec)
    plan = plan_pivot(part, gripper, Frictions())
    if not plan.pivotable:
        raise doc.error(("workflow", "part"), f"the {name} is not pivotable: {plan.reason}")
    assert plan.l_a is not None and plan.alpha is not None
    # The hole grasp holds the part the slot's grip_depth below its rim, so that, standing in
    # the slot's pocket, the part is let go on the floor with the outer finger above the machine.
    settings = skill_settings(config, layout.slot_depth, gripper)
    params = apply_config(
        PivotParams(l_a=plan.l_a, alpha=plan.alpha, **settings.pop("pivot_fixed")),
        settings.pop("pivot"),
    )
    geometry = geometry_from(layout, config.devices.arm.home_joints_deg, part.outer)
    _check_reach(config, doc, geometry)
    state = CellState(name=config.cell.name)
    s = config.safety

    def arm_joints() -> NDArray[np.float64]:
        # the plans are checked from where the arm stands when they are made (set below)
        return ctx.devices.arm.joint_positions()

    ctx = CellContext(
        devices=None,  # type: ignore[arg-type]  -- set by open_backend, after validation
        machine=None,  # type: ignore[arg-type]
        geometry=geometry,
        part=part,
        plan=plan,
        params=params,
        events=state,
        reach=reach_from_or_home(arm_joints, geometry.home_joints),
        reach_here=reach_from(arm_joints),
        arm_model=UR5_MODEL,
        limits=WorkflowLimits(
            max_failures_per_part=config.workflow.max_failures_per_part,
            max_failed_cycles=config.workflow.max_failed_cycles,
            cycles=config.workflow.cycles,
            pick_order=config.workflow.pick_order,
            ft_link_grace=s.ft_link_grace_s,
            ft_settle=s.ft_settle_s,
        ),
        default_guard=Guard(s.ft_abort_force_n, s.ft_abort_torque_nm),
        skill_params=settings,
        catalogue=[part],
    )
    tree_spec, tree_doc, path = resolve_tree_spec(config.tree, doc, DATA_DIR)
    check_tree_actuators(tree_spec, tree_doc, tuple(path), spec)
    root = build_root(
        tree_spec,
        tree_doc,
        path,
        ctx,
        {
            "timeout_s": s.default_timeout_s,
            "max_force_n": s.ft_abort_force_n,
            "max_torque_nm": s.ft_abort_torque_nm,
        },
    )
    return Prepared(
        config, doc, layout, part, [part], plan, params, geometry, ctx, root, state, spec
    )


def build_twin(prep: Prepared, seed: int | None = None, resume: Any = None) -> Any:
    """The PyBullet twin of the configured cell (`cell sim`, and behind `cell emulate`'s
    device emulators)."""
    from sim.cell_twin import SimCellBackend, TwinOptions

    config = prep.config
    sim = config.sim
    options = TwinOptions(
        seed=sim.seed if seed is None else seed,
        parts_in_bin=config.bin.parts,
        fill=config.bin.fill,
        yaw_spread=math.radians(sim.yaw_spread_deg),
        mu_ground=sim.mu_ground,
        machining_time=config.workflow.machining_time_s,
        gripper=prep.gripper,
        servo=twin_servo(config),
    )
    try:
        return SimCellBackend(prep.layout, prep.part, options, resume=resume)
    except ValueError as exc:
        raise prep.doc.error(("bin", "parts"), str(exc).split(": ", 1)[-1]) from None


def open_backend(prep: Prepared, seed: int | None = None, resume: Any = None) -> Backend:
    """Create the twin or connect the hardware named by ``cell.backend`` and hand its devices to
    the tree's context."""
    config = prep.config
    if config.cell.backend == "hw":
        from cell.hardware import open_hardware

        backend = open_hardware(prep)
    else:
        backend = build_twin(prep, seed, resume)
        if config.faults.enabled:  # the twin meets the configured faults behind its devices
            from sim.faults import twin_injector

            injector = twin_injector(backend, config.faults.rates.model_dump(), config.faults.seed)
            backend.wrap_devices(injector.wrap)
    prep.ctx.devices = backend.devices  # type: ignore[attr-defined]
    prep.ctx.machine = backend.machine  # type: ignore[attr-defined]
    prep.state.on_event.append(backend.judge)
    return backend


__all__ = ["ConfigError", "Prepared", "build_twin", "open_backend", "prepare"]
