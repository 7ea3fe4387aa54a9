"""Lower-precision variants of the shipped model: finite on any input, and within the
error bounds ``variants.ERROR_BOUNDS`` states against fp32."""

import shutil

import numpy as np
import onnx
import pytest
import torch
from onnx import numpy_helper

from lsyd import contract, data, export, variants


def relight_all(folder, images: np.ndarray, lights: np.ndarray) -> np.ndarray:
    """Each image relit from its light to the next image's light."""
    chain = contract.StageChain(folder)
    outs = [
        chain.relight(img[None], src[None], chain.light_code(tgt[None]))[0]
        for img, src, tgt in zip(images, lights, np.roll(lights, 1, axis=0))
    ]
    return np.stack(outs)


def test_fp16_and_int8_stay_finite_and_close_to_fp32(sim_data, shipped_model, tmp_path):
    res = contract.read(shipped_model / "model.json")["resolution"]
    calibration_images, calibration_lights = variants.calibration_frames(sim_data, res, count=8)
    variants.to_fp16(shipped_model, tmp_path / "fp16")
    variants.to_int8(
        shipped_model,
        tmp_path / "int8",
        variants.chain_inputs(shipped_model, calibration_images, calibration_lights),
    )
    held = data.Heldout.load(sim_data / "heldout")
    faces = data.to_tensor(data.area_resize(held.images[:, 0], res)).numpy()
    lights = held.lights
    reference = relight_all(shipped_model, faces, lights)

    rng = np.random.default_rng(0)
    extreme_faces = np.stack(
        [
            np.zeros((3, res, res), np.float32),
            np.ones((3, res, res), np.float32),
            rng.random((3, res, res), dtype=np.float32),
        ]
    )
    extreme_lights = np.stack([np.zeros_like(lights[0]), np.ones_like(lights[0]), lights[0]])
    for precision, (mean_bound, max_bound) in variants.ERROR_BOUNDS.items():
        out = relight_all(tmp_path / precision, faces, lights)
        err = np.abs(out - reference)
        print(f"{precision}: mean error {err.mean():.2g}, max {err.max():.2g}")  # shown with pytest -s
        assert err.mean() <= mean_bound, f"{precision}: mean error {err.mean():.4f} > {mean_bound}"
        assert err.max() <= max_bound, f"{precision}: max error {err.max():.4f} > {max_bound}"
        extreme = relight_all(tmp_path / precision, extreme_faces, extreme_lights)
        assert np.isfinite(extreme).all(), f"{precision}: NaN or Inf on extreme inputs"


def stage_tensors(path) -> list[list[tuple]]:
    """A stage file's inputs and outputs: name, shape, dtype."""
    model = onnx.load(path)

    def spec(v):
        t = v.type.tensor_type
        return v.name, [d.dim_value for d in t.shape.dim], onnx.helper.tensor_dtype_to_np_dtype(t.elem_type).name

    return [[spec(v) for v in model.graph.input], [spec(v) for v in model.graph.output]]


def test_int8_quantises_convolutions_only_and_keeps_the_contract_and_the_image_head(sim_data, shipped_model, tmp_path):
    res = contract.read(shipped_model / "model.json")["resolution"]
    images, lights = variants.calibration_frames(sim_data, res, count=4)
    variants.to_int8(shipped_model, tmp_path, variants.chain_inputs(shipped_model, images, lights))
    m = contract.read(tmp_path / "model.json")
    assert m["precision"] == "int8"
    for stage in contract.STAGES:
        spec = m["stages"][stage]
        # What the element checks on load (plugin/engine/contract.rs): names, shapes, dtypes.
        want = [[(t["name"], t["shape"], t["dtype"]) for t in spec[k]] for k in ("inputs", "outputs")]
        assert stage_tensors(tmp_path / spec["file"]) == want, stage
        original = (shipped_model / spec["file"]).read_bytes()
        if stage not in variants.INT8_STAGES:
            assert (tmp_path / spec["file"]).read_bytes() == original, f"{stage} changed"
            continue
        graph = onnx.load(tmp_path / spec["file"]).graph
        producer = {o: n.op_type for n in graph.node for o in n.output}
        int8 = variants.quantised_convs(graph)
        assert int8, f"{stage} was not quantised"
        # Every candidate and nothing else: not the image head, which draws the relit image in
        # fp32 (no 8-bit steps in the output). The encoder's stem is one, by blocks of 48 inputs.
        assert sorted(int8) == sorted(set(variants.int8_candidates(shipped_model, (stage,)))), stage
        assert "/decoder/out/Conv" not in int8
        # The AdaIN's scale and shift reach the normalisations unquantised.
        for norm in (n for n in graph.node if n.op_type == "InstanceNormalization"):
            assert producer[norm.input[1]] == producer[norm.input[2]] == "Split", norm.name
    decoder = onnx.load(shipped_model / contract.stage_file("decoder"))
    assert variants.image_heads(decoder) == ["/decoder/out/Conv"]
    # Of the 23 convolutions of the three stages, the image head stays fp32.
    assert len(variants.int8_candidates(shipped_model)) == 22
    assert "/encoder/stem/Conv" in variants.int8_candidates(shipped_model)
    # The benchmark's check of a variant it times: made from this model, and refused for another.
    assert sorted(variants.check_made_from(shipped_model, tmp_path)) == sorted(variants.int8_candidates(shipped_model))
    with pytest.raises(ValueError, match="is not .*starter's"):
        variants.check_made_from(shipped_model.parent / "starter", tmp_path)
    with pytest.raises(ValueError, match="does not say int8"):
        variants.check_made_from(shipped_model, shipped_model)
    # The tests' check against the fp32 network, on a held-out face; refused when far off.
    held = data.Heldout.load(sim_data / "heldout")
    image = data.to_tensor(data.area_resize(held.images[:1, 0], res))
    source, target = (torch.from_numpy(held.lights[k : k + 1]) for k in (0, 4))
    ref = export.reference_run(export.network_from_model(shipped_model), image, source, target)
    assert variants.check_close(tmp_path, ref, "int8") <= variants.ERROR_BOUNDS["int8"][0]
    ref["relit"] = 1.0 - ref["relit"]
    with pytest.raises(ValueError, match="int8 variant relights"):
        variants.check_close(tmp_path, ref, "int8")


