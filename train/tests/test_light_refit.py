"""The light decoder's refit: it trains the very function the light decoder stage runs, and
writes a model whose other stages are the original's, byte for byte; fitted after training, it
completes a run trained without light prediction."""

import dataclasses
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from lsyd import contract, data, light_refit, model, runs
from lsyd.export import network_from_model


def test_the_refit_trains_what_the_light_decoder_stage_runs(sim_data, shipped_model):
    net = network_from_model(shipped_model)
    held = data.Heldout.load(sim_data / "heldout")
    frames, _ = light_refit.frames_and_lights(held, contract.read(shipped_model / "model.json")["resolution"])
    features = light_refit.pooled_features(net, frames[:12])
    with torch.no_grad():
        fused = net.light_decoder.fuse(features)
        whole = net.predict_light(net.encode(data.to_tensor(frames[:12]))[1])
    assert torch.allclose(fused, whole, atol=1e-6)


def test_a_refit_model_changes_its_light_decoder_alone(sim_data, shipped_model, tmp_path):
    torch.set_num_threads(2)
    out = tmp_path / "refit"
    settings = light_refit.FitSettings(steps=5, batch=8, code=1.0)
    record = light_refit.refit(shipped_model, sim_data, out, settings)
    stages = contract.read(shipped_model / "model.json")["stages"]
    for name, spec in stages.items():
        same = (out / spec["file"]).read_bytes() == (shipped_model / spec["file"]).read_bytes()
        assert same == (name != "light_decoder"), name
    manifest = contract.read(out / "model.json")
    assert manifest["training"]["light_refit"]["steps"] == 5
    # The old light decoder's held-out figures do not travel with the new one.
    assert "heldout" not in manifest["metrics"]
    assert set(manifest["parity"]) >= set(stages) - {"presence"}
    assert set(record["validation_after"]) == {
        "monitor_mae",
        "brightness_corr",
        "brightness_slope",
        "colour_corr",
        "code_error",
    }
    # The record names the set it was scored on, as --validation may choose another.
    assert manifest["training"]["light_refit"]["validation"] == str(sim_data / "validation")
    assert record["code"] == 1.0


def a_face(frames: int, size: int) -> np.ndarray:
    """68 keypoints of a face in the middle of a ``size``-pixel frame, the same in each of
    ``frames``: the jaw a half circle from ear to ear, the brows a line above the eyes."""
    points = np.zeros((68, 2), np.float32)
    angles = np.linspace(np.pi, 0.0, 17)
    centre, radius = size / 2, size / 5
    points[:17] = np.stack([centre + radius * np.cos(angles), centre + radius * np.sin(angles)], 1)
    points[17:27] = np.stack([np.linspace(centre - radius, centre + radius, 10), np.full(10, centre - radius / 2)], 1)
    points[27:] = centre
    return np.broadcast_to(points, (frames, 68, 2)).copy()


