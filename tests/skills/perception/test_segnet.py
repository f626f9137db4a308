"""The learned segmentation's torch side (training only): the ONNX export agrees with torch, state
dicts and foreign networks are refused, and a tiny ``train-perception`` run writes a model that
loads. Skipped where torch (the ``learned`` extra) is not installed; inference without torch:
test_learned.py."""

from __future__ import annotations

import argparse
import io
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")
onnx = pytest.importorskip("onnx")

from lab.train_perception_cmd import (  # noqa: E402
    DEFAULT_STATE,
    DEFAULT_WEIGHTS,
    RenderedScene,
    add_parser,
    render_scene,
)
from skills.perception.heightmap import PerceptionInputError  # noqa: E402
from skills.perception.learned import (  # noqa: E402
    FORMAT_KEY,
    IN_CHANNELS,
    LearnedSegmenter,
    input_crop,
    network_input,
    with_metadata,
)
from skills.perception.segnet import SegNet, load_state, onnx_bytes, torch_logits  # noqa: E402

#: Logits of OpenCV's run of the export and of torch's may differ by float rounding only (seen:
#: 3.6e-5 at most over 15 scenes, on logits up to ~9).
LOGIT_TOLERANCE = 1e-4
#: Nominal scenes (as in test_learned.py) and training-like ones (the camera moved: other crops).
SCENES = ((1000, False), (1002, False), (1008, False), (3, True), (7, True))


def run_train(argv: list[str]) -> int:
    """``cell train-perception ARGV`` through its own parser (as cell/cli.py registers it)."""
    parser = argparse.ArgumentParser(prog="cell")
    sub = parser.add_subparsers(dest="command", required=True)
    add_parser(sub)
    args = parser.parse_args(["train-perception", *argv])
    return int(args.func(args))


@pytest.fixture(scope="module")
def scenes() -> list[RenderedScene]:
    return [render_scene(seed, augment) for seed, augment in SCENES]


def agreement(net: SegNet, seg: LearnedSegmenter, sc: RenderedScene) -> tuple[float, int, bool]:
    """Largest logit difference, pixels of another class and whether the instance labels are
    the same, between torch's ``net`` and OpenCV's ``seg`` on one scene."""
    crop = input_crop(sc.hm.height)
    ref = torch_logits(net, network_input(sc.hm.height, sc.rgb, crop)[None])[0]
    got, got_crop = seg.logits(sc.hm, sc.rgb)
    assert got_crop == crop and got.shape == ref.shape
    diff = float(np.abs(got - ref).max())
    other = int((got.argmax(axis=0) != ref.argmax(axis=0)).sum())
    same = np.array_equal(
        seg.labels_from_logits(sc.hm, got, crop), seg.labels_from_logits(sc.hm, ref, crop)
    )
    return diff, other, same


def test_the_shipped_model_agrees_with_its_torch_network(scenes: list[RenderedScene]) -> None:
    """The shipped ONNX model, run by OpenCV, against the shipped state dict run by torch: the
    same logits to float rounding, the same class at every pixel, the same instances."""
    net, seg = load_state(DEFAULT_STATE), LearnedSegmenter(DEFAULT_WEIGHTS)
    shapes = set()
    for sc in scenes:
        diff, other, same = agreement(net, seg, sc)
        assert diff < LOGIT_TOLERANCE and other == 0 and same, (sc.seed, diff, other)
        shapes.add(input_crop(sc.hm.height))
    assert len(shapes) > 1, "the scenes should exercise more than one input size"


def test_the_export_is_valid_onnx_with_the_format() -> None:
    model = onnx.load_from_string(onnx_bytes(load_state(DEFAULT_STATE)))
    onnx.checker.check_model(model)
    meta = {p.key: p.value for p in model.metadata_props}
    assert meta == {FORMAT_KEY: "[1.0, 1.0, 0.07, 2.0, 3.0]"}
    ops = {n.op_type for n in model.graph.node}
    assert ops == {"Conv", "Relu", "MaxPool", "Resize", "Concat", "Constant"}, ops


def test_weights_of_another_network_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "other.pt"
    torch.save(SegNet(widths=(8, 16, 32)).state_dict(), path)
    with pytest.raises(PerceptionInputError, match="does not match the network") as exc:
        load_state(path)
    assert "'enc0.0.weight'" in str(exc.value) and str(path) in str(exc.value)


