"""``cell train-perception``: train the learned bin segmentation on rendered scenes.

Contract::

    cell train-perception [--scenes N] [--epochs E] [--seed S] [--out PATH.onnx] [--jobs J]
    cell train-perception --export STATE.pt --out PATH.onnx

Scene ``i`` is rendered with seed ``S + i`` (parts from the catalogue lying in the bin of the
twin, some touching, seen by the wrist camera from ~0.5 m, with the D435 noise model); the last
``max(1, N // 10)`` scenes are held out and scored, never trained on. Training scenes are
augmented (camera jitter, more touching parts, see :func:`render_scene`); held-out ones are the
nominal case, so the printed scores are those the cell can expect in the twin. Labels come from
PyBullet's segmentation mask rendered with the camera's own view and projection, so they are
pixel-aligned with the depth. The trained :class:`skills.perception.segnet.SegNet` is written
twice, ~0.3 MB each: exported to ONNX at ``PATH.onnx`` (what ``--pipeline learned`` runs, through
OpenCV, without torch) and as a torch state dict at ``PATH.pt`` beside it (to export again). The
held-out scores are those of the ONNX export as OpenCV runs it. The defaults take ~8 minutes on a
2-core CPU (~1 to render, ~17 s per epoch).

``--export STATE.pt`` renders and trains nothing: it exports a state dict written earlier to
``--out`` and prints how far OpenCV's logits are from torch's on a random input.

Bad values (``--scenes`` < 2, ``--epochs`` < 1, an output that is a directory or not ``.onnx``)
end with one line and exit 2 before anything is rendered.
"""

from __future__ import annotations

import argparse
import math
import multiprocessing
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

import cell

if TYPE_CHECKING:  # torch and the twin are imported only when training runs
    from skills.perception.heightmap import HeightMap
    from skills.perception.segnet import SegNet

#: Where the shipped model lives (``LearnedSegmenter(DEFAULT_WEIGHTS)``, the ONNX export): the
#: cell's data folder, ``cell/data``, beside the package data it is installed with.
DEFAULT_WEIGHTS = Path(cell.__file__).resolve().parent / "data" / "perception_unet.onnx"
#: The torch state dict it was exported from (training only).
DEFAULT_STATE = DEFAULT_WEIGHTS.with_suffix(".pt")
#: Camera height above the bin floor's centre (m) and the jitter of the training views around it.
VIEW_HEIGHT = 0.5
VIEW_JITTER_XY = 0.02
VIEW_JITTER_Z = 0.03
#: Training windows (network pixels; multiples of 4): random crops of the bin, for augmentation
#: and for batching scenes whose bin crops differ in size.
TRAIN_WINDOW = (192, 256)
BATCH = 8
#: A predicted instance "finds" a part when their IoU exceeds this.
MATCH_IOU = 0.7
#: A part counts as visible (must be found) with at least this many pixels in view (~3 cm^2 at
#: 0.5 m; a whole rail shows ~700). A thin part lying against a tall one can be hidden by it in
#: perspective, wholly or but for a sliver that no camera image could separate.
VISIBLE_PX = 300


class TrainPerceptionInputError(ValueError):
    """Bad input for ``cell train-perception`` (reported in one line, exit 2)."""


@dataclass(frozen=True)
class RenderedScene:
    """One rendered bin scene with its ground truth (for training and scoring only)."""

    seed: int
    hm: HeightMap
    rgb: NDArray[np.uint8]
    instances: NDArray[np.int32]  #: (H, W) 0 = none, 1..n one per part body (visible pixels)
    n_parts: int  #: parts in the bin
    names: tuple[str, ...]  #: catalogue name of each part, instance k is names[k - 1]

    @property
    def visible(self) -> list[int]:
        """Instance ids of the parts with at least VISIBLE_PX pixels in view."""
        areas = np.bincount(self.instances.ravel(), minlength=self.n_parts + 1)
        return [k for k in range(1, self.n_parts + 1) if areas[k] >= VISIBLE_PX]