def test_a_swapped_surround_keeps_each_face_and_shows_another_frames_light_round_it():
    # Each frame's light is its own flat grey, so where a pixel came from reads off its value.
    frames, resolution = 6, 32
    images = np.stack([np.full((resolution, resolution, 3), 40 * (i + 1), np.uint8) for i in range(frames)])
    masks = light_refit.face_masks(a_face(frames, 128), 128, resolution)
    middle, corner = (resolution // 2, resolution // 2), (1, 1)
    assert masks[0][middle] == 1.0 and masks[0][corner] == 0.0
    swapped = light_refit.surround_swapped(images, masks, np.random.default_rng(0), 1.0)
    assert [swapped[i][middle][0] for i in range(frames)] == [images[i][middle][0] for i in range(frames)]
    surrounds = [swapped[i][corner][0] for i in range(frames)]
    # Every frame's surround is another frame's, each frame's once.
    assert sorted(surrounds) == sorted(images[:, 1, 1, 0])
    assert sum(surrounds[i] != images[i, 1, 1, 0] for i in range(frames)) >= frames - 1
    # A share of none leaves the frames as they are.
    kept = light_refit.surround_swapped(images, masks, np.random.default_rng(0), 0.0)
    assert np.array_equal(kept, images)


def test_a_refit_gives_the_saved_network_its_new_light_decoder(sim_data, shipped_model, tmp_path):
    # A model that fine-tuning can start from: the shipped one with its saved network.
    torch.set_num_threads(2)
    start = tmp_path / "start"
    shutil.copytree(shipped_model, start)
    original = network_from_model(shipped_model)
    manifest = contract.read(shipped_model / "model.json")
    net_cfg = model.NetConfig(
        resolution=manifest["resolution"],
        width=manifest["widths"][1] / model.PAPER_WIDTHS[1],
        light_field=original.decoder.light_field is not None,
    )
    runs.save_network(original, net_cfg, start / "network.pt", {"run": "shipped"})
    out = tmp_path / "refit"
    light_refit.refit(start, sim_data, out, light_refit.FitSettings(steps=3, batch=8, swap_surround=1.0))
    _, saved = runs.read_network(out / "network.pt")
    refitted = network_from_model(out).state_dict()
    before = original.state_dict()
    decoder = [k for k in saved if k.startswith("light_decoder.")]
    assert decoder and any(not torch.equal(saved[k], before[k]) for k in decoder)
    for name, value in saved.items():
        assert torch.equal(value, refitted[name] if name in decoder else before[name]), name
    source = torch.load(out / "network.pt", weights_only=True)["source"]
    assert source["run"] == "shipped" and source["light_refit"]["swap_surround"] == 1.0


def test_fits_averaged_are_the_weight_average_of_each_fit_alone(sim_data, shipped_model):
    torch.set_num_threads(2)
    validation = data.Heldout.load(sim_data / "validation")
    resolution = contract.read(shipped_model / "model.json")["resolution"]

    def fitted(settings: light_refit.FitSettings) -> tuple[dict, dict]:
        net = network_from_model(shipped_model)
        record = light_refit.fit(net, sim_data, validation, resolution, settings)
        return net.light_decoder.fuse.state_dict(), record

    settings = light_refit.FitSettings(steps=3, batch=8, swap_surround=1.0)
    alone = [fitted(dataclasses.replace(settings, seed=seed))[0] for seed in (4, 5)]
    averaged, record = fitted(dataclasses.replace(settings, seed=4, members=2))
    assert any(not torch.equal(alone[0][k], alone[1][k]) for k in averaged)
    for name, value in averaged.items():
        assert torch.allclose(value, (alone[0][name] + alone[1][name]) / 2, atol=1e-7), name
    # The record scores the average, and each member apart; a single fit's has no members.
    assert [m["seed"] for m in record["member_scores"]] == [4, 5]
    assert all(record["validation_after"] != m["validation_after"] for m in record["member_scores"])
    assert "member_scores" not in fitted(settings)[1]
    with pytest.raises(ValueError, match="at least one fit"):
        light_refit.FitSettings(members=0)


def test_the_code_term_measures_how_far_the_network_sees_two_lights_apart(sim_data, shipped_model):
    net = network_from_model(shipped_model)
    lights = torch.from_numpy(data.Heldout.load(sim_data / "validation").lights)
    distance = light_refit.CodeDistance(net, lights)
    assert float(distance(lights, lights)) == 0.0
    near, far = float(distance(lights * 1.05, lights)), float(distance(lights * 1.5, lights))
    assert 0.0 < near < far
    # Only the prediction learns: the light encoder's target is fixed.
    pred = (lights * 1.5).requires_grad_(True)
    distance(pred, lights).backward()
    assert pred.grad is not None and float(pred.grad.abs().sum()) > 0.0


def test_a_refit_never_replaces_the_model_it_refits(sim_data, shipped_model, tmp_path):
    # On a copy: should the guard break, the test must not take the shipped model with it.
    model = tmp_path / "model"
    shutil.copytree(shipped_model, model)
    with pytest.raises(SystemExit, match="would replace the model"):
        light_refit.refit(model, sim_data, model, light_refit.FitSettings(steps=1, batch=8))
    assert (model / "model.json").exists()


def test_the_card_tells_the_refit_and_the_training_from_the_manifest_alone(sim_data, shipped_model):
    # The run folder is not shipped: the card reads what the export and the refit recorded.
    from lsyd.evaluation import modelcard

    text = modelcard.card(shipped_model, None, sim_data)
    training = contract.read(shipped_model / "model.json")["training"]
    assert f"- Training: {training['steps']} steps of batch {training['batch']}" in text
    assert "Light decoder refitted on the frozen encoder" in text
    assert "follows the screen's colour as well as its brightness" in text


def no_prediction_run(folder: Path, steps_done: int = 7, arch: str = "lcfn") -> tuple[Path, torch.nn.Module]:
    """A run folder of a tiny network trained without light prediction for 7 steps, of which
    ``steps_done`` are in its checkpoint."""
    net_cfg = model.NetConfig(arch=arch, resolution=32, width=0.125, light_prediction=False)
    trained = model.build(net_cfg)
    folder.mkdir()
    weights = runs.LossWeights(delit_consistency=0.1)
    (folder / "config.json").write_text(json.dumps(runs.TrainConfig(net=net_cfg, steps=7, weights=weights).to_json()))
    torch.save({"net": trained.state_dict(), "step": steps_done}, folder / "checkpoint.pt")
    return folder, trained


def test_a_run_trained_without_light_prediction_gets_a_light_decoder_fitted_after(sim_data, tmp_path):
    torch.set_num_threads(2)
    run, trained = no_prediction_run(tmp_path / "no-prediction")
    out = tmp_path / "fitted"
    settings = light_refit.FitSettings(steps=3, batch=4, code=2.0)
    record = light_refit.fit_after(run, sim_data, out, settings)
    assert record["start"] == "fresh"
    net, cfg = runs.load_network(out)
    assert cfg.net.light_prediction and cfg.steps == 7
    # It trained without the monitor loss, whatever its weights said; the fitted run says so.
    assert cfg.weights.monitor == 0.0 and cfg.weights.unknown_source == 0.0
    # Everything but the new light decoder is the run's, weight for weight; the light decoder
    # has learnt from its fresh start.
    fitted = net.state_dict()
    for name, value in trained.state_dict().items():
        assert torch.equal(fitted[name], value), name
    torch.manual_seed(settings.seed)
    fresh = model.build(cfg.net).state_dict()
    decoder = [name for name in fitted if name.startswith("light_decoder.")]
    assert decoder and any(not torch.equal(fitted[name], fresh[name]) for name in decoder)

    # The export takes it as any run, and records the fit in the manifest's training record.
    exported = tmp_path / "model"
    subprocess.run(
        [sys.executable, "-m", "lsyd.export", "--run", str(out), "--data", str(sim_data), "--out", str(exported)],
        check=True,
        cwd=Path(__file__).resolve().parents[1],
    )
    manifest = contract.read(exported / "model.json")
    assert manifest["training"]["light_refit"]["start"] == "fresh"
    assert manifest["training"]["light_refit"]["steps"] == 3
    # Its card says the network trained without the monitor loss and got its light decoder after.
    from lsyd.evaluation import modelcard

    card = "\n".join(modelcard.configuration_lines(manifest, None))
    assert "no monitor loss" in card and "Light decoder fitted after training" in card
    assert "de-lit consistency x0.1" in card and "monitor colour x0 " not in card
    assert "light code x2," in card


def test_a_fit_after_refuses_what_it_cannot_complete(sim_data, tmp_path):
    settings = light_refit.FitSettings(steps=1)
    run, _ = no_prediction_run(tmp_path / "unfinished", steps_done=3)
    with pytest.raises(SystemExit, match="trained 3 of its 7 steps"):
        light_refit.fit_after(run, sim_data, tmp_path / "out", settings)
    baseline, _ = no_prediction_run(tmp_path / "sun", arch="sun")
    with pytest.raises(SystemExit, match="only the LCFN network"):
        light_refit.fit_after(baseline, sim_data, tmp_path / "out", settings)
    with pytest.raises(SystemExit, match="would replace the run"):
        light_refit.fit_after(run, sim_data, run, settings)
    with pytest.raises(SystemExit, match="would replace the run"):
        light_refit.fit_after(run, sim_data, tmp_path, settings)
    assert not (tmp_path / "out").exists()
