"""The learned option of the bin segmentation: a small per-pixel network that splits the parts
lying in a bin into instances, touching parts included.

Why a network: two round parts lying side by side touch along a line and, seen from above, form
one connected blob of height; a threshold on height cannot split them, and the groove between them
is only a few pixels wide and noisy. A small U-Net learns the groove (and the shading of the facets
next to it) as a *boundary* class, so that instances are simply the connected components of the
*interior* class, each grown back over the boundary pixels around it.

Contract with the classical pipeline (it fits each segment itself)::

    LearnedSegmenter(model).segment(hm, rgb) -> (H, W) int32, 0 background, 1..K one per part

Inference needs no torch: the network (:class:`skills.perception.segnet.SegNet`, torch, used
for training only) is exported to ONNX by ``cell train-perception`` and run here through
OpenCV's DNN module. The same :func:`network_input` and :func:`pixel_classes` serve training
(rendered scenes) and inference, so the two cannot drift apart. The model file carries the input
format it was trained with (ONNX metadata, :data:`FORMAT_KEY`); a file made for another format
or another network is refused, never half-loaded.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from skills.perception.heightmap import HeightMap, PerceptionInputError

#: Classes per pixel.
BACKGROUND, INTERIOR, BOUNDARY = 0, 1, 2
N_CLASSES = 3  #: the three above
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
#: Threads of OpenCV's DNN module for one frame's inference (see LearnedSegmenter.logits).
INFERENCE_THREADS = 1
#: ONNX metadata key of the input format (:func:`format_values`, a JSON list) in a model file.
FORMAT_KEY = "pivot_cell.segmentation_format"
#: Pixels (at network resolution) an input's side is a multiple of: the network pools twice by
#: 2 (:class:`skills.perception.segnet.SegNet`) and upsamples twice by 2 back to the same size.
INPUT_MULTIPLE = 4
#: The fraction of valid depth pixels in a network pixel below which its mean height is taken as
#: 0 rather than divided out (no division by a vanishing fraction).
MIN_VALID_FRACTION = 1e-3
#: A uint8 grey level's full scale: the grey channel spans 0..1.
GREY_FULL_SCALE = 255.0
#: The height channel (in HEIGHT_SCALE) is clipped to this range: a pixel deeper than the floor
#: by half a scale is noise, and anything taller than two scales (a wall's top) is no part.
MIN_HEIGHT_IN, MAX_HEIGHT_IN = -0.5, 2.0
#: Pixel connectivity of the interior blobs (4, not 8: see :func:`instances_from_classes`).
CONNECTIVITY = 4
#: Side (pixels) of the closing that fills small dropout holes in the bin's valid mask.
CLOSE_PX = 5
#: Characters kept of an error's gist in a message (the full text may be a page long).
ERROR_GIST_CHARS = 160
#: A network input's axes, (N, C, H, W): their number and where height and width are.
INPUT_NDIM = 4
H_AXIS, W_AXIS = 2, 3  #: free in an export: any height and width
#: A colour frame's channels: red, green, blue.
RGB_CHANNELS = 3
#: The first bytes of a zip file, as torch.save writes its state dicts.
ZIP_MAGIC = b"PK\x03\x04"


def format_values() -> tuple[float, ...]:
    """The input format a model must have been trained with: version, downscale, height scale,
    boundary px, input channels (the ``format`` buffer of the torch network, the
    :data:`FORMAT_KEY` metadata of its ONNX export)."""
    return (FORMAT_VERSION, DOWNSCALE, HEIGHT_SCALE, BOUNDARY_PX, IN_CHANNELS)


def input_crop(height: NDArray[np.floating]) -> tuple[int, int, int, int]:
    """Rows ``r0:r1`` and columns ``c0:c1`` (camera pixels) of the bin: the bounding box of the
    valid heights, grown to multiples of ``4 * DOWNSCALE`` so it pools evenly. Outside it the
    height map is all NaN, so the network need not look there (half the frame at 0.5 m)."""
    valid = np.isfinite(height)
    if not valid.any():
        raise PerceptionInputError("the height map holds no valid pixel")
    rows = np.flatnonzero(valid.any(axis=1))
    cols = np.flatnonzero(valid.any(axis=0))
    step = INPUT_MULTIPLE * DOWNSCALE
    h, w = height.shape

    def span(lo: int, hi: int, size: int) -> tuple[int, int]:
        n = -(-(hi - lo) // step) * step
        lo = max(0, min(lo - (n - (hi - lo)) // 2, size - n))  # exact: grown evenly both sides
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
    mean = hsum / np.maximum(frac, MIN_VALID_FRACTION)
    hmean = np.where(frac > MIN_VALID_FRACTION, mean, 0.0) / HEIGHT_SCALE
    grey = cv2.cvtColor(np.ascontiguousarray(rgb[r0:r1, c0:c1]), cv2.COLOR_RGB2GRAY)
    grey_small = _shrink(grey.astype(np.float32) / GREY_FULL_SCALE, small)
    hin = np.clip(hmean, MIN_HEIGHT_IN, MAX_HEIGHT_IN)
    return np.stack([hin, frac, grey_small]).astype(np.float32)


def pixel_classes(instances: NDArray[np.integer], crop: tuple[int, int, int, int]) -> NDArray:
    """Training target at network resolution from a camera-resolution instance map (0 = none):
    part pixels within BOUNDARY_PX of another instance or of the background are BOUNDARY, the
    rest of each part INTERIOR. Returns (h, w) int64."""
    r0, r1, c0, c1 = crop
    inst = np.ascontiguousarray(instances[r0:r1, c0:c1]).astype(np.int32)
    mid = DOWNSCALE // 2  # exact: the middle pixel of each DOWNSCALE block
    small = inst[mid::DOWNSCALE, mid::DOWNSCALE]
    small = small[: (r1 - r0) // DOWNSCALE, : (c1 - c0) // DOWNSCALE]
    k = 2 * BOUNDARY_PX + 1  # exact: BOUNDARY_PX on each side of the pixel
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
    n, comp, stats, _ = cv2.connectedComponentsWithStats(interior, connectivity=CONNECTIVITY)
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
    """Bin segmentation by the trained network's ONNX export, run by OpenCV's DNN module (CPU).

    ``model`` is an ``.onnx`` file written by ``cell train-perception``. A missing file, a file
    that is not an ONNX model (a torch state dict included), a model without the input format in
    its metadata, of another input format or of another network each raise
    :class:`PerceptionInputError` naming the file and the reason; nothing falls back silently to
    the classical segmentation.
    """

    def __init__(self, model: str | Path) -> None:
        path = Path(model)
        if not path.is_file():
            what = "is a directory, not a model file" if path.is_dir() else "no such file"
            raise PerceptionInputError(f"segmentation weights {path}: {what}")
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise PerceptionInputError(
                f"segmentation weights {path}: cannot be read: {exc.strerror or exc}"
            ) from None
        self.net = _load_net(data, f"segmentation weights {path}", path)
        self.path: Path | None = path

    @classmethod
    def from_bytes(cls, data: bytes, name: str = "the network in memory") -> LearnedSegmenter:
        """A segmenter around an ONNX model in memory (scoring during training); ``name`` stands
        for the file in messages."""
        self = cls.__new__(cls)
        self.net = _load_net(data, name, None)
        self.path = None
        return self

    def logits(self, hm: HeightMap, rgb: NDArray[np.uint8]) -> tuple[NDArray, tuple]:
        """Class logits (3, H', W') at camera resolution over the bin crop, and the crop.

        Runs on one thread (``INFERENCE_THREADS``), the process's setting restored after: on this
        2-core machine a frame takes about as long on one thread as on two while another job
        keeps a core busy (the threads wait on each other at every layer), and the second core
        stays free for the cell (docs/design.md, "Learned option")."""
        _check_inputs(hm, rgb)
        crop = input_crop(hm.height)
        x = network_input(hm.height, rgb, crop)[None]
        before = cv2.getNumThreads()
        cv2.setNumThreads(INFERENCE_THREADS)
        try:
            self.net.setInput(x)
            y = np.asarray(self.net.forward(), dtype=np.float32)[0]
        finally:
            cv2.setNumThreads(before)
        r0, r1, c0, c1 = crop
        if y.shape[1:] != (r1 - r0, c1 - c0):  # DOWNSCALE > 1: bilinear, half-pixel centres
            hwc = y.transpose(1, 2, 0)  # exact: (C, H, W) -> (H, W, C)
            y = cv2.resize(hwc, (c1 - c0, r1 - r0), interpolation=cv2.INTER_LINEAR)
            chw = y.reshape(r1 - r0, c1 - c0, -1).transpose(2, 0, 1)  # exact: and back
            y = np.ascontiguousarray(chw)
        return y, crop

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
        closing = np.ones((CLOSE_PX, CLOSE_PX), np.uint8)
        inside = cv2.morphologyEx(valid, cv2.MORPH_CLOSE, closing) > 0
        labels = np.zeros(hm.height.shape, np.int32)
        labels[r0:r1, c0:c1] = instances_from_classes(classes, inside)
        return labels


#: The side (pixels) of the zero input a loaded model is tried on: a multiple of 4, as any input.
_PROBE = 16


def _load_net(data: bytes, where: str, path: Path | None) -> cv2.dnn.Net:
    """The OpenCV network of the ONNX model ``data``, after checking that it is one, that its
    input format is this code's and that it maps the input to N_CLASSES logits per pixel."""
    if data[: len(ZIP_MAGIC)] == ZIP_MAGIC:  # torch.save's zip container
        hint = f" {path}" if path is not None else " FILE.pt"
        raise PerceptionInputError(
            f"{where}: a torch state dict, not an ONNX model; export it with "
            f"cell train-perception --export{hint} --out MODEL.onnx"
        )
    try:
        meta, inputs = onnx_metadata(data), onnx_inputs(data)
    except (ValueError, UnicodeDecodeError) as exc:
        raise PerceptionInputError(f"{where}: cannot be read as an ONNX model ({exc})") from None
    if FORMAT_KEY not in meta:
        raise PerceptionInputError(
            f"{where}: an ONNX model without the segmentation's input format (metadata "
            f"{FORMAT_KEY!r}): not written by cell train-perception"
        )
    expected = [float(v) for v in format_values()]
    try:
        got = [float(v) for v in json.loads(meta[FORMAT_KEY])]
    except (ValueError, TypeError):
        raise PerceptionInputError(
            f"{where}: metadata {FORMAT_KEY!r} is {meta[FORMAT_KEY][:60]!r}, not a list of numbers"
        ) from None
    if len(got) != len(expected) or not np.allclose(got, expected):
        raise PerceptionInputError(
            f"{where}: does not match the network: its input format is "
            f"{[round(v, 4) for v in got]} (version, downscale, height scale, boundary px, "
            f"channels), this code reads {[round(v, 4) for v in expected]}; retrain with "
            "cell train-perception"
        )
    dims = inputs[0][1] if len(inputs) == 1 else ()
    free = all(isinstance(d, str) for d in dims[H_AXIS:])
    if len(dims) != INPUT_NDIM or dims[1] != IN_CHANNELS or not free:
        # OpenCV would run a model made for other channels or another size on any input
        # without a word.
        shapes = ", ".join(f"{n} {list(d)}" for n, d in inputs) or "none"
        raise PerceptionInputError(
            f"{where}: does not match the network: its inputs are {shapes}, expected one of "
            f"shape [N, {IN_CHANNELS}, H, W] for any H and W"
        )
    try:
        net = cv2.dnn.readNetFromONNX(np.frombuffer(data, np.uint8))
        net.setInput(np.zeros((1, IN_CHANNELS, _PROBE, _PROBE), np.float32))
        shape = tuple(net.forward().shape)
    except cv2.error as exc:
        why = _cv_error(exc)
        raise PerceptionInputError(
            f"{where}: does not match the network: OpenCV cannot run it ({why})"
        ) from None
    if shape != (1, N_CLASSES, _PROBE, _PROBE):
        raise PerceptionInputError(
            f"{where}: does not match the network: it maps a (1, {IN_CHANNELS}, {_PROBE}, "
            f"{_PROBE}) input to {shape}, expected (1, {N_CLASSES}, {_PROBE}, {_PROBE})"
        )
    return net


