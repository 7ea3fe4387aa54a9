"""Measures a model for its card and writes the card.

    python -m lsyd.evaluation.modelcard --model models/default --run runs/default --data data

Measures on the held-out set (9 poses x 9 lights, every ordered pair: 648
relightings of the paper's 324 pairs) with ONNX Runtime, as the element runs
the model: RMSE on 0-255, MS-SSIM, FLIP and monitor-prediction MAE, with the
source light known and predicted; FLOPs per frame; the network's time per
frame on this machine. Records them in the manifest (``metrics.heldout``) and
writes ``models/README.md`` from the manifest, including the figures other
commands recorded there (the element end to end, the presence classifier).
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

import numpy as np
import torch

from .. import contract, data, export
from ..model import PAPER_WIDTHS
from ..runs import LossWeights, TrainConfig, hardware, read_config
from . import ROOT, benchmark, metrics

# Colour correlation from which the card says the predicted monitor follows the screen's colour.
COLOUR_FOLLOWS = 0.5


def heldout(folder: Path, held: data.Heldout) -> dict:
    """Accuracy with the source light known and predicted, and the prediction's error."""
    chain = contract.StageChain(folder, 2)
    codes = [chain.light_code(held.lights[j][None]) for j in range(held.lights.shape[0])]
    out = {}
    for mode in ("known", "predicted"):
        monitor_mae: list[float] = []
        colours: list[tuple[np.ndarray, np.ndarray]] = []  # (predicted, true) mean RGB of the screen

        def relight(
            x: np.ndarray,
            _pose: int,
            i: int,
            targets: list[int],
            mode: str = mode,
            mae: list = monitor_mae,
            colours: list = colours,
        ) -> np.ndarray:
            pred = chain.predict_light(x[None])
            mae.append(float(np.abs(pred[0] - held.lights[i]).mean()))
            colours.append((pred[0].mean(axis=(1, 2)), held.lights[i].mean(axis=(1, 2))))
            source = held.lights[i][None] if mode == "known" else pred
            return np.concatenate([chain.relight(x[None], source, codes[j]) for j in targets])

        out[mode] = metrics.score_test_set(held, chain.resolution, relight)
        if mode == "known":
            out[mode]["monitor_mae"] = float(np.mean(monitor_mae))
            pred, true = (np.array(c) for c in zip(*colours))
            # Does the prediction follow the screen's brightness, and its colour (blue minus red)?
            out[mode]["monitor_brightness_corr"] = float(np.corrcoef(pred.mean(1), true.mean(1))[0, 1])
            out[mode]["monitor_colour_corr"] = float(
                np.corrcoef(pred[:, 2] - pred[:, 0], true[:, 2] - true[:, 0])[0, 1]
            )
    # The floor: the input itself, unrelit, against the target's ground truth.
    n_pose, n_light = held.images.shape[:2]
    unrelit = [
        metrics.rmse(held.images[p, i], held.clean[p, j])
        for p in range(n_pose)
        for i in range(n_light)
        for j in range(n_light)
        if i != j
    ]
    out["input_unrelit_rmse"] = float(np.mean(unrelit))
    return out


def measure(model: Path, held: data.Heldout, data_root: Path) -> dict:
    m = contract.read(model / "model.json")
    n_pose, n_light = held.images.shape[:2]
    return {
        "command": f"python -m lsyd.evaluation.modelcard --model {model.relative_to(ROOT)} --data {data_root.name}",
        "pairs": n_pose * n_light * (n_light - 1) // 2,
        "relightings": n_pose * n_light * (n_light - 1),
        **heldout(model, held),
        "gflop_per_frame": benchmark.model_flops(model),
        "network_ms_2_threads": benchmark.time_ort(model, 2),
        "network_ms_1_thread": benchmark.time_ort(model, 1),
        "machine": hardware(torch.device("cpu")),
        "parameters_mb": sum(p.stat().st_size for p in model.glob("*.onnx")) / 1e6,
        "resolution": m["resolution"],
    }


def data_lines(data_root: Path, run: Path | None, training: dict) -> list[str]:
    """What the model trained on, from the captures' metadata and the run's pairing record (or,
    without the run, what the export recorded of it in the manifest's ``training``)."""
    metas = [json.loads(p.read_text()) for p in sorted((data_root / "captures").glob("*/meta.json"))]
    if not metas:
        return [f"- Captures: not found under {data_root}/captures."]
    spec = metas[0]["spec"]
    frames = sum(x["frames"] for x in metas)
    ratios = [float(r) for x in metas for r in re.findall(r"ratio: ([0-9.]+)", x.get("ambient", ""))]
    lines = [
        f"- {len(metas)} capture sessions of {spec['seconds']:g} s at {spec['fps']:g} frames a second ({frames:,} "
        f"frames, {spec['size']} x {spec['size']}) of subject seed {spec['subject_seed']}, each with its own outfit "
        f"and room light ({100 * min(ratios):.0f}-{100 * max(ratios):.0f}% of a white monitor's light), the monitor "
        "playing scenes, pans, fades, text pages, solid colours, moving bright patches and environment maps "
        "(`deskstage all --out data`).",
    ]
    pairing = (export.pairing_summary(run) if run else None) or training.get("pairing")
    if pairing:
        lines.append(
            "- Training pairs found by facial keypoints within each session, as on real captures (`lsyd.pairing`, "
            f"threshold {pairing['max_keypoint_distance']:g} of the inter-ocular distance): {pairing['pairs']:,} "
            f"ordered pairs, {100 * pairing['precision']:.1f}% of them within 2 degrees, 5 mm and 0.1 expression of "
            "the same pose by the simulator's truth."
        )
    else:
        lines.append(f"- Training data as the export recorded it: {training.get('data', 'not recorded')}.")
    lines.append(
        "- Never seen in training: the held-out set's 9 poses, 9 lights and outfit, the validation set, and the "
        "test recordings."
    )
    return lines


