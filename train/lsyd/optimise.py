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

``convs_by_blocks`` computes a convolution with few input channels, the encoder's 7x7 stem on
the image's 3, over blocks of 4 x 4 pixels: SpaceToDepth(4), a 3x3 convolution from 16 C to
16 O channels (each output phase of a block reads the block and its 8 neighbours) and
DepthToSpace(4). ONNX Runtime runs a 3-channel input with an unblocked direct kernel; 48 input
and 80 output channels fill its blocks, and the int8 variants can quantise the convolution
(``variants.MIN_INT8_INPUTS``). Two thirds of the 3x3 convolution's taps are zeros (an output
reads 9 blocks of 16 pixels, 144, of which the kernel's 49), which the blocked kernel still
computes; it is faster all the same (``BLOCK``).

``adain_into_norms`` folds each AdaIN's scale and shift (``model.AdaIN``: instance
normalisation, then ``x * (1 + gamma) + beta`` with gamma and beta from a light code) into the
instance normalisation's own scale and bias inputs, which ONNX Runtime reads at run time. As
exported, each AdaIN spends some twenty small operations on its [1, 2C] code vector
(``chunk``'s shape arithmetic, two slices, four unsqueezes, an add) and two whole passes over
the features (the multiply and the add) that the normalisation's single pass can do; folded,
it is the light code's Gemm, an add of [1 ... 1, 0 ... 0], a reshape and a split. The delight
stage goes from 224 operations to 49 and the decoder from 131 to 56 (the default model).

Every rewrite keeps the stage's inputs and outputs (names, shapes, dtypes: what the element
checks on load, ``plugin/engine/contract.rs``) and is checked against the original graph on
random inputs before it is written (``TOLERANCE``). A rewritten convolution keeps its
parameters' names, so ``original_parameter`` can still load the model's weights into PyTorch;
the AdaIN fold keeps the light code's Gemm and its parameters as they are.
"""

from __future__ import annotations

import argparse
import itertools
import math
from collections.abc import Iterator
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
# Rewritten by blocks: convolutions with at most this many input channels (the image's 3), in
# blocks of BLOCK x BLOCK pixels (a kernel's half-width at most BLOCK: the 7x7 stem needs 3 or
# more; 4 divides the network's 96 px and makes 48 and 80 channels, whole blocks of 16). The
# default model's encoder, CPU ms a run on 1 thread of an AVX-512 Xeon (`benchmark stages`):
# 0.966 before, 0.861 by blocks.
MAX_BLOCK_INPUTS = 4
BLOCK = 4
# Only where it was measured: a wide kernel to few outputs. Of the 144 taps an output of a 3x3
# convolution over blocks reads, a 7x7 kernel fills 49 and a 3x3 one 9; the blocked weight
# grows with the outputs as 16 O x 48 x 9. (Blocked twice is impossible: 16 C inputs.)
MIN_BLOCK_KERNEL = 5
MAX_BLOCK_OUTPUTS = 8
# Max abs difference allowed between a rewritten stage and the original (outputs are O(1)).
TOLERANCE = 1e-5


def row_weight(w: np.ndarray) -> np.ndarray:
    """A convolution's weight [O, C, kh, kw] as the 1 x kw convolution's [kh * O, C, 1, kw],
    channel j * O + o being row j of output o's kernel."""
    cout, cin, kh, kw = w.shape
    return w.transpose(2, 0, 1, 3).reshape(kh * cout, cin, 1, kw)


