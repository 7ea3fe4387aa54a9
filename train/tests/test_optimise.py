"""The stage rewrites (``lsyd.optimise``): a convolution with few outputs computed on 4x4 blocks
matches the original up to rounding; other convolutions are left alone."""

import numpy as np
import onnx
import pytest
from onnx import TensorProto, helper, numpy_helper

from lsyd import optimise


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