def edit_initializer(path, name: str, change) -> None:
    model = onnx.load(path)
    init = next(t for t in model.graph.initializer if t.name == name)
    init.CopyFrom(numpy_helper.from_array(change(numpy_helper.to_array(init).copy()), name))
    onnx.save(model, path)


def test_a_variant_is_refused_where_it_is_not_the_model(shipped_model, tmp_path):
    # Each of check_made_from's refusals, on a copy of the shipped variant changed in one place.
    int8 = shipped_model.parent / "default-int8"
    decoder = contract.stage_file("decoder")

    def two_steps_off(q):
        q.flat[0] += 2 if q.flat[0] < 100 else -2
        return q

    def nudged(w):
        w.flat[0] += 0.01
        return w

    for name, change, why in [
        ("/decoder/convs.0/Conv", two_steps_off, "int8 weights of /decoder/convs.0/Conv are not"),
        ("net.decoder.out.weight", nudged, "net.decoder.out.weight of its decoder stage is not"),
    ]:
        copy = tmp_path / name.replace("/", "_")
        shutil.copytree(int8, copy)
        graph = onnx.load(copy / decoder).graph
        producer = {o: n for n in graph.node for o in n.output}
        conv = next((n for n in graph.node if n.name == name), None)
        edit_initializer(copy / decoder, producer[conv.input[1]].input[0] if conv else name, change)
        with pytest.raises(ValueError, match=why):
            variants.check_made_from(shipped_model, copy)


def test_the_cheapest_convolutions_are_quantised_while_the_cost_stays_within_the_bound():
    alone = {"a": 0.004, "b": 0.0005, "c": 0.002, "d": 0.0001, "e": 0.001}
    calls = []

    def cost(convs):
        calls.append(list(convs))
        return sum(alone[c] for c in convs)

    choice = variants.choose_int8_convs(list(alone), cost, max_cost=0.0037)
    # Cheapest first: d, b, e (0.0016 together), then c would make 0.0036, then a 0.0076.
    assert choice["quantised"] == ["d", "b", "e", "c"]
    assert choice["kept_fp32"] == ["a"]
    assert choice["cost"] == pytest.approx(0.0036)
    assert ["d", "b", "e", "c"] in calls, "the chosen set's cost is measured, not assumed"
    everything = variants.choose_int8_convs(list(alone), cost, max_cost=0.01)
    assert everything["kept_fp32"] == [] and everything["cost"] == pytest.approx(0.0076)
    nothing = variants.choose_int8_convs(list(alone), cost, max_cost=0.00005)
    assert nothing["quantised"] == [] and nothing["cost"] == 0.0
    # Each alone, then a bisection over the five prefixes: a handful of scorings, not all 31 sets.
    calls.clear()
    variants.choose_int8_convs(list(alone), cost, max_cost=0.0037)
    assert len(calls) <= len(alone) + 4
    with pytest.raises(ValueError, match="cannot be negative"):
        variants.choose_int8_convs(list(alone), cost, max_cost=-0.001)


def test_int8_refuses_a_convolution_no_stage_has(sim_data, shipped_model, tmp_path):
    images, lights = variants.calibration_frames(sim_data, 96, count=2)
    calibration = variants.chain_inputs(shipped_model, images, lights)
    with pytest.raises(ValueError, match="'/decoder/no-such/Conv' is in 0 stages"):
        variants.to_int8(shipped_model, tmp_path, calibration, ["/decoder/no-such/Conv"])


@pytest.mark.parametrize("name", ["default", "starter"])
def test_each_shipped_int8_variant_is_made_from_its_shipped_model(sim_data, shipped_model, name):
    # Retraining a model without remaking its `models/<name>-int8` (the command in the
    # variant's metrics.int8) fails here.
    model = shipped_model.parent / name
    int8 = shipped_model.parent / f"{name}-int8"
    m = contract.read(int8 / "model.json")
    assert m["precision"] == "int8"
    # Its stages are the model's, fp32 or rounded to int8, and hold what its manifest says.
    assert sorted(variants.check_made_from(model, int8)) == sorted(m["metrics"]["int8"]["quantised"])
    # Its model card says what its manifest does.
    assert (int8 / "README.md").read_text() == variants.int8_card(model, int8)
    # A held-out face relit from one of its lights to another, within the bound every int8
    # variant is held to (a model retrained since relights it further off than that).
    held = data.Heldout.load(sim_data / "heldout")
    image = data.to_tensor(data.area_resize(held.images[:1, 0], m["resolution"]))
    source, target = (torch.from_numpy(held.lights[k : k + 1]) for k in (0, 4))
    variants.check_close(int8, export.reference_run(export.network_from_model(model), image, source, target), "int8")
