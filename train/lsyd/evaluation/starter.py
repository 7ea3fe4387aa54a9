"""Is a model safe on people it never saw? The starter model's test.

    python -m lsyd.evaluation.starter --data data/starter --models models/starter models/default [--stage dome]

For each simulated person in ``DATA/unseen`` (held-out sets of 9 poses x 9 lights of
people no model trained on; ``DATA/unseen-dome`` with ``--stage dome``, the same lit from the
dome the light code stands for), every ordered light pair is relit and put back with
the element's transfer, and scored on the face crop against exact ground truth
(RMSE on 0-255). Beside each model, with the source light known and predicted:

- the input, not relit;
- the oracle gain: the best single gain per colour channel for each relighting,
  fitted to the truth by least squares (a global colour correction that knows the
  answer).

A model is safe on strangers when it beats the oracle gain with the monitor known,
and is never worse than the input with it unknown. Writes ``OUT/starter.json`` and
``OUT/starter.md`` (``starter-dome.*`` for the dome).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from .. import contract, data
from . import ROOT, metrics


def oracle_gain_rmse(source: np.ndarray, truth: np.ndarray) -> float:
    """RMSE of the best per-channel gain from ``source`` to ``truth`` ((S, S, 3) in 0-255)."""
    x = source.reshape(-1, 3).astype(np.float64)
    y = truth.reshape(-1, 3).astype(np.float64)
    gain = (x * y).sum(0) / np.maximum((x * x).sum(0), 1e-9)
    return metrics.rmse(np.clip(x * gain, 0, 255), y)


def baselines(held: data.Heldout) -> dict[str, float]:
    n_pose, n_light = held.images.shape[:2]
    unrelit, oracle = [], []
    for p in range(n_pose):
        for i in range(n_light):
            for j in range(n_light):
                if i != j:
                    unrelit.append(metrics.rmse(held.images[p, i], held.clean[p, j]))
                    oracle.append(oracle_gain_rmse(held.images[p, i], held.clean[p, j]))
    return {"input": float(np.mean(unrelit)), "oracle_gain": float(np.mean(oracle))}


def model_rmse(folder: Path, held: data.Heldout) -> dict[str, float]:
    """Mean RMSE of every ordered light pair, source light known and predicted."""
    chain = contract.StageChain(folder, 2)
    codes = [chain.light_code(held.lights[j][None]) for j in range(held.lights.shape[0])]
    small = data.area_resize(held.images, chain.resolution) / 255.0
    n_pose, n_light = held.images.shape[:2]
    scores: dict[str, list[float]] = {"known": [], "predicted": []}
    for p in range(n_pose):
        for i in range(n_light):
            x = np.ascontiguousarray(small[p, i].transpose(2, 0, 1), dtype=np.float32)[None]
            sources = {"known": held.lights[i][None], "predicted": chain.predict_light(x)}
            for mode, source in sources.items():
                for j in range(n_light):
                    if j == i:
                        continue
                    relit = chain.relight(x, source, codes[j])[0]
                    full = metrics.transfer(held.images[p, i], x[0], relit)
                    scores[mode].append(metrics.rmse(full, held.clean[p, j]))
    return {mode: float(np.mean(v)) for mode, v in scores.items()}


def markdown(result: dict) -> str:
    names = list(result["models"])
    lines = [
        f"Face-crop RMSE (0-255) on {len(result['people'])} simulated people no model trained on "
        f"(seeds {', '.join(str(p) for p in result['people'])}), every ordered pair of 9 lights "
        f"in 9 poses each, lit from the {result['stage']}. Command: `{result['command']}`.",
        "",
        "| person | input | oracle gain | " + " | ".join(f"{n} known | {n} predicted" for n in names) + " |",
        "|---|---|---|" + "---|---|" * len(names),
    ]
    rows = [*result["per_person"].items(), ("mean", result["mean"])]
    for person, r in rows:
        cells = [f"{r['input']:.2f}", f"{r['oracle_gain']:.2f}"]
        for n in names:
            cells += [f"{r[n]['known']:.2f}", f"{r[n]['predicted']:.2f}"]
        lines.append(f"| {person} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", type=Path, default=ROOT / "data" / "starter")
    p.add_argument("--models", type=Path, nargs="+", default=[ROOT / "models" / "starter", ROOT / "models" / "default"])
    p.add_argument("--out", type=Path, default=ROOT / "results" / "starter")
    p.add_argument("--stage", default="desk", choices=["desk", "dome"], help="where the held-out lights shine from")
    a = p.parse_args()

    suffix = "" if a.stage == "desk" else f"-{a.stage}"
    unseen = a.data / f"unseen{suffix}"
    people = sorted(unseen.glob("person-*"), key=lambda d: int(d.name.split("-")[1]))
    if not people:
        raise SystemExit(f"no held-out people under {unseen}: run scripts/train-starter.sh")
    names = [m.name for m in a.models]
    per_person: dict[str, dict] = {}
    for folder in people:
        held = data.Heldout.load(folder)
        row = baselines(held)
        for model in a.models:
            row[model.name] = model_rmse(model, held)
        per_person[folder.name] = row
        print(folder.name, json.dumps(row))
    rows = list(per_person.values())
    mean = {k: float(np.mean([r[k] for r in rows])) for k in ("input", "oracle_gain")}
    for n in names:
        mean[n] = {m: float(np.mean([r[n][m] for r in rows])) for m in ("known", "predicted")}
    result = {
        "command": "python -m lsyd.evaluation.starter" + (f" --stage {a.stage}" if suffix else ""),
        "stage": a.stage,
        "people": [int(f.name.split("-")[1]) for f in people],
        "models": names,
        "per_person": per_person,
        "mean": mean,
    }
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / f"starter{suffix}.json").write_text(json.dumps(result, indent=2) + "\n")
    (a.out / f"starter{suffix}.md").write_text(markdown(result))
    print(markdown(result))


if __name__ == "__main__":
    main()
