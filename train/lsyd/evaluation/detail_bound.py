"""How much of the detail band a lighting change sampled at a given resolution can remove
(issue 16): the bound on what the element's transfer, and any network that feeds it, can do
about the source light's fine shading.

    python -m lsyd.evaluation.detail_bound \\
        --recording ../target/recordings/call-90 --face ../target/clean-faces/call-90.y4m

The element relights a frame by a gain field: per channel, the log of output over input,
sampled at the network's resolution over the face's crop and interpolated up to the frame.
Here that gain is the *exact* one, the truth's own change of the face, area-sampled at each
resolution over the face region and interpolated bilinearly back, and the face times it is
scored as ``examples/flicker.rs`` scores the element: the face region (the frame's centred
square), its error split into a smooth band (two box blurs of ``DETAIL_RADIUS_FRACTION`` of
the region's side, as ``tests/support/src/recording.rs``) and the detail band, the rest. No
network and no smoothing: what is left in the detail band is what a change at that
resolution cannot reach, however good the network.

``--guided`` adds, at each resolution, the exact change upsampled the edge-aware way (a local
linear fit of the log gain on the input's log luma at that resolution, applied at the
frame's own: the fast guided filter): whether the input's fine edges say where its fine
shading is. Run it on the noiseless face (``cargo run --release --example flicker --
--recordings call --frames 90 --clean`` renders both files), so that the detail band holds
only the light's shading. Decoded as the scorer decodes (BT.601 limited, chroma as stored),
the input's own bands equal that command's "input" columns to the digit. Prints a markdown
table; ``--out`` writes it too.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from ..data import area_resize, centre_square, read_y4m
from . import report

# As `DETAIL_RADIUS_FRACTION` in tests/support/src/recording.rs.
DETAIL_RADIUS_FRACTION = 1.0 / 48.0
# As `GAIN_EPSILON` in plugin/frame.rs, on 0-255.
GAIN_EPSILON = 0.02 * 255.0
# The guided fit's window radius (in samples at the change's resolution) and regularisation
# (on the variance of log luma).
GUIDED_RADIUS = 1
GUIDED_EPSILON = 1e-3


def detail_radius(side: int) -> int:
    """The band split's blur radius in pixels: the region's side over 48, rounded half up as
    Rust's ``f64::round``."""
    return max(1, math.floor(side * DETAIL_RADIUS_FRACTION + 0.5))


def box_blur(field: np.ndarray, radius: int) -> np.ndarray:
    """A box blur over the last two axes, ``radius`` each way, shrinking at the borders."""

    def along(a: np.ndarray, axis: int) -> np.ndarray:
        a = np.moveaxis(a, axis, -1)
        n = a.shape[-1]
        prefix = np.concatenate([np.zeros((*a.shape[:-1], 1)), np.cumsum(a, -1)], -1)
        k = np.arange(n)
        lo, hi = np.maximum(k - radius, 0), np.minimum(k + radius + 1, n)
        return np.moveaxis((prefix[..., hi] - prefix[..., lo]) / (hi - lo), -1, axis)

    return along(along(field, -1), -2)


def band_sums(output: np.ndarray, truth: np.ndarray, radius: int) -> tuple[float, float, int]:
    """Sums of squares of the smooth and detail bands of the error of an (S, S, 3) image, and
    the number of samples."""
    o, t = (np.moveaxis(np.asarray(x, np.float64), -1, 0) for x in (output, truth))
    so, st = (box_blur(box_blur(x, radius), radius) for x in (o, t))
    smooth = float(((so - st) ** 2).sum())
    detail = float((((o - so) - (t - st)) ** 2).sum())
    return smooth, detail, o.size


def exact_change(face: np.ndarray, truth: np.ndarray, resolution: int) -> np.ndarray:
    """The log gain that takes (N, S, S, 3) uint8 ``face`` to ``truth``, area-sampled to
    resolution × resolution: (N, R, R, 3)."""
    small_face, small_truth = area_resize(face, resolution), area_resize(truth, resolution)
    return np.log((small_truth + GAIN_EPSILON) / (small_face + GAIN_EPSILON))


def upsample(field: np.ndarray, side: int) -> np.ndarray:
    """(N, R, R, C) bilinearly to (N, side, side, C), sample centres aligned as the element's."""
    t = torch.from_numpy(np.ascontiguousarray(field, np.float32)).permute(0, 3, 1, 2)
    up = F.interpolate(t, size=(side, side), mode="bilinear", align_corners=False)
    return up.permute(0, 2, 3, 1).numpy().astype(np.float64)


def log_luma(images: np.ndarray) -> np.ndarray:
    """(..., 3) on 0-255 to the log of their channels' mean, (...)."""
    return np.log(np.asarray(images, np.float64).mean(-1) + GAIN_EPSILON)


