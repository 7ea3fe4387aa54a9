"""How much of a light's side the network itself draws on real faces, before the element's paste.

    python -m lsyd.evaluation.real_direction --models ../models/starter ../models/starter-next
        [--out ../results/direction/network.md]

`examples/target_lights direction` measures the key swap of the element's output; this measures the
network's own output on the same real footage (the astronaut as a 720p still and the film clip's
first frames, from ``scripts/setup.sh full``), so the two together say whether a weak swap is the
model's or the paste's. Each frame is cropped as the element crops it (BlazeFace's box and the
model's crop rule, the square moved to lie inside the frame), area-resampled to the model's
resolution and relit with the source light predicted (no monitor stream) to two side keys of this
module's own: a warm screen lit over its left quarter and a cool one over its right (the colours of
the `warm-key-left` and `cool-key-right` presets; their screens fade more softly).

Over the face's box in the crop (one face height square about the face's centre), with the element's
measure (``lsydrelight_testkit::direction``): strength, the RMS of 100 ln((Y_out + 10) / (Y_in +
10)) (Y Rec. 709 luma in 0-255); asymmetry, its mean over the image-left half less the image-right
half; key swap, the warm key's asymmetry less the cool key's. Medians over the frames.

A second table repeats the measure with the detector's box scaled about its centre by 0.94-1.06
(``BOX_SCALES``), beside the light the network predicts the face is lit by (the mean of its
predicted screen): without a monitor stream the element relights from that guess, so a guess that
swings within a detector's error makes a face's relighting strong or weak by chance. A third says
where in the crop the light decoder reads that light (``where_light_is_read``).
"""

from __future__ import annotations

import argparse
import re
import subprocess
from pathlib import Path

import cv2
import numpy as np
import onnxruntime as ort
import torch

from .. import contract, face_detector, runs
from ..data import area_resize
from . import ROOT

LUMA = np.array([0.2126, 0.7152, 0.0722])
LUMA_FLOOR = 10.0
WARM, COOL = (1.0, 0.62, 0.3), (0.45, 0.65, 1.0)
DIM = 0.04  # the rest of each key's screen, as the presets' dark part


def side_key(colour: tuple[float, float, float], left: bool) -> torch.Tensor:
    """A [1, 3, rows, cols] light: ``colour`` over a quarter of the screen at one side, dim elsewhere."""
    light = np.full((3, contract.LIGHT_ROWS, contract.LIGHT_COLS), DIM, np.float32)
    quarter = contract.LIGHT_COLS // 4
    columns = slice(0, quarter) if left else slice(contract.LIGHT_COLS - quarter, None)
    light[:, :, columns] = np.array(colour, np.float32)[:, None, None]
    return torch.from_numpy(light)[None]


def astronaut_720p(path: Path) -> np.ndarray:
    """The portrait scaled to 720 rows in a mid-grey 1280 x 720 frame, placed as
    ``lsydrelight_testkit::footage::portrait_720p`` places it (that one scales with a triangle filter)."""
    portrait = cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB)
    width = round(portrait.shape[1] * 720 / portrait.shape[0])
    frame = np.full((720, 1280, 3), 96, np.uint8)
    left = (1280 - width) // 2
    frame[:, left : left + width] = cv2.resize(portrait, (width, 720), interpolation=cv2.INTER_AREA)
    return frame


def film_frames(path: Path, count: int) -> list[np.ndarray]:
    """The first ``count`` frames, decoded by GStreamer's ``decodebin ! videoconvert`` to RGB, as the
    element's measures decode them (``lsydrelight_testkit::footage::decode``): one decoder for both."""
    if not path.exists():
        raise SystemExit(f"{path} is missing: run scripts/setup.sh full, which fetches it")
    decoded = ["filesrc", f"location={path}", "!", "decodebin", "!", "videoconvert", "!", "video/x-raw,format=RGB"]
    probe = subprocess.run(
        ["gst-launch-1.0", "-v", *decoded, "!", "fakesink", "num-buffers=1"], capture_output=True, check=False
    )
    caps = re.search(
        rb"fakesink0.GstPad:sink: caps = video/x-raw, width=\(int\)(\d+), height=\(int\)(\d+)", probe.stdout
    )
    run = subprocess.run(
        ["gst-launch-1.0", "-q", *decoded, "!", "identity", f"eos-after={count}", "!", "fdsink", "fd=1"],
        capture_output=True,
        check=False,
    )
    if caps is None or run.returncode != 0 or not run.stdout:
        raise SystemExit(
            f"{path}: GStreamer could not decode it: {(probe.stderr + run.stderr).decode(errors='replace')}"
        )
    width, height = int(caps[1]), int(caps[2])
    stride = (3 * width + 3) // 4 * 4  # GStreamer's RGB rows are 4-byte aligned
    whole = len(run.stdout) // (stride * height) * stride * height
    frames = np.frombuffer(run.stdout[:whole], np.uint8).reshape(-1, height, stride)[:count, :, : 3 * width]
    return [f.reshape(height, width, 3) for f in frames]