def render_scene(seed: int, augment: bool = False) -> RenderedScene:
    """Random bin scene ``seed`` (1-6 parts) seen from above, with its instance mask.

    Without ``augment`` this is the nominal case the cell meets: ``random_bin_scene``'s defaults
    seen from 0.5 m above the bin's centre (held-out scenes and tests). ``augment`` (training
    scenes) moves the camera a little (+-2 cm, +-3 cm in height) so the network does not learn
    one exact view, and lays up to twice as many parts against others: touching parts are the
    hard case, and the default draws too few of them for the network to learn it well. (Drawing
    the thin rail twice as often as well was tried: no better on held-out scenes.)
    """
    from cell.catalogue import load_catalogue
    from drivers.layout import CellLayout
    from sim.camera import SimCamera, default_tool_T_camera, projection_matrix, view_matrix
    from sim.cell_layout import build_cell
    from sim.scenes import look_down_pose, random_bin_scene
    from sim.world import SimWorld
    from skills.perception.heightmap import height_map

    # The water bottle is deformable: the cell never picks it from a bin.
    parts = [p for n, p in load_catalogue().parts.items() if n != "water_bottle"]
    rng = np.random.default_rng(seed)
    with SimWorld(seed=seed) as world:
        layout = CellLayout()
        build_cell(world, layout)
        n_parts = int(rng.integers(1, 7))
        touching = float(rng.uniform(0.4, 0.8)) if augment else 0.4
        scene = random_bin_scene(world, layout, parts, rng, n_parts, touching=touching)
        target = np.asarray(layout.bin_center, dtype=float)
        height = VIEW_HEIGHT
        if augment:
            target = target + rng.uniform(-VIEW_JITTER_XY, VIEW_JITTER_XY, 2)
            height += float(rng.uniform(-VIEW_JITTER_Z, VIEW_JITTER_Z))
        tool = look_down_pose(target, height, default_tool_T_camera())
        cam = SimCamera(world, lambda: tool)
        frame = cam.capture()
        intr = cam.intrinsics()
        p = world.p
        # The camera's own view and projection: the mask is pixel-aligned with the depth.
        seg = p.getCameraImage(
            intr.width,
            intr.height,
            viewMatrix=view_matrix(cam.world_T_camera()).T.ravel().tolist(),
            projectionMatrix=projection_matrix(intr, cam.near, cam.far).T.ravel().tolist(),
            shadow=0,
            renderer=p.ER_TINY_RENDERER,
        )[4]
        # Without ER_SEGMENTATION_MASK_OBJECT_AND_LINKINDEX the mask holds the raw body id.
        seg = np.asarray(seg, dtype=np.int64).reshape(intr.height, intr.width)
        instances = np.zeros(seg.shape, np.int32)
        for k, (_, truth) in enumerate(scene, start=1):
            instances[seg == truth.body] = k
        hm = height_map(
            frame,
            intr,
            cam.world_T_camera(),
            roi=layout.bin_interior(),
            rng=np.random.default_rng(seed),
        )
    names = tuple(truth.name for _, truth in scene)
    return RenderedScene(seed, hm, frame.rgb, instances, len(scene), names)


def add_parser(sub: Any) -> None:
    p = sub.add_parser(
        "train-perception",
        help="train the learned bin segmentation on rendered scenes",
        description="Render N random bin scenes in the twin, train the small U-Net of "
        "skills/perception/learned.py to split the parts in the bin into instances (touching "
        "parts included), score it on held-out scenes and save it: exported to ONNX (what "
        "--pipeline learned runs, without torch) and as a torch state dict beside it.",
    )
    p.add_argument("--scenes", type=int, default=300, help="scenes rendered; 1/10 held out (300)")
    p.add_argument("--epochs", type=int, default=24, help="passes over the training scenes (24)")
    p.add_argument("--seed", type=int, default=0, help="seed of the first scene; scene i: S+i")
    p.add_argument(
        "--out",
        type=Path,
        default=DEFAULT_WEIGHTS,
        help="where to write the ONNX model (cell/data/perception_unet.onnx); the torch state "
        "dict goes beside it, with the suffix .pt",
    )
    p.add_argument(
        "--export",
        type=Path,
        default=None,
        metavar="STATE.pt",
        help="train nothing: export this state dict (written earlier) to ONNX at --out",
    )
    p.add_argument(
        "--workers",
        "--jobs",
        dest="jobs",
        type=int,
        default=1,
        metavar="K",
        help="processes rendering scenes (1)",
    )
    p.set_defaults(func=cmd_train_perception)


