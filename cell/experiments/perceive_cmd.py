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
    p.add_argument("--weights", type=Path, default=None, help="learned: weights file")
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
    p.set_defaults(func=cmd_perceive)


def default_weights() -> Path:
    """The shipped weights, in the cell's data folder (``cell/data``, one level up)."""
    return Path(__file__).resolve().parents[1] / "data" / "perception_unet.pt"


def make_segmenter(pipeline: str, weights: Path | None) -> object | None:
    if pipeline == "classical":
        if weights is not None:
            raise ValueError("--weights: only with --pipeline learned")
        return None
    from cell.extras import require

    require("torch", "--pipeline learned")
    from skills.perception.learned import LearnedSegmenter
    return LearnedSegmenter(weights if weights is not None else default_weights())


def cmd_perceive(args: argparse.Namespace) -> int:
    from cell.catalogue import load_catalogue
    from drivers.layout import CellLayout
    from sim.camera import SimCamera
    from sim.cell_layout import build_cell
    from sim.scenes import look_down_pose, random_bin_scene
    from sim.world import SimWorld
    from skills.perception.bin_parts import detect_parts
    from skills.perception.heightmap import PerceptionInputError
    from skills.perception.scoring import Truth, score

    if args.scenes < 1:
        raise UserError(f"--scenes: must be >= 1, got {args.scenes}")
    catalogue = load_catalogue(args.catalogue)
    layout = CellLayout.from_yaml(args.cell) if args.cell is not None else CellLayout()
    parts = [p for p in catalogue.parts.values() if p.rigid]
    try:
        segmenter = make_segmenter(args.pipeline, args.weights)
    except PerceptionInputError as exc:
        raise UserError(str(exc)) from None
    matches, missed, false_pos, times, cpu_times, failed = [], 0, 0, [], [], []
    missed_names: dict[str, int] = {}
    from cell.progress import Progress

    bar = Progress(args.scenes, "scenes")
    for i in range(args.scenes):
        seed = args.seed + i
        rng = np.random.default_rng(seed)
        with SimWorld(seed=seed) as world:
            build_cell(world, layout)
            scene = random_bin_scene(world, layout, parts, rng, int(rng.integers(1, 7)))
            tool = look_down_pose(layout.bin_center, 0.5, _camera_mount(layout))
            camera = SimCamera(world, lambda tool=tool: tool, tool_T_camera=_camera_mount(layout))
            frame = camera.capture()
            # Wall and CPU time of this process for the pipeline on this one frame (height map,
            # segmentation, fits): CPU above wall means extra threads, wall above CPU means the
            # process waited for a core (another job on the machine).
            t0, c0 = time.perf_counter(), time.process_time()
            dets = detect_parts(
                frame,
                camera.intrinsics(),
                tool @ camera.tool_T_camera(),
                parts,
                layout.bin_interior(),
                segmenter=segmenter,
            )
            times.append(time.perf_counter() - t0)
            cpu_times.append(time.process_time() - c0)
        truths = [Truth(t.name, t.center, t.yaw, catalogue.get(t.name).open_ends) for _, t in scene]
        m, miss, fp = score(truths, dets)
        found = {id(x.truth) for x in m}
        for t in truths:
            if id(t) not in found:
                missed_names[t.name] = missed_names.get(t.name, 0) + 1
        matches += m
        missed += miss
        false_pos += fp
        if (miss or fp) and args.save_failures is not None:
            failed.append(
                _save_failure(
                    args.save_failures,
                    seed,
                    frame,
                    camera.intrinsics(),
                    tool @ camera.tool_T_camera(),
                    truths,
                    dets,
                )
            )
        bar.update(i + 1, f"missed {missed}  false {false_pos}")
    bar.close()
    pos = np.array([x.pos_err for x in matches]) * 1e3 if matches else np.array([math.nan])
    yaw = np.degrees([x.yaw_err for x in matches]) if matches else np.array([math.nan])
    ends = [x for x in matches if x.end_right is not None]
    seen = [x for x in ends if x.detection.open_end_seen]
    total = len(matches) + missed
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
        "parts": total,
        "found": len(matches),
        "open_end_decided": len(seen),
        "open_end_decided_right": sum(1 for x in seen if x.end_right),
        "open_end_one_ended_parts": len(ends),
        "missed_by_part": missed_names,
        "failure_images": failed,
    }
    write_json(args.json, result)
    print(
        f"pipeline    {args.pipeline}\n"
        f"scenes      {args.scenes} ({total} parts)\n"
        f"recall      {result['recall']:.3f}  ({len(matches)}/{total}), false positives "
        f"{false_pos}\n"
        f"position    median {result['pos_err_mm_median']:.2f} mm, p95 "
        f"{result['pos_err_mm_p95']:.2f} mm\n"
        f"yaw         median {result['yaw_err_deg_median']:.2f} deg, p95 "
        f"{result['yaw_err_deg_p95']:.2f} deg (modulo the part's symmetry)\n"
        f"open end    decided for {len(seen)} of {len(ends)} cups/bottles, right "
        f"{result['open_end_decided_right']}\n"
        f"time        {result['ms_per_frame_median']:.0f} ms per frame (median wall; p95 "
        f"{result['ms_per_frame_p95']:.0f}), {result['cpu_ms_per_frame_median']:.0f} ms CPU\n"
        f"wrote {args.json}"
    )
    return 0


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
