"""Refits a model's light decoder on its frozen encoder, so that the predicted monitor follows
the screen's colour as well as its brightness.

    python -m lsyd.light_refit --model ../models/default --data ../data --out ../target/refit
    python -m lsyd.light_refit --run ../runs/t-nopred --data ../data --out ../runs/t-nopred-fitted

Trained jointly with the rest of the network, the light decoder learns the screen's brightness
but not its colour (docs/accuracy.md, "Beyond the paper": colour correlation 0.01 on the held-out set),
and unknown-source relighting gets the light's strength but not its hue. Here every other stage
stays as it is, bit for bit, so relighting with the source light known does not change; only
the light decoder learns, from the model's own encoder features of every captured frame (the
second feature of levels 1-3, max-pooled as the decoder pools them, computed once), against
the frame's monitor light. The loss is the monitor loss of training (``lsyd.train``) on the
source light: L1, its gradient L1, and L1 between the mean colours, this last at ``--colour``
(training's cycle term needs the relit image, which a frozen network does not change). With
``--code``, a last term asks what relighting needs of the prediction: that the frozen light
encoder give it the true light's code (the squared difference, each of the code's dimensions in
units of its spread over the captures), as that code is what de-lights the features.

The captures are the training data (``deskstage captures``); the validation set is scored
before and after, and one of its frames traces the export, so the held-out set stays unseen
until the model card measures it. The output folder is a whole model: the other stages copied,
the light decoder re-exported and checked against PyTorch like any export, the manifest's
training record extended with the refit's, and its held-out metrics dropped (they were the old
light decoder's; ``lsyd.evaluation.modelcard`` measures them again).

With ``--run``, the same fit completes a finished training run: one trained without light
prediction (``lsyd.train --no-light-prediction``) gets a fresh light decoder, learnt on its
frozen encoder in the same way. Trained jointly, light prediction costs known-source accuracy
(README, Table 3); fitted after, it costs none, as the relighting stages are the run's. The
output is a run folder (its configuration with light prediction on, its checkpoint, its
records, and ``light_fit.json``) that the export and the evaluation read as any other run.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shutil
import time
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from . import contract, data, losses, model, runs
from .export import network_from_model, parity, reference_run, write_stages
from .runs import LIGHT_FIT_RECORD, load_network

# A model folder's saved network, which fine-tuning starts from (models/CONTRACT.md).
SAVED_NETWORK = "network.pt"
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


# The face's ellipse round its keypoints: its half-width as a share of the jaw's, and how far
# above the brows it reaches (the forehead), in brows-to-chin heights.
FACE_WIDTH_MARGIN = 1.1
FOREHEAD = 0.35
# Beyond the ellipse the face fades into the other frame's surround over this share of its size.
FACE_FADE = 0.1


def face_masks(keypoints: np.ndarray, size: int, resolution: int) -> np.ndarray:
    """Per frame, a soft ellipse over the face (jaw, brows and forehead) from its 68 keypoints in
    a ``size``-pixel capture, as (N, R, R, 1) weights in [0, 1] at network resolution."""
    k = keypoints[:, :27] * (resolution / size)  # jaw line and brows
    left, right = k[..., 0].min(1), k[..., 0].max(1)
    brows, chin = k[:, 17:27, 1].min(1), k[:, :17, 1].max(1)
    top = brows - FOREHEAD * (chin - brows)
    cx, cy = (left + right) / 2, (top + chin) / 2
    ax, ay = FACE_WIDTH_MARGIN * (right - left) / 2, (chin - top) / 2
    # A face with no extent (keypoints all at one place) gets a one-pixel ellipse, not a NaN.
    ax, ay = np.maximum(ax, 1.0), np.maximum(ay, 1.0)
    grid = np.arange(resolution) + 0.5
    dx = (grid[None, None, :] - cx[:, None, None]) / ax[:, None, None]
    dy = (grid[None, :, None] - cy[:, None, None]) / ay[:, None, None]
    r = np.sqrt(dx**2 + dy**2)
    return np.clip((1.0 + FACE_FADE - r) / FACE_FADE, 0.0, 1.0)[..., None].astype(np.float32)


def session_face_masks(session: Path, resolution: int) -> np.ndarray:
    """``face_masks`` of a capture session's frames, from its keypoints."""
    size = data.Capture.load(session).face.shape[1]
    return face_masks(np.load(session / "keypoints.npy"), size, resolution)


