"""The learned segmentation's network in torch, for training only: :class:`SegNet`, its state
dict's checks and its export to ONNX, the file that inference reads.

``cell train-perception`` trains a :class:`SegNet` and writes both its state dict (``.pt``, to
train on or export again) and its ONNX export (``.onnx``, what
:class:`skills.perception.learned.LearnedSegmenter` runs through OpenCV, without torch). The
export carries the input format as ONNX metadata, as the state dict carries it in its ``format``
buffer. Exporting needs the ``onnx`` package besides torch (both in the ``learned`` extra).
"""

from __future__ import annotations

import io
import json
import pickle
import warnings
from pathlib import Path

import numpy as np
import torch
from numpy.typing import NDArray
from torch import nn
from torch.nn import functional as F

from skills.perception.heightmap import PerceptionInputError
from skills.perception.learned import (
    ERROR_GIST_CHARS,
    FORMAT_KEY,
    H_AXIS,
    IN_CHANNELS,
    N_CLASSES,
    W_AXIS,
    WIDTHS,
    format_values,
    with_metadata,
)

#: The ONNX operator set of the export: its Conv, Relu, MaxPool, Resize (nearest, constant
#: scales) and Concat are read by OpenCV's DNN module from 4.8 on.
ONNX_OPSET = 17
#: px: the side of every convolution of a block, with a padding of one pixel so the size
#: stays; two 3 x 3 layers per block are the U-Net's own. The weights' shapes hold it: the
#: shipped model (cell/data/perception_unet.onnx) was trained with it.
KERNEL = 3
#: the pooling between levels (2 x 2 max) and the upsampling back (nearest, by 2.0): each level
#: halves the resolution, which input_crop's multiple of 4 (two levels) relies on.
POOL, UPSAMPLE = 2, 2.0
#: decimals of the input format written into an export's metadata (the format's values are
#: short decimals; this drops float32 round-off such as 0.07 -> 0.07000000029802322)
FORMAT_DECIMALS = 6
#: decimals of a format shown in a message
SHOWN_DECIMALS = 4


def _format_tensor() -> torch.Tensor:
    return torch.tensor(format_values())


def _block(c_in: int, c_out: int) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(c_in, c_out, KERNEL, padding=1, bias=False),
        nn.BatchNorm2d(c_out),
        nn.ReLU(inplace=True),
        nn.Conv2d(c_out, c_out, KERNEL, padding=1, bias=False),
        nn.BatchNorm2d(c_out),
        nn.ReLU(inplace=True),
    )


class SegNet(nn.Module):
    """A three-level U-Net: (N, IN_CHANNELS, h, w) -> (N, 3, h, w) class logits.

    ``h`` and ``w`` must be multiples of 4 (two poolings, then two upsamplings by 2);
    :func:`skills.perception.learned.input_crop` crops to that. Three levels give a receptive
    field of ~45 pixels (~4.5 cm in the bin): enough to see a contact line together with the
    facets of both parts on either side of it, which is what decides the boundary class; the
    interior class only needs the height under the pixel.

    The upsamplings are by a constant factor of 2 (not to the skip connection's size, the same
    for such inputs): the ONNX export then holds no shape arithmetic, which OpenCV's DNN module
    before 5.0 cannot run on inputs of varying size.
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
        b = self.enc1(F.max_pool2d(a, POOL))
        c = self.mid(F.max_pool2d(b, POOL))
        d = self.dec1(torch.cat([F.interpolate(c, scale_factor=UPSAMPLE), b], dim=1))
        e = self.dec0(torch.cat([F.interpolate(d, scale_factor=UPSAMPLE), a], dim=1))
        return self.head(e)


def onnx_bytes(net: SegNet) -> bytes:
    """``net`` (put in eval mode: batch norms folded into the convolutions) exported to ONNX,
    with any height and width, and the input format as metadata (:data:`FORMAT_KEY`)."""
    net = net.eval()
    buf = io.BytesIO()
    example = torch.zeros(1, IN_CHANNELS, 64, 64)
    with warnings.catch_warnings():
        # torch 2.9+ warns that the TorchScript exporter is the legacy one; the other
        # (dynamo=True) needs onnxscript and writes a graph OpenCV 4.x cannot read.
        warnings.simplefilter("ignore", DeprecationWarning)
        torch.onnx.export(
            net,
            (example,),
            buf,
            dynamo=False,
            opset_version=ONNX_OPSET,
            input_names=["x"],
            output_names=["logits"],
            dynamic_axes={"x": {H_AXIS: "h", W_AXIS: "w"}, "logits": {H_AXIS: "h", W_AXIS: "w"}},
        )
    fmt = [round(float(v), FORMAT_DECIMALS) for v in net.get_buffer("format")]
    return with_metadata(buf.getvalue(), {FORMAT_KEY: json.dumps(fmt)})


def torch_logits(net: SegNet, x: NDArray[np.float32]) -> NDArray[np.float32]:
    """``net``'s logits for the network input ``x`` (N, IN_CHANNELS, h, w) on one torch thread
    (the reference the ONNX export is compared with)."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        with torch.no_grad():
            return net.eval()(torch.from_numpy(np.ascontiguousarray(x))).numpy()
    finally:
        torch.set_num_threads(before)


def load_state(path: str | Path) -> SegNet:
    """The :class:`SegNet` of a state dict written by ``cell train-perception``. A missing
    file, a file torch cannot read and a state dict of another network or input format each
    raise :class:`PerceptionInputError` naming the file and the reason."""
    path = Path(path)
    where = f"segmentation weights {path}"
    if not path.is_file():
        what = "is a directory, not a weights file" if path.is_dir() else "no such file"
        raise PerceptionInputError(f"{where}: {what}")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except OSError as exc:
        raise PerceptionInputError(f"{where}: cannot be read: {exc.strerror or exc}") from None
    except Exception as exc:  # torch raises many types for a file it cannot unpickle
        # weights_only refuses anything but tensors and plain containers; its message is a
        # page long, so only its gist is kept.
        if isinstance(exc, pickle.UnpicklingError):
            why = "not a file of tensors written by torch.save"
        else:
            why = (str(exc).splitlines() or [type(exc).__name__])[0][:ERROR_GIST_CHARS]
        raise PerceptionInputError(f"{where}: cannot be read as torch weights ({why})") from None
    net = SegNet()
    check_state_dict(net, state, path)
    net.load_state_dict(state)
    return net.eval()


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
    return [round(float(v), SHOWN_DECIMALS) for v in t.flatten()]