def _cv_error(exc: cv2.error) -> str:
    """The gist of an OpenCV error: its ``error: (...) message`` line, without the source path."""
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    for ln in lines:
        if "error: (" in ln:
            return ln.split("error: ", 1)[1][:ERROR_GIST_CHARS]
    return (lines or [type(exc).__name__])[0][:ERROR_GIST_CHARS]


# ONNX files are protocol buffers (a ModelProto). Reading the metadata needs only the top level of
# the message, so it is read here rather than with the onnx package, which inference does not need.
_IR_VERSION, _GRAPH, _METADATA = 1, 7, 14  # ModelProto field numbers
#: The protocol buffer encoding (protobuf.dev/programming-guides/encoding): a key is the field
#: number shifted left by 3 bits over the wire type; a varint carries 7 bits a byte, low first,
#: the top bit set on every byte but the last, and is at most 64 bits (shifts up to 63).
_WIRE_BITS, _WIRE_MASK = 3, 0x7
_VARINT_BITS, _VARINT_MASK, _VARINT_MORE = 7, 0x7F, 0x80  #: payload bits, their mask, more flag
_VARINT_MAX_SHIFT = 63  #: the last shift of a 64-bit varint
#: wire types: varint, fixed 64-bit, length-delimited, fixed 32-bit
_VARINT, _I64, _LEN, _I32 = 0, 1, 2, 5
_I64_SIZE, _I32_SIZE = 8, 4  #: bytes of the fixed wire types
#: field numbers of the messages inside a ModelProto read here (onnx/onnx.proto):
#: StringStringEntryProto key, value; GraphProto initializer, input; TensorProto name;
#: ValueInfoProto name, type; TypeProto tensor_type; TypeProto.Tensor shape;
#: TensorShapeProto dim; its Dimension's dim_value, dim_param.
_ENTRY_KEY, _ENTRY_VALUE = 1, 2
_GRAPH_INITIALIZER, _GRAPH_INPUT = 5, 11  #: GraphProto
_TENSOR_NAME = 8  #: TensorProto
_VALUE_INFO_NAME, _VALUE_INFO_TYPE = 1, 2  #: ValueInfoProto
_TYPE_TENSOR = 1  #: TypeProto
_TENSOR_TYPE_SHAPE = 2  #: TypeProto.Tensor
_SHAPE_DIM = 1  #: TensorShapeProto
_DIM_VALUE, _DIM_PARAM = 1, 2  #: TensorShapeProto.Dimension


