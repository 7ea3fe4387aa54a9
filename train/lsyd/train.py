"""Train a relighting network on desk light-stage captures.

    python -m lsyd.train --data data --out runs/default --steps 6000

Pairs come from facial keypoints within each capture session (as on real
captures), optionally joined by the simulator's exact pairs. Training is
seeded and resumable: a checkpoint is written every ``--checkpoint-every``
steps, and ``--resume`` continues from it to the same final weights as an
uninterrupted run of the same command on the same machine. Ctrl-C saves a checkpoint
at the step reached, so ``--resume`` continues from there.

``--init models/starter/network.pt`` fine-tunes a saved network (``lsyd.runs``) instead
of starting from random weights; the network's configuration comes from the file.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import os
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch.optim.swa_utils import AveragedModel, get_ema_multi_avg_fn
from tqdm import tqdm

from . import data, losses, model, pairing
from .runs import LossWeights, TrainConfig, hardware, initial_weights, jitter, read_config, read_network, share


def load_pairs(cfg: TrainConfig, root: Path) -> tuple[data.PairSet, list[dict]]:
    res = cfg.net.resolution
    sets, reports = [], []
    if cfg.pairs in ("keypoints", "both"):
        kp, reports = data.keypoint_pairs(root / "captures", res, cfg.pairing)
        sets.append(kp)
    if cfg.pairs in ("exact", "both"):
        sets.append(data.exact_pairs(root / "paired", res))
    if not sets:
        raise ValueError(f"--pairs must be keypoints, exact or both, not {cfg.pairs!r}")
    offset, pairs = 0, []
    for s in sets:
        pairs.append(s.pairs + offset)
        offset += len(s.images)
    return (
        data.PairSet(
            images=torch.cat([s.images for s in sets]),
            lights=torch.cat([s.lights for s in sets]),
            pairs=torch.cat(pairs),
            rehearsed=torch.cat([s.rehearsed for s in sets]),
        ),
        reports,
    )


class Trainer:
    def __init__(self, cfg: TrainConfig, run: Path, device: torch.device):
        self.cfg = cfg
        self.run = run
        self.device = device
        if cfg.weights.delit_consistency and not (cfg.net.arch == "lcfn" and cfg.net.delight):
            raise ValueError("the de-lit consistency loss needs the LCFN network with de-lighting")
        torch.manual_seed(cfg.seed)
        # channels_last runs the small convolutions about 1.5x faster on CPU (oneDNN).
        self.net = model.build(cfg.net)
        if cfg.init:
            try:
                self.net.load_state_dict(initial_weights(Path(cfg.init), cfg.net))
            except ValueError as e:
                raise SystemExit(str(e)) from e
        self.net = self.net.to(device, memory_format=torch.channels_last)
        self.disc = losses.PatchDiscriminator().to(device, memory_format=torch.channels_last)
        self.opt_g = torch.optim.Adam(self.net.parameters(), lr=cfg.lr, betas=(0.5, 0.999))
        self.opt_d = torch.optim.Adam(self.disc.parameters(), lr=cfg.lr, betas=(0.5, 0.999))
        # The weights' moving average smooths the last steps' noise out of the kept network;
        # training itself goes on with the last weights.
        self.average = (
            AveragedModel(self.net, multi_avg_fn=get_ema_multi_avg_fn(cfg.weight_average), use_buffers=True)
            if cfg.weight_average > 0
            else None
        )
        self.step = 0
        self.sampler = torch.Generator().manual_seed(cfg.seed + 1)

    def lr_at(self, step: int) -> float:
        # Cosine decay to a tenth of the initial rate.
        t = step / max(1, self.cfg.steps)
        return self.cfg.lr * (0.1 + 0.9 * 0.5 * (1.0 + np.cos(np.pi * t)))

    def train_step(self, batch: tuple[torch.Tensor, ...]) -> dict[str, float]:
        w = self.cfg.weights
        src, l_src, tgt, l_tgt = batch
        src = src.to(self.device, memory_format=torch.channels_last)
        tgt = tgt.to(self.device, memory_format=torch.channels_last)
        l_src, l_tgt = l_src.to(self.device), l_tgt.to(self.device)
        for opt in (self.opt_g, self.opt_d):
            for g in opt.param_groups:
                g["lr"] = self.lr_at(self.step)
        predicts = self.cfg.net.arch == "sun" or (self.cfg.net.arch == "lcfn" and self.cfg.net.light_prediction)
        unknown = self.cfg.net.arch == "lcfn" and predicts and torch.rand((), generator=self.sampler) < w.unknown_source
        relit, pred_src = self.net(src, None if unknown else l_src, l_tgt)
        cycled, pred_tgt = self.net(relit, l_tgt, l_src)

        d_loss = losses.lsgan_discriminator(self.disc(tgt), self.disc(relit.detach()))
        self.opt_d.zero_grad(set_to_none=True)
        d_loss.backward()
        self.opt_d.step()

        terms = {
            "l1": F.l1_loss(relit, tgt),
            "perceptual": losses.perceptual(relit, tgt),
            "cycle": F.l1_loss(cycled, src),
            "adversarial": losses.lsgan_generator(self.disc(relit)),
        }
        g_loss = (
            w.l1 * terms["l1"]
            + w.perceptual * terms["perceptual"]
            + w.cycle * terms["cycle"]
            + w.adversarial * terms["adversarial"]
        )
        if w.change:
            terms["change"] = losses.change_l1(src, relit, tgt)
            g_loss = g_loss + w.change * terms["change"]
        if w.coarse_change:
            terms["coarse_change"] = losses.coarse_change_l1(src, relit, tgt)
            g_loss = g_loss + w.coarse_change * terms["coarse_change"]
        if pred_src is not None:
            terms["monitor"] = losses.monitor_match(
                pred_src, l_src, w.l1, w.perceptual, w.monitor_colour
            ) + w.cycle * F.l1_loss(pred_tgt, l_tgt)
            g_loss = g_loss + w.monitor * terms["monitor"]
        if w.delit_consistency:
            delit = self.net.delit_image(torch.cat([src, tgt]), torch.cat([l_src, l_tgt]))
            halves = [f.chunk(2) for f in delit]
            terms["delit"] = losses.standardised_distance([h[0] for h in halves], [h[1] for h in halves])
            g_loss = g_loss + w.delit_consistency * terms["delit"]
        self.opt_g.zero_grad(set_to_none=True)
        g_loss.backward()
        self.opt_g.step()
        if self.average is not None:
            self.average.update_parameters(self.net)
        self.step += 1
        return {"g": g_loss.item(), "d": d_loss.item(), **{k: v.item() for k, v in terms.items()}}

    def state(self) -> dict:
        return {
            "step": self.step,
            "net": self.net.state_dict(),
            "disc": self.disc.state_dict(),
            "opt_g": self.opt_g.state_dict(),
            "opt_d": self.opt_d.state_dict(),
            "sampler": self.sampler.get_state(),
            "torch_rng": torch.get_rng_state(),
        } | ({"average": self.average.state_dict()} if self.average is not None else {})

    def save(self) -> None:
        tmp = self.run / "checkpoint.pt.tmp"
        torch.save(self.state(), tmp)
        os.replace(tmp, self.run / "checkpoint.pt")

    def load(self, path: Path) -> None:
        s = torch.load(path, map_location=self.device, weights_only=False)
        self.net.load_state_dict(s["net"])
        self.disc.load_state_dict(s["disc"])
        self.opt_g.load_state_dict(s["opt_g"])
        self.opt_d.load_state_dict(s["opt_d"])
        if self.average is not None:
            self.average.load_state_dict(s["average"])
        self.sampler.set_state(s["sampler"])
        torch.set_rng_state(s["torch_rng"])
        self.step = s["step"]


def train(
    cfg: TrainConfig,
    data_root: Path,
    run: Path,
    resume: bool,
    checkpoint_every: int,
    device: torch.device,
    stop_at: int | None = None,
) -> None:
    """Trains to ``cfg.steps``, or pauses after step ``stop_at`` with a checkpoint to resume from."""
    run.mkdir(parents=True, exist_ok=True)
    config_path = run / "config.json"
    if resume and config_path.exists():
        saved = read_config(run)
        if saved != cfg:
            was, now = saved.to_json(), cfg.to_json()
            changed = ", ".join(f"{k} {was[k]} then, {now[k]} now" for k in now if was.get(k) != now[k])
            raise SystemExit(
                f"{run}: the run there was started with a different configuration ({changed}); "
                f"to start it again with this one, remove {run}"
            )
    config_path.write_text(json.dumps(cfg.to_json(), indent=2) + "\n")

    t0 = time.time()
    pairs, reports = load_pairs(cfg, data_root)
    if len(pairs.pairs) == 0:
        raise SystemExit("no training pairs: loosen the pairing thresholds or capture more")
    (run / "pairing.json").write_text(
        json.dumps({"rule": dataclasses.asdict(cfg.pairing), "sessions": reports}, indent=2) + "\n"
    )
    print(f"{len(pairs.pairs)} training pairs from {len(pairs.images)} frames, loaded in {time.time() - t0:.0f} s")

    trainer = Trainer(cfg, run, device)
    ckpt = run / "checkpoint.pt"
    if resume and ckpt.exists():
        trainer.load(ckpt)
        print(f"resumed at step {trainer.step}")
    elif ckpt.exists():
        raise SystemExit(f"{ckpt} exists: pass --resume to continue it, or choose another --out")

    log_path = run / "log.csv"
    fields = [
        "step",
        "seconds",
        "g",
        "d",
        "l1",
        "perceptual",
        "cycle",
        "adversarial",
        "monitor",
        "delit",
        "change",
        "coarse_change",
    ]
    # Rows logged after the checkpoint we resume from are trained again; keep them once.
    kept = []
    if resume and log_path.exists():
        with open(log_path, newline="") as f:
            kept = [row for row in csv.DictReader(f) if int(row["step"]) <= trainer.step]
    session_start = trainer.step
    with open(log_path, "w", newline="") as f:
        log = csv.DictWriter(f, fieldnames=fields, extrasaction="ignore")
        log.writeheader()
        log.writerows(kept)
        bar = tqdm(total=cfg.steps, initial=trainer.step, desc=run.name, unit="step")
        start = time.time()
        end = min(cfg.steps, stop_at) if stop_at else cfg.steps
        try:
            while trainer.step < end:
                idx = pairs.draw(cfg.batch, cfg.rehearsal_share, trainer.sampler)
                batch = pairs.batch(idx)
                if cfg.box_jitter:
                    batch = data.jitter_crops(batch, cfg.box_jitter, trainer.sampler)
                if cfg.mirror:
                    batch = data.mirror_pairs(batch, trainer.sampler)
                terms = trainer.train_step(batch)
                bar.update(1)
                if trainer.step % 20 == 0 or trainer.step == cfg.steps:
                    bar.set_postfix(l1=f"{terms['l1']:.4f}", g=f"{terms['g']:.3f}")
                    log.writerow({"step": trainer.step, "seconds": round(time.time() - start, 1), **terms})
                    f.flush()
                if trainer.step % checkpoint_every == 0 or trainer.step == end:
                    trainer.save()
        except KeyboardInterrupt:
            # The step in progress is dropped whole: the state saved is after the last full step.
            bar.close()
            trainer.save()
            record_session(run, device, session_start, trainer.step, time.time() - start)
            print(f"interrupted at step {trainer.step} of {cfg.steps}; checkpoint {ckpt}, --resume continues")
            raise
        bar.close()
    record_session(run, device, session_start, trainer.step, time.time() - start)
    print(f"trained {trainer.step} of {cfg.steps} steps; checkpoint {ckpt}")


def record_session(run: Path, device: torch.device, first: int, last: int, seconds: float) -> None:
    """Appends which machine trained which steps, and how long it took, to ``machine.json``."""
    path = run / "machine.json"
    sessions = json.loads(path.read_text()) if path.exists() else []
    sessions.append(
        {
            "steps": [first, last],
            "seconds": round(seconds, 1),
            "device": device.type,
            "hardware": hardware(device),
            "cpu_threads": torch.get_num_threads(),
        }
    )
    path.write_text(json.dumps(sessions, indent=2) + "\n")


def init_config(
    path: Path,
    arch: str | None,
    resolution: int | None,
    width: float | None,
    no_delight: bool,
    no_light: bool,
    light_field: bool,
) -> model.NetConfig:
    """The configuration of the saved network at ``path``; options given on the command line
    must agree with it (the weights fit only the network they were trained in), except that
    ``--light-field`` grows a light field onto a network without one."""
    try:
        cfg, _ = read_network(path)
    except ValueError as e:
        raise SystemExit(str(e)) from e
    asked = {"arch": arch, "resolution": resolution, "width": width}
    asked |= {"delight": False} if no_delight else {}
    asked |= {"light_prediction": False} if no_light else {}
    wrong = [
        f"--{k.replace('_', '-')} {v} (the network has {getattr(cfg, k)})"
        for k, v in asked.items()
        if v is not None and v != getattr(cfg, k)
    ]
    if wrong:
        raise SystemExit(f"--init {path}: the saved network's configuration differs: {'; '.join(wrong)}")
    return dataclasses.replace(cfg, light_field=True) if light_field else cfg


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", type=Path, default=Path("data"))
    p.add_argument("--out", type=Path, required=True, help="run folder: config, checkpoint, log")
    p.add_argument("--arch", default=None, choices=["lcfn", "sun", "sengupta"], help="default lcfn")
    p.add_argument("--resolution", type=int, default=None, help="default 128")
    p.add_argument("--width", type=float, default=None, help="channel widths as a fraction of the paper's; 0.25")
    p.add_argument("--init", type=Path, default=None, help="start from this saved network (network.pt)")
    p.add_argument("--no-delight", action="store_true", help="ablation: plain skips instead of LCFN de-lighting")
    p.add_argument("--no-light-prediction", action="store_true", help="ablation: no light decoder or monitor loss")
    p.add_argument(
        "--light-field",
        action="store_true",
        help="not in the paper: a map of where the target light falls, drawn into the decoder (grown onto --init)",
    )
    p.add_argument(
        "--monitor-colour",
        type=float,
        default=LossWeights.monitor_colour,
        help="not in the paper: weight of the predicted monitor's mean-colour term",
    )
    p.add_argument(
        "--delit-consistency",
        type=float,
        default=LossWeights.delit_consistency,
        help="not in the paper: weight of the loss pulling a pair's de-lit features together",
    )
    p.add_argument(
        "--change",
        type=float,
        default=LossWeights.change,
        help="not in the paper: weight of the L1 between the relit and target images' smooth lighting changes",
    )
    p.add_argument(
        "--coarse-change",
        type=float,
        default=LossWeights.coarse_change,
        help="not in the paper: weight of the L1 between the two lighting changes averaged over 8 px cells",
    )
    p.add_argument("--steps", type=int, default=TrainConfig.steps)
    p.add_argument("--batch", type=int, default=TrainConfig.batch)
    p.add_argument("--lr", type=float, default=TrainConfig.lr)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--weight-average",
        type=float,
        default=TrainConfig.weight_average,
        help="keep an exponential moving average of the weights with this decay and use it (0: the last weights)",
    )
    p.add_argument(
        "--rehearsal-share",
        type=share,
        default=None,
        help="draw the pairs of sessions named rehearsal-* for this share of each batch (default: as any pair)",
    )
    p.add_argument(
        "--box-jitter",
        type=jitter,
        default=TrainConfig.box_jitter,
        help="not in the paper: zoom each pair by up to this fraction, and shift it by half as many face heights",
    )
    p.add_argument(
        "--mirror",
        action="store_true",
        help="not in the paper: show each pair mirrored left to right half of the time, face and lights alike",
    )
    p.add_argument("--pairs", default="keypoints", choices=["keypoints", "exact", "both"])
    p.add_argument("--max-keypoint-distance", type=float, default=pairing.PairingRule.max_keypoint_distance)
    p.add_argument("--threads", type=int, default=0, help="CPU threads (0: all cores)")
    p.add_argument("--device", default="auto", help="auto, cpu or cuda")
    p.add_argument("--checkpoint-every", type=int, default=500)
    p.add_argument("--resume", action="store_true")
    p.add_argument("--stop-at", type=int, default=None, help="pause after this step; --resume continues")
    a = p.parse_args()

    if a.threads:
        torch.set_num_threads(a.threads)
    device = torch.device(
        "cuda" if a.device == "auto" and torch.cuda.is_available() else ("cpu" if a.device == "auto" else a.device)
    )
    net = model.NetConfig(
        arch=a.arch or "lcfn",
        resolution=a.resolution or 128,
        width=a.width or 0.25,
        delight=not a.no_delight,
        light_prediction=not a.no_light_prediction,
        light_field=a.light_field,
    )
    if a.init:
        net = init_config(a.init, a.arch, a.resolution, a.width, a.no_delight, a.no_light_prediction, a.light_field)
    cfg = TrainConfig(
        net=net,
        steps=a.steps,
        batch=a.batch,
        lr=a.lr,
        seed=a.seed,
        pairs=a.pairs,
        pairing=pairing.PairingRule(max_keypoint_distance=a.max_keypoint_distance),
        weights=LossWeights(
            delit_consistency=a.delit_consistency,
            monitor_colour=a.monitor_colour,
            change=a.change,
            coarse_change=a.coarse_change,
        ),
        init=str(a.init.resolve()) if a.init else None,
        weight_average=a.weight_average,
        rehearsal_share=a.rehearsal_share,
        box_jitter=a.box_jitter,
        mirror=a.mirror,
    )
    print(f"training {net} on {device} with {torch.get_num_threads()} threads")
    train(cfg, a.data, a.out, a.resume, a.checkpoint_every, device, a.stop_at)


if __name__ == "__main__":
    main()
