"""Exact rewrites of exported stages that ONNX Runtime's CPU kernels run faster.

    python -m lsyd.optimise --model ../models/default     # rewrites the folder's stages in place

ONNX Runtime computes convolutions in a blocked channel layout (8 channels a block with
AVX2, 16 with AVX-512) and pads a convolution's output channels to whole blocks. A
convolution with a few output channels computes mostly padding: the decoder's last 7x7
convolution (16 to 3 channels at full resolution) is 15% of the network's FLOPs but took a
third of its time.

``convs_by_rows`` computes such a kh x kw convolution by kernel rows: one 1 x kw convolution
with kh times the outputs, whose channel j * O + o is row j of output o's kernel applied along
the image's rows, then the sum of kh slices of it, slice j shifted down by j rows:
``y[o, r] = sum_j z[j * O + o, r + j]``. The 1 x kw convolution pads kh // 2 rows above and
below, which are the original's zero padding rows, so the result is exact up to rounding
(the same products, summed in another order). The decoder's 21 row channels fill 3 blocks of
8; the slices and their sum are small memory-bound operations.

Measured against another exact rewrite, SpaceToDepth(4), a 3x3 convolution on 4x4 blocks and
DepthToSpace(4): two thirds of that convolution's taps are zeros, and the decoder took 3.4 ms
of CPU a frame with it against 2.5 ms by rows, 5.0 ms before either (1 thread, CPU time, so
the shared machine's load counts less).

Every rewrite keeps the stage's inputs and outputs (names, shapes, dtypes: what the element
checks on load, ``plugin/engine/contract.rs``) and is checked against the original graph on
random inputs before it is written (``TOLERANCE``). A rewritten convolution keeps its
parameters' names, so ``original_parameter`` can still load the model's weights into PyTorch.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import onnx
from onnx import helper, numpy_helper

from . import contract

# Rewritten: convolutions with at most this many output channels. Measured on the 2-core AVX2
# machine (CPU time, 1 thread): the decoder's 3-channel output convolution gains (decoder 5.0 to
# 2.5 ms); the encoder's 5-channel stem, whose blocked layout wastes only 3 of 8 channels,
# barely does (encoder 1.21 to 1.18 ms) and was no faster in wall time, with 8 more operations.
MAX_OUTPUT_CHANNELS = 4
# Max abs difference allowed between a rewritten stage and the original (outputs are O(1)).
TOLERANCE = 1e-5


def row_weight(w: np.ndarray) -> np.ndarray:
    """A convolution's weight [O, C, kh, kw] as the 1 x kw convolution's [kh * O, C, 1, kw],
    channel j * O + o being row j of output o's kernel."""
    cout, cin, kh, kw = w.shape
    return w.transpose(2, 0, 1, 3).reshape(kh * cout, cin, 1, kw)


