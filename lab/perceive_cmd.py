"""``cell perceive``: perception scored on random rendered bin scenes.

Contract (scripts rely on it)::

    cell perceive --scenes N --seed S --json FILE

Scene ``i`` uses seed ``S + i``: 1-6 parts drawn from the catalogue lying in the bin at random
poses, some touching, seen by the wrist camera 0.5 m above the bin with D435-like depth noise.
The twin's ground truth is used only to score the detections, never by them.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from cell.errors import UserError
from cell.output import write_json


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "perceive",
        help="score bin perception on random rendered scenes",
        description="Render N random bin scenes in the twin, find the lying parts from each "
        "RGB-D frame and score them against the simulator's ground truth.",
    )
    p.add_argument("--scenes", type=int, required=True, help="number of scenes")
    p.add_argument("--seed", type=int, required=True, help="seed of the first scene; i: S+i")
    p.add_argument("--json", type=Path, required=True, help="where to write the scores")
    p.add_argument(
        "--pipeline",
        choices=("classical", "learned"),
        default="classical",
        help="segmentation: classical depth pipeline (default) or the learned network",
    )
    p.add_argument(
        "--weights",
        type=Path,
        default=None,
        help="learned: the ONNX model (default: the shipped cell/data/perception_unet.onnx)",
    )
    p.add_argument(
        "--layout",
        "--cell",
        dest="cell",
        type=Path,
        default=None,
        metavar="FILE",
        help="cell layout YAML (default: the default layout)",
    )
    p.add_argument("--catalogue", type=Path, default=None, help="part catalogue YAML")
    p.add_argument(
        "--save-failures", type=Path, default=None, help="directory for images of failed scenes"
    )
    p.add_argument(
        "--fill",
        choices=("staged", "random"),
        default="staged",
        help="staged: parts laid at random poses, some side by side (default); random: tipped "
        "in as a person would, settling against walls, touching and leaning",
    )
    p.add_argument(
        "--parts",
        type=int,
        default=None,
        help="parts per scene (default: drawn, 1-6 staged, 3-10 random)",
    )
    p.add_argument(
        "--part",
        default=None,
        metavar="NAME",
        help="only this catalogue part (default: the catalogue's rigid parts, mixed)",
    )
    p.add_argument(
        "--second-view",
        choices=("auto", "on", "off"),
        default="auto",
        help="for a cup or bottle whose open end the wide view did not decide, look again "
        "from beyond its ends as the Look skill does (auto: on with --fill random)",
    )
    p.set_defaults(func=cmd_perceive)


def default_weights() -> Path:
    """The shipped model (the network's ONNX export), in the cell's data folder (``cell/data``)."""
    import cell

    return Path(cell.__file__).resolve().parent / "data" / "perception_unet.onnx"


def make_segmenter(pipeline: str, weights: Path | None) -> object | None:
    if pipeline == "classical":
        if weights is not None:
            raise ValueError("--weights: only with --pipeline learned")
        return None
    # No extra: the learned segmentation runs its ONNX export through OpenCV, without torch.
    from skills.perception.learned import LearnedSegmenter

    return LearnedSegmenter(weights if weights is not None else default_weights())


def cmd_perceive(args: argparse.Namespace) -> int:
    from cell.catalogue import load_catalogue
    from drivers.layout import CellLayout
    from skills.perception.heightmap import PerceptionInputError
    from skills.perception.scoring import score

    if args.scenes < 1:
        raise UserError(f"--scenes: must be >= 1, got {args.scenes}")
    if args.parts is not None and not 1 <= args.parts <= 20:
        raise UserError(f"--parts: must be 1..20, got {args.parts}")
    catalogue = load_catalogue(args.catalogue)
    layout = CellLayout.from_yaml(args.cell) if args.cell is not None else CellLayout()
    parts = [p for p in catalogue.parts.values() if p.rigid]
    if args.part is not None:
        if args.part not in catalogue.parts:
            raise UserError(
                f"--part: {args.part!r} is not in the catalogue "
                f"({', '.join(sorted(catalogue.parts))})"
            )
        parts = [catalogue.parts[args.part]]
    second = args.second_view == "on" or (args.second_view == "auto" and args.fill == "random")
    try:
        segmenter = make_segmenter(args.pipeline, args.weights)
    except PerceptionInputError as exc:
        raise UserError(str(exc)) from None
    matches, missed, false_pos, times, cpu_times, failed = [], 0, 0, [], [], []
    second_times: list[float] = []
    scene_times: list[tuple[int, float]] = []  #: (parts in the bin, s for all its views)
    missed_names: dict[str, int] = {}
    rows: list[tuple[Any, str, Any]] = []  #: (truth, situation, match or None) per scored part
    not_lying: dict[str, int] = {}
    from cell.progress import Progress

    bar = Progress(args.scenes, "scenes")
    for i in range(args.scenes):
        seed = args.seed + i
        scene = _render(args, seed, layout, parts, catalogue, segmenter, second)
        times.append(scene.wall)
        cpu_times.append(scene.cpu)
        second_times += scene.second_wall
        # the whole scene as the Look sees it: its wide view(s) and every end view taken
        scene_times.append((len(scene.truths), scene.wall + sum(scene.second_wall)))
        for label in scene.not_lying:
            not_lying[label] = not_lying.get(label, 0) + 1
        truths, dets = scene.truths, scene.detections
        m, miss, fp = score(truths, dets)
        by_truth = {id(x.truth): x for x in m}
        for t, label in zip(truths, scene.labels, strict=True):
            rows.append((t, label, by_truth.get(id(t))))
            if id(t) not in by_truth:
                missed_names[t.name] = missed_names.get(t.name, 0) + 1
        matches += m
        missed += miss
        false_pos += fp
        if (miss or fp) and args.save_failures is not None:
            failed.append(
                _save_failure(
                    args.save_failures,
                    seed,
                    scene.frame,
                    scene.intrinsics,
                    scene.world_T_camera,
                    truths,
                    dets,
                )
            )
        bar.update(i + 1, f"missed {missed}  false {false_pos}")
    bar.close()
    pos = np.array([x.pos_err for x in matches]) * 1e3 if matches else np.array([math.nan])
    # a standing part has no yaw to get wrong: its matches stay out of the yaw figures
    lying = [x for x in matches if not x.truth.standing]
    yaw = np.degrees([x.yaw_err for x in lying]) if lying else np.array([math.nan])
    ends = [x for x in matches if x.end_right is not None]
    seen = [x for x in ends if x.detection.open_end_seen]
    total = len(matches) + missed
    one_ended = sum(1 for t, _, _ in rows if t.open_ends == 1)
    flat = [r for r in rows if r[1] in ("free", "touching", "wall")]
    flat_found = sum(1 for r in flat if r[2] is not None)
    result = {
        "scenes": args.scenes,
        "recall": len(matches) / total if total else math.nan,
        "false_positives": false_pos,
        "yaw_err_deg_median": float(np.median(yaw)),
        "yaw_err_deg_p95": float(np.percentile(yaw, 95)),
        "pos_err_mm_median": float(np.median(pos)),
        "pos_err_mm_p95": float(np.percentile(pos, 95)),
        "ms_per_frame_median": 1e3 * float(np.median(times)),
        "ms_per_frame_p95": 1e3 * float(np.percentile(times, 95)),
        "cpu_ms_per_frame_median": 1e3 * float(np.median(cpu_times)),
        "pipeline": args.pipeline,
        "seed": args.seed,
        "fill": args.fill,
        "second_view": second,
        "parts": total,
        "found": len(matches),
        "open_end_decided": len(seen),
        "open_end_decided_right": sum(1 for x in seen if x.end_right),
        "open_end_one_ended_parts": len(ends),
        "one_ended_parts_in_scenes": one_ended,
        "second_views": len(second_times),
        "ms_per_second_view_median": (
            1e3 * float(np.median(second_times)) if second_times else math.nan
        ),
        "ms_per_scene_median": 1e3 * float(np.median([t for _, t in scene_times])),
        "ms_per_scene_by_parts": _by_parts(scene_times),
        "recall_lying_flat": flat_found / len(flat) if flat else math.nan,
        "lying_flat_parts": len(flat),
        "not_lying": not_lying,
        "by_part": _split(rows, lambda t, label: t.name),
        "by_situation": _split(rows, lambda t, label: label),
        "missed_by_part": missed_names,
        "failure_images": failed,
    }
    write_json(args.json, result)
    lines = [
        f"pipeline    {args.pipeline}, fill {args.fill}, second view {'on' if second else 'off'}",
        f"scenes      {args.scenes} ({total} parts)",
        f"recall      {result['recall']:.3f}  ({len(matches)}/{total}), false positives "
        f"{false_pos}",
        f"position    median {result['pos_err_mm_median']:.2f} mm, p95 "
        f"{result['pos_err_mm_p95']:.2f} mm",
        f"yaw         median {result['yaw_err_deg_median']:.2f} deg, p95 "
        f"{result['yaw_err_deg_p95']:.2f} deg (modulo the part's symmetry)",
        f"open end    decided for {len(seen)} of {len(ends)} cups/bottles, right "
        f"{result['open_end_decided_right']}",
        f"time        {result['ms_per_frame_median']:.0f} ms per frame (median wall; p95 "
        f"{result['ms_per_frame_p95']:.0f}), {result['cpu_ms_per_frame_median']:.0f} ms CPU",
        f"per scene   {result['ms_per_scene_median']:.0f} ms median with all its views; by "
        "parts: "
        + ", ".join(
            f"{k}: {v['ms_median']:.0f} ({v['scenes']})"
            for k, v in result["ms_per_scene_by_parts"].items()
        ),
    ]
    if args.fill == "random":
        lines.append(
            f"lying flat  recall {result['recall_lying_flat']:.3f} of {len(flat)} "
            f"(free, touching, against a wall); out of the bin, left out: {not_lying or 'none'}"
        )
        if second:
            lines.append(
                f"second view {len(second_times)} taken, median "
                f"{result['ms_per_second_view_median']:.0f} ms each"
            )
        for title, key in (("by part", "by_part"), ("by situation", "by_situation")):
            lines.append(f"{title}:")
            for name, row in result[key].items():
                lines.append(f"  {name:16s} {_row_text(row)}")
    lines.append(f"wrote {args.json}")
    print("\n".join(lines))
    return 0


def _by_parts(scene_times: list[tuple[int, float]]) -> dict[str, dict[str, float]]:
    """Median ms per scene (all its views) by how many parts lay in it, in bands of two."""
    bands: dict[str, list[float]] = {}
    for n, t in scene_times:
        lo = 2 * ((max(n, 1) - 1) // 2) + 1  # exact: bands 1-2, 3-4, ... (none: 1-2)
        bands.setdefault(f"{lo}-{lo + 1}", []).append(t)
    return {
        k: {"scenes": len(v), "ms_median": 1e3 * float(np.median(v))}
        for k, v in sorted(bands.items(), key=lambda kv: int(kv[0].split("-")[0]))
    }


def _split(rows: list[tuple[Any, str, Any]], key: Any) -> dict[str, dict[str, Any]]:
    """The figures per group of scored parts (``key(truth, situation)`` names the group)."""
    groups: dict[str, list[tuple[Any, str, Any]]] = {}
    for r in rows:
        groups.setdefault(str(key(r[0], r[1])), []).append(r)
    out = {}
    for name in sorted(groups):
        g = groups[name]
        found = [m for _, _, m in g if m is not None]
        ends = [m for m in found if m.end_right is not None]
        seen = [m for m in ends if m.detection.open_end_seen]
        level = [m for m in found if not m.truth.standing]
        yaw = np.degrees([m.yaw_err for m in level]) if level else np.array([math.nan])
        pos = 1e3 * np.array([m.pos_err for m in found]) if found else np.array([math.nan])
        out[name] = {
            "parts": len(g),
            "found": len(found),
            "recall": len(found) / len(g),
            "yaw_err_deg_p95": float(np.percentile(yaw, 95)),
            "pos_err_mm_p95": float(np.percentile(pos, 95)),
            "one_ended_found": len(ends),
            "open_end_decided": len(seen),
            "open_end_right": sum(1 for m in seen if m.end_right),
        }
    return out


def _row_text(row: dict[str, Any]) -> str:
    text = (
        f"recall {row['recall']:.3f} ({row['found']}/{row['parts']}), yaw p95 "
        f"{row['yaw_err_deg_p95']:.1f} deg, pos p95 {row['pos_err_mm_p95']:.1f} mm"
    )
    if row["one_ended_found"]:
        text += (
            f", open end decided {row['open_end_decided']}/{row['one_ended_found']}"
            f" right {row['open_end_right']}"
        )
    return text


class _Scene:
    """One rendered, perceived scene: the parts scored (truths and how each lies), what was
    left out (not lying in the bin), the detections and the pipeline's time."""

    def __init__(self) -> None:
        self.truths: list[Any] = []
        self.labels: list[str] = []
        self.not_lying: list[str] = []
        self.detections: list[Any] = []
        self.wall = self.cpu = 0.0
        self.second_wall: list[float] = []
        self.frame: Any = None
        self.intrinsics: Any = None
        self.world_T_camera: Any = None


def _render(
    args: argparse.Namespace,
    seed: int,
    layout: Any,
    parts: list[Any],
    catalogue: Any,
    segmenter: object | None,
    second: bool,
) -> _Scene:
    """Build scene ``seed``, take the wide view (and the second views), detect, keep the truth."""
    from sim.camera import SimCamera
    from sim.cell_layout import build_cell
    from sim.part_body import spawn_part
    from sim.scenes import dropped_bin_fill, look_down_pose, random_bin_scene, situation
    from sim.world import SimWorld
    from skills.perception.bin_parts import (
        combine_end_views,
        detect_parts,
        open_end_from_view,
    )
    from skills.perception.look import (
        LookParams,
        end_views,
        merge_views,
        wholly_in_view,
        wide_views,
    )
    from skills.perception.scoring import Truth

    out = _Scene()
    rng = np.random.default_rng(seed)
    mount = _camera_mount(layout)
    look = LookParams()
    with SimWorld(seed=seed) as world:
        fixtures = build_cell(world, layout)
        if args.fill == "random":
            n = args.parts if args.parts is not None else int(rng.integers(3, 11))
            bodies = dropped_bin_fill(
                world,
                layout,
                parts,
                rng,
                n,
                lambda kind, pose: spawn_part(world, kind, pose, lateral_friction=1.0),
            )
            for b in bodies:
                where = situation(world, b, bodies, fixtures.bin, layout)
                label = where.label()
                if label == "outside":
                    out.not_lying.append(label)
                    continue
                axis = b.axis()
                yaw = math.atan2(axis[1], axis[0])
                out.truths.append(
                    Truth(
                        b.part.name,
                        b.pose().position.copy(),
                        yaw,
                        b.part.open_ends,
                        standing=label == "standing",
                        open_up=bool(axis[2] > 0.0),
                    )
                )
                out.labels.append(label)
        else:
            n = args.parts if args.parts is not None else int(rng.integers(1, 7))
            scene = random_bin_scene(world, layout, parts, rng, n)
            out.truths = [
                Truth(t.name, t.center, t.yaw, catalogue.get(t.name).open_ends) for _, t in scene
            ]
            out.labels = ["staged"] * len(out.truths)
        view = [look_down_pose(layout.bin_center, look.view_height, mount)]
        camera = SimCamera(world, lambda: view[0], tool_T_camera=mount)
        # the Look's wide views: one, or two where one does not take in the whole bin
        top = layout.bin_floor_z + max(p.outer for p in parts)
        wide = wide_views(
            camera.intrinsics(), mount, layout.bin_center, layout.bin_interior(), top,
            look.view_height,
        )
        tool = view[0] = look_down_pose(wide[0], look.view_height, mount)
        out.frame = frame = camera.capture()
        out.intrinsics = intr = camera.intrinsics()
        out.world_T_camera = tool @ camera.tool_T_camera()
        roi = layout.bin_interior()
        # Wall and CPU time of this process for the pipeline on this one frame (height map,
        # segmentation, fits): CPU above wall means extra threads, wall above CPU means the
        # process waited for a core (another job on the machine).
        t0, c0 = time.perf_counter(), time.process_time()
        dets = detect_parts(frame, intr, out.world_T_camera, parts, roi, segmenter=segmenter)
        out.wall, out.cpu = time.perf_counter() - t0, time.process_time() - c0
        if len(wide) > 1:  # as the Look: each view's whole parts, merged
            dets = [d for d in dets if wholly_in_view(d, intr, out.world_T_camera)]
            tool = view[0] = look_down_pose(wide[1], look.view_height, mount)
            pose = tool @ camera.tool_T_camera()
            t0, c0 = time.perf_counter(), time.process_time()
            more = detect_parts(camera.capture(), intr, pose, parts, roi, segmenter=segmenter)
            more = [d for d in more if wholly_in_view(d, intr, pose)]
            dets = merge_views(dets, more)
            out.wall += time.perf_counter() - t0
            out.cpu += time.process_time() - c0
        if second:
            kinds = {p.name: p for p in parts}
            for k, d in enumerate(dets):
                part = kinds.get(d.part or "")
                if (
                    part is None
                    or part.open_ends != 1
                    or d.open_end_seen
                    or d.tilted
                    or d.standing
                ):
                    continue
                # The Look's views beyond both ends; decided where those that decide agree.
                judged = []
                for xy in end_views(d, look.second_offset, roi, dets):
                    tool = view[0] = look_down_pose(xy, look.second_height, mount)
                    frame2 = camera.capture()
                    t0 = time.perf_counter()
                    judged.append(open_end_from_view(d, part, frame2, intr, tool @ mount, roi))
                    out.second_wall.append(time.perf_counter() - t0)
                dets[k] = combine_end_views(d, judged)
        out.detections = dets
    return out


def _camera_mount(layout: Any) -> Any:
    """The configured camera-to-tool transform (the layout's, once calibration exists)."""
    mount = getattr(layout, "tool_T_camera", None)
    if callable(mount):
        return mount()
    from sim.camera import default_tool_T_camera

    return default_tool_T_camera()


def _save_failure(
    directory: Path,
    seed: int,
    frame: Any,
    intr: Any,
    world_T_camera: Any,
    truths: list[Any],
    dets: list[Any],
) -> str:
    """The frame with the true parts (green, axis to the open end) and the detections (red)."""
    import cv2

    directory.mkdir(parents=True, exist_ok=True)
    img = cv2.cvtColor(frame.rgb, cv2.COLOR_RGB2BGR)
    cam_T_world = world_T_camera.inverse()

    def px(p: Any) -> tuple[int, int]:
        x, y, z = cam_T_world.transform(p)
        return int(round(intr.fx * x / z + intr.cx)), int(round(intr.fy * y / z + intr.cy))

    for t in truths:
        tip = t.center + 0.03 * np.array([math.cos(t.yaw), math.sin(t.yaw), 0.0])
        cv2.arrowedLine(img, px(t.center), px(tip), (0, 200, 0), 2)
    for d in dets:
        cv2.circle(img, px(d.center), 4, (0, 0, 255), -1)
        cv2.line(img, px(d.center), px(d.open_end), (0, 0, 255), 1)
    path = directory / f"scene_{seed}.png"
    cv2.imwrite(str(path), img)
    return str(path)
