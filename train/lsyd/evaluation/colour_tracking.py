"""Fits and scores the element's colour tracking: the predicted source light's colour taken
from how the face's own colour changes (``plugin/engine/colour_tracking.rs``).

    python -m lsyd.evaluation.colour_tracking --data data/starter --model models/starter

A light decoder reads the screen's brightness from a face but hardly its colour, and for a
stranger one frame cannot tell skin from light. Within one person, though, the face's log
chromaticity departs from its slow mean as the light's does. The element keeps the slow mean
of the prediction's colour and replaces its departure by the face's, times a gain per axis
(ln r/g, ln b/g). This fits those gains, by least squares pooled over the training people's
desk sessions (``DATA/captures/person-1NN``: the departures of the screen's log chromaticity
on the face's, each from its slow mean at the element's weight), for several weights, and
scores each weight on the people the model never saw (``DATA/unseen-captures``, capture
sessions of the unseen people that ``scripts/train-starter.sh`` records): per session, the
correlation over its frames of the colour (blue less red over the sum, as the monitor-match
check reads it) of the predicted light with the screen's, from the decoder alone and tracked.
Writes ``OUT/results.json`` and ``OUT/table.md``.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import numpy as np
import torch

from .. import contract, data
from ..export import network_from_model
from . import ROOT

# The element's face region, in face heights from the face's centre (colour_tracking.rs).
HALF_WIDTH, HALF_HEIGHT = 0.3, 0.35
FLOOR = 1e-4
WEIGHTS = (0.002, 0.005, 0.01, 0.02)
ELEMENT_WEIGHT = 0.005


def face_region(resolution: int, crop: dict) -> tuple[slice, slice]:
    """Rows and columns of the network input that the element reads the face's colour from,
    where the crop rule puts the face."""
    height = 1.0 / crop["side"]
    centre = (0.5, 0.5 + crop["lift"] / crop["side"])

    def span(c: float, half: float) -> slice:
        lo = min(max(int(np.floor((c - half * height) * resolution)), 0), resolution - 1)
        return slice(lo, max(int(np.ceil((c + half * height) * resolution)), lo + 1))

    return span(centre[1], HALF_HEIGHT), span(centre[0], HALF_WIDTH)


def chroma(rgb: np.ndarray) -> np.ndarray:
    """ln(r/g), ln(b/g) of (..., 3) colours."""
    rgb = np.maximum(rgb, FLOOR)
    return np.stack([np.log(rgb[..., 0] / rgb[..., 1]), np.log(rgb[..., 2] / rgb[..., 1])], -1)


def departures(x: np.ndarray, weight: float) -> np.ndarray:
    """Each row of ``x`` less the slow mean that includes it, as the element updates it."""
    mean, out = x[0].copy(), np.empty_like(x)
    for i, v in enumerate(x):
        mean += weight * (v - mean)
        out[i] = v - mean
    return out


def track(face: np.ndarray, predicted: np.ndarray, weight: float, gain: np.ndarray) -> np.ndarray:
    """The element's rule on per-frame mean colours: (T, 3) face and predicted light in, the
    predicted light's mean colour tracked out (same sum of channels)."""
    # The departures start at zero, so the first frame passes as it is.
    want = chroma(predicted) - departures(chroma(predicted), weight) + gain * departures(chroma(face), weight)
    shift = want - chroma(predicted)
    tinted = predicted * np.exp(np.stack([shift[:, 0], np.zeros(len(shift)), shift[:, 1]], 1))
    return tinted * (predicted.sum(1) / tinted.sum(1))[:, None]


def colour(rgb: np.ndarray) -> np.ndarray:
    return (rgb[:, 2] - rgb[:, 0]) / rgb.sum(1)


