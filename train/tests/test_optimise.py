"""The stage rewrites (``lsyd.optimise``): a convolution with few outputs computed on 4x4 blocks
matches the original up to rounding, on single convolutions and on the shipped network's
stages with real and random inputs; other convolutions are left alone; the shipped model is
rewritten and keeps its contract; the benchmark times it with and without the rewrites beside
PyTorch."""

import numpy as np
import onnx
import pytest
import torch
from onnx import TensorProto, helper, numpy_helper
from skimage import data as skdata

from lsyd import contract, data, export, optimise
from lsyd.evaluation import benchmark


def conv_graph(cout: int, k: int, size: int, stride: int = 1, pad: int | None = None, cin: int = 16):
    """x [1,cin,size,size] -> Conv(k x k, bias) -> Clip(0, 1) -> y, with random weights."""
    rng = np.random.default_rng(k * 100 + cout)
    pad = k // 2 if pad is None else pad
    w = (rng.standard_normal((cout, cin, k, k)) / np.sqrt(cin * k * k)).astype(np.float32)
    b = rng.standard_normal(cout).astype(np.float32)
    nodes = [
        helper.make_node(
            "Conv", ["x", "w", "b"], ["h"], "conv", kernel_shape=[k, k], pads=[pad] * 4, strides=[stride] * 2
        ),
        helper.make_node("Clip", ["h", "lo", "hi"], ["y"], "clip"),
    ]
    out = (size + 2 * pad - k) // stride + 1
    graph = helper.make_graph(
        nodes,
        "conv",
        [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, cin, size, size])],
        [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, cout, out, out])],
        [
            numpy_helper.from_array(w, "w"),
            numpy_helper.from_array(b, "b"),
            numpy_helper.from_array(np.float32(0), "lo"),
            numpy_helper.from_array(np.float32(1), "hi"),
        ],
    )
    # ir_version pinned: onnx 1.23 writes IR 14 by default, newer than ONNX Runtime 1.31 reads.
    return helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)], ir_version=8)


def copy(model: onnx.ModelProto) -> onnx.ModelProto:
    out = onnx.ModelProto()
    out.CopyFrom(model)
    return out


@pytest.mark.parametrize("cout,k,size", [(3, 7, 96), (1, 3, 16), (4, 5, 32), (2, 9, 24)])
def test_convolution_on_blocks_matches_the_original(cout, k, size):
    original = conv_graph(cout, k, size)
    rewritten = copy(original)
    assert optimise.space_to_depth_convs(rewritten) == ["conv"]
    # The clamp runs on blocks, where ONNX Runtime fuses it into the convolution.
    assert [n.op_type for n in rewritten.graph.node] == ["SpaceToDepth", "Conv", "Clip", "DepthToSpace"]
    assert rewritten.graph.output == original.graph.output
    # Inputs in [0, 1) and wider, negative ones (a feature map's range), so the clamp cuts both ends.
    wide = {"x": 4 * np.random.default_rng(1).standard_normal((1, 16, size, size)).astype(np.float32)}
    diff = optimise.max_difference(original, rewritten, optimise.random_feeds(original) + [wide])
    assert diff <= optimise.TOLERANCE


@pytest.mark.parametrize(
    "why,model",
    [
        ("strided", conv_graph(3, 3, 16, stride=2)),
        ("one output block", conv_graph(8, 7, 96)),
        ("the stem's 5 outputs", conv_graph(5, 7, 96, cin=3)),
        ("map not whole blocks", conv_graph(3, 7, 18)),
        ("not 'same' padding", conv_graph(3, 7, 96, pad=0)),
    ],
)
def test_other_convolutions_are_left_alone(why, model):
    assert optimise.space_to_depth_convs(model) == [], why


@pytest.mark.parametrize("k,block", [(7, 4), (3, 4), (5, 2), (9, 4)])
def test_kernel_weight_recovers_the_original_weight(k, block):
    w = np.random.default_rng(k).standard_normal((3, 5, k, k)).astype(np.float32)
    wd = optimise.depth_weight(w, block)
    r = -(-(k // 2) // block)
    assert wd.shape == (3 * block * block, 5 * block * block, 2 * r + 1, 2 * r + 1)
    np.testing.assert_array_equal(optimise.kernel_weight(wd, 3, k), w)


def tensors(model: onnx.ModelProto) -> list[tuple]:
    def spec(v):
        t = v.type.tensor_type
        return v.name, [d.dim_value for d in t.shape.dim], onnx.helper.tensor_dtype_to_np_dtype(t.elem_type).name

    return [[spec(v) for v in model.graph.input], [spec(v) for v in model.graph.output]]


def test_shipped_model_is_rewritten_and_keeps_its_contract(shipped_model, tmp_path):
    m = contract.read(shipped_model / "model.json")
    for stage in contract.STAGES:
        spec = m["stages"][stage]
        model = onnx.load(shipped_model / spec["file"])
        want = [[(t["name"], t["shape"], t["dtype"]) for t in spec[k]] for k in ("inputs", "outputs")]
        assert tensors(model) == want, stage
        assert optimise.space_to_depth_convs(model) == [], f"{stage} has a convolution left to rewrite"
    assert "SpaceToDepth" in {n.op_type for n in onnx.load(shipped_model / "decoder.onnx").graph.node}


def real_frame(resolution: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """scikit-image's astronaut portrait, head and shoulders, as the element crops a face; a
    white screen and the portrait itself shown on the screen as the source and target lights."""
    portrait = skdata.astronaut()
    image = data.to_tensor(data.area_resize(portrait[:320, 90:410], resolution)).numpy()[None]
    white = contract.light_from_frames(np.full((90, 160, 3), 255, np.uint8))[None]
    return image, white, contract.light_from_frames(portrait)[None]


def test_rewritten_stages_match_the_export_on_real_and_random_inputs(shipped_model, tmp_path):
    net = export.network_from_model(shipped_model)
    m = contract.read(shipped_model / "model.json")
    specs = contract.stage_specs(m["resolution"], tuple(m["widths"]))
    image, source, target = real_frame(m["resolution"])
    ref = export.reference_run(net, *(torch.from_numpy(x) for x in (image, source, target)))
    export.write_stages(net, specs, tmp_path, ref, rewrite=False)
    real = contract.StageChain(tmp_path).stage_inputs(image, source, target)
    diffs = {}
    for stage in contract.STAGES:
        original = onnx.load(tmp_path / contract.stage_file(stage))
        rewritten = copy(original)
        if not optimise.space_to_depth_convs(rewritten):
            continue
        feeds = [real[stage], *optimise.random_feeds(original)]
        diffs[stage] = optimise.max_difference(original, rewritten, feeds)
        # The shipped stage is this rewrite of its own weights.
        shipped = onnx.load(shipped_model / contract.stage_file(stage))
        assert optimise.max_difference(rewritten, shipped, feeds) == 0.0, stage
    print(f"max abs difference of the rewritten stages: {diffs}")  # shown with pytest -s
    assert list(diffs) == ["decoder"]
    assert max(diffs.values()) <= optimise.TOLERANCE


def test_network_timings_compare_the_rewrite_and_the_peer_in_one_run(shipped_model):
    timings = benchmark.network_timings(shipped_model, threads=(1,), rounds=2, frames=1)
    for name in ("onnxruntime", "onnxruntime, not rewritten", "pytorch"):
        t = timings[name]["1"]
        assert 0 < t["min"] <= t["median"] <= t["max"], name
    assert timings["peer_ratio"]["1"] > 0
    assert "| 1 |" in benchmark.network_table(timings)
