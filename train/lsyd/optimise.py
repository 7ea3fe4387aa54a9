"""Exact rewrites of exported stages that ONNX Runtime's CPU kernels run faster.

    python -m lsyd.optimise --model ../models/default     # rewrites the folder's stages in place

ONNX Runtime computes convolutions in a blocked channel layout (8 channels a block with
AVX2, 16 with AVX-512) and pads a convolution's output channels to whole blocks. A
convolution with a few output channels computes mostly padding: the decoder's last 7x7
convolution (16 to 3 channels at full resolution) is 15% of the network's FLOPs but took a
third of its time.

``space_to_depth_convs`` computes such a convolution on 4x4 blocks of pixels instead:
SpaceToDepth(4), a convolution with 16 times the input and output channels and a 3x3 kernel,
then DepthToSpace(4). Output pixel (4Y + a, 4X + b) with a 7x7 window reaches input rows
4Y + a - 3 .. 4Y + a + 3, all within blocks Y - 1 .. Y + 1, so the 3x3 kernel holds the
7x7 one at offsets that depend on (a, b), with zeros where a tap falls outside the original
window. Zero padding matches because the map's size is a multiple of 4: the 3x3
convolution's padding is exactly the original's padding rows, in whole blocks. The products
summed are the original's, in another order, so results differ only by rounding. The
per-pixel operations that follow (the output's clamp, an activation) move before
DepthToSpace, where ONNX Runtime fuses them into the convolution.

Every rewrite keeps the stage's inputs and outputs (names, shapes, dtypes: what the element
checks on load, ``plugin/engine/contract.rs``) and is checked against the original graph on
random inputs before it is written (``TOLERANCE``). A rewritten convolution keeps its weight's
name, so ``kernel_weight`` can still load the model's weights into PyTorch.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import onnx
from onnx import helper, numpy_helper

from . import contract

BLOCK = 4
# Rewritten: convolutions with at most this many output channels. Measured on the 2-core AVX2
# machine: the decoder's 3-channel output convolution gains (decoder 5.0 to 3.5 ms, 1 thread,
# under load), the encoder's 5-channel stem loses (1.22 to 1.25 ms): 80 output channels on
# blocks compute three times its FLOPs, where the blocked layout wasted only 3 of 8 channels.
MAX_OUTPUT_CHANNELS = 4
# Per-pixel operations with at most scalar parameters, which commute with DepthToSpace.
PER_PIXEL = ("Clip", "Relu", "LeakyRelu", "Sigmoid", "Tanh")
# Max abs difference allowed between a rewritten stage and the original (outputs are O(1)).
TOLERANCE = 1e-5


def depth_weight(w: np.ndarray, block: int) -> np.ndarray:
    """A stride-1 'same' convolution's weight [O, C, k, k] (k odd) as the weight of the same
    convolution on SpaceToDepth(block) maps: [block² O, block² C, 2r + 1, 2r + 1] with
    r = ceil(k // 2 / block). Channels are ONNX's SpaceToDepth / DepthToSpace (DCR) order,
    (row offset * block + column offset) * channels + channel."""
    cout, cin, k, _ = w.shape
    p = k // 2
    r = -(-p // block)
    kd = 2 * r + 1
    out = np.zeros((block, block, cout, block, block, cin, kd, kd), dtype=w.dtype)
    offsets = range(block)
    for a in offsets:  # output pixel's row offset in its block
        for b in offsets:  # and column offset
            for a2 in offsets:  # input pixel's offsets
                for b2 in offsets:
                    for ky in range(kd):
                        dy = block * (ky - r) + a2 - a
                        if abs(dy) > p:
                            continue
                        for kx in range(kd):
                            dx = block * (kx - r) + b2 - b
                            if abs(dx) <= p:
                                out[a, b, :, a2, b2, :, ky, kx] = w[:, :, dy + p, dx + p]
    return out.reshape(block * block * cout, block * block * cin, kd, kd)


def kernel_weight(wd: np.ndarray, cout: int, k: int) -> np.ndarray:
    """The original weight [cout, C, k, k] inside a ``depth_weight``: the taps of the block's
    first output pixel (offsets 0, 0), which reach every offset of the original window."""
    block = int(round((wd.shape[0] // cout) ** 0.5))
    cin = wd.shape[1] // (block * block)
    p, r = k // 2, wd.shape[-1] // 2
    taps = wd[:cout].reshape(cout, block, block, cin, wd.shape[-2], wd.shape[-1])
    w = np.empty((cout, cin, k, k), dtype=wd.dtype)
    for dy in range(-p, p + 1):
        for dx in range(-p, p + 1):
            ky, a2 = divmod(dy, block)
            kx, b2 = divmod(dx, block)
            w[:, :, dy + p, dx + p] = taps[:, a2, b2, :, ky + r, kx + r]
    return w


def _attrs(node: onnx.NodeProto) -> dict:
    return {a.name: helper.get_attribute_value(a) for a in node.attribute}


def _rewritable(node: onnx.NodeProto, inits: dict, shapes: dict) -> bool:
    """A stride-1, 'same'-padded square convolution with constant weights, at most
    ``MAX_OUTPUT_CHANNELS`` outputs and a map that divides into blocks."""
    if node.op_type != "Conv" or node.input[1] not in inits:
        return False
    if len(node.input) > 2 and node.input[2] not in inits:
        return False
    w = inits[node.input[1]]
    cout, _, kh, kw = w.dims
    a = _attrs(node)
    shape = shapes.get(node.input[0])
    return (
        cout <= MAX_OUTPUT_CHANNELS
        and kh == kw
        and kh % 2 == 1
        and a.get("group", 1) == 1
        and a.get("auto_pad", b"NOTSET") == b"NOTSET"
        and list(a.get("strides", [1, 1])) == [1, 1]
        and list(a.get("dilations", [1, 1])) == [1, 1]
        and list(a.get("pads", [0] * 4)) == [kh // 2] * 4
        and shape is not None
        and all(isinstance(d, int) and d % BLOCK == 0 for d in shape[2:])
    )


def space_to_depth_convs(model: onnx.ModelProto) -> list[str]:
    """Rewrites, in place, every convolution with few outputs of a graph as SpaceToDepth, a
    convolution on blocks and DepthToSpace (see the module's notes). Returns the rewritten
    nodes' names."""
    g = model.graph
    inits = {t.name: t for t in g.initializer}
    inferred = onnx.shape_inference.infer_shapes(model, strict_mode=True).graph
    shapes = {
        v.name: [d.dim_value if d.HasField("dim_value") else None for d in v.type.tensor_type.shape.dim]
        for v in [*inferred.input, *inferred.value_info, *inferred.output]
    }
    outputs = {o.name for o in g.output}
    consumers: dict[str, list[onnx.NodeProto]] = {}
    for n in g.node:
        for i in n.input:
            consumers.setdefault(i, []).append(n)

    rewritten = []
    for conv in [n for n in g.node if _rewritable(n, inits, shapes)]:
        w = inits[conv.input[1]]
        k = w.dims[-1]
        # The same parameter in the blocks' layout, under its own name (see kernel_weight).
        w.CopyFrom(numpy_helper.from_array(depth_weight(numpy_helper.to_array(w), BLOCK), w.name))
        if len(conv.input) > 2:
            b = inits[conv.input[2]]
            b.CopyFrom(numpy_helper.from_array(np.tile(numpy_helper.to_array(b), BLOCK * BLOCK), b.name))
        r = -(-(k // 2) // BLOCK)
        for a in conv.attribute:
            if a.name == "kernel_shape":
                a.CopyFrom(helper.make_attribute("kernel_shape", [2 * r + 1] * 2))
            elif a.name == "pads":
                a.CopyFrom(helper.make_attribute("pads", [r] * 4))

        # The convolution and the per-pixel operations after it run on blocks; the chain's
        # last tensor keeps its name and comes out of DepthToSpace.
        chain = [conv]
        while True:
            t = chain[-1].output[0]
            nxt = consumers.get(t, [])
            if t in outputs or len(nxt) != 1 or nxt[0].op_type not in PER_PIXEL or nxt[0].input[0] != t:
                break
            chain.append(nxt[0])
        for node in chain:
            node.output[0] += "/blocks"
        for node in chain[1:]:
            node.input[0] += "/blocks"
        last = chain[-1].output[0]

        x = conv.input[0]
        conv.input[0] = f"{x}/blocks"
        s2d = helper.make_node("SpaceToDepth", [x], [conv.input[0]], f"{conv.name}/space_to_depth", blocksize=BLOCK)
        d2s = helper.make_node(
            "DepthToSpace", [last], [last.removesuffix("/blocks")], f"{conv.name}/depth_to_space", blocksize=BLOCK
        )
        nodes = list(g.node)
        nodes.insert(nodes.index(conv), s2d)
        nodes.insert(nodes.index(chain[-1]) + 1, d2s)
        del g.node[:]
        g.node.extend(nodes)
        rewritten.append(conv.name)
    # Intermediate shapes changed; ONNX Runtime infers its own.
    del g.value_info[:]
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
    rewritten = space_to_depth_convs(model)
    if not rewritten:
        return [], 0.0
    diff = max_difference(original, model, random_feeds(original))
    if diff > TOLERANCE:
        raise ValueError(f"{path}: the rewrite differs from the original by {diff:.1e} > {TOLERANCE:.0e}")
    onnx.save(model, path)
    return rewritten, diff


def optimise_folder(folder: Path) -> dict[str, tuple[list[str], float]]:
    """Rewrites a model folder's network stages in place (idempotent: a rewritten
    convolution no longer qualifies)."""
    return {stage: optimise_file(folder / contract.stage_file(stage)) for stage in contract.STAGES}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", type=Path, required=True, help="a model folder, rewritten in place")
    a = p.parse_args()
    for stage, (nodes, diff) in optimise_folder(a.model).items():
        print(f"{stage}: {', '.join(nodes) or 'nothing to rewrite'}" + (f" (max abs diff {diff:.1e})" if nodes else ""))


if __name__ == "__main__":
    main()
