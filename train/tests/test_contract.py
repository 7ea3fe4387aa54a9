"""The model contract: stage shapes agree with the network, lights are computed as defined,
and the stage chain feeds every stage what it takes."""

import numpy as np
import pytest
import torch

from lsyd import contract, model


@pytest.mark.parametrize("resolution,width", [(128, 0.25), (96, 0.125), (160, 0.5)])
def test_stage_shapes_match_the_network(resolution, width):
    cfg = model.NetConfig(resolution=resolution, width=width)
    net = model.build(cfg).eval()
    specs = contract.stage_specs(resolution, cfg.widths)
    with torch.no_grad():
        image = torch.zeros(1, 3, resolution, resolution)
        light = torch.zeros(1, 3, contract.LIGHT_ROWS, contract.LIGHT_COLS)
        stem, feats = net.encode(image)
        code = net.light_encoder(light)
        delit = net.delit(feats, code)
        got = {
            "stem": stem,
            "code": code,
            "predicted_light": net.predict_light(feats),
            "relit": net.decode(stem, delit, code),
            **{f"e{i + 1}": f for i, f in enumerate(feats)},
            **{f"f{i + 1}": f for i, f in enumerate(delit)},
        }
    for stage in specs.values():
        for t in stage["inputs"] + stage["outputs"]:
            if t["name"] in got:
                assert list(got[t["name"]].shape) == t["shape"], t["name"]


def test_white_frame_is_unit_light():
    light = contract.light_from_frames(np.full((90, 160, 3), 255, dtype=np.uint8))
    assert light.shape == (3, 16, 32)
    np.testing.assert_allclose(light, 1.0, atol=1e-6)


def test_screen_left_is_column_zero_and_top_is_row_zero():
    frame = np.zeros((32, 64, 3), dtype=np.uint8)
    frame[:16, :32, 0] = 255
    light = contract.light_from_frames(frame)
    assert light[0, 0, 0] == pytest.approx(1.0)
    assert light[0, -1, -1] == pytest.approx(0.0)


def test_fractional_cells_average_by_area():
    # 48 columns into 32 cells: each cell covers 1.5 columns, as in the Rust element.
    frame = np.zeros((16, 48, 3), dtype=np.uint8)
    frame[:, 0, 1] = 255
    light = contract.light_from_frames(frame)
    assert light[1, 0, 0] == pytest.approx(1.0 / 1.5, abs=1e-6)
    assert light[1, 0, 1] == pytest.approx(0.0, abs=1e-7)


def test_manifest_round_trip_and_refusal(tmp_path):
    m = contract.manifest("x", 128, (8, 16, 32, 64, 128), "fp32", {}, {})
    contract.write(tmp_path / "model.json", m)
    assert contract.read(tmp_path / "model.json")["stages"]["decoder"]["outputs"][0]["shape"] == [1, 3, 128, 128]
    m["version"] = contract.VERSION + 1
    contract.write(tmp_path / "model.json", m)
    with pytest.raises(ValueError, match="version"):
        contract.read(tmp_path / "model.json")


def test_stage_chain_feeds_every_stage_its_inputs(shipped_model):
    chain = contract.StageChain(shipped_model)
    r = chain.resolution
    rng = np.random.default_rng(0)
    image = rng.random((1, 3, r, r), dtype=np.float32)
    source, target = rng.random((2, 1, 3, contract.LIGHT_ROWS, contract.LIGHT_COLS), dtype=np.float32)
    feeds = chain.stage_inputs(image, source, target)
    for stage in contract.STAGES:
        assert list(feeds[stage]) == [i.name for i in chain.sessions[stage].get_inputs()], stage
    (relit,) = chain.sessions["decoder"].run(None, feeds["decoder"])
    np.testing.assert_array_equal(relit, chain.relight(image, source, chain.light_code(target)))
