"""Personal models (``lsydrelight train``): the saved-network format, ``--init``, and the
session format ``lsydrelight train`` prepares (``lights.npy`` instead of ``monitor.npy``)."""

import argparse
import json

import numpy as np
import pytest
import torch

from lsyd import data, model, pairing, personal, runs, train

TINY = model.NetConfig(resolution=32, width=0.125)


def write_session(folder, frames: int = 12, seed: int = 0):
    """A prepared session: random faces; frames in pairs of identical keypoints (one pose)
    under two different screen lights, so every even frame pairs with the next."""
    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True)
    np.save(folder / "face.npy", rng.integers(0, 256, (frames, 64, 64, 3), dtype=np.uint8))
    np.save(folder / "timestamps.npy", np.arange(frames, dtype=np.float64) / 10)
    lights = np.where(np.arange(frames)[:, None, None, None] % 2 == 0, 0.1, 0.6)
    np.save(folder / "lights.npy", np.broadcast_to(lights, (frames, 3, 16, 32)).astype(np.float32))
    base = rng.uniform(10, 50, (68, 2)).astype(np.float32)
    base[pairing.RIGHT_EYE_OUTER], base[pairing.LEFT_EYE_OUTER] = (20, 30), (44, 30)
    poses = np.stack([base + 5.0 * (i // 2) for i in range(frames)])
    np.save(folder / "keypoints.npy", poses)
    return folder


def test_a_saved_network_reads_back_with_its_configuration(tmp_path):
    torch.manual_seed(0)
    net = model.build(TINY)
    path = tmp_path / "network.pt"
    runs.save_network(net, TINY, path, {"run": "test"})
    cfg, state = runs.read_network(path)
    assert cfg == TINY
    for k, v in net.state_dict().items():
        assert torch.equal(state[k], v), k
    # The file holds plain types and tensors only: it loads without running code.
    saved = torch.load(path, weights_only=True)
    assert saved["format"] == runs.NETWORK_FORMAT and saved["version"] == runs.NETWORK_VERSION
    assert saved["net"]["resolution"] == 32


def test_a_saved_network_that_does_not_fit_is_refused_with_the_reason(tmp_path):
    path = tmp_path / "network.pt"
    runs.save_network(model.build(TINY), TINY, path, {})
    with pytest.raises(ValueError, match="resolution: saved 32, asked 64"):
        runs.read_network(path, expected=model.NetConfig(resolution=64, width=0.125))
    saved = torch.load(path, weights_only=True)
    torch.save({**saved, "version": 99}, tmp_path / "future.pt")
    with pytest.raises(ValueError, match="version 99"):
        runs.read_network(tmp_path / "future.pt")
    torch.save({"net": {}}, tmp_path / "other.pt")
    with pytest.raises(ValueError, match="not a saved network"):
        runs.read_network(tmp_path / "other.pt")
    bad = dict(saved["state_dict"])
    bad.pop(next(iter(bad)))
    torch.save({**saved, "state_dict": bad}, tmp_path / "short.pt")
    with pytest.raises(ValueError, match="do not fit"):
        runs.read_network(tmp_path / "short.pt")


def test_a_session_with_lights_npy_loads_and_pairs(tmp_path):
    session = write_session(tmp_path / "captures" / "s0")
    cap = data.Capture.load(session)
    assert cap.monitor is None
    assert cap.lights().shape == (12, 3, 16, 32)
    pairs, _ = data.keypoint_pairs(tmp_path / "captures", 32, pairing.PairingRule())
    # Frames 2k and 2k+1 share a pose under different lights: both orders of each of 6 pairs.
    assert sorted(map(tuple, pairs.pairs.tolist())) == sorted(
        [(2 * k, 2 * k + 1) for k in range(6)] + [(2 * k + 1, 2 * k) for k in range(6)]
    )
    assert pairs.images.shape == (12, 3, 32, 32)


def test_rehearsal_pairs_are_drawn_at_their_share_however_many_they_are(tmp_path):
    # One session of the person's own (6 frames, 6 pairs) beside a rehearsal session with
    # four times the pairs: drawn uniformly, rehearsal would fill 80% of the batches.
    write_session(tmp_path / "captures" / "capture-session-000", frames=6)
    write_session(tmp_path / "captures" / f"{data.REHEARSAL_PREFIX}dome-100", frames=24, seed=1)
    pairs, _ = data.keypoint_pairs(tmp_path / "captures", 32, pairing.PairingRule())
    assert pairs.rehearsed.tolist() == [False] * 6 + [True] * 24
    generator = torch.Generator().manual_seed(0)
    uniform = pairs.rehearsed[pairs.draw(20_000, None, generator)].float().mean().item()
    shared = pairs.rehearsed[pairs.draw(20_000, 0.2, generator)].float().mean().item()
    assert uniform == pytest.approx(0.8, abs=0.02)
    assert shared == pytest.approx(0.2, abs=0.02)
    # Within each kind, every pair is drawn.
    assert len(set(pairs.draw(20_000, 0.2, generator).tolist())) == 30


def test_a_share_outside_0_to_1_is_refused_with_what_to_give():
    assert runs.share("0.1") == 0.1
    for bad in ("1.5", "-0.1", "a tenth"):
        with pytest.raises(argparse.ArgumentTypeError, match="from 0 to 1"):
            runs.share(bad)


def test_lights_npy_of_the_wrong_shape_is_refused(tmp_path):
    session = write_session(tmp_path / "s0")
    np.save(session / "lights.npy", np.zeros((11, 3, 16, 32), np.float32))
    with pytest.raises(ValueError, match="lights.npy"):
        data.Capture.load(session)


def tiny_run(root, init=None, steps: int = 2) -> runs.TrainConfig:
    return runs.TrainConfig(net=TINY, steps=steps, batch=2, weights=personal.WEIGHTS, init=init)


def test_training_from_a_saved_network_starts_from_its_weights_and_resumes(tmp_path):
    torch.set_num_threads(2)
    write_session(tmp_path / "data" / "captures" / "s0")
    cpu = torch.device("cpu")
    train.train(tiny_run(tmp_path), tmp_path / "data", tmp_path / "first", False, 2, cpu)
    network = tmp_path / "network.pt"
    assert runs.save_run_network(tmp_path / "first", network) == TINY
    first = torch.load(tmp_path / "first" / "checkpoint.pt", weights_only=False)["net"]

    cfg = tiny_run(tmp_path, init=str(network), steps=4)
    trainer = train.Trainer(cfg, tmp_path / "x", cpu)
    for k, v in trainer.net.state_dict().items():
        assert torch.equal(v, first[k]), k
    # Stopped after two steps and resumed: the config (with its init) is the run's own.
    train.train(cfg, tmp_path / "data", tmp_path / "tuned", False, 2, cpu, stop_at=2)
    train.train(cfg, tmp_path / "data", tmp_path / "tuned", True, 2, cpu)
    assert torch.load(tmp_path / "tuned" / "checkpoint.pt", weights_only=False)["step"] == 4
    assert json.loads((tmp_path / "tuned" / "config.json").read_text())["init"] == str(network)
    # Resumed with another configuration: refused, naming what changed and what to do.
    with pytest.raises(SystemExit, match=r"different configuration \(init .* then, None now\); .* remove"):
        train.train(tiny_run(tmp_path, steps=4), tmp_path / "data", tmp_path / "tuned", True, 2, cpu)
    # A network of another configuration does not start a run of this one.
    other = model.NetConfig(resolution=48, width=0.125)
    with pytest.raises(SystemExit, match="resolution"):
        train.Trainer(runs.TrainConfig(net=other, init=str(network)), tmp_path / "y", cpu)


def test_init_options_must_agree_with_the_saved_network(tmp_path):
    network = tmp_path / "network.pt"
    runs.save_network(model.build(TINY), TINY, network, {})
    assert train.init_config(network, None, None, None, False, False, False) == TINY
    assert train.init_config(network, "lcfn", 32, 0.125, False, False, False) == TINY
    with pytest.raises(SystemExit, match="--resolution 96 \\(the network has 32\\)"):
        train.init_config(network, None, 96, None, False, False, False)


def test_pose_spread_measures_roll_and_face_size():
    kp = np.zeros((2, 68, 2), np.float32)
    kp[:, pairing.RIGHT_EYE_OUTER] = (10, 10)
    kp[0, pairing.LEFT_EYE_OUTER] = (30, 10)  # level eyes, 20 px apart
    kp[1, pairing.LEFT_EYE_OUTER] = (30, 30)  # rolled 45 degrees
    kp[:, 30] = (20, 25)
    spread = personal.pose_spread(kp)
    assert spread["frames_with_face"] == 2
    lo, hi = spread["p5_p95"]["roll_deg"]
    assert lo == pytest.approx(2.25, abs=0.01) and hi == pytest.approx(42.75, abs=0.01)
    assert spread["p5_p95"]["eye_distance_px"][0] == pytest.approx(20.0 + 0.05 * 8.284, abs=0.01)
    assert personal.pose_spread(np.full((3, 68, 2), np.nan, np.float32)) == {"frames_with_face": 0}