def surround_swapped(images: np.ndarray, masks: np.ndarray, rng: np.random.Generator, share: float) -> np.ndarray:
    """A ``share`` of a session's frames, drawn at random, with their face (``masks``) over the
    surround (hair, clothes, room) of another of its frames, also drawn at random; the rest as
    they are. The surround then shows some other screen's light, as a real crop's collar, helmet
    or wall shows none, so a light decoder fitted on all of them can read the light only off the
    face. The draw is a permutation, so about one frame a session keeps its own surround; it is
    made once, before the fit, so each face is fitted over one surround."""
    other = rng.permutation(len(images))
    kept = rng.random(len(images)) >= share
    other[kept] = np.flatnonzero(kept)
    mixed = masks * images + (1.0 - masks) * images[other]
    return np.round(mixed).astype(np.uint8)


def agreement(pred: np.ndarray, true: np.ndarray) -> dict[str, float]:
    """How a predicted monitor follows the true one over frames: MAE, the correlation of
    brightness and of colour (blue minus red) of their means, as the model card measures them,
    and the brightness slope: the least-squares slope of the predicted mean brightness against
    the true one (1: it follows the screen's changes in full; near 0: it guesses about the same
    light whatever the screen shows, however well correlated)."""
    p, t = pred.mean(axis=(2, 3)), true.mean(axis=(2, 3))
    return {
        "monitor_mae": float(np.abs(pred - true).mean()),
        "brightness_corr": float(np.corrcoef(p.mean(1), t.mean(1))[0, 1]),
        "brightness_slope": float(np.polyfit(t.mean(1), p.mean(1), 1)[0]),
        "colour_corr": float(np.corrcoef(p[:, 2] - p[:, 0], t[:, 2] - t[:, 0])[0, 1]),
    }


def frames_and_lights(held: data.Heldout, resolution: int) -> tuple[np.ndarray, np.ndarray]:
    """A test set's frames at network resolution and, per frame, its monitor light."""
    n_pose, n_light = held.images.shape[:2]
    frames = held.images.reshape(n_pose * n_light, *held.images.shape[2:])
    lights = np.tile(held.lights, (n_pose, 1, 1, 1))
    return data.resize_frames(frames, resolution), lights


@dataclasses.dataclass(frozen=True)
class FitSettings:
    """How the light decoder learns: steps of Adam at ``lr`` with cosine decay to a tenth, over
    batches of ``batch`` frames, the monitor loss's mean-colour term at ``colour`` and the
    light-code term at ``code``. With ``members`` above 1, that many fits from the same start,
    seeded ``seed``, ``seed + 1``, ..., are averaged weight by weight (a "model soup", Wortsman
    et al. 2022): fitted from one start, their weights can be averaged into one decoder of the
    same shape, whose guess on faces unlike the training's varies less with the seed than a
    single fit's (docs/targets.md measures both)."""

    steps: int = 4000
    batch: int = 64
    lr: float = 1e-3
    colour: float = 1.0
    code: float = 0.0
    seed: int = 0
    swap_surround: float = 0.0  # the share of frames fitted on with another frame's surround
    members: int = 1

    def __post_init__(self):
        if self.members < 1:
            raise ValueError(f"members={self.members}: at least one fit is needed")


class CodeDistance:
    """How far apart two lights are for the network: the mean squared difference of their codes
    from ``net``'s frozen light encoder, each dimension in units of its standard deviation over
    ``lights``, so that the weight does not depend on the code's scale."""

    def __init__(self, net: model.LcfnNet, lights: torch.Tensor):
        self.encode = net.light_encoder
        with torch.no_grad():
            self.spread = self.encode(lights).std(dim=0) + 1e-6

    def __call__(self, pred: torch.Tensor, light: torch.Tensor) -> torch.Tensor:
        with torch.no_grad():
            target = self.encode(light)
        return (((self.encode(pred) - target) / self.spread) ** 2).mean()


