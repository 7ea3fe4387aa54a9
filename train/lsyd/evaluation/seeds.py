"""Issue 16's four cells over several seeds: how far below each baseline ours is, seed by seed
and over the seeds, from the held-out records ``lsyd.evaluation.evaluate`` writes.

    python -m lsyd.evaluation.seeds \\
        0=../results/paper.json,../results/paper-fitted/t-nopred-code.json \\
        1=../results/seed-1/heldout.json 2=../results/seed-2/heldout.json

Each argument is a seed's label and its records (``table1`` of an ``evaluate`` JSON); where a
seed's rows are split over several records, later records' rows replace earlier ones of the
same name (seed 0's baselines come from the paper's run, its own rows from the fitted run).
The four cells compare ours with the source light given against Sengupta et al. and ours with
it predicted against Sun et al., each in RMSE and FLIP. Over the seeds the margin is that of
the means (ours' mean error against the baseline's), beside the smallest and largest of the
seeds' own margins. Prints a markdown table.
"""

from __future__ import annotations

import argparse
import json
import statistics
from dataclasses import dataclass
from pathlib import Path

from . import evaluate, report

# (cell, ours' row, the baseline's row).
CELLS = (
    ("source given, against Sengupta et al.", evaluate.OURS_GIVEN_ROW, evaluate.SENGUPTA_ROW),
    ("source predicted, against Sun et al.", evaluate.OURS_PREDICTED_ROW, evaluate.SUN_ROW),
)
METRICS = (("RMSE", "rmse", 3), ("FLIP", "flip", 4))


@dataclass
class Seed:
    label: str
    rows: dict[str, dict[str, float]]


def read_seed(argument: str) -> Seed:
    """A ``LABEL=FILE[,FILE...]`` argument's rows, later files' rows replacing earlier ones."""
    label, sep, files = argument.partition("=")
    if not sep or not files:
        raise SystemExit(f"{argument!r}: expected LABEL=FILE[,FILE...], such as 1=../results/seed-1/heldout.json")
    rows: dict[str, dict[str, float]] = {}
    for name in files.split(","):
        path = Path(name)
        if not path.is_file():
            raise SystemExit(f"seed {label}: no record at {path}; lsyd.evaluation.evaluate writes it")
        rows.update(json.loads(path.read_text())["table1"])
    for _, ours, baseline in CELLS:
        for row in (ours, baseline):
            if row not in rows:
                raise SystemExit(f"seed {label}: no row {row!r} in {files}")
    return Seed(label, rows)


def margin(ours: float, baseline: float) -> float:
    """How far below the baseline ours is, in percent of the baseline."""
    return 100.0 * (1.0 - ours / baseline)


def table(seeds: list[Seed]) -> str:
    """The markdown table: a row per cell and metric, a column per seed and the seeds' mean."""
    labels = " | ".join(f"seed {s.label}" for s in seeds)
    lines = [
        f"| cell | metric | {labels} | mean over the seeds | margins' range |",
        "|---|---|" + "---|" * len(seeds) + "---|---|",
    ]
    for cell, ours_row, baseline_row in CELLS:
        for metric, key, digits in METRICS:
            ours = [s.rows[ours_row][key] for s in seeds]
            baseline = [s.rows[baseline_row][key] for s in seeds]
            margins = [margin(o, b) for o, b in zip(ours, baseline)]
            per_seed = " | ".join(
                f"{o:.{digits}f} / {b:.{digits}f}: {m:.1f}%" for o, b, m in zip(ours, baseline, margins)
            )
            mean_ours, mean_baseline = statistics.fmean(ours), statistics.fmean(baseline)
            lines.append(
                f"| {cell} | {metric} | {per_seed} | {mean_ours:.{digits}f} / {mean_baseline:.{digits}f}: "
                f"**{margin(mean_ours, mean_baseline):.1f}%** | {min(margins):.1f}% to {max(margins):.1f}% |"
            )
    return "\n".join(lines) + "\n"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("seed", nargs="+", help="LABEL=FILE[,FILE...]: a seed's held-out records")
    p.add_argument("--out", type=Path, help="also write the table to this markdown file")
    args = p.parse_args()
    report(table([read_seed(a) for a in args.seed]), args.out)


if __name__ == "__main__":
    main()
