"""The shipped face detector is MediaPipe's: the committed ONNX, decoded as the element decodes it, finds what
MediaPipe's own face detector finds with the original ``.tflite``."""

import numpy as np
import onnxruntime as ort
from conftest import ROOT

from lsyd import face_detector


def test_anchors_are_two_grids_of_896():
    a = face_detector.anchors()
    assert a.shape == (896, 2)
    # The 16 x 16 grid, 2 anchors a cell, then the 8 x 8 grid, 6 a cell.
    np.testing.assert_allclose(a[[0, 1, 2]], [[1 / 32, 1 / 32], [1 / 32, 1 / 32], [3 / 32, 1 / 32]])
    np.testing.assert_allclose(
        a[[512, 517, 518, 895]], [[1 / 16, 1 / 16], [1 / 16, 1 / 16], [3 / 16, 1 / 16], [15 / 16, 15 / 16]]
    )


def test_the_shipped_detector_finds_what_mediapipe_finds(tmp_path):
    tflite = tmp_path / "face_detector.tflite"
    tflite.write_bytes(face_detector.tflite_model())
    session = ort.InferenceSession(str(ROOT / "models" / "face" / "blazeface.onnx"), providers=["CPUExecutionProvider"])
    for name, image in face_detector.test_images().items():
        x, place = face_detector.letterbox(image)
        regressors, scores = session.run(["regressors", "classificators"], {"input": x})
        ours = face_detector.decode(regressors, scores, place)
        worst = face_detector.compare(ours, face_detector.mediapipe_faces(tflite, image), name)
        assert worst["pixels"] <= face_detector.MAX_PIXELS and worst["score"] <= face_detector.MAX_SCORE
