"""The learned option of the bin segmentation: a small per-pixel network that splits the parts
lying in a bin into instances, touching parts included.

Why a network: two round parts lying side by side touch along a line and, seen from above, form
one connected blob of height; a threshold on height cannot split them, and the groove between them
is only a few pixels wide and noisy. A small U-Net learns the groove (and the shading of the facets
next to it) as a *boundary* class, so that instances are simply the connected components of the
*interior* class, each grown back over the boundary pixels around it.

Contract with the classical pipeline (it fits each segment itself)::

    LearnedSegmenter(weights).segment(hm, rgb) -> (H, W) int32, 0 background, 1..K one per part

The same :func:`network_input` and :func:`pixel_classes` serve training (``cell
train-perception``, rendered scenes) and inference, so the two cannot drift apart. The weights
carry the input format they were trained with (a ``format`` buffer); a file made for another
format or another network is refused, never half-loaded.
"""

from __future__ import annotations

import pickle
from pathlib import Path

import cv2
import numpy as np
import torch
from numpy.typing import NDArray
from scipy import ndimage
from torch import nn
from torch.nn import functional as F

from skills.perception.heightmap import HeightMap, PerceptionInputError

#: Classes per pixel.
BACKGROUND, INTERIOR, BOUNDARY = 0, 1, 2
N_CLASSES = 3
#: The network sees the image at 1 / DOWNSCALE of the camera's resolution. 1, because at 0.5 m a
#: camera pixel is ~1 mm and the thinnest part (the 7.6 mm rail) is only 7-9 pixels wide: at half
#: resolution (tried first) it had ~2 interior pixels left and 46 % of the rails were lost in
#: held-out scenes, against 21 % at full resolution, for twice the training time.
DOWNSCALE = 1
#: Heights are divided by this (m) so that parts span ~0..1 (the tallest lying part is 66 mm).
HEIGHT_SCALE = 0.07
#: Width (pixels at network resolution) of the boundary class around every instance: two pixels
#: on each side of a contact line make a 4-pixel band, wide enough to survive the depth noise.
BOUNDARY_PX = 2
#: Bump when the input or label definition changes: old weights are then refused.
FORMAT_VERSION = 1
#: Inputs: height / HEIGHT_SCALE, fraction of valid depth, grey level.
IN_CHANNELS = 3
#: Channels per level of the U-Net (66 k parameters, ~260 kB of float32 weights).
WIDTHS = (12, 24, 48)
#: Interior blobs smaller than this (camera pixels) are noise, not parts: the smallest part seen
#: from above (the rail, 83 x 7.6 mm) covers ~600 pixels.
MIN_INTERIOR_PX = 40
#: Predicted part pixels farther than this (camera pixels) from every interior blob are dropped.
MAX_GROW_PX = 12
#: torch threads for one frame's inference (see LearnedSegmenter.logits).
INFERENCE_THREADS = 1


def _format_tensor() -> torch.Tensor:
    return torch.tensor([FORMAT_VERSION, DOWNSCALE, HEIGHT_SCALE, BOUNDARY_PX, IN_CHANNELS])


def _block(c_in: int, c_out: int) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(c_in, c_out, 3, padding=1, bias=False),
        nn.BatchNorm2d(c_out),
        nn.ReLU(inplace=True),
        nn.Conv2d(c_out, c_out, 3, padding=1, bias=False),
        nn.BatchNorm2d(c_out),
        nn.ReLU(inplace=True),
    )


class SegNet(nn.Module):
    """A three-level U-Net: (N, IN_CHANNELS, h, w) -> (N, 3, h, w) class logits.

    ``h`` and ``w`` must be multiples of 4 (two poolings); :func:`network_input` pads to that.
    Three levels give a receptive field of ~45 pixels (~4.5 cm in the bin): enough to see a
    contact line together with the facets of both parts on either side of it, which is what
    decides the boundary class; the interior class only needs the height under the pixel.
    """

    def __init__(self, widths: tuple[int, int, int] = WIDTHS) -> None:
        super().__init__()
        w0, w1, w2 = widths
        self.enc0 = _block(IN_CHANNELS, w0)
        self.enc1 = _block(w0, w1)
        self.mid = _block(w1, w2)
        self.dec1 = _block(w2 + w1, w1)
        self.dec0 = _block(w1 + w0, w0)
        self.head = nn.Conv2d(w0, N_CLASSES, 1)
        self.register_buffer("format", _format_tensor())

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        a = self.enc0(x)
        b = self.enc1(F.max_pool2d(a, 2))
        c = self.mid(F.max_pool2d(b, 2))
        d = self.dec1(torch.cat([F.interpolate(c, size=b.shape[-2:]), b], dim=1))
        e = self.dec0(torch.cat([F.interpolate(d, size=a.shape[-2:]), a], dim=1))
        return self.head(e)


