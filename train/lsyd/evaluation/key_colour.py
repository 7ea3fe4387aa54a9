"""Does a model colour a face by a light's colour wherever on the grid the light sits?

    python -m lsyd.evaluation.key_colour --data data/starter --model models/starter \\
        --targets target/tmp/targets-call-60

For each simulated person no model trained on (``DATA/unseen/person-*``: 9 poses x 9 lights;
every other pose, five, with each of its lights taken as the known source), the network
relights to each preset light (the monitor frames ``cargo run --release --example
target_lights -- measure`` writes as ``target-preset-*.png``) and to the same light spread
evenly over the grid (every cell the grid's mean), and the face's change of warmth, ln(R / B)
of its mean colour over the face's middle in the network's crop (where the element reads the
face's colour), is read for both. The even spread has the same colour and power; a light's
place changes where it falls, not the face's overall colour, and at the desk, whose screen is
the grid (all within about 26 degrees of straight ahead), hardly even where it falls. The
ratio (preset over even spread) is how much of a local light's colour the model gives: 1
keeps it; a preset whose even spread hardly warms or cools a face (by less than
``LEAST_SPREAD``) has no ratio. Writes ``OUT/results.json`` and ``OUT/table.md``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from PIL import Image

from .. import contract, data
from . import ROOT
from .colour_tracking import face_region

# Added to each channel's mean before the log, as the element's gain (GAIN_EPSILON).
EPSILON = 0.02
# Every other pose: five of nine hold the face's turns both ways and halve the time.
POSES = range(0, 9, 2)
# The least change of warmth an even spread must make for a ratio to mean anything.
LEAST_SPREAD = 0.1


def even_spread(light: np.ndarray) -> np.ndarray:
    """A light [1, 3, H, W] with every cell its grid's mean, per channel."""
    return np.broadcast_to(light.mean(axis=(2, 3), keepdims=True), light.shape).astype(np.float32)


def warmth(image: np.ndarray, crop: dict) -> float:
    """ln(R / B) of the mean colour over the face's middle of a [3, R, R] image in [0, 1], the
    face where ``crop`` (the model's crop rule) puts it."""
    rows, columns = face_region(image.shape[-1], crop)
    mean = image[:, rows, columns].mean(axis=(1, 2)) + EPSILON
    return float(np.log(mean[0] / mean[2]))


def preset_lights(targets: Path) -> dict[str, np.ndarray]:
    """The preset lights of ``targets``' ``target-preset-*.png``, by preset name."""
    lights = {}
    for png in sorted(targets.glob("target-preset-*.png")):
        frame = np.asarray(Image.open(png).convert("RGB"))
        lights[png.stem.removeprefix("target-preset-")] = contract.light_from_frames(frame[None]).astype(np.float32)
    return lights


def warmth_changes(chain: contract.StageChain, crop: dict, held: data.Heldout, target: np.ndarray) -> list[float]:
    """The face's change of warmth, relit to ``target`` from each pose's every light."""
    code = chain.light_code(target)
    small = data.area_resize(held.images, chain.resolution) / 255.0
    changes = []
    for p in POSES:
        for i in range(held.lights.shape[0]):
            x = np.ascontiguousarray(small[p, i].transpose(2, 0, 1), dtype=np.float32)
            relit = chain.relight(x[None], held.lights[i][None], code)[0]
            changes.append(warmth(relit, crop) - warmth(x, crop))
    return changes


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", type=Path, default=ROOT / "data/starter")
    p.add_argument("--model", type=Path, default=ROOT / "models/starter")
    p.add_argument("--targets", type=Path, default=ROOT / "target/tmp/targets-call-60")
    p.add_argument("--out", type=Path, default=ROOT / "results/key_colour")
    a = p.parse_args()
    lights = preset_lights(a.targets)
    people = sorted((a.data / "unseen").glob("person-*"))
    if not lights or not people:
        raise SystemExit(
            f"no presets in {a.targets} (run `cargo run --release --example target_lights -- measure`) "
            f"or no people in {a.data / 'unseen'} (run scripts/train-starter.sh)"
        )
    chain = contract.StageChain(a.model, 2)
    crop = contract.read(a.model / "model.json")["crop"]
    helds = [data.Heldout.load(person) for person in people]
    relightings = len(people) * len(POSES) * helds[0].lights.shape[0]
    rows = []
    for name, light in lights.items():
        local = np.concatenate([warmth_changes(chain, crop, h, light) for h in helds])
        spread = np.concatenate([warmth_changes(chain, crop, h, even_spread(light)) for h in helds])
        # Least squares through the origin, over every relighting.
        ratio = float(local @ spread / (spread @ spread)) if abs(spread.mean()) >= LEAST_SPREAD else None
        rows.append(
            {
                "preset": name,
                "as_given": round(float(local.mean()), 4),
                "evenly_spread": round(float(spread.mean()), 4),
                "ratio": None if ratio is None else round(ratio, 3),
            }
        )
    a.out.mkdir(parents=True, exist_ok=True)
    record = {"model": a.model.name, "people": len(people), "relightings_per_preset": relightings, "rows": rows}
    (a.out / "results.json").write_text(json.dumps(record, indent=2) + "\n")
    lines = [
        f"Face's change of warmth, ln(R/B), with `{a.model.name}` on {len(people)} unseen people "
        f"({relightings} relightings a preset; `python -m lsyd.evaluation.key_colour`). No ratio where the "
        f"even spread changes the face's warmth by less than {LEAST_SPREAD}.",
        "",
        "| preset | as given | evenly spread | ratio |",
        "|---|---|---|---|",
    ]
    lines += [
        f"| {r['preset']} | {r['as_given']:+.3f} | {r['evenly_spread']:+.3f} | "
        + ("n/a" if r["ratio"] is None else f"{r['ratio']:.2f}")
        + " |"
        for r in rows
    ]
    (a.out / "table.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