class Detector:
    """BlazeFace short-range as the element runs it: the largest face's box in frame pixels, or None.
    A face smaller in the whole frame than ``1 / NEAR_SIDE`` of the input is looked at again in a
    square of ``NEAR_SIDE`` face heights round it, whose box replaces the whole frame's where it
    scores as high, as the element's detector does on a first detection (``plugin/face/search.rs``
    and ``detector.rs``; without the grid its later squares keep, nor the margin by which the
    look that boxed a face keeps it): in the whole frame such a face's box is often coarse and
    jumps as the face moves (the 720p portrait), but some it boxes better there (the film clip)."""

    NEAR_SIDE = 3.0

    def __init__(self, model: Path):
        self.session = ort.InferenceSession(str(model), providers=["CPUExecutionProvider"])

    def largest_scored(self, image: np.ndarray) -> tuple[list[float], float] | None:
        """The largest face's box in ``image``'s letterbox, in its pixels, and its score."""
        tensor, place = face_detector.letterbox(image)
        outputs = self.session.run(None, {self.session.get_inputs()[0].name: tensor})
        regressors, scores = sorted(outputs, key=lambda o: o.shape[-1], reverse=True)
        faces = face_detector.decode(regressors, scores, place)
        if not faces:
            return None
        face = max(faces, key=lambda f: (f["box"][2] - f["box"][0]) * (f["box"][3] - f["box"][1]))
        return face["box"], face["score"]

    def largest(self, image: np.ndarray) -> list[float] | None:
        """The largest face's box in ``image``'s letterbox, in its pixels."""
        found = self.largest_scored(image)
        return None if found is None else found[0]

    def box(self, frame: np.ndarray) -> list[float] | None:
        found = self.largest_scored(frame)
        if found is None:
            return None
        whole, whole_score = found
        height, width = frame.shape[:2]
        if (whole[3] - whole[1]) * face_detector.SIZE / max(width, height) >= face_detector.SIZE / self.NEAR_SIDE:
            return whole
        near = self.closer(frame, whole)
        return whole if near is None or near[1] < whole_score else near[0]

    def closer(self, frame: np.ndarray, whole: list[float]) -> tuple[list[float], float] | None:
        """The largest face's box and score in the square of ``NEAR_SIDE`` face heights round
        ``whole``: at least the input's size, no larger than the frame's shorter side, moved to
        lie inside the frame; the box in frame pixels."""
        height, width = frame.shape[:2]
        side = round(min(max(self.NEAR_SIDE * (whole[3] - whole[1]), face_detector.SIZE), width, height))
        x0 = min(max(round((whole[0] + whole[2] - side) / 2), 0), width - side)
        y0 = min(max(round((whole[1] + whole[3] - side) / 2), 0), height - side)
        near = self.largest_scored(frame[y0 : y0 + side, x0 : x0 + side])
        if near is None:
            return None
        box, score = near
        return [box[0] + x0, box[1] + y0, box[2] + x0, box[3] + y0], score


