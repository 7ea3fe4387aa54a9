"""Pairing frames of one capture by facial keypoints, as the paper does.

A pair is two frames of the same capture session whose keypoints match (same
pose and expression) while the monitor showed different content. Real
captures get keypoints from a detector (``landmarks.py``); the
simulator writes the exact projections. Both go through ``find_pairs``.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np

# iBUG 68-point indices of the outer eye corners, for the inter-ocular distance.
RIGHT_EYE_OUTER = 36
LEFT_EYE_OUTER = 45
# Facial regions of the 68-point layout. A blink or a parted mouth moves only
# a few points; averaging within regions keeps such changes visible.
REGIONS = {
    "jaw": slice(0, 17),
    "brows": slice(17, 27),
    "nose": slice(27, 36),
    "eyes": slice(36, 48),
    "mouth": slice(48, 68),
}


@dataclasses.dataclass(frozen=True)
class PairingRule:
    """Thresholds: keypoint distance as a fraction of the inter-ocular distance,
    and how different the two monitor lights must be (mean absolute difference
    of linear light)."""

    max_keypoint_distance: float = 0.02
    min_light_difference: float = 0.03


def normalised_distances(keypoints: np.ndarray) -> np.ndarray:
    """Keypoint distance between all frames: the largest over facial regions of the
    mean point distance in the region, over the inter-ocular distance.

    keypoints: (T, 68, 2) image coordinates; frames without a face are NaN and
    get infinite distance to everything."""
    t = keypoints.shape[0]
    valid = ~np.isnan(keypoints).any(axis=(1, 2))
    iod = np.linalg.norm(keypoints[:, LEFT_EYE_OUTER] - keypoints[:, RIGHT_EYE_OUTER], axis=1)
    d = np.full((t, t), np.inf, dtype=np.float32)
    idx = np.flatnonzero(valid)
    if idx.size == 0:
        return d
    k = keypoints[idx]
    # In blocks of frames to bound memory.
    for a in range(0, idx.size, 256):
        diff = k[a : a + 256, None] - k[None]
        point = np.sqrt((diff**2).sum(-1))
        dist = np.max([point[..., r].mean(-1) for r in REGIONS.values()], axis=0)
        scale = 0.5 * (iod[idx[a : a + 256], None] + iod[None, idx])
        d[np.ix_(idx[a : a + 256], idx)] = dist / scale
    return d


def find_pairs(keypoints: np.ndarray, lights: np.ndarray, rule: PairingRule) -> np.ndarray:
    """All ordered pairs (i, j), i != j, of frames that match by keypoints under different light.

    keypoints: (T, 68, 2); lights: (T, 3, 16, 32) linear. Returns (P, 2) int64."""
    d = normalised_distances(keypoints)
    np.fill_diagonal(d, np.inf)
    candidates = np.argwhere(d <= rule.max_keypoint_distance)
    flat = lights.reshape(len(lights), -1)
    # Light differences only for keypoint matches, in blocks: all T x T of them
    # would not fit in memory for a long real capture.
    light_diff = (
        np.concatenate(
            [
                np.abs(flat[block[:, 0]] - flat[block[:, 1]]).mean(-1)
                for block in np.array_split(candidates, max(1, len(candidates) // 4096))
            ]
        )
        if len(candidates)
        else np.zeros(0, dtype=np.float32)
    )
    return candidates[light_diff >= rule.min_light_difference]


def true_pose_error(truth: np.ndarray, pairs: np.ndarray) -> dict[str, np.ndarray]:
    """How far apart the paired frames really are, from the simulator's truth rows
    (yaw, pitch, roll in degrees; translation in metres; expressions in [0, 1])."""
    a, b = truth[pairs[:, 0]], truth[pairs[:, 1]]
    return {
        "rotation_deg": np.abs(a[:, 0:3] - b[:, 0:3]).max(1),
        "translation_mm": 1000.0 * np.linalg.norm(a[:, 3:6] - b[:, 3:6], axis=1),
        "expression": np.abs(a[:, 6:9] - b[:, 6:9]).max(1),
    }


def pairing_report(keypoints: np.ndarray, lights: np.ndarray, truth: np.ndarray, rule: PairingRule) -> dict:
    """Pairs found and how well they agree with the true pose.

    A pair counts as correct when rotation differs by at most 2 degrees,
    translation by at most 5 mm and every expression weight by at most 0.1."""
    pairs = find_pairs(keypoints, lights, rule)
    if len(pairs) == 0:
        return {"pairs": 0, "precision": float("nan")}
    err = true_pose_error(truth, pairs)
    correct = (err["rotation_deg"] <= 2.0) & (err["translation_mm"] <= 5.0) & (err["expression"] <= 0.1)
    return {
        "pairs": int(len(pairs)),
        "precision": float(correct.mean()),
        "rotation_deg_p95": float(np.percentile(err["rotation_deg"], 95)),
        "translation_mm_p95": float(np.percentile(err["translation_mm"], 95)),
        "expression_p95": float(np.percentile(err["expression"], 95)),
    }


def main() -> None:
    """Sweeps the keypoint threshold over every capture session and reports pairs and their
    true precision, with exact keypoints and with detector-like noise added."""
    from . import data

    p = argparse.ArgumentParser(description=main.__doc__)
    p.add_argument("--data", type=Path, default=Path("data"))
    p.add_argument("--out", type=Path, default=None, help="markdown file to write")
    a = p.parse_args()
    sessions = [data.Capture.load(d) for d in data.capture_dirs(a.data / "captures")]
    lights = [c.lights() for c in sessions]
    rng = np.random.default_rng(0)
    lines = [
        "| keypoints | threshold (x IOD) | pairs | precision | rotation p95 (deg) | translation p95 (mm) "
        "| expression p95 |",
        "|---|---|---|---|---|---|---|",
    ]
    for noise in (0.0, 0.5, 1.0):
        for tau in (0.01, 0.015, 0.02, 0.03, 0.05):
            rule = PairingRule(max_keypoint_distance=tau)
            reports = []
            for cap, lit in zip(sessions, lights):
                kp = (
                    cap.keypoints + rng.normal(0, noise, cap.keypoints.shape).astype(np.float32)
                    if noise
                    else cap.keypoints
                )
                reports.append(pairing_report(kp, lit, cap.truth, rule))
            n = sum(r["pairs"] for r in reports)
            prec = sum(r["precision"] * r["pairs"] for r in reports if r["pairs"]) / max(n, 1)

            def median_over_sessions(k: str, rs: list[dict] = reports) -> float:
                return float(np.median([r[k] for r in rs if r["pairs"]]))

            kind = "exact" if noise == 0 else f"+{noise:g} px noise"
            lines.append(
                f"| {kind} | {tau:g} | {n} | {prec:.3f} | {median_over_sessions('rotation_deg_p95'):.2f} | "
                f"{median_over_sessions('translation_mm_p95'):.2f} | {median_over_sessions('expression_p95'):.3f} |"
            )
    text = (
        "\n".join(lines) + "\n\nA pair is correct when its true rotation differs by at most 2 degrees, translation by "
    )
    text += "at most 5 mm and every expression weight by at most 0.1; p95 columns are medians over sessions.\n"
    print(text)
    if a.out:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(text)


if __name__ == "__main__":
    main()
