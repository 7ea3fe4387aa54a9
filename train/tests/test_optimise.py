"""The stage rewrites (``lsyd.optimise``): a convolution with few outputs computed by kernel
rows, one with few inputs by blocks, and an AdaIN's scale and shift folded into its
normalisation, match the original up to rounding, on single operations and on the shipped
network's stages with real and random inputs; other convolutions and plain normalisations are
left alone; the shipped model is rewritten and keeps its contract; the benchmark times it with
and without the rewrites beside PyTorch."""

import numpy as np
import onnx
import pytest
import torch
from onnx import TensorProto, helper, numpy_helper

from lsyd import contract, export, model, optimise, variants
from lsyd.evaluation import benchmark


def conv_graph(
    cout: int, kernel: tuple[int, int], size: int, stride: int = 1, same: bool = True, cin: int = 16, group: int = 1
):
    """x [1,cin,size,size] -> Conv(kernel, bias) -> Clip(0, 1) -> y, with random weights."""
    kh, kw = kernel
    rng = np.random.default_rng(kh * 100 + kw * 10 + cout)
    pads = [kh // 2, kw // 2] * 2 if same else [0] * 4
    w = (rng.standard_normal((cout, cin // group, kh, kw)) / np.sqrt(cin * kh * kw)).astype(np.float32)
    b = rng.standard_normal(cout).astype(np.float32)
    nodes = [
        helper.make_node(
            "Conv",
            ["x", "w", "b"],
            ["h"],
            "conv",
            kernel_shape=[kh, kw],
            pads=pads,
            strides=[stride] * 2,
            group=group,
        ),
        helper.make_node("Clip", ["h", "lo", "hi"], ["y"], "clip"),
    ]
    out_h = (size + pads[0] + pads[2] - kh) // stride + 1
    out_w = (size + pads[1] + pads[3] - kw) // stride + 1
    graph = helper.make_graph(
        nodes,
        "conv",
        [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, cin, size, size])],
        [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, cout, out_h, out_w])],
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


@pytest.mark.parametrize("cout,kernel,size", [(3, (7, 7), 96), (1, (3, 3), 16), (4, (5, 3), 18), (2, (9, 9), 24)])
def test_convolution_by_rows_matches_the_original(cout, kernel, size):
    original = conv_graph(cout, kernel, size)
    rewritten = copy(original)
    assert optimise.convs_by_rows(rewritten) == ["conv"]
    ops = [n.op_type for n in rewritten.graph.node]
    assert ops == ["Conv"] + ["Slice"] * kernel[0] + ["Sum", "Clip"]
    assert rewritten.graph.input == original.graph.input
    assert rewritten.graph.output == original.graph.output
    # Inputs in [0, 1) and wider, negative ones (a feature map's range), so the clamp cuts both ends.
    wide = {"x": 4 * np.random.default_rng(1).standard_normal((1, 16, size, size)).astype(np.float32)}
    diff = optimise.max_difference(original, rewritten, optimise.random_feeds(original) + [wide])
    assert diff <= optimise.TOLERANCE


@pytest.mark.parametrize(
    "why,model",
    [
        ("strided", conv_graph(3, (3, 3), 16, stride=2)),
        ("a whole output block", conv_graph(8, (7, 7), 96)),
        ("the stem's 5 outputs", conv_graph(5, (7, 7), 96, cin=3)),
        ("one row", conv_graph(3, (1, 7), 96)),
        ("not 'same' padding", conv_graph(3, (7, 7), 96, same=False)),
    ],
)
def test_other_convolutions_are_left_alone(why, model):
    assert optimise.convs_by_rows(model) == [], why


@pytest.mark.parametrize("cout,k,size,cin", [(5, 7, 96, 3), (8, 5, 24, 1), (6, 9, 16, 4), (4, 7, 16, 2)])
def test_convolution_by_blocks_matches_the_original(cout, k, size, cin):
    original = conv_graph(cout, (k, k), size, cin=cin)
    rewritten = copy(original)
    assert optimise.convs_by_blocks(rewritten) == ["conv"]
    ops = [n.op_type for n in rewritten.graph.node]
    assert ops == ["SpaceToDepth", "Conv", "DepthToSpace", "Clip"]
    weight = numpy_helper.to_array(rewritten.graph.initializer[0])
    assert weight.shape == (16 * cout, 16 * cin, 3, 3)
    assert rewritten.graph.input == original.graph.input
    assert rewritten.graph.output == original.graph.output
    wide = {"x": 4 * np.random.default_rng(1).standard_normal((1, cin, size, size)).astype(np.float32)}
    diff = optimise.max_difference(original, rewritten, optimise.random_feeds(original) + [wide])
    assert diff <= optimise.TOLERANCE
    assert optimise.convs_by_blocks(rewritten) == [], "rewriting twice changes nothing"


@pytest.mark.parametrize(
    "why,model",
    [
        ("strided", conv_graph(5, (7, 7), 96, stride=2, cin=3)),
        ("more inputs than the image's", conv_graph(5, (7, 7), 96, cin=5)),
        ("a size that blocks do not tile", conv_graph(5, (7, 7), 90, cin=3)),
        ("a kernel wider than a block each side", conv_graph(5, (11, 11), 96, cin=3)),
        ("a 3x3 kernel, 9 of the 144 taps", conv_graph(5, (3, 3), 96, cin=3)),
        ("more outputs than measured", conv_graph(16, (7, 7), 96, cin=3)),
        ("grouped", conv_graph(4, (7, 7), 96, cin=4, group=2)),
        ("not square", conv_graph(5, (7, 5), 96, cin=3)),
        ("not 'same' padding", conv_graph(5, (7, 7), 96, same=False, cin=3)),
    ],
)
def test_other_convolutions_are_not_blocked(why, model):
    assert optimise.convs_by_blocks(model) == [], why


def test_two_convolutions_of_one_input_are_blocked_apart():
    # Each rewrite's tensors are named after its convolution, not the input they share.
    model = conv_graph(5, (7, 7), 32, cin=3)
    second = onnx.NodeProto()
    second.CopyFrom(model.graph.node[0])
    second.name, second.output[0] = "conv2", "h2"
    second.input[1], second.input[2] = "w2", "b2"
    for name, init in zip(("w2", "b2"), model.graph.initializer[:2]):
        model.graph.initializer.append(numpy_helper.from_array(1.5 * numpy_helper.to_array(init), name))
    model.graph.node.insert(1, second)
    model.graph.node.insert(2, helper.make_node("Add", ["h", "h2"], ["sum"], "add"))
    model.graph.node[3].input[0] = "sum"
    original = copy(model)
    assert optimise.convs_by_blocks(model) == ["conv", "conv2"]
    assert optimise.max_difference(original, model, optimise.random_feeds(original)) <= optimise.TOLERANCE


def test_a_small_convolution_on_few_channels_is_rewritten_once_by_rows():
    model = conv_graph(3, (7, 7), 32, cin=3)
    assert optimise.rewrite(model) == ["conv"]
    assert "SpaceToDepth" not in [n.op_type for n in model.graph.node]


def test_original_parameter_undoes_the_layout():
    rng = np.random.default_rng(0)
    w = rng.standard_normal((3, 5, 7, 3)).astype(np.float32)
    np.testing.assert_array_equal(optimise.original_parameter(optimise.row_weight(w), w.shape), w)
    model = conv_graph(3, (7, 7), 16)
    b = numpy_helper.to_array(model.graph.initializer[1])
    optimise.convs_by_rows(model)
    rows_bias = numpy_helper.to_array(model.graph.initializer[1])
    assert rows_bias.shape == (21,)
    np.testing.assert_array_equal(optimise.original_parameter(rows_bias, b.shape), b)
    # By blocks: every tap of a 7 x 7 and of a 9 x 9 kernel comes back, and the bias.
    for k in (7, 9):
        w = rng.standard_normal((5, 3, k, k)).astype(np.float32)
        np.testing.assert_array_equal(optimise.original_parameter(optimise.block_weight(w), w.shape), w)
    model = conv_graph(5, (7, 7), 16, cin=3)
    b = numpy_helper.to_array(model.graph.initializer[1])
    optimise.convs_by_blocks(model)
    blocks_bias = numpy_helper.to_array(model.graph.initializer[1])
    assert blocks_bias.shape == (80,)
    np.testing.assert_array_equal(optimise.original_parameter(blocks_bias, b.shape), b)
    with pytest.raises(ValueError, match="not .* by rows or by blocks"):
        optimise.original_parameter(np.zeros((80, 40, 3, 3), np.float32), (5, 3, 7, 7))


def adain_graph(path, channels: int = 16, size: int = 24) -> onnx.ModelProto:
    """``model.AdaIN`` with random weights, exported as the network's stages are."""
    torch.manual_seed(channels)
    block = model.AdaIN(channels, channels, 32).eval()
    with torch.no_grad():
        block.affine.weight.normal_(0, 0.2)
        block.affine.bias.normal_(0, 0.2)
    x, code = torch.rand(1, channels, size, size), torch.rand(1, 32)
    torch.onnx.export(
        block, (x, code), path, input_names=["x", "code"], output_names=["y"], opset_version=export.OPSET, dynamo=False
    )
    return onnx.load(path)


def test_adain_folded_into_its_normalisation_matches_the_original(tmp_path):
    original = adain_graph(tmp_path / "adain.onnx")
    folded = copy(original)
    assert len(optimise.adain_into_norms(folded)) == 1
    ops = [n.op_type for n in folded.graph.node]
    assert sorted(ops) == sorted(["Conv", "Gemm", "Add", "Reshape", "Split", "InstanceNormalization", "LeakyRelu"]), ops
    assert len(original.graph.node) > 3 * len(ops), "the exported AdaIN's small operations are gone"
    assert folded.graph.input == original.graph.input and folded.graph.output == original.graph.output
    # Codes and features wider than [0, 1): gamma below -1 flips a channel, which must survive.
    rng = np.random.default_rng(2)
    wide = {
        "x": 4 * rng.standard_normal((1, 16, 24, 24)).astype(np.float32),
        "code": 8 * rng.standard_normal((1, 32)).astype(np.float32),
    }
    assert optimise.max_difference(original, folded, optimise.random_feeds(original) + [wide]) <= optimise.TOLERANCE
    assert optimise.adain_into_norms(folded) == [], "folding twice changes nothing"


def test_plain_instance_normalisation_is_left_alone(tmp_path):
    torch.onnx.export(
        torch.nn.InstanceNorm2d(8),
        torch.rand(1, 8, 12, 12),
        tmp_path / "norm.onnx",
        opset_version=export.OPSET,
        dynamo=False,
    )
    norm = onnx.load(tmp_path / "norm.onnx")
    assert optimise.adain_into_norms(norm) == []


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
        assert optimise.rewrite(model) == [], f"{stage} has an operation left to rewrite"
    decoder = onnx.load(shipped_model / "decoder.onnx")
    weight = next(t for t in decoder.graph.initializer if t.name == "net.decoder.out.weight")
    assert list(weight.dims) == [7 * 3, 16, 1, 7], "the decoder's output convolution is not by rows"
    encoder = onnx.load(shipped_model / "encoder.onnx")
    weight = next(t for t in encoder.graph.initializer if t.name == "net.encoder.stem.weight")
    assert list(weight.dims) == [16 * 5, 16 * 3, 3, 3], "the encoder's stem is not by blocks"


def test_rewritten_stages_match_the_export_on_real_and_random_inputs(shipped_model, tmp_path):
    net = export.network_from_model(shipped_model)
    m = contract.read(shipped_model / "model.json")
    specs = contract.stage_specs(m["resolution"], tuple(m["widths"]))
    image, source, target = benchmark.portrait_frame(m["resolution"])
    ref = export.reference_run(net, *(torch.from_numpy(x) for x in (image, source, target)))
    export.write_stages(net, specs, tmp_path, ref, rewrite=False)
    real = contract.StageChain(tmp_path).stage_inputs(image, source, target)
    diffs = {}
    for stage in contract.STAGES:
        original = onnx.load(tmp_path / contract.stage_file(stage))
        rewritten = copy(original)
        if not optimise.rewrite(rewritten):
            continue
        feeds = [real[stage], *optimise.random_feeds(original)]
        diffs[stage] = optimise.max_difference(original, rewritten, feeds)
        # The shipped stage is this rewrite of its own weights.
        shipped = onnx.load(shipped_model / contract.stage_file(stage))
        assert optimise.max_difference(rewritten, shipped, feeds) == 0.0, stage
    print(f"max abs difference of the rewritten stages: {diffs}")  # shown with pytest -s
    assert list(diffs) == ["encoder", "delight", "decoder"]
    assert max(diffs.values()) <= optimise.TOLERANCE


def test_network_timings_compare_the_rewrite_int8_and_the_peer_in_one_run(shipped_model, tmp_path):
    # The shipped model's int8 variant, calibrated on one frame: the benchmark only times it.
    image, source, target = benchmark.portrait_frame(contract.read(shipped_model / "model.json")["resolution"])
    variants.to_int8(shipped_model, tmp_path, variants.chain_inputs(shipped_model, image, source))
    timings = benchmark.network_timings(shipped_model, threads=(1,), rounds=2, frames=1, int8=tmp_path)
    for name in ("onnxruntime", "onnxruntime, int8", "onnxruntime, not rewritten", "pytorch"):
        t = timings[name]["1"]
        assert 0 < t["min"] <= t["median"] <= t["max"], name
        assert 0 < t["cpu"]["min"] <= t["cpu"]["median"] <= t["cpu"]["max"], name
    assert timings["peer_ratio"]["1"] > 0 and timings["peer_ratio_int8"]["1"] > 0
    table = benchmark.network_table(timings)
    assert "ONNX Runtime, int8" in table and "peer / ONNX Runtime, int8" in table
    assert table.count("| 1 |") == 2, "a wall-time row and a CPU-time row"


def test_stage_and_traffic_timings_cover_every_stage_and_size(shipped_model):
    by_stage = benchmark.stage_timings({"fp32": shipped_model}, rounds=1, frames=1)
    assert list(by_stage) == list(contract.STAGES)
    for stage, t in by_stage.items():
        assert 0 <= t["fp32"]["min"] <= t["fp32"]["median"] <= t["fp32"]["max"], stage
    after = benchmark.network_after_traffic(shipped_model, sizes_mb=(0, 1), threads=1, rounds=2)
    assert list(after) == [0, 1]
    assert all(0 < t["min"] <= t["median"] <= t["max"] for t in after.values())


def test_a_light_field_model_is_rebuilt_from_its_stages_with_its_light_field(shipped_model):
    # The starter's decoder draws a light field; a network rebuilt without it (the benchmark's
    # peer, the light refit, the int8 check's reference) relit 0.017 from the model's own stages.
    starter = shipped_model.parent / "starter"
    net = export.network_from_model(starter)
    assert net.decoder.light_field is not None
    image, source, target = benchmark.portrait_frame(contract.read(starter / "model.json")["resolution"])
    ref = export.reference_run(net, *(torch.from_numpy(x) for x in (image, source, target)))
    chain = contract.StageChain(starter)
    relit = chain.relight(ref["image"], ref["light"], chain.light_code(ref["target_light"]))
    assert float(np.abs(relit - ref["relit"]).max()) < 1e-4