def machine_line(sessions: list[dict]) -> str:
    """Where and how long the model trained, from ``lsyd.train``'s record."""
    if not sessions:
        return "an unrecorded machine"
    minutes = sum(x["seconds"] for x in sessions) / 60
    machines = sorted({f"{x['hardware']} ({x['device']}, {x['cpu_threads']} threads)" for x in sessions})
    return f"{' and '.join(machines)} in {minutes:.0f} minutes"


def configuration_lines(m: dict, cfg: TrainConfig | None) -> list[str]:
    """How the model was built and trained, from its manifest (what the export recorded of the
    run), with the learning rate from the run's configuration where the run is at hand."""
    t = m["training"]
    w = LossWeights(**t["losses"])
    res, widths = m["resolution"], list(m["widths"])
    lr = cfg.lr if cfg else t.get("lr")
    lr = f"lr {lr:g}, " if lr else ""
    refit = t.get("light_refit")
    # A run trained without light prediction whose light decoder was fitted after it.
    fitted_after = bool(refit) and refit.get("start") == "fresh"
    lines = [
        f"- Architecture: the paper's LCFN U-Net at {res} x {res}, widths {widths} "
        f"({widths[1] / PAPER_WIDTHS[1]:g} of the paper's 32-64-128-256-512), light codes of {m['code_dim']}.",
        f"- Training: {t['steps']} steps of batch {t['batch']}, Adam ({lr}cosine to a tenth), seed {t['seed']}, "
        f"on {machine_line(t.get('machine', []))} (`scripts/train-all.sh`).",
        f"- Losses (paper eqs. 3-6): L1 x{w.l1:g}; perceptual x{w.perceptual:g}, an offline stand-in "
        "(Laplacian-pyramid L1 plus 0.5 (1 - SSIM); ImageNet networks cannot be downloaded here); "
        f"cycle x{w.cycle:g}; LSGAN PatchGAN x{w.adversarial:g}; "
        + (
            "no monitor loss: the network trained without its light decoder (`--no-light-prediction`), "
            "which was fitted afterwards (below)."
            if fitted_after
            else f"monitor loss x{w.monitor:g} (L1, gradient L1 as its perceptual term, and cycle on the target "
            f"light). {100 * w.unknown_source:.0f}% of steps de-light with the predicted source light."
        ),
    ]
    added = []
    if w.delit_consistency:
        added.append(
            f"de-lit consistency x{w.delit_consistency:g}, the standardised distance between the de-lit "
            "features of a pair's two images, each de-lit with its own light"
        )
    if w.monitor_colour:
        added.append(
            f"monitor colour x{w.monitor_colour:g} inside the monitor loss, L1 between the predicted and true "
            "screens' mean colours"
        )
    if added:
        lines.append(
            "- Added to the paper's losses (each off in the tables' runs; README, \"Beyond the paper\"): "
            + "; ".join(added)
            + "."
        )
    if refit:
        before, after = refit["validation_before"], refit["validation_after"]
        how = "fitted after training" if fitted_after else "refitted"
        lines.append(
            f"- Light decoder {how} on the frozen encoder (`lsyd.light_refit`): "
            + (f"the weight average of {refit['members']} fits, each " if refit.get("members", 1) > 1 else "")
            + f"{refit['steps']} steps of batch "
            f"{refit['batch']} over the {refit['frames']:,} captured frames' features, Adam (lr {refit['lr']:g}, "
            f"cosine to a tenth), monitor colour x{refit['colour']:g}"
            + (f", light code x{refit['code']:g}" if refit.get("code") else "")
            + f", in {refit['seconds'] / 60:.0f} minutes; "
            "every other stage as trained. On the validation set its colour correlation went from "
            f"{before['colour_corr']:.2f} to {after['colour_corr']:.2f}, its monitor MAE from "
            f"{before['monitor_mae']:.4f} to {after['monitor_mae']:.4f}."
        )
    return lines