def _varint(data: bytes, i: int) -> tuple[int, int]:
    out = shift = 0
    while True:
        if i >= len(data):
            raise ValueError("truncated")
        b = data[i]
        i += 1
        out |= (b & _VARINT_MASK) << shift
        if not b & _VARINT_MORE:
            return out, i
        shift += _VARINT_BITS
        if shift > _VARINT_MAX_SHIFT:
            raise ValueError("a malformed number")


def _fields(data: bytes) -> Iterator[tuple[int, int, int | bytes, int, int]]:
    """``(field, wire type, value, start, end)`` for each field at the top level of the protocol
    buffer ``data`` (``value``: an int for a varint, else the raw bytes); ValueError when
    ``data`` is not one."""
    i, n = 0, len(data)
    while i < n:
        start = i
        key, i = _varint(data, i)
        field, wire = key >> _WIRE_BITS, key & _WIRE_MASK
        value: int | bytes
        if field == 0:
            raise ValueError("not a protocol buffer")
        if wire == _VARINT:
            value, i = _varint(data, i)
        elif wire == _LEN:
            size, i = _varint(data, i)
            value, i = data[i : i + size], i + size
        elif wire in (_I64, _I32):
            size = _I64_SIZE if wire == _I64 else _I32_SIZE
            value, i = data[i : i + size], i + size
        else:
            raise ValueError("not a protocol buffer")
        if i > n:
            raise ValueError("truncated")
        yield field, wire, value, start, i