def input_crop(height: NDArray[np.floating]) -> tuple[int, int, int, int]:
    """Rows ``r0:r1`` and columns ``c0:c1`` (camera pixels) of the bin: the bounding box of the
    valid heights, grown to multiples of ``4 * DOWNSCALE`` so it pools evenly. Outside it the
    height map is all NaN, so the network need not look there (half the frame at 0.5 m)."""
    valid = np.isfinite(height)
    if not valid.any():
        raise PerceptionInputError("the height map holds no valid pixel")
    rows = np.flatnonzero(valid.any(axis=1))
    cols = np.flatnonzero(valid.any(axis=0))
    step = 4 * DOWNSCALE
    h, w = height.shape

    def span(lo: int, hi: int, size: int) -> tuple[int, int]:
        n = -(-(hi - lo) // step) * step
        lo = max(0, min(lo - (n - (hi - lo)) // 2, size - n))
        return lo, min(size, lo + n)

    r0, r1 = span(int(rows[0]), int(rows[-1]) + 1, h)
    c0, c1 = span(int(cols[0]), int(cols[-1]) + 1, w)
    return r0, r1, c0, c1


def _shrink(img: NDArray[np.float32], shape: tuple[int, int]) -> NDArray[np.float32]:
    out = cv2.resize(img, (shape[1], shape[0]), interpolation=cv2.INTER_AREA)
    return out.astype(np.float32)


def network_input(
    height: NDArray[np.floating], rgb: NDArray[np.uint8], crop: tuple[int, int, int, int]
) -> NDArray[np.float32]:
    """(IN_CHANNELS, h, w) network input for the ``crop`` of a frame, at 1 / DOWNSCALE.

    Channels: the mean valid height / HEIGHT_SCALE (0 where nothing is valid), the fraction of
    valid pixels (so a dropped depth pixel is not mistaken for the floor) and the grey level
    (the facets of a round part shade differently, which marks the line where two touch).
    """
    r0, r1, c0, c1 = crop
    hc = np.asarray(height[r0:r1, c0:c1], dtype=np.float32)
    valid = np.isfinite(hc).astype(np.float32)
    small = ((r1 - r0) // DOWNSCALE, (c1 - c0) // DOWNSCALE)
    frac = _shrink(valid, small)
    hsum = _shrink(np.where(valid > 0, hc, 0.0).astype(np.float32), small)
    hmean = np.where(frac > 1e-3, hsum / np.maximum(frac, 1e-3), 0.0) / HEIGHT_SCALE
    grey = cv2.cvtColor(np.ascontiguousarray(rgb[r0:r1, c0:c1]), cv2.COLOR_RGB2GRAY)
    grey_small = _shrink(grey.astype(np.float32) / 255.0, small)
    return np.stack([np.clip(hmean, -0.5, 2.0), frac, grey_small]).astype(np.float32)


def pixel_classes(instances: NDArray[np.integer], crop: tuple[int, int, int, int]) -> NDArray:
    """Training target at network resolution from a camera-resolution instance map (0 = none):
    part pixels within BOUNDARY_PX of another instance or of the background are BOUNDARY, the
    rest of each part INTERIOR. Returns (h, w) int64."""
    r0, r1, c0, c1 = crop
    inst = np.ascontiguousarray(instances[r0:r1, c0:c1]).astype(np.int32)
    small = inst[DOWNSCALE // 2 :: DOWNSCALE, DOWNSCALE // 2 :: DOWNSCALE]
    small = small[: (r1 - r0) // DOWNSCALE, : (c1 - c0) // DOWNSCALE]
    k = 2 * BOUNDARY_PX + 1
    kernel = np.ones((k, k), np.uint8)
    # A pixel is a boundary when the max or min label in its window differs from its own.
    f = small.astype(np.float32)
    hi = cv2.dilate(f, kernel, borderType=cv2.BORDER_REPLICATE)
    lo = cv2.erode(f, kernel, borderType=cv2.BORDER_REPLICATE)
    out = np.where(small > 0, INTERIOR, BACKGROUND).astype(np.int64)
    out[(small > 0) & ((hi != f) | (lo != f))] = BOUNDARY
    return out


def instances_from_classes(classes: NDArray[np.integer], part_ok: NDArray[np.bool_]) -> NDArray:
    """Instance labels (int32, 0 = background) from a per-pixel class map at camera resolution.

    Each 4-connected INTERIOR blob of at least MIN_INTERIOR_PX pixels seeds one instance (4- not
    8-connectivity: a diagonal step across a thin boundary must not merge two parts); every other
    predicted part pixel within MAX_GROW_PX and inside ``part_ok`` joins its nearest seed, which
    gives each part back its boundary ring. Labels are numbered 1..K by interior size, largest
    first.
    """
    interior = (classes == INTERIOR).astype(np.uint8)
    n, comp, stats, _ = cv2.connectedComponentsWithStats(interior, connectivity=4)
    keep = np.zeros(n, np.int32)
    big = [i for i in range(1, n) if stats[i, cv2.CC_STAT_AREA] >= MIN_INTERIOR_PX]
    big.sort(key=lambda i: -stats[i, cv2.CC_STAT_AREA])
    for new, old in enumerate(big, start=1):
        keep[old] = new
    seeds = keep[comp]
    if not big:
        return seeds
    dist, (ri, ci) = ndimage.distance_transform_edt(seeds == 0, return_indices=True)
    grown = seeds[ri, ci]
    part = (classes != BACKGROUND) & part_ok & (dist <= MAX_GROW_PX)
    return np.where(part | (seeds > 0), grown, 0).astype(np.int32)


class LearnedSegmenter:
    """Bin segmentation by the trained :class:`SegNet` (CPU, no gradients).

    ``weights`` is a state dict saved by ``cell train-perception``. A missing file, a file torch
    cannot read and a state dict of another network or input format each raise
    :class:`PerceptionInputError` naming the file and the reason; nothing falls back silently to
    random weights or to the classical segmentation.
    """

    def __init__(self, weights: str | Path) -> None:
        path = Path(weights)
        if not path.is_file():
            what = "is a directory, not a weights file" if path.is_dir() else "no such file"
            raise PerceptionInputError(f"segmentation weights {path}: {what}")
        try:
            state = torch.load(path, map_location="cpu", weights_only=True)
        except OSError as exc:
            raise PerceptionInputError(
                f"segmentation weights {path}: cannot be read: {exc.strerror or exc}"
            ) from None
        except Exception as exc:  # torch raises many types for a file it cannot unpickle
            # weights_only refuses anything but tensors and plain containers; its message is a
            # page long, so only its gist is kept.
            if isinstance(exc, pickle.UnpicklingError):
                why = "not a file of tensors written by torch.save"
            else:
                why = (str(exc).splitlines() or [type(exc).__name__])[0][:160]
            raise PerceptionInputError(
                f"segmentation weights {path}: cannot be read as torch weights ({why})"
            ) from None
        net = SegNet()
        check_state_dict(net, state, path)
        net.load_state_dict(state)
        self.net = net.eval()
        self.path: Path | None = path

    @classmethod
    def from_module(cls, net: SegNet) -> LearnedSegmenter:
        """A segmenter around a network in memory (scoring during training); ``net`` is put in
        eval mode."""
        self = cls.__new__(cls)
        self.net = net.eval()
        self.path = None
        return self

    @torch.no_grad()
    def logits(self, hm: HeightMap, rgb: NDArray[np.uint8]) -> tuple[NDArray, tuple]:
        """Class logits (3, H', W') at camera resolution over the bin crop, and the crop.

        Runs on one thread (``INFERENCE_THREADS``), the process's setting restored after: with
        torch's default of one thread per core, on this 2-core machine a frame took 95 ms
        alone but 570 ms while another job kept a core busy (the two threads wait on each
        other at every layer); one thread takes 95 ms either way."""
        _check_inputs(hm, rgb)
        crop = input_crop(hm.height)
        x = torch.from_numpy(network_input(hm.height, rgb, crop))[None]
        before = torch.get_num_threads()
        torch.set_num_threads(INFERENCE_THREADS)
        try:
            y = self.net(x)
        finally:
            torch.set_num_threads(before)
        r0, r1, c0, c1 = crop
        y = F.interpolate(y, size=(r1 - r0, c1 - c0), mode="bilinear", align_corners=False)
        return y[0].numpy(), crop

    def segment(self, hm: HeightMap, rgb: NDArray[np.uint8]) -> NDArray[np.int32]:
        """(H, W) int32 instance labels: 0 background, 1..K one per part (largest first).

        Pixels outside the bin (NaN height beyond small dropout holes) are always background."""
        logits, crop = self.logits(hm, rgb)
        return self.labels_from_logits(hm, logits, crop)

    @staticmethod
    def labels_from_logits(
        hm: HeightMap, logits: NDArray[np.float32], crop: tuple[int, int, int, int]
    ) -> NDArray[np.int32]:
        """The instance labels of :meth:`segment` from the output of :meth:`logits`."""
        r0, r1, c0, c1 = crop
        classes = logits.argmax(axis=0)
        valid = np.isfinite(hm.height[r0:r1, c0:c1]).astype(np.uint8)
        inside = cv2.morphologyEx(valid, cv2.MORPH_CLOSE, np.ones((5, 5), np.uint8)) > 0
        labels = np.zeros(hm.height.shape, np.int32)
        labels[r0:r1, c0:c1] = instances_from_classes(classes, inside)
        return labels


def check_state_dict(net: nn.Module, state: object, path: Path | str) -> None:
    """Raise :class:`PerceptionInputError` unless ``state`` has exactly ``net``'s keys, shapes
    and input format; the message names the first key that does not match."""
    where = f"segmentation weights {path}"
    if not isinstance(state, dict):
        raise PerceptionInputError(
            f"{where}: does not match the network: holds a {type(state).__name__}, not a state dict"
        )
    expected = net.state_dict()
    for key, ref in expected.items():
        if key not in state:
            raise PerceptionInputError(f"{where}: does not match the network: no key {key!r}")
        got = state[key]
        if not isinstance(got, torch.Tensor) or got.shape != ref.shape:
            shape = tuple(got.shape) if isinstance(got, torch.Tensor) else type(got).__name__
            raise PerceptionInputError(
                f"{where}: does not match the network: key {key!r} is {shape}, "
                f"expected {tuple(ref.shape)}"
            )
    extra = [k for k in state if k not in expected]
    if extra:
        raise PerceptionInputError(
            f"{where}: does not match the network: unexpected key {extra[0]!r}"
        )
    if not torch.allclose(state["format"].float(), expected["format"].float()):
        raise PerceptionInputError(
            f"{where}: does not match the network: key 'format' is "
            f"{_fmt(state['format'])} (version, downscale, height scale, boundary px, "
            f"channels), this code reads {_fmt(expected['format'])}; retrain with "
            "cell train-perception"
        )


def _fmt(t: torch.Tensor) -> list[float]:
    return [round(float(v), 4) for v in t.flatten()]


def _check_inputs(hm: HeightMap, rgb: NDArray[np.uint8]) -> None:
    h = hm.height
    if not isinstance(h, np.ndarray) or h.ndim != 2:
        raise PerceptionInputError(
            f"height must be an (H, W) array, got {getattr(h, 'shape', type(h).__name__)}"
        )
    if not isinstance(rgb, np.ndarray) or rgb.shape != (*h.shape, 3) or rgb.dtype != np.uint8:
        raise PerceptionInputError(
            f"rgb must be a uint8 {h.shape[0]} x {h.shape[1]} x 3 array like the height map, got "
            f"{getattr(rgb, 'dtype', type(rgb).__name__)} {getattr(rgb, 'shape', '')}"
        )
