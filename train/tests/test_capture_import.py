"""Real captures take the same path: an offline detector's keypoints, the same pairing."""

import subprocess

import numpy as np
from conftest import ROOT, deskstage

from lsyd import capture_import, data, pairing

STABLE = [30, 36, 39, 42, 45, 48, 54]  # nose tip, eye and mouth corners


def test_detected_keypoints_match_the_true_ones(sim_data):
    cap = data.Capture.load(sim_data / "captures" / "session-000")
    frames = np.asarray(cap.face[::5])
    truth = cap.keypoints[::5]
    kp = capture_import.detect_keypoints(frames)
    found = ~np.isnan(kp[:, 0, 0])
    assert found.mean() >= 0.95
    iod = np.linalg.norm(truth[:, 45] - truth[:, 36], axis=1)
    err = np.linalg.norm(kp[found][:, STABLE] - truth[found][:, STABLE], axis=2).mean(1) / iod[found]
    assert np.median(err) < 0.08, np.median(err)


def test_pairing_on_detected_keypoints_is_as_precise(sim_data):
    cap = data.Capture.load(sim_data / "captures" / "session-000")
    kp = capture_import.detect_keypoints(np.asarray(cap.face))
    report = pairing.pairing_report(kp, cap.lights(), cap.truth, pairing.PairingRule())
    assert report["pairs"] >= 300, report
    assert report["precision"] >= 0.9, report


def test_two_videos_become_a_capture(tmp_path):
    deskstage("recording", "--name", "call", "--frames", "20", "--out", str(tmp_path))
    rec = tmp_path / "call"
    videos = {}
    for name in ("face", "monitor"):
        # As a webcam recorder and a screen recorder would write them: H.264 in MP4.
        videos[name] = tmp_path / f"{name}.mp4"
        pipeline = (
            f"filesrc location={rec / (name + '.y4m')} ! y4mdec ! videoconvert ! video/x-raw,format=I420 "
            f"! x264enc speed-preset=ultrafast ! mp4mux ! filesink location={videos[name]}"
        )
        subprocess.run(["gst-launch-1.0", "-q", *pipeline.split()], check=True, cwd=ROOT)
    meta = capture_import.import_capture(videos["face"], videos["monitor"], tmp_path / "session", fps=10)
    cap = data.Capture.load(tmp_path / "session")
    assert meta["frames"] == len(cap.face) >= 6
    assert cap.face.shape[1:] == (256, 256, 3)
    assert cap.monitor.shape[0] == cap.face.shape[0]
    assert meta["faces_found"] == meta["frames"]
    assert cap.lights().shape == (meta["frames"], 3, 16, 32)