def _check_args(args: argparse.Namespace) -> None:
    if args.scenes < 2:
        raise TrainPerceptionInputError(
            f"--scenes: must be >= 2 (one is held out for scoring), got {args.scenes}"
        )
    if args.epochs < 1:
        raise TrainPerceptionInputError(f"--epochs: must be >= 1, got {args.epochs}")
    if args.jobs < 1:
        raise TrainPerceptionInputError(f"--workers (--jobs): must be >= 1, got {args.jobs}")
    if args.out.is_dir():
        raise TrainPerceptionInputError(f"--out: {args.out} is a directory, need a file path")
    if args.out.suffix != ".onnx":
        raise TrainPerceptionInputError(
            f"--out: {args.out}: the model is written as ONNX, name it NAME.onnx (the torch "
            "state dict goes beside it as NAME.pt)"
        )
    try:
        args.out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise TrainPerceptionInputError(f"--out: cannot create {args.out.parent}: {exc}") from None


_bars: dict[str, Any] = {}


def _bar(what: str, done: int, total: int, wall: float) -> None:
    """A :class:`cell.progress.Progress` per phase (a bar on a terminal, lines in a log)."""
    from cell.progress import Progress

    if what not in _bars or _bars[what].total != total or done <= 1:
        _bars[what] = Progress(total, what)
    _bars[what].update(done)
    if done >= total:
        _bars.pop(what).close()


def _render(job: tuple[int, bool]) -> RenderedScene:
    return render_scene(*job)


def render_scenes(jobs_: list[tuple[int, bool]], jobs: int) -> list[RenderedScene]:
    """Render the ``(seed, augment)`` scenes (in ``jobs`` processes), with a progress bar."""
    t0 = time.perf_counter()
    out: list[RenderedScene] = []
    if jobs > 1 and len(jobs_) > 1:
        with multiprocessing.get_context("spawn").Pool(jobs) as pool:
            for s in pool.imap(_render, jobs_, chunksize=4):
                out.append(s)
                _bar("render", len(out), len(jobs_), time.perf_counter() - t0)
    else:
        for job in jobs_:
            out.append(_render(job))
            _bar("render", len(out), len(jobs_), time.perf_counter() - t0)
    return out


@dataclass
class Scores:
    """Held-out scores of a segmenter (all in [0, 1])."""

    part_iou: float  #: IoU of predicted part pixels (interior or boundary) with the true ones
    boundary_iou: float  #: IoU of the boundary class at network resolution
    count_accuracy: float  #: fraction of scenes with exactly as many instances as visible parts
    found: float  #: fraction of visible parts matched by one instance with IoU > MATCH_IOU
    mean_match_iou: float  #: mean over visible parts of the best IoU of an instance
    parts: int  #: visible parts scored
    hidden: int  #: parts not counted: (nearly) hidden behind others in perspective


def match_ious(
    pred: NDArray[np.integer], truth: NDArray[np.integer], ids: list[int] | None = None
) -> list[float]:
    """Per true instance (those in ``ids``, default all present), the best IoU of any predicted
    instance (0 when none overlaps)."""
    out = []
    if ids is None:
        ids = [int(t) for t in np.unique(truth) if t != 0]
    for t in ids:
        tm = truth == t
        best = 0.0
        for q in np.unique(pred[tm]):
            if q == 0:
                continue
            pm = pred == q
            best = max(best, float((tm & pm).sum() / (tm | pm).sum()))
        out.append(best)
    return out