def original_parameter(value: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """A rewritten convolution's weight or bias back in its original ``shape``."""
    cout = shape[0]
    if value.ndim == 4:
        return value.reshape(-1, cout, *value.shape[1:2], value.shape[3]).transpose(1, 2, 0, 3)
    # The bias is in one row's channels, zeros in the others'.
    return value.reshape(-1, cout).sum(axis=0)


def _attrs(node: onnx.NodeProto) -> dict:
    return {a.name: helper.get_attribute_value(a) for a in node.attribute}


def _rewritable(node: onnx.NodeProto, inits: dict, shapes: dict) -> bool:
    """A stride-1, 'same'-padded convolution with constant parameters, at most
    ``MAX_OUTPUT_CHANNELS`` outputs, a kernel of more than one row and a known height."""
    if node.op_type != "Conv" or node.input[1] not in inits:
        return False
    if len(node.input) > 2 and node.input[2] not in inits:
        return False
    cout, _, kh, kw = inits[node.input[1]].dims
    a = _attrs(node)
    shape = shapes.get(node.input[0])
    return (
        cout <= MAX_OUTPUT_CHANNELS
        and kh > 1
        and kh % 2 == 1
        and kw % 2 == 1
        and a.get("group", 1) == 1
        and a.get("auto_pad", b"NOTSET") == b"NOTSET"
        and list(a.get("strides", [1, 1])) == [1, 1]
        and list(a.get("dilations", [1, 1])) == [1, 1]
        and list(a.get("pads", [0] * 4)) == [kh // 2, kw // 2] * 2
        and shape is not None
        and len(shape) == 4
        and isinstance(shape[2], int)
    )


def convs_by_rows(model: onnx.ModelProto) -> list[str]:
    """Rewrites, in place, every convolution of a graph with few outputs as a convolution by
    kernel rows and a sum of shifted rows (see the module's notes). Returns the rewritten
    nodes' names."""
    g = model.graph
    inits = {t.name: t for t in g.initializer}
    inferred = onnx.shape_inference.infer_shapes(model, strict_mode=True).graph
    shapes = {
        v.name: [d.dim_value if d.HasField("dim_value") else None for d in v.type.tensor_type.shape.dim]
        for v in [*inferred.input, *inferred.value_info, *inferred.output]
    }
    rewritten = []
    # By name: rebuilding the node list below replaces the node objects.
    for name in [n.name for n in g.node if _rewritable(n, inits, shapes)]:
        at, conv = next((i, n) for i, n in enumerate(g.node) if n.name == name)
        w = inits[conv.input[1]]
        cout, _, kh, kw = w.dims
        height = shapes[conv.input[0]][2]
        w.CopyFrom(numpy_helper.from_array(row_weight(numpy_helper.to_array(w)), w.name))
        if len(conv.input) > 2:
            # The bias is added once, with the middle row's channels.
            b = inits[conv.input[2]]
            bias = numpy_helper.to_array(b)
            rows_bias = np.zeros((kh, cout), dtype=bias.dtype)
            rows_bias[kh // 2] = bias
            b.CopyFrom(numpy_helper.from_array(rows_bias.ravel(), b.name))
        for a in conv.attribute:
            if a.name == "kernel_shape":
                a.CopyFrom(helper.make_attribute("kernel_shape", [1, kw]))
            elif a.name == "pads":
                a.CopyFrom(helper.make_attribute("pads", [kh // 2, kw // 2] * 2))

        y = conv.output[0]
        conv.output[0] = f"{y}/rows"
        axes = f"{conv.name}/rows/axes"
        g.initializer.append(numpy_helper.from_array(np.array([1, 2], np.int64), axes))
        nodes = []
        for j in range(kh):
            starts, ends = f"{conv.name}/row{j}/starts", f"{conv.name}/row{j}/ends"
            g.initializer.extend(
                [
                    numpy_helper.from_array(np.array([j * cout, j], np.int64), starts),
                    numpy_helper.from_array(np.array([(j + 1) * cout, j + height], np.int64), ends),
                ]
            )
            nodes.append(
                helper.make_node("Slice", [conv.output[0], starts, ends, axes], [f"{y}/row{j}"], f"{conv.name}/row{j}")
            )
        nodes.append(helper.make_node("Sum", [n.output[0] for n in nodes], [y], f"{conv.name}/sum"))
        all_nodes = list(g.node)
        all_nodes[at + 1 : at + 1] = nodes
        del g.node[:]
        g.node.extend(all_nodes)
        rewritten.append(conv.name)
    onnx.checker.check_model(model, full_check=True)
    return rewritten


def max_difference(original: onnx.ModelProto, rewritten: onnx.ModelProto, feeds: list[dict]) -> float:
    """Max abs difference of all outputs of two graphs with the same inputs, over ``feeds``."""
    a, b = (contract.open_session(m.SerializeToString()) for m in (original, rewritten))
    worst = 0.0
    for feed in feeds:
        for x, y in zip(a.run(None, feed), b.run(None, feed)):
            worst = max(worst, float(np.abs(x - y).max()))
    return worst


def random_feeds(model: onnx.ModelProto, n: int = 3, seed: int = 0) -> list[dict]:
    """Inputs in [0, 1) of a stage's shapes: the range of images, lights and activations."""
    rng = np.random.default_rng(seed)
    shapes = {i.name: [d.dim_value for d in i.type.tensor_type.shape.dim] for i in model.graph.input}
    return [{k: rng.random(s, dtype=np.float32) for k, s in shapes.items()} for _ in range(n)]


def optimise_file(path: Path) -> tuple[list[str], float]:
    """Rewrites one stage file in place when any rewrite applies; returns the rewritten
    nodes and the max abs difference from the original on random inputs."""
    original = onnx.load(path)
    model = onnx.ModelProto()
    model.CopyFrom(original)
    rewritten = convs_by_rows(model)
    if not rewritten:
        return [], 0.0
    diff = max_difference(original, model, random_feeds(original))
    if diff > TOLERANCE:
        raise ValueError(f"{path}: the rewrite differs from the original by {diff:.1e} > {TOLERANCE:.0e}")
    onnx.save(model, path)
    return rewritten, diff


def optimise_folder(folder: Path) -> dict[str, tuple[list[str], float]]:
    """Rewrites a model folder's network stages in place (idempotent: a rewritten
    convolution's kernel has one row and no longer qualifies)."""
    return {stage: optimise_file(folder / contract.stage_file(stage)) for stage in contract.STAGES}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", type=Path, required=True, help="a model folder, rewritten in place")
    a = p.parse_args()
    for stage, (nodes, diff) in optimise_folder(a.model).items():
        print(f"{stage}: {', '.join(nodes) or 'nothing to rewrite'}" + (f" (max abs diff {diff:.1e})" if nodes else ""))


if __name__ == "__main__":
    main()
