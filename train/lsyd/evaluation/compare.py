"""Compare trained runs on the validation set: what the additions beyond the paper change.

    python -m lsyd.evaluation.compare --data data --runs runs p-r96 e-r96
    python -m lsyd.evaluation.compare --set heldout ../models/default ../models/mine

Each run is exported to ``target/compare/<run>`` and scored with ONNX Runtime on the
validation set (9 poses x 9 lights, exact ground truth): relighting RMSE and FLIP with the
source light known and predicted, the predicted monitor's MAE and how its brightness
and colour (blue minus red) follow the true screen's (``modelcard.heldout``), and the
de-lighting ratio (``delighting_ratios``). Prints a markdown table. A folder holding an
exported model (``model.json``) is scored as it is; ``--set heldout`` scores the held-out set,
as a model card does, without writing the card.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from .. import contract, data, export, losses
from . import ROOT, modelcard

# The light pairs of a 9-light set (held-out or validation) that the de-lighting ratio compares.
DELIGHT_PAIRS = ((0, 5), (2, 3), (0, 8), (4, 6))


def delighting_ratios(folder: Path, held: data.Heldout) -> list[float]:
    """For each pose and light pair: the standardised distance between one face's de-lit
    features under the two lights, each de-lit with its own light, over the distance between
    its raw encoder features (paper section 3.2). Below 1 when de-lighting removes the light."""
    chain = contract.StageChain(folder)

    def features(pose: int, light: int) -> tuple[list[torch.Tensor], list[torch.Tensor]]:
        image = data.to_tensor(data.area_resize(held.clean[pose, light], chain.resolution))[None].numpy()
        raw = chain.encode(image)
        delit = chain.delight(raw, chain.light_code(held.lights[light][None]))
        return [torch.from_numpy(raw[e]) for e in contract.RAW], [torch.from_numpy(d) for d in delit]

    ratios = []
    for a, b in DELIGHT_PAIRS:
        for pose in range(held.clean.shape[0]):
            (raw_a, delit_a), (raw_b, delit_b) = features(pose, a), features(pose, b)
            delit = losses.standardised_distance(delit_a, delit_b)
            raw = losses.standardised_distance(raw_a, raw_b)
            ratios.append((delit / raw).item())
    return ratios


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", type=Path, default=ROOT / "data")
    p.add_argument("--runs", type=Path, default=ROOT / "runs")
    p.add_argument(
        "run",
        nargs="+",
        help="run folder names under --runs, or exported model folders (holding model.json), scored as they are",
    )
    p.add_argument(
        "--set",
        choices=("validation", "heldout"),
        default="validation",
        help="the set scored: validation (what choices are made on) or the held-out set (what model cards report)",
    )
    a = p.parse_args()
    scored = data.Heldout.load(a.data / a.set)
    rows = [
        "| run | RMSE, source known | RMSE, source predicted | FLIP, known | FLIP, predicted | monitor MAE "
        "| monitor brightness corr | monitor colour corr | de-lighting ratio (median) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for run in a.run:
        out = Path(run)
        if not (out / "model.json").is_file():
            out = ROOT / "target" / "compare" / run
            cfg = export.export(a.runs / run, a.data, out)["config"]
            manifest = contract.manifest(run, cfg.net.resolution, cfg.net.widths, "fp32", {}, {})
            contract.write(out / "model.json", manifest)
        h = modelcard.heldout(out, scored)
        known, predicted = h["known"], h["predicted"]
        ratio = float(np.median(delighting_ratios(out, scored)))
        rows.append(
            f"| {run} | {known['rmse']:.3f} | {predicted['rmse']:.3f} | {known['flip']:.4f} | {predicted['flip']:.4f} "
            f"| {known['monitor_mae']:.4f} | {known['monitor_brightness_corr']:.2f} "
            f"| {known['monitor_colour_corr']:.2f} | {ratio:.3f} |"
        )
        print(rows[-1], flush=True)
    print("\n".join(rows))


if __name__ == "__main__":
    main()