def score(model: bytes, scenes: list[RenderedScene]) -> Scores:
    """Run the full inference (the ONNX ``model`` through OpenCV, instances at camera
    resolution) on ``scenes``."""
    from skills.perception.learned import BOUNDARY, DOWNSCALE, LearnedSegmenter, pixel_classes

    seg = LearnedSegmenter.from_bytes(model, "the trained network")
    inter = union = b_inter = b_union = 0
    counts_ok = 0
    ious: list[float] = []
    for sc in scenes:
        logits, crop = seg.logits(sc.hm, sc.rgb)
        labels = seg.labels_from_logits(sc.hm, logits, crop)
        pred, true = labels > 0, sc.instances > 0
        inter += int((pred & true).sum())
        union += int((pred | true).sum())
        target = pixel_classes(sc.instances, crop) == BOUNDARY
        k = DOWNSCALE // 2  # the pixel pixel_classes samples in each DOWNSCALE block
        small = logits[:, k::DOWNSCALE, k::DOWNSCALE].argmax(axis=0)
        small = small[: target.shape[0], : target.shape[1]]
        b_inter += int(((small == BOUNDARY) & target).sum())
        b_union += int(((small == BOUNDARY) | target).sum())
        counts_ok += int(labels.max() == len(sc.visible))
        ious += match_ious(labels, sc.instances, sc.visible)
    return Scores(
        part_iou=inter / max(1, union),
        boundary_iou=b_inter / max(1, b_union),
        count_accuracy=counts_ok / max(1, len(scenes)),
        found=float(np.mean([i > MATCH_IOU for i in ious])) if ious else 1.0,
        mean_match_iou=float(np.mean(ious)) if ious else 1.0,
        parts=len(ious),
        hidden=sum(sc.n_parts for sc in scenes) - len(ious),
    )


def _windows(
    xs: list[NDArray[np.float32]], ys: list[NDArray[np.int64]], rng: np.random.Generator
) -> tuple[NDArray[np.float32], NDArray[np.int64]]:
    """One random TRAIN_WINDOW from each scene (zero / background padded), randomly flipped."""
    wh, ww = TRAIN_WINDOW
    bx = np.zeros((len(xs), xs[0].shape[0], wh, ww), np.float32)
    by = np.zeros((len(xs), wh, ww), np.int64)
    for i, (x, y) in enumerate(zip(xs, ys, strict=True)):
        h, w = y.shape
        r = int(rng.integers(0, max(0, h - wh) + 1))
        c = int(rng.integers(0, max(0, w - ww) + 1))
        xw, yw = x[:, r : r + wh, c : c + ww], y[r : r + wh, c : c + ww]
        if rng.random() < 0.5:
            xw, yw = xw[:, ::-1], yw[::-1]
        if rng.random() < 0.5:
            xw, yw = xw[:, :, ::-1], yw[:, ::-1]
        bx[i, :, : yw.shape[0], : yw.shape[1]] = xw
        by[i, : yw.shape[0], : yw.shape[1]] = yw
    return bx, by


def train(
    scenes: list[RenderedScene], epochs: int, seed: int, log: Any = print
) -> tuple[SegNet, list[float]]:
    """Adam on class-weighted cross entropy over random windows of ``scenes``; the mean loss of
    each epoch is returned with the trained network (in eval mode)."""
    import torch
    from torch.nn import functional as F

    from skills.perception.learned import N_CLASSES, input_crop, network_input
    from skills.perception.learned import pixel_classes as classes_of
    from skills.perception.segnet import SegNet

    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    xs, ys = [], []
    for sc in scenes:
        crop = input_crop(sc.hm.height)
        xs.append(network_input(sc.hm.height, sc.rgb, crop))
        ys.append(classes_of(sc.instances, crop))
    freq = np.bincount(np.concatenate([y.ravel() for y in ys]), minlength=N_CLASSES)
    # Inverse square-root frequency: the thin boundary class (a few % of the pixels) is what
    # separates touching parts, so it must not be drowned by the background.
    weight = 1.0 / np.sqrt(np.maximum(freq, 1) / freq.sum())
    weight = torch.tensor(weight / weight.mean(), dtype=torch.float32)
    net = SegNet()
    opt = torch.optim.Adam(net.parameters(), lr=3e-3)
    steps_per_epoch = math.ceil(len(xs) / BATCH)
    sched = torch.optim.lr_scheduler.OneCycleLR(
        opt, max_lr=3e-3, total_steps=epochs * steps_per_epoch, pct_start=0.15
    )
    losses = []
    t0 = time.perf_counter()
    for epoch in range(epochs):
        net.train()
        order = rng.permutation(len(xs))
        total = 0.0
        for b in range(steps_per_epoch):
            idx = order[b * BATCH : (b + 1) * BATCH]
            bx, by = _windows([xs[i] for i in idx], [ys[i] for i in idx], rng)
            logits = net(torch.from_numpy(bx))
            loss = F.cross_entropy(logits, torch.from_numpy(by), weight=weight)
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            total += loss.item() * len(idx)
        losses.append(total / len(xs))
        log(
            f"epoch {epoch + 1:3d}/{epochs}  loss {losses[-1]:.4f}  "
            f"{time.perf_counter() - t0:.0f} s"
        )
    return net.eval(), losses


