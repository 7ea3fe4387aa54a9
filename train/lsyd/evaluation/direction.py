"""Does a model light the side of the face the light comes from? Measured against exact truth.

    python -m lsyd.evaluation.direction --data data/starter --models models/starter [--stage dome]

For each simulated person no model trained on (``DATA/unseen-dome``: 9 poses x 9 lights
from the dome the light code stands for; ``DATA/unseen`` with ``--stage desk``), every ordered
light pair is relit with the source light known (or, with ``--source predicted``, predicted from
the face as without a monitor stream), and the face's change is read on the
network's crop, before the element's paste, so that this measures the network alone:

- asymmetry: the mean of 100 ln((Y_out + 2) / (Y_in + 2)) (Y luma in 0-255) over the face's
  left half minus that over its right half (halves split at the nose, within the box round the
  68 keypoints; the person's left is the image's right);
- strength: the RMS over the face of the same log change.

The truth's asymmetry and strength come from the same measure on the exact clean frames. The
summary is the least-squares slope of the model's asymmetry on the truth's (1 means the side and
the size are right, 0 that the side is ignored, negative that it is mirrored), their correlation,
and the ratio of strengths. Writes ``OUT/direction[-STAGE][-predicted].json`` and ``.md``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from .. import contract, data
from . import ROOT

LUMA = np.array([0.299, 0.587, 0.114], dtype=np.float32)
NOSE_TIP = 30  # in the 68-point layout


def log_change(before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """100 ln((Y_after + 2) / (Y_before + 2)) of two (r, r, 3) images in 0-255."""
    return 100.0 * np.log((after @ LUMA + 2.0) / (before @ LUMA + 2.0))


def face_halves(keypoints: np.ndarray, size: int, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """Masks of the face's left and right halves (the person's) on an image of ``size``,
    from keypoints in an image ``scale`` times larger."""
    k = keypoints / scale
    x0, y0 = np.floor(k.min(0)).astype(int)
    x1, y1 = np.ceil(k.max(0)).astype(int)
    ys, xs = np.mgrid[0:size, 0:size]
    inside = (xs >= x0) & (xs <= x1) & (ys >= y0) & (ys <= y1)
    nose = k[NOSE_TIP, 0]
    return inside & (xs > nose), inside & (xs < nose)


def measure(change: np.ndarray, left: np.ndarray, right: np.ndarray) -> tuple[float, float]:
    """(asymmetry, strength) of a log change over the face halves."""
    face = left | right
    return float(change[left].mean() - change[right].mean()), float(np.sqrt((change[face] ** 2).mean()))


def score(folder: Path, held: data.Heldout, keypoints: np.ndarray, predicted: bool) -> dict[str, list[float]]:
    chain = contract.StageChain(folder, 2)
    r = chain.resolution
    codes = [chain.light_code(held.lights[j][None]) for j in range(held.lights.shape[0])]
    small = data.area_resize(held.images, r).astype(np.float32)
    clean = data.area_resize(held.clean, r).astype(np.float32)
    n_pose, n_light = held.images.shape[:2]
    out: dict[str, list[float]] = {k: [] for k in ("truth_asym", "model_asym", "truth_strength", "model_strength")}
    for p in range(n_pose):
        left, right = face_halves(keypoints[p], r, held.images.shape[2] / r)
        for i in range(n_light):
            x = np.ascontiguousarray(small[p, i].transpose(2, 0, 1) / 255.0)[None]
            source = chain.predict_light(x) if predicted else held.lights[i][None]
            for j in range(n_light):
                if j == i:
                    continue
                relit = np.clip(chain.relight(x, source, codes[j])[0], 0, 1).transpose(1, 2, 0) * 255.0
                ta, ts = measure(log_change(clean[p, i], clean[p, j]), left, right)
                ma, ms = measure(log_change(small[p, i], relit), left, right)
                out["truth_asym"].append(ta)
                out["model_asym"].append(ma)
                out["truth_strength"].append(ts)
                out["model_strength"].append(ms)
    return out


def slope(t: np.ndarray, m: np.ndarray) -> float:
    return float((t * m).sum() / max((t * t).sum(), 1e-9))


def correlation(t: np.ndarray, m: np.ndarray) -> float:
    """Pearson's correlation, 0 where either side does not vary (a model blind to the target)."""
    if t.std() == 0 or m.std() == 0:
        return 0.0
    return float(np.corrcoef(t, m)[0, 1])


