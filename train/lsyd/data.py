"""Loading captures, the held-out set and recordings written by ``deskstage``.

Images are resampled to the network's resolution with exact area weights,
the same resampling the element applies to its face crop.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from . import contract, pairing


def area_resize(images: np.ndarray, out_h: int, out_w: int | None = None) -> np.ndarray:
    """Area resampling of (..., H, W, C) uint8 images; returns float32 in [0, 255]."""
    out_w = out_w or out_h
    ry = contract._area_matrix(images.shape[-3], out_h)
    rx = contract._area_matrix(images.shape[-2], out_w)
    return np.einsum("rh,...hwc,kw->...rkc", ry, images.astype(np.float32), rx, optimize=True)


def to_tensor(images: np.ndarray) -> torch.Tensor:
    """(..., H, W, 3) in [0, 255] to (..., 3, H, W) float in [0, 1]."""
    t = torch.from_numpy(np.ascontiguousarray(images, dtype=np.float32)) / 255.0
    return t.movedim(-1, -3)


@dataclasses.dataclass
class Capture:
    """One capture session as written by ``deskstage captures``
    (the monitor frames, ``monitor.npy``), or by ``lsydrelight train`` from a capture folder
    (the monitor's light grid of each frame, ``lights.npy``, (T, 3, 16, 32) float32)."""

    path: Path
    face: np.ndarray  # (T, S, S, 3) uint8, memory-mapped
    monitor: np.ndarray | None  # (T, H, W, 3) uint8, memory-mapped; None with lights.npy
    timestamps: np.ndarray
    keypoints: np.ndarray  # (T, 68, 2)
    truth: np.ndarray | None  # simulator only: never used for training
    light_grid: np.ndarray | None = None  # (T, 3, 16, 32), from lights.npy

    @classmethod
    def load(cls, path: Path) -> Capture:
        truth = path / "truth.npy"
        monitor = path / "monitor.npy"
        return cls(
            path=path,
            face=np.load(path / "face.npy", mmap_mode="r"),
            monitor=np.load(monitor, mmap_mode="r") if monitor.exists() else None,
            timestamps=np.load(path / "timestamps.npy"),
            keypoints=np.load(path / "keypoints.npy"),
            truth=np.load(truth) if truth.exists() else None,
            light_grid=None if monitor.exists() else read_lights(path, len(np.load(path / "timestamps.npy"))),
        )

    def lights(self) -> np.ndarray:
        if self.monitor is None:
            return self.light_grid
        return np.concatenate(
            [contract.light_from_frames(self.monitor[i : i + 64]) for i in range(0, len(self.monitor), 64)]
        )


def read_lights(session: Path, frames: int) -> np.ndarray:
    """A session's ``lights.npy``, checked: one (3, 16, 32) float32 grid per frame."""
    path = session / "lights.npy"
    if not path.exists():
        raise FileNotFoundError(f"{session}: neither monitor.npy nor lights.npy")
    lights = np.load(path)
    shape = (frames, 3, contract.LIGHT_ROWS, contract.LIGHT_COLS)
    if lights.dtype != np.float32 or lights.shape != shape:
        raise ValueError(f"{path}: {lights.dtype} {lights.shape}, expected float32 {shape}")
    return lights


def capture_dirs(root: Path) -> list[Path]:
    dirs = sorted(p for p in root.iterdir() if (p / "face.npy").exists())
    if not dirs:
        raise FileNotFoundError(f"no capture sessions (folders with face.npy) under {root}")
    return dirs


# Sessions whose folder name starts so are rehearsal: simulated people the starter trained on,
# mixed into a personal run by ``lsydrelight train`` (cli/src/train/rehearsal.rs).
REHEARSAL_PREFIX = "rehearsal-"


@dataclasses.dataclass
class PairSet:
    """Frames at network resolution, their lights, and (source, target) index pairs."""

    images: torch.Tensor  # (N, 3, R, R) uint8
    lights: torch.Tensor  # (N, 3, 16, 32) float32
    pairs: torch.Tensor  # (P, 2) int64
    rehearsed: torch.Tensor  # (P,) bool: the pair comes from a rehearsal session

    def batch(self, idx: torch.Tensor) -> tuple[torch.Tensor, ...]:
        p = self.pairs[idx]
        s, t = p[:, 0], p[:, 1]
        return self.images[s].float() / 255.0, self.lights[s], self.images[t].float() / 255.0, self.lights[t]

    def draw(self, n: int, rehearsal_share: float | None, generator: torch.Generator) -> torch.Tensor:
        """``n`` pair indices at random: uniformly, or with the rehearsal pairs drawn
        ``rehearsal_share`` of the time whatever their number, when there are both kinds."""
        rehearsed = self.rehearsed
        if rehearsal_share is None or rehearsed.all() or not rehearsed.any():
            return torch.randint(len(self.pairs), (n,), generator=generator)
        counts = (rehearsed.sum(), (~rehearsed).sum())
        weights = torch.where(rehearsed, rehearsal_share / counts[0], (1.0 - rehearsal_share) / counts[1])
        return torch.multinomial(weights.double(), n, replacement=True, generator=generator)


def jitter_crops(
    batch: tuple[torch.Tensor, ...], jitter: float, generator: torch.Generator
) -> tuple[torch.Tensor, ...]:
    """A batch of (source, source light, target, target light) with each pair's two images
    zoomed about the face by a factor in [1 - jitter, 1 + jitter] and shifted by up to
    ``jitter / 2`` face heights each way, the same for both (they show one pose), the
    picture's edge continued where the view reaches past it.

    A real detector's box is a few percent larger or smaller than the crop rule assumes, and
    off centre. Tried on the starter to steady the light decoder's guess on a real face, which
    swings with a few percent of the box's size: it did not (docs/training.md, "Box jitter")."""
    src, l_src, tgt, l_tgt = batch
    n = src.shape[0]
    draw = lambda: 2.0 * torch.rand(n, generator=generator) - 1.0  # noqa: E731
    zoom = 1.0 + jitter * draw()
    face_height = 2.0 / contract.CROP["side"]  # in the [-1, 1] coordinates of affine_grid
    centre_y = 2.0 * contract.CROP["lift"] / contract.CROP["side"]  # the face's centre, below the crop's
    shift = 0.5 * jitter * face_height * torch.stack([draw(), draw()], dim=1)
    # Output point p samples the input at centre + (p - centre) / zoom + shift.
    theta = torch.zeros(n, 2, 3)
    theta[:, 0, 0] = theta[:, 1, 1] = 1.0 / zoom
    theta[:, 0, 2] = shift[:, 0]
    theta[:, 1, 2] = shift[:, 1] + centre_y * (1.0 - 1.0 / zoom)
    grid = F.affine_grid(theta, list(src.shape), align_corners=False)
    warp = lambda x: F.grid_sample(x, grid, mode="bilinear", padding_mode="border", align_corners=False)  # noqa: E731
    return warp(src), l_src, warp(tgt), l_tgt


def mirror_pairs(batch: tuple[torch.Tensor, ...], generator: torch.Generator) -> tuple[torch.Tensor, ...]:
    """A batch of (source, source light, target, target light) with each pair, at random half
    of the time, mirrored left to right: both images and both lights (the screen as shown, its
    columns reversed), the same for the pair's two halves.

    The mirrored pair is the mirror image of the person under the mirrored screen, lit as the
    physics lights it (the webcam sits over the screen's middle), so it is a true pair. Tried
    for the starter's last stage and not kept: it drew less of a light's side (docs/training.md,
    "Mirrored pairs")."""
    src, l_src, tgt, l_tgt = batch
    flip = torch.rand(src.shape[0], generator=generator) < 0.5

    def mirrored(x: torch.Tensor) -> torch.Tensor:
        x = x.clone()
        x[flip] = x[flip].flip(-1)
        return x

    return mirrored(src), mirrored(l_src), mirrored(tgt), mirrored(l_tgt)


def resize_frames(frames: np.ndarray, resolution: int) -> np.ndarray:
    """(N, H, W, 3) frames area-resized to (N, R, R, 3) uint8, a block at a time to bound memory."""
    out = np.empty((len(frames), resolution, resolution, 3), dtype=np.uint8)
    for i in range(0, len(frames), 128):
        out[i : i + 128] = np.clip(np.rint(area_resize(frames[i : i + 128], resolution)), 0, 255)
    return out


def centre_square(frames: np.ndarray) -> np.ndarray:
    """The centred square of full height of (..., H, W, 3) frames: the element's default face region."""
    h, w = frames.shape[-3:-1]
    s = min(h, w)
    y0, x0 = (h - s) // 2, (w - s) // 2
    return frames[..., y0 : y0 + s, x0 : x0 + s, :]


def session_frames(session: Path, resolution: int) -> tuple[np.ndarray, np.ndarray]:
    """A session's frames at network resolution and its lights, computed once and kept
    next to the capture (``cache-<resolution>.npz``)."""
    path = session / f"cache-{resolution}.npz"
    sources = [session / n for n in ("face.npy", "monitor.npy", "lights.npy")]
    source_time = max(p.stat().st_mtime for p in sources if p.exists())
    if path.exists() and path.stat().st_mtime >= source_time:
        with np.load(path) as z:
            return z["images"], z["lights"]
    cap = Capture.load(session)
    images, lights = resize_frames(cap.face, resolution), cap.lights()
    np.savez(path, images=images, lights=lights)
    return images, lights


def keypoint_pairs(root: Path, resolution: int, rule: pairing.PairingRule) -> tuple[PairSet, list[dict]]:
    """Pairs found by keypoints within each capture session, as on real captures."""
    images, lights, pairs, rehearsed, reports = [], [], [], [], []
    offset = 0
    for d in capture_dirs(root):
        imgs, lit = session_frames(d, resolution)
        keypoints = np.load(d / "keypoints.npy")
        p = pairing.find_pairs(keypoints, lit, rule)
        truth = d / "truth.npy"
        if truth.exists():
            reports.append({"session": d.name, **pairing.pairing_report(keypoints, lit, np.load(truth), rule)})
        images.append(imgs)
        lights.append(lit)
        pairs.append(p + offset)
        rehearsed.append(np.full(len(p), d.name.startswith(REHEARSAL_PREFIX)))
        offset += len(imgs)
    return (
        PairSet(
            images=torch.from_numpy(np.concatenate(images)).permute(0, 3, 1, 2).contiguous(),
            lights=torch.from_numpy(np.concatenate(lights)),
            pairs=torch.from_numpy(np.concatenate(pairs)).long(),
            rehearsed=torch.from_numpy(np.concatenate(rehearsed)),
        ),
        reports,
    )


def exact_pairs(root: Path, resolution: int) -> PairSet:
    """All ordered pairs of the simulator's paired ground truth (same pose, different light)."""
    face = np.load(root / "face.npy", mmap_mode="r")  # (poses, lights, S, S, 3)
    monitor = np.load(root / "monitor.npy", mmap_mode="r")
    n_pose, n_light = face.shape[:2]
    images = resize_frames(face.reshape(-1, *face.shape[2:]), resolution)
    lights = contract.light_from_frames(np.asarray(monitor).reshape(-1, *monitor.shape[2:]))
    idx = np.arange(n_pose * n_light).reshape(n_pose, n_light)
    pairs = np.array([(p[i], p[j]) for p in idx for i in range(n_light) for j in range(n_light) if i != j])
    return PairSet(
        images=torch.from_numpy(images).permute(0, 3, 1, 2).contiguous(),
        lights=torch.from_numpy(lights),
        pairs=torch.from_numpy(pairs).long(),
        rehearsed=torch.zeros(len(pairs), dtype=torch.bool),
    )


@dataclasses.dataclass
class Heldout:
    """A 9 poses x 9 lights set (the held-out test set, or the validation set):
    webcam frames, exact clean frames, lights."""

    images: np.ndarray  # (9, 9, S, S, 3) uint8, inputs
    clean: np.ndarray  # (9, 9, S, S, 3) uint8, exact ground truth
    lights: np.ndarray  # (9, 3, 16, 32)

    @classmethod
    def load(cls, path: Path) -> Heldout:
        return cls(
            images=np.load(path / "images.npy"),
            clean=np.load(path / "clean.npy"),
            lights=contract.light_from_frames(np.load(path / "monitor.npy")),
        )


def read_y4m(path: Path) -> tuple[np.ndarray, int]:
    """All frames of a ``.y4m`` written by ``deskstage`` as RGB uint8 (BT.601 limited), and the fps."""
    raw = path.read_bytes()
    header_end = raw.index(b"\n")
    fields = raw[:header_end].decode().split()
    w = int(next(f[1:] for f in fields if f.startswith("W")))
    h = int(next(f[1:] for f in fields if f.startswith("H")))
    fps = int(next(f[1:] for f in fields if f.startswith("F")).split(":")[0])
    c444 = any(f.startswith("C444") for f in fields)
    cw, ch = (w, h) if c444 else (w // 2, h // 2)
    frame_bytes = w * h + 2 * cw * ch
    frames = []
    pos = header_end + 1
    while pos < len(raw):
        pos = raw.index(b"\n", pos) + 1  # past "FRAME...\n"
        buf = np.frombuffer(raw, dtype=np.uint8, count=frame_bytes, offset=pos)
        pos += frame_bytes
        y = buf[: w * h].reshape(h, w).astype(np.float32)
        u = buf[w * h : w * h + cw * ch].reshape(ch, cw).astype(np.float32)
        v = buf[w * h + cw * ch :].reshape(ch, cw).astype(np.float32)
        if not c444:
            u = u.repeat(2, 0).repeat(2, 1)
            v = v.repeat(2, 0).repeat(2, 1)
        yy = (y - 16.0) / 219.0
        cb = (u - 128.0) / 224.0
        cr = (v - 128.0) / 224.0
        rgb = np.stack([yy + 1.402 * cr, yy - 0.344136 * cb - 0.714136 * cr, yy + 1.772 * cb], -1)
        frames.append(np.clip(np.rint(rgb * 255.0), 0, 255).astype(np.uint8))
    return np.stack(frames), fps


@dataclasses.dataclass
class RecordingCrops:
    """A test recording's centre-square crops at network resolution, its lights and ground truth."""

    name: str
    face: np.ndarray  # (T, R, R, 3) float32 in [0, 255]
    lights: np.ndarray  # (T, 3, 16, 32)
    truth: dict[str, np.ndarray]  # target name -> (T, R, R, 3) float32
    target_lights: dict[str, np.ndarray]  # target name -> (3, 16, 32)
    cuts: list[int]

    @classmethod
    def load(cls, path: Path, resolution: int) -> RecordingCrops:
        meta = json.loads((path / "meta.json").read_text())

        def crop(frames: np.ndarray) -> np.ndarray:
            return area_resize(centre_square(frames), resolution)

        face, _ = read_y4m(path / "face.y4m")
        monitor, _ = read_y4m(path / "monitor.y4m")
        truth = {t: crop(read_y4m(path / f"truth-{t}.y4m")[0]) for t in meta["targets"]}
        from PIL import Image

        target_lights = {
            t: contract.light_from_frames(np.asarray(Image.open(path / f"target-{t}.png").convert("RGB")))
            for t in meta["targets"]
        }
        return cls(
            name=path.name,
            face=crop(face),
            lights=contract.light_from_frames(monitor),
            truth=truth,
            target_lights=target_lights,
            cuts=meta["cuts_before_frames"],
        )
