"""Draws the monitor-match check's ROC curves from results.json.

Usage: .venv/bin/python results/match_check/plot.py
(after `cargo run --release --example match_check`).
"""

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

HERE = Path(__file__).parent


def main() -> None:
    results = json.loads((HERE / "results.json").read_text())
    fig, ax = plt.subplots(figsize=(5, 5))
    for window, r in results["windows"].items():
        fpr = [0.0] + [p[1] for p in r["roc"]]
        tpr = [0.0] + [p[2] for p in r["roc"]]
        ax.plot(fpr, tpr, label=f"{float(window):g} s window, AUC {r['auc']:.3f}")
    ax.plot([0, 1], [0, 1], color="grey", linewidth=0.5, linestyle=":")
    ax.set_xlabel("impostor windows passed (delayed or swapped screen)")
    ax.set_ylabel("genuine windows passed")
    ax.set_title("Monitor-match check on the simulator")
    ax.legend(loc="lower right")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.01)
    fig.tight_layout()
    fig.savefig(HERE / "roc.png", dpi=120)


if __name__ == "__main__":
    main()
