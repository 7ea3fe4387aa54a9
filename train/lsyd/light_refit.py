"""Refits a model's light decoder on its frozen encoder, so that the predicted monitor follows
the screen's colour as well as its brightness.

    python -m lsyd.light_refit --model ../models/default --data ../data --out ../target/refit

Trained jointly with the rest of the network, the light decoder learns the screen's brightness
but not its colour (README, "Beyond the paper": colour correlation 0.01 on the held-out set),
and unknown-source relighting gets the light's strength but not its hue. Here every other stage
stays as it is, bit for bit, so relighting with the source light known does not change; only
the light decoder learns, from the model's own encoder features of every captured frame (the
second feature of levels 1-3, max-pooled as the decoder pools them, computed once), against
the frame's monitor light. The loss is the monitor loss of training (``lsyd.train``) on the
source light: L1, its gradient L1, and L1 between the mean colours, this last at ``--colour``
(training's cycle term needs the relit image, which a frozen network does not change).

The captures are the training data (``deskstage captures``); the validation set is scored
before and after, and one of its frames traces the export, so the held-out set stays unseen
until the model card measures it. The output folder is a whole model: the other stages copied,
the light decoder re-exported and checked against PyTorch like any export, the manifest's
training record extended with the refit's, and its held-out metrics dropped (they were the old
light decoder's; ``lsyd.evaluation.modelcard`` measures them again).
"""

from __future__ import annotations

import argparse
import json
import shutil
import time
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from . import contract, data, losses
from .export import network_from_model, parity, reference_run, write_stages

# Frames encoded at a time when the features are computed.
ENCODE_BATCH = 128


def pooled_features(net, images: np.ndarray) -> torch.Tensor:
    """The light decoder's input for (N, R, R, 3) uint8 frames: e2, e4 and e6 max-pooled to the
    bottleneck's size and stacked, as ``LightDecoder.forward`` does before its fusion."""
    out = []
    with torch.no_grad():
        for i in range(0, len(images), ENCODE_BATCH):
            _, feats = net.encode(data.to_tensor(images[i : i + ENCODE_BATCH]))
            out.append(net.light_decoder.pool(feats[1], feats[3], feats[5]))
    return torch.cat(out)


def agreement(pred: np.ndarray, true: np.ndarray) -> dict[str, float]:
    """How a predicted monitor follows the true one over frames: MAE, and the correlation of
    brightness and of colour (blue minus red) of their means, as the model card measures them."""
    p, t = pred.mean(axis=(2, 3)), true.mean(axis=(2, 3))
    return {
        "monitor_mae": float(np.abs(pred - true).mean()),
        "brightness_corr": float(np.corrcoef(p.mean(1), t.mean(1))[0, 1]),
        "colour_corr": float(np.corrcoef(p[:, 2] - p[:, 0], t[:, 2] - t[:, 0])[0, 1]),
    }


def frames_and_lights(held: data.Heldout, resolution: int) -> tuple[np.ndarray, np.ndarray]:
    """A test set's frames at network resolution and, per frame, its monitor light."""
    n_pose, n_light = held.images.shape[:2]
    frames = held.images.reshape(n_pose * n_light, *held.images.shape[2:])
    lights = np.tile(held.lights, (n_pose, 1, 1, 1))
    return data.resize_frames(frames, resolution), lights


def refit(model: Path, data_root: Path, out: Path, steps: int, batch: int, lr: float, colour: float, seed: int) -> dict:
    if out.resolve() == model.resolve() or model.resolve().is_relative_to(out.resolve()):
        raise SystemExit(f"--out {out} would replace the model it refits; choose another folder")
    torch.manual_seed(seed)
    net = network_from_model(model)
    resolution = contract.read(model / "model.json")["resolution"]
    sessions = data.capture_dirs(data_root / "captures")
    validation = data.Heldout.load(data_root / "validation")
    t0 = time.time()
    frames = [data.session_frames(s, resolution) for s in sessions]
    images = np.concatenate([f[0] for f in frames])
    lights = torch.from_numpy(np.concatenate([f[1] for f in frames]))
    features = pooled_features(net, images)
    val_images, val_lights = frames_and_lights(validation, resolution)
    val_features = pooled_features(net, val_images)
    print(f"{len(images)} frames of {len(sessions)} sessions encoded in {time.time() - t0:.0f} s")

    fuse = net.light_decoder.fuse

    def score_validation() -> dict[str, float]:
        with torch.no_grad():
            return agreement(fuse(val_features).numpy(), val_lights)

    before = score_validation()
    opt = torch.optim.Adam(fuse.parameters(), lr=lr)
    sampler = torch.Generator().manual_seed(seed + 1)
    start = time.time()
    for step in tqdm(range(steps), desc="light decoder", unit="step"):
        # Cosine decay to a tenth, as in training.
        for g in opt.param_groups:
            g["lr"] = lr * (0.1 + 0.9 * 0.5 * (1.0 + np.cos(np.pi * step / steps)))
        idx = torch.randint(len(features), (batch,), generator=sampler)
        loss = losses.monitor_match(fuse(features[idx]), lights[idx], 1.0, 1.0, colour)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
    seconds = time.time() - start
    after = score_validation()

    # The other stages as they were; the light decoder written anew and the whole chain checked.
    if out.exists():
        shutil.rmtree(out)
    shutil.copytree(model, out)
    specs = contract.stage_specs(resolution, contract.read(model / "model.json")["widths"])
    image = data.to_tensor(data.area_resize(validation.images[0, 0], resolution))[None]
    lights = [torch.from_numpy(validation.lights[i])[None] for i in (0, 4)]
    ref = reference_run(net, image, *lights)
    write_stages(net, {"light_decoder": specs["light_decoder"]}, out, ref)
    checked = parity(out, specs, ref)
    record = {
        "stage": "light_decoder",
        "encoder": "frozen",
        "frames": len(images),
        "sessions": len(sessions),
        "steps": steps,
        "batch": batch,
        "lr": lr,
        "colour": colour,
        "seed": seed,
        "seconds": round(seconds, 1),
        "validation_before": before,
        "validation_after": after,
    }
    manifest = contract.read(out / "model.json")
    manifest["training"]["light_refit"] = record
    manifest.get("metrics", {}).pop("heldout", None)
    manifest["parity"].update(checked)  # other stages (presence) keep their own
    contract.write(out / "model.json", manifest)
    return record


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", type=Path, required=True, help="the model folder whose light decoder is refitted")
    p.add_argument("--data", type=Path, default=Path("data"), help="captures, validation and held-out sets")
    p.add_argument("--out", type=Path, required=True, help="the refitted model's folder (replaced)")
    p.add_argument("--steps", type=int, default=4000)
    p.add_argument("--batch", type=int, default=64)
    p.add_argument("--lr", type=float, default=1e-3)
    p.add_argument("--colour", type=float, default=1.0, help="weight of the mean colour's L1")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--threads", type=int, default=0, help="CPU threads (0: all cores)")
    a = p.parse_args()
    if a.threads:
        torch.set_num_threads(a.threads)
    record = refit(a.model, a.data, a.out, a.steps, a.batch, a.lr, a.colour, a.seed)
    print(json.dumps(record, indent=2))


if __name__ == "__main__":
    main()
