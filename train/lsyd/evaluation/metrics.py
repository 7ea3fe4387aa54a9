"""Image metrics against exact ground truth, and the transfer of a relit crop to full size.

- RMSE on 0-255.
- MS-SSIM (Wang, Simoncelli, Bovik 2003), five scales with the standard weights,
  over the three RGB channels.
- FLIP (Andersson et al. 2020, ``flip-evaluator``), LDR mode: a perceptual
  difference in [0, 1].
- Temporal: the paper's adjacent-frame RMSE and the share of adjacent pairs
  above thresholds; and, since the ground truth is exact, the RMSE of the
  frame-to-frame change against the ground truth's change, which separates
  flicker from real motion.

``score_test_set`` is the one loop that scores a network on a 9 x 9 test set.
"""

from __future__ import annotations

from collections.abc import Callable

import flip_evaluator
import numpy as np
import torch
import torch.nn.functional as F

from .. import data, losses

MS_SSIM_WEIGHTS = (0.0448, 0.2856, 0.3001, 0.2363, 0.1333)
# Thresholds of the adjacent-frame error rates, RMSE on 0-255. The paper's
# 0.2/0.3/0.4 have no stated unit; these are chosen on our own scale.
TEMPORAL_THRESHOLDS = (2.0, 4.0, 8.0)


def rmse(a: np.ndarray, b: np.ndarray) -> float:
    """RMSE on 0-255 of two images in [0, 255]."""
    d = a.astype(np.float64) - b.astype(np.float64)
    return float(np.sqrt((d * d).mean()))


def ms_ssim(a: np.ndarray, b: np.ndarray) -> float:
    """MS-SSIM of two HxWx3 images in [0, 255]; needs at least 176 pixels a side."""
    ta = torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32)).permute(2, 0, 1)[None] / 255.0
    tb = torch.from_numpy(np.ascontiguousarray(b, dtype=np.float32)).permute(2, 0, 1)[None] / 255.0
    vals = []
    for i, _ in enumerate(MS_SSIM_WEIGHTS):
        luminance, cs = losses.ssim_maps(ta, tb)
        # Contrast-structure at every scale; luminance too at the coarsest.
        vals.append((luminance * cs).mean() if i == len(MS_SSIM_WEIGHTS) - 1 else cs.mean())
        ta, tb = F.avg_pool2d(ta, 2), F.avg_pool2d(tb, 2)
    out = torch.ones(())
    for v, w in zip(vals, MS_SSIM_WEIGHTS):
        out = out * v.clamp(min=1e-6) ** w
    return float(out)


def flip(a: np.ndarray, b: np.ndarray) -> float:
    """Mean FLIP error (LDR, sRGB inputs) of test `a` against reference `b`, both in [0, 255]."""
    ref = np.ascontiguousarray(b, dtype=np.float32) / 255.0
    test = np.ascontiguousarray(a, dtype=np.float32) / 255.0
    _, mean, _ = flip_evaluator.evaluate(ref, test, "LDR", applyMagma=False)
    return float(mean)


GAIN_EPSILON = 0.02
MAX_GAIN = 4.0


def transfer(full: np.ndarray, small_in: np.ndarray, small_out: np.ndarray) -> np.ndarray:
    """The element's lighting transfer (``plugin/frame.rs``): the relit crop's low frequencies,
    the full-size frame's detail scaled by the change in luminance.

    full: (H, W, 3) in [0, 255]; small_in, small_out: (3, r, r) in [0, 1]. Returns (H, W, 3) in [0, 255]."""
    h, w = full.shape[:2]
    lum = np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)[:, None, None]
    gain = np.clip(((small_out * lum).sum(0) + GAIN_EPSILON) / ((small_in * lum).sum(0) + GAIN_EPSILON), 0, MAX_GAIN)

    def up(x: np.ndarray) -> np.ndarray:
        t = torch.from_numpy(np.ascontiguousarray(x, dtype=np.float32))
        t = t[None, None] if t.ndim == 2 else t[None]
        return F.interpolate(t, size=(h, w), mode="bilinear", align_corners=False)[0].numpy()

    base, inp, g = up(small_out * 255.0), up(small_in * 255.0), up(gain)[0]
    out = base + g[None] * (full.transpose(2, 0, 1).astype(np.float32) - inp)
    return np.clip(np.rint(out), 0, 255).transpose(1, 2, 0)


def temporal(outputs: np.ndarray, truth: np.ndarray, cuts: list[int]) -> dict[str, float]:
    """Temporal metrics of a relit sequence (T, H, W, 3) against its exact ground truth."""
    o = outputs.astype(np.float64)
    g = truth.astype(np.float64)
    adj = np.sqrt(((o[1:] - o[:-1]) ** 2).mean(axis=(1, 2, 3)))
    change = np.sqrt((((o[1:] - o[:-1]) - (g[1:] - g[:-1])) ** 2).mean(axis=(1, 2, 3)))
    # A cut before frame c shows in the change from frame c - 1; a cut at frame 0 has none.
    at_cuts = [c - 1 for c in cuts if c >= 1]
    out = {
        "adjacent_rmse": float(adj.mean()),
        "change_rmse": float(change.mean()),
        "change_rmse_at_cuts": float(change[at_cuts].mean()) if at_cuts else float("nan"),
        "rmse": float(np.sqrt(((o - g) ** 2).mean())),
    }
    for t in TEMPORAL_THRESHOLDS:
        out[f"adjacent_over_{t:g}"] = float((adj > t).mean())
    return out


SCORES = {"rmse": rmse, "ms_ssim": ms_ssim, "flip": flip}


def score_test_set(
    held: data.Heldout,
    resolution: int,
    relight: Callable[[np.ndarray, int, int, list[int]], np.ndarray],
    scores: tuple[str, ...] = tuple(SCORES),
) -> dict[str, float]:
    """Mean RMSE, MS-SSIM and FLIP (or those of them named in ``scores``: MS-SSIM and FLIP take
    most of the time) of every ordered light pair of every pose (648 relightings of the
    paper's 324 pairs), each relit crop put back at full size with the element's transfer and
    scored against the exact ground truth.

    ``relight(x, pose, source, targets)`` relights the network input ``x`` (3, r, r) in
    [0, 1], lit by light ``source``, to each light in ``targets``: (len(targets), 3, r, r)."""
    small = data.area_resize(held.images, resolution) / 255.0
    n_pose, n_light = held.images.shape[:2]
    values: dict[str, list[float]] = {k: [] for k in scores}
    for p in range(n_pose):
        for i in range(n_light):
            x = np.ascontiguousarray(small[p, i].transpose(2, 0, 1), dtype=np.float32)
            targets = [j for j in range(n_light) if j != i]
            relit = relight(x, p, i, targets)
            for k, j in enumerate(targets):
                full = transfer(held.images[p, i], x, relit[k])
                gt = held.clean[p, j]
                for k, v in values.items():
                    v.append(SCORES[k](full, gt))
    return {k: float(np.mean(v)) for k, v in values.items()}