def guided_upsample(change: np.ndarray, face: np.ndarray) -> np.ndarray:
    """``change`` (N, R, R, 3) upsampled to ``face``'s (N, S, S) by a local linear fit on the
    input's log luma at resolution R, applied to its log luma at S."""
    resolution, side = change.shape[1], face.shape[1]
    guide = log_luma(area_resize(face, resolution))
    mean_guide = box_blur(guide, GUIDED_RADIUS)
    variance = box_blur(guide * guide, GUIDED_RADIUS) - mean_guide**2
    slopes, offsets = [], []
    for c in range(3):
        mean_change = box_blur(change[..., c], GUIDED_RADIUS)
        covariance = box_blur(guide * change[..., c], GUIDED_RADIUS) - mean_guide * mean_change
        slope = covariance / (variance + GUIDED_EPSILON)
        slopes.append(box_blur(slope, GUIDED_RADIUS))
        offsets.append(box_blur(mean_change - slope * mean_guide, GUIDED_RADIUS))
    slope, offset = (upsample(np.stack(x, -1), side) for x in (slopes, offsets))
    return slope * log_luma(face)[..., None] + offset


def apply(face: np.ndarray, log_gain: np.ndarray) -> np.ndarray:
    """``face`` changed by ``log_gain`` as the element changes it, ``(v' + ε) = g (v + ε)``,
    rounded to 8 bits."""
    out = (np.asarray(face, np.float64) + GAIN_EPSILON) * np.exp(log_gain) - GAIN_EPSILON
    return np.clip(np.rint(out), 0, 255)


def bands(outputs, truth: np.ndarray, radius: int) -> tuple[float, float]:
    """The smooth and detail bands' RMSE over frames: ``outputs`` yields (S, S, 3) images."""
    sums = np.zeros(3)
    for out, t in zip(outputs, truth, strict=True):
        sums += band_sums(out, t, radius)
    return math.sqrt(sums[0] / sums[2]), math.sqrt(sums[1] / sums[2])


Row = tuple[str, float, float]


def bound_rows(face: np.ndarray, truth: np.ndarray, resolutions: list[int], guided: bool) -> list[Row]:
    """(what, smooth band, detail band) for the input and the exact change at each resolution."""
    radius = detail_radius(face.shape[1])

    def row(what: str, log_gain: np.ndarray) -> Row:
        return (what, *bands(apply(face, log_gain), truth, radius))

    rows = [("input, not relit", *bands(face, truth, radius))]
    for resolution in resolutions:
        change = exact_change(face, truth, resolution)
        rows.append(row(f"exact change at {resolution} px", upsample(change, face.shape[1])))
        if guided:
            rows.append(row(f"exact change at {resolution} px, guided", guided_upsample(change, face)))
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--recording", type=Path, required=True, help="a recording folder with truth-<target>.y4m")
    p.add_argument("--face", type=Path, default=None, help="the face video relit (default: the recording's face.y4m)")
    p.add_argument("--frames", type=int, default=90)
    p.add_argument("--targets", default="studio,sunset,left-key")
    p.add_argument("--resolutions", default="48,96,192,256,320", help="comma-separated, in samples across the region")
    p.add_argument("--guided", action="store_true", help="also the edge-aware upsampling of each")
    p.add_argument("--out", type=Path, default=None, help="also write the table here")
    a = p.parse_args()

    face_path = a.face or a.recording / "face.y4m"
    for path in (face_path, *(a.recording / f"truth-{t}.y4m" for t in a.targets.split(","))):
        if not path.is_file():
            raise SystemExit(
                f"no {path}: `cargo run --release --example flicker -- --recordings NAME --frames N --clean` writes "
                "target/recordings/NAME-N and target/clean-faces/NAME-N.y4m"
            )
    face = centre_square(read_y4m(face_path)[0][: a.frames])
    try:
        resolutions = [int(r) for r in a.resolutions.split(",")]
    except ValueError:
        raise SystemExit(f"--resolutions {a.resolutions}: expected whole numbers, such as 48,96,192") from None
    if not all(1 <= r <= face.shape[1] for r in resolutions):
        raise SystemExit(f"--resolutions {a.resolutions}: each must be 1 to the face region's {face.shape[1]} px")
    per_target = {}
    for target in a.targets.split(","):
        truth = centre_square(read_y4m(a.recording / f"truth-{target}.y4m")[0][: len(face)])
        if len(truth) != len(face):
            raise SystemExit(f"truth-{target}.y4m has {len(truth)} frames, the face {len(face)}")
        per_target[target] = bound_rows(face, truth, resolutions, a.guided)
    targets = list(per_target)
    lines = [
        f"Face region {face.shape[1]} px square, {len(face)} frames of {face_path.name}; "
        f"band split at {detail_radius(face.shape[1])} px (two box blurs).",
        "",
        "| change | " + " | ".join(f"{t}: smooth / detail" for t in targets) + " | mean detail |",
        "|---|" + "---|" * (len(targets) + 1),
    ]
    for i, (what, *_) in enumerate(per_target[targets[0]]):
        cells = [per_target[t][i] for t in targets]
        mean_detail = sum(c[2] for c in cells) / len(cells)
        lines.append(f"| {what} | " + " | ".join(f"{c[1]:.3f} / {c[2]:.3f}" for c in cells) + f" | {mean_detail:.3f} |")
    report("\n".join(lines) + "\n", a.out)


if __name__ == "__main__":
    main()