def training_features(
    net: model.LcfnNet, sessions: list[Path], resolution: int, swap_surround: float, seed: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """The light decoder's input for every frame of ``sessions`` (a ``swap_surround`` share of
    them over another frame's surround, drawn from a generator seeded by ``seed``) and, per
    frame, the monitor light."""
    frames = [data.session_frames(s, resolution) for s in sessions]
    if swap_surround:
        rng = np.random.default_rng(seed)
        frames = [
            (surround_swapped(images, session_face_masks(s, resolution), rng, swap_surround), lights)
            for s, (images, lights) in zip(sessions, frames)
        ]
    images = np.concatenate([f[0] for f in frames])
    return pooled_features(net, images), torch.from_numpy(np.concatenate([f[1] for f in frames]))


def fit_fuse(
    fuse: torch.nn.Module,
    features: torch.Tensor,
    lights: torch.Tensor,
    settings: FitSettings,
    seed: int,
    code_distance: CodeDistance,
) -> None:
    """Trains ``fuse`` in place on ``features`` against ``lights``, its batches drawn from a
    generator seeded by ``seed + 1``."""
    opt = torch.optim.Adam(fuse.parameters(), lr=settings.lr)
    sampler = torch.Generator().manual_seed(seed + 1)
    for step in tqdm(range(settings.steps), desc=f"light decoder, seed {seed}", unit="step"):
        # Cosine decay to a tenth, as in training.
        for g in opt.param_groups:
            g["lr"] = settings.lr * (0.1 + 0.9 * 0.5 * (1.0 + np.cos(np.pi * step / settings.steps)))
        idx = torch.randint(len(features), (settings.batch,), generator=sampler)
        pred = fuse(features[idx])
        loss = losses.monitor_match(pred, lights[idx], 1.0, 1.0, settings.colour)
        if settings.code:
            loss = loss + settings.code * code_distance(pred, lights[idx])
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()


def fit(net: model.LcfnNet, data_root: Path, validation: data.Heldout, resolution: int, settings: FitSettings) -> dict:
    """Trains ``net``'s light decoder, in place, on its frozen encoder's features of every
    captured frame against the frame's monitor light; returns the fit's record, with the
    ``validation`` set's scores before and after (and each member's, where ``settings.members``
    fits are averaged; its ``seconds`` are then all of theirs, re-encodings included)."""
    sessions = data.capture_dirs(data_root / "captures")
    val_images, val_lights = frames_and_lights(validation, resolution)
    val_features = pooled_features(net, val_images)

    fuse = net.light_decoder.fuse
    # Only the light decoder learns; the code term's gradient passes through the light encoder
    # without collecting there.
    for p in net.parameters():
        p.requires_grad_(False)
    for p in fuse.parameters():
        p.requires_grad_(True)

    def score_validation() -> dict[str, float]:
        with torch.no_grad():
            pred = fuse(val_features)
            code_error = float(code_distance(pred, torch.from_numpy(val_lights)))
            return {**agreement(pred.numpy(), val_lights), "code_error": code_error}

    def encoded(seed: int) -> tuple[torch.Tensor, torch.Tensor]:
        t0 = time.time()
        features, lights = training_features(net, sessions, resolution, settings.swap_surround, seed)
        print(f"{len(features)} frames of {len(sessions)} sessions encoded in {time.time() - t0:.0f} s")
        return features, lights

    features, lights = encoded(settings.seed)
    code_distance = CodeDistance(net, lights)
    before = score_validation()
    start_weights = {k: v.clone() for k, v in fuse.state_dict().items()}
    start = time.time()
    member_scores, fitted = [], []
    for seed in range(settings.seed, settings.seed + settings.members):
        if seed != settings.seed and settings.swap_surround:
            features, _ = encoded(seed)  # each member's own draw of surrounds; the lights are the same
        fuse.load_state_dict(start_weights)
        fit_fuse(fuse, features, lights, settings, seed, code_distance)
        fitted.append({k: v.clone() for k, v in fuse.state_dict().items()})
        member_scores.append({"seed": seed, "validation_after": score_validation()})
    fuse.load_state_dict({k: torch.stack([w[k] for w in fitted]).mean(dim=0) for k in start_weights})
    return {
        "stage": "light_decoder",
        "encoder": "frozen",
        "frames": len(features),
        "sessions": len(sessions),
        **dataclasses.asdict(settings),
        "seconds": round(time.time() - start, 1),
        "validation_before": before,
        "validation_after": score_validation(),
        **({"member_scores": member_scores} if settings.members > 1 else {}),
    }


def refit(model_dir: Path, data_root: Path, out: Path, settings: FitSettings, validation: Path | None = None) -> dict:
    """Refits an exported model's light decoder and writes the model to ``out``: the other
    stages copied, the light decoder re-exported and the whole chain checked, the saved network
    (where the model has one) given the refitted light decoder. ``validation`` is the set scored
    before and after (default: ``data_root/validation``)."""
    if out.resolve() == model_dir.resolve() or model_dir.resolve().is_relative_to(out.resolve()):
        raise SystemExit(f"--out {out} would replace the model it refits; choose another folder")
    net = network_from_model(model_dir)
    manifest = contract.read(model_dir / "model.json")
    resolution = manifest["resolution"]
    scored_on = validation or data_root / "validation"
    scored = data.Heldout.load(scored_on)
    record = {**fit(net, data_root, scored, resolution, settings), "validation": str(scored_on)}

    if out.exists():
        shutil.rmtree(out)
    shutil.copytree(model_dir, out)
    specs = contract.stage_specs(resolution, manifest["widths"])
    image = data.to_tensor(data.area_resize(scored.images[0, 0], resolution))[None]
    lights = [torch.from_numpy(scored.lights[i])[None] for i in (0, 4)]
    ref = reference_run(net, image, *lights)
    write_stages(net, {"light_decoder": specs["light_decoder"]}, out, ref)
    checked = parity(out, specs, ref)
    manifest["training"]["light_refit"] = record
    if (model_dir / SAVED_NETWORK).exists():
        # Fine-tuning starts from the saved network: it gets the refitted light decoder too.
        refit_saved_network(net, model_dir / SAVED_NETWORK, out / SAVED_NETWORK, record)
    manifest.get("metrics", {}).pop("heldout", None)
    manifest["parity"].update(checked)  # other stages (presence) keep their own
    contract.write(out / "model.json", manifest)
    return record


def refit_saved_network(net: model.LcfnNet, saved: Path, out: Path, record: dict) -> None:
    """Writes the saved network ``saved`` to ``out`` with ``net``'s light decoder in place of its
    own, every other weight as saved, and the refit's ``record`` in its provenance."""
    cfg, state = runs.read_network(saved)
    refitted = net.state_dict()
    state = {k: refitted[k] if k.startswith("light_decoder.") else v for k, v in state.items()}
    whole = model.build(cfg)
    whole.load_state_dict(state)
    source = torch.load(saved, map_location="cpu", weights_only=True).get("source", {})
    runs.save_network(whole, cfg, out, {**source, "light_refit": record})


# What ``fit_after`` copies of the run it starts from: the records the export reads.
RUN_RECORDS = ("pairing.json", "machine.json", "log.csv")


def fit_after(run: Path, data_root: Path, out: Path, settings: FitSettings) -> dict:
    """Gives a finished LCFN run trained without light prediction (``lsyd.train
    --no-light-prediction``) a light decoder fitted on its frozen encoder (or refits the one it
    has), and writes the result as a run folder at ``out`` (replaced) that the export and the
    evaluation read as any other."""
    if out.resolve() == run.resolve() or run.resolve().is_relative_to(out.resolve()):
        raise SystemExit(f"--out {out} would replace the run it starts from; choose another folder")
    trained, cfg = load_network(run)
    if cfg.net.arch != "lcfn":
        raise SystemExit(f"{run}: a {cfg.net.arch} run; only the LCFN network has a light decoder to fit")
    checkpoint = torch.load(run / "checkpoint.pt", map_location="cpu", weights_only=False)
    if checkpoint["step"] < cfg.steps:
        raise SystemExit(
            f"{run}: trained {checkpoint['step']} of its {cfg.steps} steps; finish it first (lsyd.train --resume)"
        )
    net_cfg = dataclasses.replace(cfg.net, light_prediction=True)
    with torch.random.fork_rng():
        torch.manual_seed(settings.seed)  # a fresh light decoder's initial weights
        net = model.build(net_cfg).eval()
    missing, unexpected = net.load_state_dict(trained.state_dict(), strict=False)
    if unexpected or any(not k.startswith("light_decoder.") for k in missing):
        raise SystemExit(f"{run}: not an LCFN network this fit can complete ({missing=}, {unexpected=})")
    validation = data.Heldout.load(data_root / "validation")
    record = fit(net, data_root, validation, net_cfg.resolution, settings)
    record["start"] = "fresh" if missing else "as trained"

    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    torch.save({"net": net.state_dict(), "step": checkpoint["step"]}, out / "checkpoint.pt")
    weights = cfg.weights
    if missing:
        # The network trained without light prediction: no monitor loss, no steps de-lit with
        # a predicted light, whatever the configuration's weights said.
        weights = dataclasses.replace(weights, monitor=0.0, unknown_source=0.0, monitor_colour=0.0)
    # The network fitted on is the run's average where it kept one, and the fitted checkpoint
    # holds it as its network; the light fit's record says which it was.
    fitted_cfg = dataclasses.replace(cfg, net=net_cfg, weights=weights, weight_average=0.0)
    (out / "config.json").write_text(json.dumps(fitted_cfg.to_json(), indent=2) + "\n")
    for name in RUN_RECORDS:
        if (run / name).exists():
            shutil.copy2(run / name, out / name)
    source = {"run": run.name, "weight_average": cfg.weight_average}
    (out / LIGHT_FIT_RECORD).write_text(json.dumps(source | record, indent=2) + "\n")
    (out / "done").touch()
    return record


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--model", type=Path, help="the model folder whose light decoder is refitted")
    what.add_argument(
        "--run", type=Path, help="a training run (say one without light prediction) given a light decoder fitted after"
    )
    p.add_argument("--data", type=Path, default=Path("data"), help="captures, validation and held-out sets")
    p.add_argument("--validation", type=Path, help="the set scored before and after (default: DATA/validation)")
    p.add_argument("--out", type=Path, required=True, help="the refitted model's folder (replaced), or the run's")
    p.add_argument("--steps", type=int, default=4000)
    p.add_argument("--batch", type=int, default=64)
    p.add_argument("--lr", type=float, default=1e-3)
    p.add_argument("--colour", type=float, default=1.0, help="weight of the mean colour's L1")
    p.add_argument("--code", type=float, default=0.0, help="weight of the light code's standardised squared error")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--members",
        type=int,
        default=1,
        help="fits from the same start, seeded SEED, SEED+1, ..., averaged weight by weight",
    )
    p.add_argument(
        "--swap-surround",
        type=float,
        default=0.0,
        help="share of the frames fitted on with their face over another frame's surround (1: read the face)",
    )
    p.add_argument("--threads", type=int, default=0, help="CPU threads (0: all cores)")
    a = p.parse_args()
    if a.threads:
        torch.set_num_threads(a.threads)
    if a.members < 1:
        raise SystemExit(f"--members {a.members}: at least one fit is needed")
    settings = FitSettings(
        steps=a.steps,
        batch=a.batch,
        lr=a.lr,
        colour=a.colour,
        code=a.code,
        seed=a.seed,
        swap_surround=a.swap_surround,
        members=a.members,
    )
    if a.run and a.validation:
        raise SystemExit("--validation is for --model; a run is scored on DATA/validation")
    if a.model:
        record = refit(a.model, a.data, a.out, settings, a.validation)
    else:
        record = fit_after(a.run, a.data, a.out, settings)
    print(json.dumps(record, indent=2))


if __name__ == "__main__":
    main()