def card(model: Path, run: Path | None, data_root: Path) -> str:
    m = contract.read(model / "model.json")
    h = m["metrics"].get("heldout", {})
    e = m["metrics"].get("element", {})
    p = m["metrics"].get("presence", {})
    cfg = read_config(run) if run and (run / "config.json").exists() else None
    lines = [
        f"# Model card: `{model.name}`",
        "",
        "The personalised relighting network of the desk light-stage simulator's default person, in the",
        "[model contract](CONTRACT.md)'s five stages plus the optional presence stage.",
        "",
        "## Data",
        "",
        *data_lines(data_root, run, m["training"]),
        "",
        "## Configuration",
        "",
    ]
    lines += configuration_lines(m, cfg)
    lines += [
        f"- Size: {h.get('parameters_mb', 0):.1f} MB of ONNX graphs; {h.get('gflop_per_frame', 0):.3f} GFLOP a "
        "frame as the element runs it (encoder, source light code, de-lighting, decoder).",
        "",
        "## Accuracy on the held-out set",
        "",
        f"{h.get('relightings', 0)} relightings (every ordered light pair of 9 poses x 9 lights: the paper's "
        f"{h.get('pairs', 0)} pairs both ways), against exact ground truth at 256 x 256, the relit crop put back "
        f"with the element's transfer. Command: `{h.get('command', '')}`.",
        "",
        "| source light | RMSE (0-255) | MS-SSIM | FLIP | monitor MAE (linear) |",
        "|---|---|---|---|---|",
    ]
    for mode, label in (("known", "known (from the monitor)"), ("predicted", "predicted (unknown source)")):
        r = h.get(mode, {})
        if r:
            mae = f"{h['known'].get('monitor_mae', float('nan')):.4f}" if mode == "known" else ""
            lines.append(f"| {label} | {r['rmse']:.2f} | {r['ms_ssim']:.4f} | {r['flip']:.4f} | {mae} |")
    if "input_unrelit_rmse" in h:
        lines.append(f"| (the input, not relit) | {h['input_unrelit_rmse']:.2f} | | | |")
    known = h.get("known", {})
    if "monitor_colour_corr" in known:
        lines += [
            "",
            "The predicted monitor against the true one, over the held-out frames: its brightness correlates "
            f"{known['monitor_brightness_corr']:.2f}, its colour (blue minus red) {known['monitor_colour_corr']:.2f}. "
            + (
                "The prediction follows the screen's colour as well as its brightness, so an unknown light is "
                "relit in its hue too; the monitor stream, where there is one, still relights best (the known row)."
                if known["monitor_colour_corr"] >= COLOUR_FOLLOWS
                else "A prediction that follows brightness but not colour relights the strength of an unknown light "
                "better than its hue; give the element the monitor stream where colour matters."
            ),
        ]
    lines += [
        "",
        "## End to end through the element",
        "",
    ]
    for key, rec in e.items():
        lines += [
            f"The standard recording `{key.rsplit('_', 1)[0]}`, first {key.rsplit('_', 1)[1]} frames at 480 x 360 I420",
            "with its monitor video, relit to each target light; RMSE on 0-255 over the face region (the",
            f"centred square) against exact ground truth. Command: `{rec['command']}`. The end-to-end test",
            "(`tests/end_to_end.rs`) checks the element still gives these numbers.",
            "",
            "| target | RMSE face region | input RMSE (not relit) | change RMSE |",
            "|---|---|---|---|",
        ]
        for t, s in rec["targets"].items():
            lines.append(f"| {t} | {s['rmse_region']:.3f} | {s['input_rmse_region']:.3f} | {s['change_rmse']:.3f} |")
        lines.append("")
    lines += [
        "## Speed",
        "",
        f"The network alone in ONNX Runtime on this machine ({h.get('machine', '')}): "
        f"{h.get('network_ms_2_threads', 0):.1f} ms a frame with 2 threads, "
        f"{h.get('network_ms_1_thread', 0):.1f} ms with 1 (`{h.get('command', '')}`). "
        "Through the whole element, and against every other configuration, see the",
        "benchmark in the README.",
        "",
    ]
    if p:
        lines += [
            "## Presence stage",
            "",
            f"Is anybody in the face region: {p['accuracy']:.4f} accuracy on {p['heldout_frames']} held-out frames"
            f" ({p['missed_person']} missed, {p['false_person']} false). Command: `{p['command']}`.",
            "",
        ]
    lines += [
        "## Export",
        "",
        f"ONNX Runtime against PyTorch, max abs difference: {max(m.get('parity', {'-': float('nan')}).values()):.1e}"
        " (the export fails above 1e-4). Re-train from scratch with `scripts/train-all.sh`.",
        "",
    ]
    return "\n".join(lines)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", type=Path, default=ROOT / "models" / "default")
    p.add_argument("--run", type=Path, default=ROOT / "runs" / "default")
    p.add_argument("--data", type=Path, default=ROOT / "data")
    p.add_argument("--card-only", action="store_true", help="rewrite the card from the recorded numbers")
    a = p.parse_args()
    model = a.model.resolve()
    if not a.card_only:
        m = json.loads((model / "model.json").read_text())
        m.setdefault("metrics", {})["heldout"] = measure(model, data.Heldout.load(a.data / "heldout"), a.data)
        contract.write(model / "model.json", m)
    (model.parent / "README.md").write_text(card(model, a.run, a.data))
    print(f"wrote {model.parent / 'README.md'}")


if __name__ == "__main__":
    main()