def onnx_metadata(data: bytes) -> dict[str, str]:
    """The ``metadata_props`` of the ONNX model ``data`` (the last value of a repeated key);
    ValueError when ``data`` is not an ONNX model."""
    meta: dict[str, str] = {}
    seen = set()
    for field, wire, value, _, _ in _fields(data):
        seen.add((field, wire))
        if field == _METADATA and wire == _LEN:
            assert isinstance(value, bytes)
            entry = {f: v for f, w, v, _, _ in _fields(value) if w == _LEN}
            try:
                key, val = (
                    bytes(entry.get(f, b"")).decode() for f in (_ENTRY_KEY, _ENTRY_VALUE)
                )
            except UnicodeDecodeError:
                raise ValueError("metadata that is not text") from None
            meta[key] = val
    if (_IR_VERSION, _VARINT) not in seen or (_GRAPH, _LEN) not in seen:
        raise ValueError("no model version or no graph")
    return meta


def _sub(msg: bytes, field: int) -> list[bytes]:
    """The length-delimited fields number ``field`` at the top level of ``msg``."""
    return [v for f, _, v, _, _ in _fields(msg) if f == field and isinstance(v, bytes)]


def onnx_inputs(data: bytes) -> list[tuple[str, tuple[int | str, ...]]]:
    """Name and shape (a dimension's size, or its name where it is free) of each input of the
    ONNX model ``data``'s graph that is not an initializer; ValueError when ``data`` is not an
    ONNX model."""
    graphs = _sub(data, _GRAPH)
    if not graphs:
        raise ValueError("no graph")
    graph = graphs[-1]
    # GraphProto: initializer 5 (TensorProto, name 8), input 11 (ValueInfoProto: name 1, type 2);
    # TypeProto: tensor_type 1 (shape 2); TensorShapeProto: dim 1 (dim_value 1, dim_param 2).
    weights = {b"".join(_sub(t, _TENSOR_NAME)) for t in _sub(graph, _GRAPH_INITIALIZER)}
    out = []
    for value_info in _sub(graph, _GRAPH_INPUT):
        name = b"".join(_sub(value_info, _VALUE_INFO_NAME))
        if name in weights:
            continue
        dims: list[int | str] = []
        for t in _sub(value_info, _VALUE_INFO_TYPE):
            for tensor in _sub(t, _TYPE_TENSOR):
                for shape in _sub(tensor, _TENSOR_TYPE_SHAPE):
                    for dim in _sub(shape, _SHAPE_DIM):
                        size = [
                            v for f, w, v, _, _ in _fields(dim) if f == _DIM_VALUE and w == _VARINT
                        ]
                        if size:
                            dims.append(int(size[-1]))
                        else:
                            dims.append(b"".join(_sub(dim, _DIM_PARAM)).decode())
        out.append((name.decode(errors="replace"), tuple(dims)))
    return out


