"""Measures a model for its card and writes the card.

    python -m lsyd.modelcard --model models/default --run runs/default --data data

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
import platform
from pathlib import Path

import numpy as np

from . import benchmark, contract, data, metrics
from .train import TrainConfig

ROOT = Path(__file__).resolve().parents[2]


def heldout(folder: Path, held: data.Heldout) -> dict:
    net = benchmark.OrtModel(folder, 2)
    res = net.m["resolution"]
    small = data.area_resize(held.images, res) / 255.0
    codes = [net.code(held.lights[j][None]) for j in range(held.lights.shape[0])]
    out = {}
    for mode in ("known", "predicted"):
        scores: dict[str, list[float]] = {"rmse": [], "ms_ssim": [], "flip": [], "monitor_mae": []}
        for p in range(held.images.shape[0]):
            for i in range(held.images.shape[1]):
                x = np.ascontiguousarray(small[p, i].transpose(2, 0, 1)[None], dtype=np.float32)
                enc = dict(zip(net.enc_names, net.s["encoder"].run(None, {"image": x})))
                (pred,) = net.s["light_decoder"].run(None, {k: enc[k] for k in ("e2", "e4", "e6")})
                if mode == "known":
                    scores["monitor_mae"].append(float(np.abs(pred[0] - held.lights[i]).mean()))
                source = held.lights[i][None] if mode == "known" else pred
                for j in range(held.images.shape[1]):
                    if j == i:
                        continue
                    relit = net.relight(x, source, codes[j])[0]
                    full = metrics.transfer(held.images[p, i], x[0], relit)
                    gt = held.clean[p, j]
                    scores["rmse"].append(metrics.rmse(full, gt))
                    scores["ms_ssim"].append(metrics.ms_ssim(full, gt))
                    scores["flip"].append(metrics.flip(full, gt))
        out[mode] = {k: float(np.mean(v)) for k, v in scores.items() if v}
    # The floor: the input itself, unrelit, against the target's ground truth.
    unrelit = [
        metrics.rmse(held.images[p, i], held.clean[p, j])
        for p in range(held.images.shape[0])
        for i in range(held.images.shape[1])
        for j in range(held.images.shape[1])
        if i != j
    ]
    out["input_unrelit_rmse"] = float(np.mean(unrelit))
    return out


def measure(model: Path, held: data.Heldout, data_root: Path) -> dict:
    m = contract.read(model / "model.json")
    return {
        "command": f"python -m lsyd.modelcard --model {model.relative_to(ROOT)} --data {data_root.name}",
        "pairs": 324,
        "relightings": 648,
        **heldout(model, held),
        "gflop_per_frame": benchmark.model_flops(model),
        "network_ms_2_threads": benchmark.time_ort(model, 2),
        "network_ms_1_thread": benchmark.time_ort(model, 1),
        "machine": f"{platform.processor() or platform.machine()}, 2 cores",
        "parameters_mb": sum(p.stat().st_size for p in model.glob("*.onnx")) / 1e6,
        "resolution": m["resolution"],
    }


def card(model: Path, run: Path | None) -> str:
    m = contract.read(model / "model.json")
    h = m["metrics"].get("heldout", {})
    e = m["metrics"].get("element", {})
    p = m["metrics"].get("presence", {})
    cfg = (
        TrainConfig.from_json(json.loads((run / "config.json").read_text()))
        if run and (run / "config.json").exists()
        else None
    )
    lines = [
        f"# Model card: `{model.name}`",
        "",
        "The personalised relighting network of the default synthetic subject (the desk light-stage",
        "simulator's person, seed 7), in the [model contract](CONTRACT.md)'s five stages plus the optional",
        "presence stage.",
        "",
        "## Data",
        "",
        "- 16 capture sessions of 60 s at 10 frames a second (9,600 frames, 256 x 256), each with its own outfit and",
        "  room light (ceiling, lamp left or right, window; 8-35% of a white monitor's light), the monitor playing",
        "  scenes, pans, fades, text pages, solid colours, moving bright patches and environment maps",
        "  (`deskstage all --out data`).",
        "- Training pairs found by facial keypoints within each session, as on real captures",
        "  (`lsyd.pairing`, threshold 0.02 of the inter-ocular distance; about 95,000 ordered pairs, 93-96% of them",
        "  within 2 degrees, 5 mm and 0.1 expression of the same pose by the simulator's truth).",
        "- Never seen in training: the held-out set's 9 poses, 9 lights and outfit, and the test recordings.",
        "",
        "## Configuration",
        "",
    ]
    if cfg:
        w = cfg.weights
        machine = m["training"].get("machine", "the 2-core CPU build machine")
        lines += [
            f"- Architecture: the paper's LCFN U-Net at {cfg.net.resolution} x {cfg.net.resolution}, widths "
            f"{list(cfg.net.widths)} ({cfg.net.width:g} of the paper's 32-64-128-256-512), light codes of 256.",
            f"- Training: {cfg.steps} steps of batch {cfg.batch}, Adam (lr {cfg.lr:g}, cosine to a tenth), "
            f"seed {cfg.seed}, on {machine} (`scripts/train-all.sh`).",
            f"- Losses (paper eqs. 3-6): L1 x{w.l1:g}; perceptual x{w.perceptual:g}, an offline stand-in "
            "(Laplacian-pyramid L1 plus 0.5 (1 - SSIM); ImageNet networks cannot be downloaded here); "
            f"cycle x{w.cycle:g}; LSGAN PatchGAN x{w.adversarial:g}; monitor loss x{w.monitor:g} (L1, gradient L1 "
            "as its perceptual term, and cycle on the target light). "
            f"{100 * w.unknown_source:.0f}% of steps de-light with the predicted source light.",
        ]
    lines += [
        f"- Size: {h.get('parameters_mb', 0):.1f} MB of ONNX graphs; {h.get('gflop_per_frame', 0):.2f} GFLOP a frame.",
        "",
        "## Accuracy on the held-out set",
        "",
        "648 relightings (every ordered light pair of 9 poses x 9 lights: the paper's 324 pairs both ways), against",
        "exact ground truth at 256 x 256, the relit crop put back with the element's transfer. "
        f"Command: `{h.get('command', '')}`.",
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
    (model.parent / "README.md").write_text(card(model, a.run))
    print(f"wrote {model.parent / 'README.md'}")


if __name__ == "__main__":
    main()