def summary(s: dict[str, list[float]], targets: int) -> dict[str, float]:
    t, m = np.array(s["truth_asym"]), np.array(s["model_asym"])
    # Pairs come in runs of one source relit to every other light: centred within a run, what
    # is left is how the change's side follows the target alone.
    tc = (t.reshape(-1, targets) - t.reshape(-1, targets).mean(1, keepdims=True)).ravel()
    mc = (m.reshape(-1, targets) - m.reshape(-1, targets).mean(1, keepdims=True)).ravel()
    return {
        "slope": slope(t, m),
        "correlation": correlation(t, m),
        "target_slope": slope(tc, mc),
        "target_correlation": correlation(tc, mc),
        "truth_asym_rms": float(np.sqrt((t**2).mean())),
        "model_asym_rms": float(np.sqrt((m**2).mean())),
        "strength_ratio": float(np.median(s["model_strength"]) / max(np.median(s["truth_strength"]), 1e-9)),
    }


def markdown(result: dict) -> str:
    lines = [
        f"The face's left-minus-right change (points of 100 ln luma) of every ordered pair of 9 lights "
        f"in 9 poses, {len(result['people'])} simulated people no model trained on, lit from the "
        f"{result['stage']}, the source light {result['source']}; the network's crop against exact truth. "
        f"Command: `{result['command']}`.",
        "",
        "| model | slope on truth | correlation | target's slope | target's correlation | asymmetry RMS (truth) "
        "| asymmetry RMS (model) | strength / truth's |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, r in result["models"].items():
        lines.append(
            f"| {name} | {r['slope']:.2f} | {r['correlation']:.2f} | {r['target_slope']:.2f} | "
            f"{r['target_correlation']:.2f} | {r['truth_asym_rms']:.1f} | "
            f"{r['model_asym_rms']:.1f} | {r['strength_ratio']:.2f} |"
        )
    return "\n".join(lines) + "\n"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", type=Path, default=ROOT / "data" / "starter")
    p.add_argument("--models", type=Path, nargs="+", default=[ROOT / "models" / "starter"])
    p.add_argument("--out", type=Path, default=ROOT / "results" / "starter")
    p.add_argument("--stage", default="dome", choices=["desk", "dome"], help="where the held-out lights shine from")
    p.add_argument("--people", type=int, default=8, help="how many of the held-out people to score")
    p.add_argument(
        "--source",
        default="known",
        choices=["known", "predicted"],
        help="the source light as the monitor showed it, or predicted from the face (no monitor stream)",
    )
    a = p.parse_args()

    predicted = a.source == "predicted"
    stage_suffix = "" if a.stage == "desk" else f"-{a.stage}"
    suffix = stage_suffix + ("-predicted" if predicted else "")
    unseen = a.data / f"unseen{stage_suffix}"
    people = sorted(unseen.glob("person-*"), key=lambda d: int(d.name.split("-")[1]))[: a.people]
    if not people:
        raise SystemExit(f"no held-out people under {unseen}: run scripts/train-starter.sh")
    scores: dict[str, dict[str, list[float]]] = {m.name: {} for m in a.models}
    targets = 0
    for folder in people:
        held = data.Heldout.load(folder)
        targets = held.lights.shape[0] - 1
        keypoints = np.load(folder / "keypoints.npy")
        for model in a.models:
            for k, v in score(model, held, keypoints, predicted).items():
                scores[model.name].setdefault(k, []).extend(v)
        print(folder.name, {m: summary(s, targets)["target_slope"] for m, s in scores.items()})
    result = {
        "command": f"python -m lsyd.evaluation.direction --stage {a.stage} --people {a.people} --source {a.source}",
        "stage": a.stage,
        "source": a.source,
        "people": [int(f.name.split("-")[1]) for f in people],
        "models": {name: summary(s, targets) for name, s in scores.items()},
    }
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / f"direction{suffix}.json").write_text(json.dumps(result, indent=2) + "\n")
    (a.out / f"direction{suffix}.md").write_text(markdown(result))
    print(markdown(result))


if __name__ == "__main__":
    main()