def test_state_dict_missing_a_key_is_refused(tmp_path: Path) -> None:
    state = SegNet().state_dict()
    del state["head.bias"]
    path = tmp_path / "cut.pt"
    torch.save(state, path)
    with pytest.raises(
        PerceptionInputError, match="does not match the network: no key 'head.bias'"
    ):
        load_state(path)


def test_a_file_that_is_not_torch_weights_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "junk.pt"
    path.write_bytes(b"not a torch file")
    with pytest.raises(PerceptionInputError, match="cannot be read as torch weights"):
        load_state(path)


def _export(module: torch.nn.Module, channels: int, any_size: bool) -> bytes:
    buf = io.BytesIO()
    axes = {"x": {2: "h", 3: "w"}} if any_size else None
    x = torch.zeros(1, channels, 16, 16)
    torch.onnx.export(module.eval(), (x,), buf, dynamo=False, input_names=["x"], dynamic_axes=axes)
    return with_metadata(buf.getvalue(), {FORMAT_KEY: "[1, 1, 0.07, 2, 3]"})


@pytest.mark.filterwarnings("ignore::DeprecationWarning")
@pytest.mark.parametrize(
    ("channels_in", "classes", "any_size", "message"),
    [
        (IN_CHANNELS, 2, True, r"maps a \(1, 3, 16, 16\) input to \(1, 2, 16, 16\), expected"),
        (IN_CHANNELS + 1, 3, True, r"its inputs are x \[1, 4, 'h', 'w'\], expected one of shape"),
        (IN_CHANNELS, 3, False, r"its inputs are x \[1, 3, 16, 16\], expected .* any H and W"),
    ],
)
def test_an_onnx_model_of_another_network_is_refused(
    channels_in: int, classes: int, any_size: bool, message: str, tmp_path: Path
) -> None:
    """An ONNX model with the right metadata but another network behind it (OpenCV would run
    the second and third on any input without complaint)."""
    path = tmp_path / "other.onnx"
    path.write_bytes(_export(torch.nn.Conv2d(channels_in, classes, 1), channels_in, any_size))
    with pytest.raises(PerceptionInputError, match=message) as exc:
        LearnedSegmenter(path)
    assert str(exc.value).startswith(f"segmentation weights {path}: ")
    assert "\n" not in str(exc.value)


def test_tiny_training_run_writes_a_model_and_its_state(
    tmp_path: Path, capsys, scenes: list[RenderedScene]
) -> None:
    out = tmp_path / "w" / "tiny.onnx"
    assert run_train(["--scenes", "3", "--epochs", "1", "--seed", "5", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "held out" in printed and "(ONNX," in printed and "(torch state dict," in printed
    seg, net = LearnedSegmenter(out), load_state(out.with_suffix(".pt"))
    diff, _, _ = agreement(net, seg, scenes[0])
    # An untrained-looking network has near ties between classes, so only the logits are held
    # to agree here; the shipped pair's classes and instances are checked above.
    assert diff < LOGIT_TOLERANCE


def test_export_of_a_state_dict(tmp_path: Path, capsys) -> None:
    out = tmp_path / "x.onnx"
    assert run_train(["--export", str(DEFAULT_STATE), "--out", str(out)]) == 0
    assert "differ from torch's by at most" in capsys.readouterr().out
    assert out.read_bytes() == onnx_bytes(load_state(DEFAULT_STATE))
    LearnedSegmenter(out)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--scenes", "1"], "--scenes: must be >= 2"),
        (["--epochs", "0"], "--epochs: must be >= 1"),
        (["--out", "{d}/x.pt"], "--out: .*x.pt: the model is written as ONNX"),
        (["--export", "{d}/none.pt"], r"--export: segmentation weights .*none\.pt: no such file"),
    ],
)
def test_bad_arguments_are_refused_before_rendering(
    tmp_path: Path, argv: list[str], message: str
) -> None:
    argv = [a.replace("{d}", str(tmp_path)) for a in argv]
    if "--out" not in argv:
        argv += ["--out", str(tmp_path / "x.onnx")]
    with pytest.raises(ValueError, match=message):
        run_train(argv)
    assert not list(tmp_path.glob("x.*"))
