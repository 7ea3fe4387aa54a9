"""Lower-precision variants of the shipped model: finite on any input, and within the
error bounds ``variants.ERROR_BOUNDS`` states against fp32."""

import numpy as np
import onnx
import pytest
import torch

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


def test_int8_of_chosen_stages_keeps_the_contract_and_the_other_stages(sim_data, shipped_model, tmp_path):
    res = contract.read(shipped_model / "model.json")["resolution"]
    images, lights = variants.calibration_frames(sim_data, res, count=4)
    chosen = ("delight", "decoder")
    variants.to_int8(shipped_model, tmp_path, variants.chain_inputs(shipped_model, images, lights), chosen)
    m = contract.read(tmp_path / "model.json")
    assert m["precision"] == "int8"
    for stage in contract.STAGES:
        spec = m["stages"][stage]
        # What the element checks on load (plugin/engine/contract.rs): names, shapes, dtypes.
        want = [[(t["name"], t["shape"], t["dtype"]) for t in spec[k]] for k in ("inputs", "outputs")]
        assert stage_tensors(tmp_path / spec["file"]) == want, stage
        ops = {n.op_type for n in onnx.load(tmp_path / spec["file"]).graph.node}
        original = (shipped_model / spec["file"]).read_bytes()
        if stage in chosen:
            assert "QuantizeLinear" in ops, f"{stage} was not quantised"
        else:
            assert (tmp_path / spec["file"]).read_bytes() == original, f"{stage} changed"
    # The benchmark's check of a variant it times: close to the fp32 network, and refused when not.
    net = export.network_from_model(shipped_model)
    gen = torch.Generator().manual_seed(0)
    image = torch.rand(1, 3, res, res, generator=gen)
    source, target = torch.rand(2, 1, 3, contract.LIGHT_ROWS, contract.LIGHT_COLS, generator=gen)
    ref = export.reference_run(net, image, source, target)
    assert variants.check_close(tmp_path, ref, "int8") <= variants.ERROR_BOUNDS["int8"][0]
    ref["relit"] = 1.0 - ref["relit"]
    with pytest.raises(ValueError, match="int8 variant relights"):
        variants.check_close(tmp_path, ref, "int8")
