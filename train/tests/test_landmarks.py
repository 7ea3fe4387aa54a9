"""Real captures take the same path as simulated ones: an offline detector's keypoints, the same pairing."""

import numpy as np

from lsyd import data, landmarks, pairing

STABLE = [30, 36, 39, 42, 45, 48, 54]  # nose tip, eye and mouth corners


def test_detected_keypoints_match_the_true_ones(sim_data):
    cap = data.Capture.load(sim_data / "captures" / "session-000")
    frames = np.asarray(cap.face[::5])
    truth = cap.keypoints[::5]
    kp = landmarks.detect_keypoints(frames)
    found = ~np.isnan(kp[:, 0, 0])
    assert found.mean() >= 0.95
    iod = np.linalg.norm(truth[:, 45] - truth[:, 36], axis=1)
    err = np.linalg.norm(kp[found][:, STABLE] - truth[found][:, STABLE], axis=2).mean(1) / iod[found]
    assert np.median(err) < 0.08, np.median(err)


def test_pairing_on_detected_keypoints_is_as_precise(sim_data):
    cap = data.Capture.load(sim_data / "captures" / "session-000")
    kp = landmarks.detect_keypoints(np.asarray(cap.face))
    report = pairing.pairing_report(kp, cap.lights(), cap.truth, pairing.PairingRule())
    assert report["pairs"] >= 300, report
    assert report["precision"] >= 0.9, report