def session_colours(net, session: Path, resolution: int, region) -> dict[str, np.ndarray]:
    """Per frame: the face region's mean linear colour, the screen's and the predicted light's."""
    images, lights = data.session_frames(session, resolution)
    face = contract.srgb_to_linear(images[:, region[0], region[1]] / 255.0).mean((1, 2))
    predicted = []
    with torch.no_grad():
        for i in range(0, len(images), 100):
            _, feats = net.encode(data.to_tensor(images[i : i + 100]))
            predicted.append(net.predict_light(feats).numpy().mean((2, 3)))
    return {"face": face, "screen": lights.mean((2, 3)), "predicted": np.concatenate(predicted)}


def fit_gain(sessions: list[dict], weight: float) -> np.ndarray:
    """Least squares, pooled over sessions, of the screen's chroma departures on the face's."""
    f = np.concatenate([departures(chroma(s["face"]), weight) for s in sessions])
    t = np.concatenate([departures(chroma(s["screen"]), weight) for s in sessions])
    return (f * t).sum(0) / (f * f).sum(0)


def correlations(sessions: list[dict], weight: float, gain: np.ndarray) -> dict[str, list[float]]:
    def corr(a, b):
        return round(float(np.corrcoef(colour(a), colour(b))[0, 1]), 4)

    return {
        "decoder": [corr(s["predicted"], s["screen"]) for s in sessions],
        "tracked": [corr(track(s["face"], s["predicted"], weight, gain), s["screen"]) for s in sessions],
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", type=Path, default=ROOT / "data/starter")
    p.add_argument("--model", type=Path, default=ROOT / "models/starter")
    p.add_argument("--out", type=Path, default=ROOT / "results/colour_tracking")
    a = p.parse_args()
    manifest = contract.read(a.model / "model.json")
    resolution = manifest["resolution"]
    region = face_region(resolution, manifest["crop"])
    net = network_from_model(a.model).eval()
    train_dirs = sorted(d for d in (a.data / "captures").glob("person-1*") if not d.name.endswith("-dome"))
    unseen_dirs = sorted((a.data / "unseen-captures").glob("person-*"))
    if not train_dirs or not unseen_dirs:
        raise SystemExit(f"{a.data}: no desk sessions in captures/ or unseen-captures/; run scripts/train-starter.sh")
    train = [session_colours(net, d, resolution, region) for d in train_dirs]
    unseen = [session_colours(net, d, resolution, region) for d in unseen_dirs]

    rows = []
    for weight in WEIGHTS:
        gain = fit_gain(train, weight)
        rows.append(
            {
                "weight": weight,
                "gain": [round(float(g), 3) for g in gain],
                "training": correlations(train, weight, gain),
                "unseen": correlations(unseen, weight, gain),
            }
        )
    a.out.mkdir(parents=True, exist_ok=True)
    record = {"model": a.model.name, "training_sessions": len(train), "unseen_sessions": len(unseen), "rows": rows}
    (a.out / "results.json").write_text(json.dumps(record, indent=2) + "\n")

    def cell(values: list[float]) -> str:
        return f"{np.median(values):.2f} ({np.min(values):.2f} to {np.max(values):.2f})"

    lines = [
        "# The predicted light's colour: from the light decoder, and tracked from the face",
        "",
        f"Model `{a.model.name}`. Colour correlation of the predicted light with the screen over each desk "
        f"session's 300 frames, median (least to most) over {len(train)} training people and {len(unseen)} "
        "people the model never saw. Gains (ln r/g, ln b/g) fitted on the training people at each weight "
        f"of the slow means; the element uses {ELEMENT_WEIGHT}.",
        "",
        "| weight | gains | training, decoder | training, tracked | unseen, decoder | unseen, tracked |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['weight']} | {r['gain'][0]:.2f}, {r['gain'][1]:.2f} | {cell(r['training']['decoder'])} | "
            f"{cell(r['training']['tracked'])} | {cell(r['unseen']['decoder'])} | {cell(r['unseen']['tracked'])} |"
        )

    def shown(path: Path) -> str:
        return os.path.relpath(path.resolve(), ROOT / "train")

    lines += [
        "",
        "Made by `cd train && ../.venv/bin/python -m lsyd.evaluation.colour_tracking "
        f"--data {shown(a.data)} --model {shown(a.model)}`.",
    ]
    (a.out / "table.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