def original_parameter(value: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """A convolution's weight or bias, rewritten by rows or by blocks, back in its original
    ``shape``."""
    cout = shape[0]
    if value.ndim == 4 and value.shape[2] == 1:
        # By rows: [kh * O, C, 1, kw].
        return value.reshape(-1, cout, *value.shape[1:2], value.shape[3]).transpose(1, 2, 0, 3)
    if value.ndim == 4:
        # By blocks: output phase (0, 0) holds every tap of the kernel once (``block_weight``).
        _, cin, k, _ = shape
        block = math.isqrt(value.shape[0] // cout)
        if value.shape != (block * block * cout, block * block * cin, 3, 3):
            raise ValueError(f"a weight of shape {value.shape} is not {shape} by rows or by blocks")
        taps = [divmod(i - k // 2, block) for i in range(k)]  # (block from the centre, phase)
        w = np.empty(shape, value.dtype)
        for (ky, (dy, py)), (kx, (dx, px)) in itertools.product(enumerate(taps), repeat=2):
            c = (py * block + px) * cin
            w[:, :, ky, kx] = value[:cout, c : c + cin, dy + 1, dx + 1]
        return w
    if value.size == BLOCK * BLOCK * cout:
        # By blocks: the bias once for each output phase. (By rows it is kh * O, kh odd.)
        return value[:cout]
    # By rows: the bias is in one row's channels, zeros in the others'.
    return value.reshape(-1, cout).sum(axis=0)


def _attrs(node: onnx.NodeProto) -> dict:
    return {a.name: helper.get_attribute_value(a) for a in node.attribute}


def _shapes(model: onnx.ModelProto) -> dict[str, list[int | None]]:
    """Every tensor's inferred shape, None for a dimension not known."""
    inferred = onnx.shape_inference.infer_shapes(model, strict_mode=True).graph
    return {
        v.name: [d.dim_value if d.HasField("dim_value") else None for d in v.type.tensor_type.shape.dim]
        for v in [*inferred.input, *inferred.value_info, *inferred.output]
    }


def _same_conv(node: onnx.NodeProto, inits: dict, shapes: dict) -> tuple[list[int], list[int]] | None:
    """For a plain convolution (constant parameters, one group, stride 1, no dilation) with an
    odd kernel, 'same' padding and an input of known rank 4: its weight's dims and its input's
    shape (None where a size is not known). None for any other node."""
    if node.op_type != "Conv" or node.input[1] not in inits:
        return None
    if len(node.input) > 2 and node.input[2] not in inits:
        return None
    dims = list(inits[node.input[1]].dims)
    kh, kw = dims[2:]
    a = _attrs(node)
    shape = shapes.get(node.input[0])
    plain = (
        kh % 2 == 1
        and kw % 2 == 1
        and a.get("group", 1) == 1
        and a.get("auto_pad", b"NOTSET") == b"NOTSET"
        and list(a.get("strides", [1, 1])) == [1, 1]
        and list(a.get("dilations", [1, 1])) == [1, 1]
        and list(a.get("pads", [0] * 4)) == [kh // 2, kw // 2] * 2
        and shape is not None
        and len(shape) == 4
    )
    return (dims, shape) if plain else None


def _each_node(model: onnx.ModelProto, wanted) -> Iterator[tuple[int, onnx.NodeProto, dict, dict]]:
    """Each node that ``wanted(node, initializers, shapes)`` picks, with its index when it is
    reached, the graph's initializers by name and the tensors' shapes before any rewrite. Found
    by name: rewriting a node rebuilds the node list and replaces the node objects."""
    g = model.graph
    inits = {t.name: t for t in g.initializer}
    shapes = _shapes(model)
    for name in [n.name for n in g.node if wanted(n, inits, shapes)]:
        at, node = next((i, n) for i, n in enumerate(g.node) if n.name == name)
        yield at, node, inits, shapes


def _splice(g: onnx.GraphProto, at: slice, nodes: list[onnx.NodeProto]) -> None:
    """Replaces the graph's nodes ``at`` with ``nodes``."""
    all_nodes = list(g.node)
    all_nodes[at] = nodes
    del g.node[:]
    g.node.extend(all_nodes)


def _set_kernel(conv: onnx.NodeProto, kernel: list[int], pads: list[int]) -> None:
    for a in conv.attribute:
        if a.name == "kernel_shape":
            a.CopyFrom(helper.make_attribute("kernel_shape", kernel))
        elif a.name == "pads":
            a.CopyFrom(helper.make_attribute("pads", pads))


def _rewritable(node: onnx.NodeProto, inits: dict, shapes: dict) -> bool:
    """A plain 'same' convolution (``_same_conv``) with at most ``MAX_OUTPUT_CHANNELS`` outputs,
    a kernel of more than one row and a known height."""
    found = _same_conv(node, inits, shapes)
    if found is None:
        return False
    (cout, _, kh, _), shape = found
    return cout <= MAX_OUTPUT_CHANNELS and kh > 1 and isinstance(shape[2], int)


def convs_by_rows(model: onnx.ModelProto) -> list[str]:
    """Rewrites, in place, every convolution of a graph with few outputs as a convolution by
    kernel rows and a sum of shifted rows (see the module's notes). Returns the rewritten
    nodes' names."""
    g = model.graph
    rewritten = []
    for at, conv, inits, shapes in _each_node(model, _rewritable):
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
        _set_kernel(conv, [1, kw], [kh // 2, kw // 2] * 2)
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
        _splice(g, slice(at + 1, at + 1), nodes)
        rewritten.append(conv.name)
    onnx.checker.check_model(model, full_check=True)
    return rewritten


def block_weight(w: np.ndarray) -> np.ndarray:
    """A k x k convolution's weight [O, C, k, k] (odd k, k // 2 <= BLOCK) as the 3 x 3
    convolution's [B² O, B² C, 3, 3] over SpaceToDepth(B) of its input (B = ``BLOCK``), whose
    output DepthToSpace(B) (DCR) puts back: output phase (ay, ax) of output o is channel
    (ay * B + ax) * O + o, input phase (py, px) of input c is channel (py * B + px) * C + c, and
    tap (dy, dx) of the 3 x 3 kernel is the original's (B (dy - 1) + py - ay + k // 2, same in x)."""
    cout, cin, k, _ = w.shape
    b = BLOCK
    out = np.zeros((b * b * cout, b * b * cin, 3, 3), w.dtype)
    for ay, ax, py, px, dy, dx in np.ndindex(b, b, b, b, 3, 3):
        ky, kx = b * (dy - 1) + py - ay + k // 2, b * (dx - 1) + px - ax + k // 2
        if 0 <= ky < k and 0 <= kx < k:
            o, c = (ay * b + ax) * cout, (py * b + px) * cin
            out[o : o + cout, c : c + cin, dy, dx] = w[:, :, ky, kx]
    return out


def _blockable(node: onnx.NodeProto, inits: dict, shapes: dict) -> bool:
    """A plain 'same' convolution (``_same_conv``) with at most ``MAX_BLOCK_INPUTS`` inputs and
    ``MAX_BLOCK_OUTPUTS`` outputs, a square kernel from ``MIN_BLOCK_KERNEL`` to 2 ``BLOCK`` + 1
    wide, and a known size that whole blocks tile."""
    found = _same_conv(node, inits, shapes)
    if found is None:
        return False
    (cout, cin, kh, kw), shape = found
    return (
        cin <= MAX_BLOCK_INPUTS
        and cout <= MAX_BLOCK_OUTPUTS
        and kh == kw
        and MIN_BLOCK_KERNEL <= kh <= 2 * BLOCK + 1
        and all(isinstance(d, int) and d % BLOCK == 0 for d in shape[2:])
    )


def convs_by_blocks(model: onnx.ModelProto) -> list[str]:
    """Rewrites, in place, every convolution of a graph with few inputs as SpaceToDepth(BLOCK), a
    3 x 3 convolution over the blocks (``block_weight``) and DepthToSpace(BLOCK): the same products,
    summed in another order, so exact up to rounding. The convolution keeps its name and its
    parameters' names. Returns the rewritten nodes' names."""
    g = model.graph
    rewritten = []
    for at, conv, inits, _ in _each_node(model, _blockable):
        name = conv.name
        w = inits[conv.input[1]]
        w.CopyFrom(numpy_helper.from_array(block_weight(numpy_helper.to_array(w)), w.name))
        if len(conv.input) > 2:
            b = inits[conv.input[2]]
            b.CopyFrom(numpy_helper.from_array(np.tile(numpy_helper.to_array(b), BLOCK * BLOCK), b.name))
        _set_kernel(conv, [3, 3], [1, 1, 1, 1])
        x, y = conv.input[0], conv.output[0]
        # Named after the convolution: two of them may read the same tensor.
        conv.input[0], conv.output[0] = f"{name}/blocks_in", f"{name}/blocks_out"
        before = helper.make_node("SpaceToDepth", [x], [conv.input[0]], f"{name}/to_blocks", blocksize=BLOCK)
        after = helper.make_node(
            "DepthToSpace", [conv.output[0]], [y], f"{name}/from_blocks", blocksize=BLOCK, mode="DCR"
        )
        _splice(g, slice(at, at + 1), [before, conv, after])
        rewritten.append(name)
    onnx.checker.check_model(model, full_check=True)
    return rewritten


def _constant(g: onnx.GraphProto, name: str) -> np.ndarray | None:
    """The value of a tensor given by an initializer or a Constant node, else None."""
    for t in g.initializer:
        if t.name == name:
            return numpy_helper.to_array(t)
    for n in g.node:
        if n.op_type == "Constant" and n.output[0] == name and n.attribute[0].name == "value":
            return numpy_helper.to_array(n.attribute[0].t)
    return None


def _adain(g: onnx.GraphProto, norm: onnx.NodeProto, producer: dict, consumers: dict) -> tuple | None:
    """For an instance normalisation with unit scale and zero bias that ``model.AdaIN`` scales
    and shifts afterwards, returns (the Mul and Add that do it, the Gemm output whose first half
    is gamma and second beta, the channel count); None for any other."""

    def only_consumer(t: str, op: str) -> onnx.NodeProto | None:
        users = consumers.get(t, [])
        return users[0] if len(users) == 1 and users[0].op_type == op else None

    def other_input(node: onnx.NodeProto, t: str) -> str:
        return node.input[1] if node.input[0] == t else node.input[0]

    def sliced_from(t: str) -> onnx.NodeProto | None:
        """The Slice a [1, C, 1, 1] tensor was unsqueezed from (on axes 2 and 3)."""
        n, axes = producer.get(t), []
        while n is not None and n.op_type == "Unsqueeze":
            value = _constant(g, n.input[1]) if len(n.input) > 1 else None
            axes += [] if value is None else value.ravel().tolist()
            n = producer.get(n.input[0])
        return n if n is not None and n.op_type == "Slice" and sorted(axes) == [2, 3] else None

    scale, bias = (_constant(g, t) for t in norm.input[1:3])
    if scale is None or bias is None or not (np.all(scale == 1) and np.all(bias == 0)):
        return None
    mul = only_consumer(norm.output[0], "Mul")
    if mul is None:
        return None
    one_plus = producer.get(other_input(mul, norm.output[0]))
    add = only_consumer(mul.output[0], "Add")
    if one_plus is None or one_plus.op_type != "Add" or add is None:
        return None
    ones = [i for i in one_plus.input if (v := _constant(g, i)) is not None and v.size == 1 and v.ravel()[0] == 1.0]
    if len(ones) != 1:
        return None
    gamma = sliced_from(other_input(one_plus, ones[0]))
    beta = sliced_from(other_input(add, mul.output[0]))
    if gamma is None or beta is None or gamma.input[0] != beta.input[0]:
        return None
    gemm = producer.get(gamma.input[0])
    start = _constant(g, gamma.input[1])
    if gemm is None or gemm.op_type != "Gemm" or start is None or start.ravel().tolist() != [0]:
        return None
    rows = _constant(g, gemm.input[1])
    width = None if rows is None else rows.shape[0 if _attrs(gemm).get("transB", 0) else 1]
    if width not in (None, 2 * scale.size):
        return None
    return mul, add, gamma.input[0], scale.size


def adain_into_norms(model: onnx.ModelProto) -> list[str]:
    """Folds, in place, every AdaIN's scale and shift into its instance normalisation's scale
    and bias inputs, and drops the operations left unused (see the module's notes). Returns
    the folded normalisations' names.

    The match follows ``model.AdaIN`` as exported at batch 1 (``torch.chunk`` into gamma, then
    beta). Beta's slice starts where ``chunk``'s shape arithmetic says at run time, which the
    match does not evaluate; ``optimise_file`` checks every rewrite against the original graph
    before it writes one."""
    g = model.graph
    producer = {o: n for n in g.node for o in n.output}
    consumers: dict[str, list[onnx.NodeProto]] = {}
    for n in g.node:
        for i in n.input:
            consumers.setdefault(i, []).append(n)
    replaced: dict[int, list[onnx.NodeProto]] = {}
    folded = []
    for norm in [n for n in g.node if n.op_type == "InstanceNormalization"]:
        found = _adain(g, norm, producer, consumers)
        if found is None:
            continue
        mul, add, code_affine, channels = found
        name = norm.name or norm.output[0]
        offset, flat, halves = f"{name}/one_plus", f"{name}/flat", f"{name}/halves"
        g.initializer.extend(
            [
                # 1 + gamma, beta: gamma's half of the Gemm's output gains 1.
                numpy_helper.from_array(np.repeat(np.float32([1, 0]), channels)[None], offset),
                numpy_helper.from_array(np.array([-1], np.int64), flat),
                numpy_helper.from_array(np.array([channels, channels], np.int64), halves),
            ]
        )
        scale, shift = f"{name}/scale", f"{name}/shift"
        replaced[id(norm)] = replaced[id(mul)] = []
        # The new operations take the place of the Add, after both the convolution and the Gemm.
        replaced[id(add)] = [
            helper.make_node("Add", [code_affine, offset], [f"{name}/affine"], f"{name}/one_plus"),
            helper.make_node("Reshape", [f"{name}/affine", flat], [f"{name}/affine_flat"], f"{name}/flat"),
            helper.make_node("Split", [f"{name}/affine_flat", halves], [scale, shift], f"{name}/split", axis=0),
            helper.make_node(
                "InstanceNormalization", [norm.input[0], scale, shift], [add.output[0]], name, **_attrs(norm)
            ),
        ]
        folded.append(name)
    if folded:
        nodes = [m for n in g.node for m in replaced.get(id(n), [n])]
        del g.node[:]
        g.node.extend(nodes)
        _drop_unused(g)
        onnx.checker.check_model(model, full_check=True)
    return folded


def _drop_unused(g: onnx.GraphProto) -> None:
    """Removes the nodes and initializers that no graph output depends on."""
    needed = {o.name for o in g.output}
    kept = []
    for n in reversed(g.node):
        if any(o in needed for o in n.output):
            kept.append(n)
            needed.update(n.input)
    del g.node[:]
    g.node.extend(reversed(kept))
    inits = [t for t in g.initializer if t.name in needed]
    del g.initializer[:]
    g.initializer.extend(inits)


def rewrite(model: onnx.ModelProto) -> list[str]:
    """Every rewrite, in place; returns the rewritten nodes' names."""
    return convs_by_rows(model) + convs_by_blocks(model) + adain_into_norms(model)


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
    rewritten = rewrite(model)
    if not rewritten:
        return [], 0.0
    diff = max_difference(original, model, random_feeds(original))
    if diff > TOLERANCE:
        raise ValueError(f"{path}: the rewrite differs from the original by {diff:.1e} > {TOLERANCE:.0e}")
    onnx.save(model, path)
    return rewritten, diff


def optimise_folder(folder: Path) -> dict[str, tuple[list[str], float]]:
    """Rewrites a model folder's network stages in place (idempotent: a convolution by rows has
    a kernel of one row, one by blocks 16 times its inputs, and a folded normalisation's scale
    is no longer constant, so none qualifies again)."""
    return {stage: optimise_file(folder / contract.stage_file(stage)) for stage in contract.STAGES}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", type=Path, required=True, help="a model folder, rewritten in place")
    a = p.parse_args()
    for stage, (nodes, diff) in optimise_folder(a.model).items():
        print(f"{stage}: {', '.join(nodes) or 'nothing to rewrite'}" + (f" (max abs diff {diff:.1e})" if nodes else ""))


if __name__ == "__main__":
    main()