def crop(frame: np.ndarray, box: list[float], rule: dict, resolution: int) -> tuple[np.ndarray, tuple[slice, slice]]:
    """The model's square round the face, moved (and no larger than the frame's shorter side) to
    lie inside the frame as the element's tracker keeps it, in [0, 1], resolution²; and the rows
    and columns of it that hold the face: one face height square about the face's centre, higher
    in the square where the square was moved down."""
    height, width = frame.shape[:2]
    face_height = box[3] - box[1]
    side = min(round(rule["side"] * face_height), height, width)
    face_x, face_y = (box[0] + box[2]) / 2, (box[1] + box[3]) / 2
    x0 = min(max(round(face_x - side / 2), 0), width - side)
    y0 = min(max(round(face_y - rule["lift"] * face_height - side / 2), 0), height - side)
    square = frame[y0 : y0 + side, x0 : x0 + side]
    image = area_resize(square[None].astype(np.float32) / 255.0, resolution)[0]
    scale = resolution / side
    half = face_height * scale / 2
    centre_x, centre_y = (face_x - x0) * scale, (face_y - y0) * scale
    rows = slice(round(centre_y - half), round(centre_y + half))
    columns = slice(round(centre_x - half), round(centre_x + half))
    return image, (rows, columns)


def shape(before: np.ndarray, after: np.ndarray, box: tuple[slice, slice]) -> tuple[float, float]:
    """(asymmetry, strength) of the change over the face box of two crops in [0, 1]."""
    level = lambda img: 255.0 * img[box] @ LUMA + LUMA_FLOOR  # noqa: E731
    change = 100.0 * np.log(level(after) / level(before))
    half = change.shape[1] // 2
    return float(change[:, :half].mean() - change[:, -half:].mean()), float(np.sqrt((change**2).mean()))


BOX_SCALES = (0.94, 0.97, 1.0, 1.03, 1.06)


def scaled(box: list[float], scale: float) -> list[float]:
    """``box`` (x0, y0, x1, y1) scaled about its centre."""
    cx, cy = (box[0] + box[2]) / 2, (box[1] + box[3]) / 2
    hw, hh = scale * (box[2] - box[0]) / 2, scale * (box[3] - box[1]) / 2
    return [cx - hw, cy - hh, cx + hw, cy + hh]


def relit_by_keys(net, image: np.ndarray, face: tuple[slice, slice]) -> tuple[float, list[float], float]:
    """One crop relit from its predicted light to the two side keys: the key swap, the two
    strengths, and the mean of the predicted screen."""
    tensor = torch.from_numpy(image.transpose(2, 0, 1).copy())[None]
    shapes = []
    for key in (side_key(WARM, left=True), side_key(COOL, left=False)):
        with torch.no_grad():
            relit, predicted = net(tensor, None, key)
        shapes.append(shape(image, relit[0].clamp(0, 1).numpy().transpose(1, 2, 0), face))
    return shapes[0][0] - shapes[1][0], [s[1] for s in shapes], float(predicted.mean())


def measure(model: Path, frames: list[np.ndarray], detector: Detector) -> dict[float, dict[str, float]]:
    """Per scale of the detector's box in ``BOX_SCALES`` (1: the box as found): over the frames
    with a face, the median of the network's key swap, of its strength and of the predicted
    screen's mean (linear light in [0, 1]). The element's tracker and this module's detector put
    the box a few percent apart, as detectors do; a model whose guess of the present light
    swings within that relights the same face strongly or hardly at all by chance."""
    net, cfg = runs.load_saved_network(model / "network.pt")
    rule = contract.read(model / "model.json")["crop"]
    faces = [(frame, box) for frame in frames if (box := detector.box(frame)) is not None]
    if not faces:
        raise SystemExit(f"{model}: no face was found in any frame")
    out = {}
    for scale in BOX_SCALES:
        swaps, strengths, screens = [], [], []
        for frame, box in faces:
            swap, two, screen = relit_by_keys(net, *crop(frame, scaled(box, scale), rule, cfg.resolution))
            swaps.append(swap)
            strengths.extend(two)
            screens.append(screen)
        out[scale] = {
            "frames": len(faces),
            "key_swap": float(np.median(swaps)),
            "strength": float(np.median(strengths)),
            "screen": float(np.median(screens)),
        }
    return out


def where_light_is_read(net, images: list[np.ndarray]) -> dict[str, float]:
    """The light decoder's confidence (its weight in the fused light) over crops in [0, 1],
    averaged over them: the share on the crop's bottom row of its map (at 96 px a band 16 px
    high, under the chin: shoulders, collar, shirt) and on the map's central 4 x 4 cells,
    round the face."""
    maps = []
    for image in images:
        with torch.no_grad():
            _, feats = net.encode(torch.from_numpy(np.ascontiguousarray(image.transpose(2, 0, 1)))[None].float())
            maps.append(net.light_decoder.confidence_map(feats[1], feats[3], feats[5])[0].numpy())
    mean = np.mean(maps, axis=0)
    return {"bottom_row": float(mean[-1].sum()), "centre": float(mean[1:-1, 1:-1].sum())}