def cmd_train_perception(args: argparse.Namespace) -> int:
    from cell.extras import require

    require("torch", "cell train-perception")
    require("onnx", "cell train-perception (its export to ONNX)")
    import torch

    from skills.perception.segnet import onnx_bytes

    if args.export is not None:
        return _export(args)
    _check_args(args)
    n_held = max(1, args.scenes // 10)
    n_train = args.scenes - n_held
    todo = [(args.seed + i, i < n_train) for i in range(args.scenes)]
    t0 = time.perf_counter()
    scenes = render_scenes(todo, args.jobs)
    t_render = time.perf_counter() - t0
    train_set, held = scenes[:-n_held], scenes[-n_held:]
    print(
        f"rendered {len(scenes)} scenes in {t_render:.0f} s: {len(train_set)} for training, "
        f"{len(held)} held out (seeds {held[0].seed}-{held[-1].seed})",
        flush=True,
    )
    t1 = time.perf_counter()
    net, _ = train(train_set, args.epochs, args.seed, log=lambda s: print(s, flush=True))
    t_train = time.perf_counter() - t1
    model = onnx_bytes(net)
    s = score(model, held)
    n_par = sum(p.numel() for p in net.parameters())
    state = args.out.with_suffix(".pt")
    try:
        args.out.write_bytes(model)
        torch.save(net.state_dict(), state)
    except OSError as exc:
        raise TrainPerceptionInputError(
            f"--out: cannot write {exc.filename or state}: {exc.strerror or exc}"
        ) from None
    print(
        f"trained {n_par} parameters in {t_train:.0f} s ({args.epochs} epochs)\n"
        f"held out  part-pixel IoU {s.part_iou:.3f}  boundary IoU {s.boundary_iou:.3f}  "
        f"instance count right in {100 * s.count_accuracy:.0f} % of {len(held)} scenes  "
        f"parts found (IoU > {MATCH_IOU}) {100 * s.found:.0f} % of {s.parts}  "
        f"mean best IoU {s.mean_match_iou:.3f}  ({s.hidden} parts hidden in view, not scored)\n"
        f"wrote {args.out} (ONNX, {args.out.stat().st_size / 1024:.0f} kB) and {state} "
        f"(torch state dict, {state.stat().st_size / 1024:.0f} kB)"
    )
    return 0


def _export(args: argparse.Namespace) -> int:
    """``--export STATE.pt``: the state dict to ONNX at ``--out``, and the largest difference of
    OpenCV's logits from torch's on a random input."""
    from skills.perception.heightmap import PerceptionInputError
    from skills.perception.learned import IN_CHANNELS, LearnedSegmenter
    from skills.perception.segnet import load_state, onnx_bytes, torch_logits

    _check_args(args)
    try:
        net = load_state(args.export)
    except PerceptionInputError as exc:
        raise TrainPerceptionInputError(f"--export: {exc}") from None
    model = onnx_bytes(net)
    try:
        args.out.write_bytes(model)
    except OSError as exc:
        raise TrainPerceptionInputError(f"--out: cannot write {args.out}: {exc}") from None
    x = np.random.default_rng(0).uniform(0, 1, (1, IN_CHANNELS, 96, 128)).astype(np.float32)
    seg = LearnedSegmenter(args.out)
    seg.net.setInput(x)
    diff = float(np.abs(seg.net.forward() - torch_logits(net, x)).max())
    print(
        f"exported {args.export} to {args.out} (ONNX, {len(model) / 1024:.0f} kB); on a random "
        f"input OpenCV's logits differ from torch's by at most {diff:.1e}"
    )
    return 0
