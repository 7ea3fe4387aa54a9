"""Evaluate trained networks the way the paper's Tables 1-3 do, on exact ground truth.

    python -m lsyd.evaluation.evaluate --data data --out results/paper \\
        --ours runs/t-lcfn --sun runs/t-sun --sengupta runs/t-sengupta \\
        [--no-delight runs/t-nodelight] [--no-prediction runs/t-nopred] [--neither runs/t-neither]
    python -m lsyd.evaluation.evaluate --data data --out results/fitted --ours runs/t-nopred-fitted --held-out-only

- Table 1: relighting the held-out set (9 poses x 9 lights; every ordered pair of
  lights of a pose, 648 relightings over the paper's 324 pairs), ours with and
  without the known source light against both baselines: RMSE (0-255), MS-SSIM,
  FLIP, and monitor-prediction MAE.
- Table 2: temporal consistency on the test recordings relit to each target light:
  the paper's adjacent-frame RMSE and error rates, the change error against the
  ground truth's changes, and accuracy; ablating feature smoothing,
  source-light averaging and LCFN de-lighting (whose absence leaves the skips
  lit, so smoothing them smooths the light as well).
- Table 3: ablation of LCFN de-lighting and of source-light prediction.

A row whose run is not given is left out, and Table 3 without any of its ablations;
``--held-out-only`` leaves out Table 2, which takes most of the run's time. Outputs
``<out>.md``, ``<out>.json`` and a bar chart ``<out>.png``. Relit crops are put back at
the held-out set's full 256 x 256 with the element's transfer (``metrics.transfer``);
recordings are scored at network resolution.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

from .. import data
from ..runs import load_network
from . import metrics

# Table 1's rows, as its records name them (`lsyd.evaluation.seeds` reads them back).
SUN_ROW = "Sun et al. 2019 (source predicted)"
OURS_PREDICTED_ROW = "Ours, source predicted"
SENGUPTA_ROW = "Sengupta et al. 2021 (source given)"
OURS_GIVEN_ROW = "Ours, source given"

TABLE2_RECORDINGS = ("steady", "slow", "cuts")


def _img(x: np.ndarray) -> torch.Tensor:
    """(..., H, W, 3) in [0, 255] to (N, 3, H, W) in [0, 1]."""
    return data.to_tensor(x).reshape(-1, 3, *x.shape[-3:-1])


@torch.no_grad()
def heldout_scores(net, cfg, held: data.Heldout, known_source: bool) -> dict[str, float]:
    """Table 1/3 metrics of one network on the held-out set."""
    lights = torch.from_numpy(held.lights)
    monitor_mae: list[float] = []

    def relight(x: np.ndarray, _pose: int, i: int, targets: list[int]) -> np.ndarray:
        batch = torch.from_numpy(x)[None].expand(len(targets), -1, -1, -1)
        src = lights[i][None].expand(len(targets), -1, -1, -1) if known_source else None
        relit, predicted = net(batch, src, lights[targets])
        if predicted is not None:
            monitor_mae.append(float((predicted[0] - lights[i]).abs().mean()))
        return relit.clamp(0, 1).numpy()

    scores = metrics.score_test_set(held, cfg.net.resolution, relight)
    return {**scores, "monitor_mae": float(np.mean(monitor_mae)) if monitor_mae else float("nan")}


class Sequence:
    """Relights a video frame by frame as the element does: averaged source light,
    smoothed de-lit features (LCFN networks), one target per output."""

    def __init__(self, net, cfg, alpha: float, beta: float, frames: int, known_source: bool):
        self.net, self.cfg = net, cfg
        self.alpha, self.beta, self.frames = alpha, beta, frames
        self.known = known_source
        self.history: list[torch.Tensor] = []
        self.previous: list[torch.Tensor] | None = None

    def _average(self, light: torch.Tensor) -> torch.Tensor:
        self.history = [light] + self.history[: self.frames - 1]
        w = torch.tensor([self.beta**i for i in range(len(self.history))])
        return sum(wi * li for wi, li in zip(w, self.history)) / w.sum()

    @torch.no_grad()
    def step(self, image: torch.Tensor, light: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
        """image (1, 3, r, r), light (1, 3, 16, 32), targets (T, 3, 16, 32) -> (T, 3, r, r)."""
        n = len(targets)
        if self.cfg.net.arch != "lcfn":
            src = self._average(light) if self.known and self.cfg.net.arch == "sengupta" else light
            relit, _ = self.net(image.expand(n, -1, -1, -1), src.expand(n, -1, -1, -1), targets)
            return relit.clamp(0, 1)
        stem, feats = self.net.encode(image)
        src = light if self.known else self.net.predict_light(feats)
        code = self.net.light_encoder(self._average(src))
        f = self.net.delit(feats, code)
        if self.previous is not None:
            f = [self.alpha * a + (1 - self.alpha) * b for a, b in zip(f, self.previous)]
        self.previous = f
        tcode = self.net.light_encoder(targets)
        relit = self.net.decode(stem.expand(n, -1, -1, -1), [t.expand(n, -1, -1, -1) for t in f], tcode)
        return relit.clamp(0, 1)


def recording_scores(net, cfg, rec: data.RecordingCrops, alpha: float, beta: float, frames: int, known: bool) -> dict:
    seq = Sequence(net, cfg, alpha, beta, frames, known)
    names = list(rec.truth)
    targets = torch.from_numpy(np.stack([rec.target_lights[t] for t in names]))
    outs = []
    for t in range(len(rec.face)):
        image = data.to_tensor(rec.face[t])[None]
        light = torch.from_numpy(rec.lights[t])[None]
        outs.append(seq.step(image, light, targets).numpy())
    outs = np.stack(outs) * 255.0  # (T, targets, 3, r, r)
    per_target = [
        metrics.temporal(outs[:, k].transpose(0, 2, 3, 1), rec.truth[name], rec.cuts) for k, name in enumerate(names)
    ]
    return {k: float(np.mean([p[k] for p in per_target])) for k in per_target[0]}


def mean_over(recs: list, **kw) -> dict:
    rows = [recording_scores(rec=r, **kw) for r in recs]
    return {k: float(np.nanmean([r[k] for r in rows])) for k in rows[0]}


def fmt(v: float, digits: int = 4) -> str:
    return "n/a" if v != v else f"{v:.{digits}f}"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", type=Path, default=Path("data"))
    p.add_argument("--out", type=Path, default=Path("results/paper"))
    p.add_argument("--ours", type=Path, required=True)
    for name in ("sun", "sengupta"):
        p.add_argument(f"--{name}", type=Path, default=None, help="a baseline; its rows are left out without it")
    for name in ("no-delight", "no-prediction", "neither"):
        p.add_argument(f"--{name}", type=Path, default=None, help="a Table 3 cell; its row is left out without it")
    p.add_argument("--held-out-only", action="store_true", help="Tables 1 and 3 only, not the recordings' Table 2")
    p.add_argument(
        "--last-weights",
        action="store_true",
        help="score the runs' last weights where they kept an average of them (lsyd.train --weight-average)",
    )
    p.add_argument("--threads", type=int, default=0)
    a = p.parse_args()
    if a.threads:
        torch.set_num_threads(a.threads)

    held = data.Heldout.load(a.data / "heldout")
    nets = {
        k: load_network(getattr(a, k.replace("-", "_")), last_weights=a.last_weights)
        for k in ("ours", "sun", "sengupta", "no-delight", "no-prediction", "neither")
        if getattr(a, k.replace("-", "_")) is not None
    }
    results: dict = {"table1": {}, "table2": {}, "table3": {}}

    def held_row(key: str, known: bool) -> dict:
        net, cfg = nets[key]
        print(f"held-out: {key} ({'known' if known else 'predicted'} source)", flush=True)
        return heldout_scores(net, cfg, held, known)

    ours_known = held_row("ours", True)
    if "sun" in nets:
        results["table1"][SUN_ROW] = held_row("sun", True)
    if nets["ours"][1].net.light_prediction:
        results["table1"][OURS_PREDICTED_ROW] = held_row("ours", False)
    else:
        print("ours has no light decoder: the predicted-source row is left out (lsyd.light_refit --run fits one)")
    if "sengupta" in nets:
        results["table1"][SENGUPTA_ROW] = held_row("sengupta", True)
    results["table1"][OURS_GIVEN_ROW] = ours_known
    if "neither" in nets:
        results["table3"]["no prediction, no de-lighting"] = held_row("neither", True)
    if "no-delight" in nets:
        results["table3"]["prediction, no de-lighting"] = held_row("no-delight", True)
    if "no-prediction" in nets:
        results["table3"]["no prediction, de-lighting"] = held_row("no-prediction", True)
    if results["table3"]:
        results["table3"]["prediction, de-lighting (ours)"] = ours_known

    # Each network sees the recordings at its own resolution.
    crops: dict[int, list[data.RecordingCrops]] = {}

    def recordings(cfg) -> list[data.RecordingCrops]:
        r = cfg.net.resolution
        if r not in crops:
            crops[r] = [data.RecordingCrops.load(a.data / "recordings" / n, r) for n in TABLE2_RECORDINGS]
        return crops[r]

    ours, cfg = nets["ours"]
    rows2 = {}
    if "sun" in nets:
        rows2["Sun et al. 2019"] = dict(
            net=nets["sun"][0], cfg=nets["sun"][1], alpha=1.0, beta=0.6, frames=1, known=True
        )
    if "sengupta" in nets:
        sengupta, sengupta_cfg = nets["sengupta"]
        rows2["Sengupta et al. 2021"] = dict(net=sengupta, cfg=sengupta_cfg, alpha=1.0, beta=0.6, frames=1, known=True)
        rows2["Sengupta et al. 2021 + L_src avg"] = dict(
            net=sengupta, cfg=sengupta_cfg, alpha=1.0, beta=0.6, frames=3, known=True
        )
    rows2 |= {
        "Ours (base)": dict(net=ours, cfg=cfg, alpha=1.0, beta=0.6, frames=1, known=True),
        "Ours + L_src avg": dict(net=ours, cfg=cfg, alpha=1.0, beta=0.6, frames=3, known=True),
        "Ours + LCFN smoothing": dict(net=ours, cfg=cfg, alpha=0.7, beta=0.6, frames=1, known=True),
        "Ours + L_src avg + LCFN smoothing": dict(net=ours, cfg=cfg, alpha=0.7, beta=0.6, frames=3, known=True),
    }
    if "no-delight" in nets:
        plain, plain_cfg = nets["no-delight"]
        # Without LCFN the skips carry the source light, so smoothing them smooths light too.
        rows2["No LCFN + L_src avg"] = dict(net=plain, cfg=plain_cfg, alpha=1.0, beta=0.6, frames=3, known=True)
        rows2["No LCFN + L_src avg + skip smoothing"] = dict(
            net=plain, cfg=plain_cfg, alpha=0.7, beta=0.6, frames=3, known=True
        )
    for name, kw in ({} if a.held_out_only else rows2).items():
        print(f"recordings: {name}", flush=True)
        results["table2"][name] = mean_over(recordings(kw["cfg"]), **kw)

    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.with_suffix(".json").write_text(json.dumps(results, indent=2) + "\n")
    a.out.with_suffix(".md").write_text(markdown(results))
    chart(results, a.out.with_suffix(".png"))
    print(markdown(results))


def markdown(r: dict) -> str:
    lines = ["### Table 1: relighting the held-out set (648 relightings of 324 pairs, exact ground truth)", ""]
    lines += ["| method | RMSE (0-255) | MS-SSIM | FLIP | monitor MAE |", "|---|---|---|---|---|"]
    for k, v in r["table1"].items():
        lines.append(
            f"| {k} | {fmt(v['rmse'], 3)} | {fmt(v['ms_ssim'])} | {fmt(v['flip'])} | {fmt(v['monitor_mae'])} |"
        )
    if r["table2"]:
        lines += [
            "",
            "### Table 2: temporal consistency on the test recordings (steady, slow, cuts; 3 targets each)",
            "",
        ]
        t = metrics.TEMPORAL_THRESHOLDS
        over = " | ".join(f">{x:g}" for x in t)
        lines += [
            f"| method | adjacent RMSE | {over} | change RMSE | change RMSE at cuts | RMSE |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for k, v in r["table2"].items():
            rates = " | ".join(f"{100 * v[f'adjacent_over_{x:g}']:.1f}%" for x in t)
            lines.append(
                f"| {k} | {fmt(v['adjacent_rmse'], 3)} | {rates} | {fmt(v['change_rmse'], 3)} | "
                f"{fmt(v['change_rmse_at_cuts'], 3)} | {fmt(v['rmse'], 3)} |"
            )
    if r["table3"]:
        lines += ["", "### Table 3: ablation of source-light prediction and LCFN de-lighting (held-out set)", ""]
        lines += ["| variant | RMSE (0-255) | MS-SSIM | FLIP |", "|---|---|---|---|"]
        for k, v in r["table3"].items():
            lines.append(f"| {k} | {fmt(v['rmse'], 3)} | {fmt(v['ms_ssim'])} | {fmt(v['flip'])} |")
    return "\n".join(lines) + "\n"


def chart(r: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t2 = r["table2"]
    fig, axes = plt.subplots(1, 3 if t2 else 2, figsize=(15 if t2 else 10, 4.5))
    t1 = r["table1"]
    names = list(t1)
    # Baselines grey, ours green (darker with the source light given).
    colours = ["#999" if "et al." in n else "#2a6" if "given" in n else "#4a8" for n in names]
    for ax, key, label in zip(axes[:2], ("rmse", "flip"), ("RMSE (0-255), lower is better", "FLIP, lower is better")):
        ax.barh(names, [t1[n][key] for n in names], color=colours)
        ax.set_xlabel(label)
        ax.set_title(f"Table 1: held-out {key.upper()}")
    if t2:
        n2 = list(t2)
        axes[2].barh(n2, [t2[n]["change_rmse"] for n in n2], color="#58a")
        axes[2].set_xlabel("change RMSE vs ground truth, lower is better")
        axes[2].set_title("Table 2: temporal")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    main()