def with_metadata(data: bytes, meta: dict[str, str]) -> bytes:
    """The ONNX model ``data`` with ``meta`` as its only ``metadata_props``."""

    def length_delimited(field: int, payload: bytes) -> bytes:
        out, key, size = bytearray(), field << _WIRE_BITS | _LEN, len(payload)
        for v in (key, size):
            while v > _VARINT_MASK:
                out.append(v & _VARINT_MASK | _VARINT_MORE)
                v >>= _VARINT_BITS
            out.append(v)
        return bytes(out) + payload

    kept = b"".join(data[s:e] for f, _, _, s, e in _fields(data) if f != _METADATA)
    added = b"".join(
        length_delimited(
            _METADATA,
            length_delimited(_ENTRY_KEY, k.encode()) + length_delimited(_ENTRY_VALUE, v.encode()),
        )
        for k, v in meta.items()
    )
    return kept + added


def _check_inputs(hm: HeightMap, rgb: NDArray[np.uint8]) -> None:
    h = hm.height
    if not isinstance(h, np.ndarray) or h.ndim != 2:  # exact: an image: rows, columns
        raise PerceptionInputError(
            f"height must be an (H, W) array, got {getattr(h, 'shape', type(h).__name__)}"
        )
    if (
        not isinstance(rgb, np.ndarray)
        or rgb.shape != (*h.shape, RGB_CHANNELS)
        or rgb.dtype != np.uint8
    ):
        raise PerceptionInputError(
            f"rgb must be a uint8 {h.shape[0]} x {h.shape[1]} x 3 array like the height map, got "
            f"{getattr(rgb, 'dtype', type(rgb).__name__)} {getattr(rgb, 'shape', '')}"
        )
