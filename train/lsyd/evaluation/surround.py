"""Does a light decoder read the light off the face, or off what surrounds it?

    python -m lsyd.evaluation.surround --models ../models/starter /tmp/starter-face \\
        [--data ../data/starter] [--out ../results/surround]

On the desk sessions of the simulated people no model trained on (``DATA/unseen-captures``), the
predicted monitor of each frame is scored against the screen it faced (``lsyd.light_refit``'s
agreement: MAE in linear light, the correlation over the frames of its mean's brightness and
colour, and the slope of its brightness against the screen's), twice: the frames as filmed, and
each frame's face over the surround (hair, clothes, room) of another frame of its session
(``light_refit.surround_swapped``, all of them). The surround then shows another screen's light,
as a real crop's collar, helmet or wall shows no screen's. A decoder that reads the face keeps
its score; one that reads the shirt loses it. A guess can correlate with the screen and yet
hardly move with it: the slope says how much of the screen's change the guess follows.
Writes ``OUT/results.json`` and ``OUT/table.md``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

from .. import contract, data, light_refit
from ..export import network_from_model
from . import ROOT

# The share of frames whose surround is swapped in the second reading: all of them (a permutation,
# so about one frame a session keeps its own).
ALL = 1.0


def predicted_monitors(net, images: np.ndarray) -> np.ndarray:
    """The light decoder's predicted monitor for (N, R, R, 3) uint8 frames."""
    with torch.no_grad():
        return net.light_decoder.fuse(light_refit.pooled_features(net, images)).numpy()


def score(model_dir: Path, sessions: list[Path], seed: int) -> dict[str, dict[str, float]]:
    """The model's agreement with the screen over every frame of ``sessions``, as filmed and with
    the surround swapped (drawn from a generator seeded by ``seed``, the same for every model)."""
    net = network_from_model(model_dir).eval()
    resolution = contract.read(model_dir / "model.json")["resolution"]
    rng = np.random.default_rng(seed)
    filmed, swapped, lights = [], [], []
    for s in sessions:
        images, lit = data.session_frames(s, resolution)
        masks = light_refit.session_face_masks(s, resolution)
        filmed.append(predicted_monitors(net, images))
        swapped.append(predicted_monitors(net, light_refit.surround_swapped(images, masks, rng, ALL)))
        lights.append(lit)
    true = np.concatenate(lights)
    return {
        "as filmed": light_refit.agreement(np.concatenate(filmed), true),
        "surround swapped": light_refit.agreement(np.concatenate(swapped), true),
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--models", type=Path, nargs="+", default=[ROOT / "models/starter"])
    p.add_argument("--data", type=Path, default=ROOT / "data/starter")
    p.add_argument("--out", type=Path, default=ROOT / "results/surround")
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args()
    sessions = data.capture_dirs(a.data / "unseen-captures")
    if not sessions:
        raise SystemExit(f"{a.data / 'unseen-captures'}: no sessions; scripts/train-starter.sh records them")
    results = {m.name: score(m, sessions, a.seed) for m in a.models}
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "results.json").write_text(json.dumps(results, indent=2) + "\n")
    names = " ".join(str(m) for m in a.models)
    lines = [
        f"The predicted monitor against the screen on {len(sessions)} unseen people's desk sessions "
        f"(`python -m lsyd.evaluation.surround --models {names}`): MAE (linear light) / brightness "
        "correlation / brightness slope (1: the guess follows the screen's changes in full) / colour "
        "correlation, with the frames as filmed and with each face over another frame's surround.",
        "",
        "| model | as filmed | surround swapped |",
        "|---|---|---|",
    ]
    for name, readings in results.items():
        cells = [
            f"{r['monitor_mae']:.3f} / {r['brightness_corr']:.2f} / {r['brightness_slope']:.2f} / "
            f"{r['colour_corr']:.2f}"
            for r in readings.values()
        ]
        lines.append(f"| {name} | {' | '.join(cells)} |")
    (a.out / "table.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