def simulated_strangers(sessions: Path, resolution: int) -> list[np.ndarray]:
    """Every 50th frame of each unseen person's desk session, at network resolution."""
    frames = []
    for session in sorted(sessions.glob("person-*")):
        face = np.load(session / "face.npy", mmap_mode="r")
        every_50th = np.asarray(face[::50], dtype=np.float32) / 255.0
        frames.extend(area_resize(every_50th, resolution))
    return frames


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--models", type=Path, nargs="+", default=[ROOT / "models" / "starter"])
    p.add_argument("--media", type=Path, default=ROOT / "target" / "real-media")
    p.add_argument("--frames", type=int, default=30, help="frames of the film clip")
    p.add_argument("--out", type=Path, default=ROOT / "results" / "direction" / "network.md")
    a = p.parse_args()

    portrait = a.media / "astronaut.png"
    if not portrait.exists():
        raise SystemExit(f"{portrait} is missing: run scripts/setup.sh full, which fetches it")
    clips = {
        "astronaut-720p": [astronaut_720p(portrait)],
        "megamind": film_frames(a.media / "Megamind.avi", a.frames),
    }
    detector = Detector(ROOT / "models" / "face" / "blazeface.onnx")
    lines = [
        f"Made by `python -m lsyd.evaluation.real_direction --models {' '.join(m.name for m in a.models)}`: "
        "the network alone, before the element's paste (the module's docstring says how).",
        "",
        "| model | clip | frames | the network's key swap % "
        "| its median strength % (counts the blur of its output as change) |",
        "|---|---|---|---|---|",
    ]
    measured = {(model, name): measure(model, frames, detector) for model in a.models for name, frames in clips.items()}
    for (model, name), by_box in measured.items():
        m = by_box[1.0]
        lines.append(f"| {model.name} | {name} | {m['frames']} | {m['key_swap']:+.1f} | {m['strength']:.1f} |")
        print(lines[-1])
    scales = " / ".join(f"x{s:g}" for s in BOX_SCALES)
    lines += [
        "",
        "The same with the detector's box scaled about its centre, "
        f"{scales} (a real detector's box errs by as much): "
        "the predicted screen's mean (linear light, 0-1; the presets' are 0.17-0.68), "
        "then the network's key swap and strength as above.",
        "",
        "| model | clip | predicted screen | key swap % | strength % |",
        "|---|---|---|---|---|",
    ]
    for (model, name), by_box in measured.items():
        cells = [
            " / ".join(fmt.format(m[k]) for m in by_box.values())
            for k, fmt in (("screen", "{:.3f}"), ("key_swap", "{:+.1f}"), ("strength", "{:.1f}"))
        ]
        lines.append(f"| {model.name} | {name} | " + " | ".join(cells) + " |")
        print(lines[-1])
    strangers = ROOT / "data" / "starter" / "unseen-captures"
    lines += [
        "",
        "Where the light decoder reads the light: its confidence (weight in the predicted screen) "
        "on the bottom row of its 6 x 6 map (shoulders, collar, shirt) and on the central 4 x 4 "
        "cells, round the face (the rest is on its other edge cells); the portrait's crop as found, "
        "the film clip's frames and, "
        f"where `{strangers.relative_to(ROOT)}` holds them, every 50th frame of the unseen "
        "simulated people's desk sessions.",
        "",
        "| model | crops | bottom row | central 4 x 4 |",
        "|---|---|---|---|",
    ]
    for model in a.models:
        net, cfg = runs.load_saved_network(model / "network.pt")
        rule = contract.read(model / "model.json")["crop"]
        crops = {
            name: [crop(f, b, rule, cfg.resolution)[0] for f in frames if (b := detector.box(f)) is not None]
            for name, frames in clips.items()
        }
        if strangers.exists():
            crops["simulated strangers"] = simulated_strangers(strangers, cfg.resolution)
        for name, images in crops.items():
            read = where_light_is_read(net, images)
            lines.append(f"| {model.name} | {name} | {read['bottom_row']:.2f} | {read['centre']:.2f} |")
            print(lines[-1])
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text("\n".join(lines) + "\n")
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
