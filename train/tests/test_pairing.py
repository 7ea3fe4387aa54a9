"""Pairing by facial keypoints, measured against the simulator's true poses."""

import numpy as np

from lsyd import data, pairing


def test_pairs_match_the_true_pose(sim_data):
    cap = data.Capture.load(sim_data / "captures" / "session-000")
    lights = cap.lights()
    report = pairing.pairing_report(cap.keypoints, lights, cap.truth, pairing.PairingRule())
    assert report["pairs"] >= 500, report
    assert report["precision"] >= 0.9, report
    assert report["rotation_deg_p95"] <= 2.0, report


def test_pairs_have_different_light_and_no_self_pairs(sim_data):
    cap = data.Capture.load(sim_data / "captures" / "session-000")
    lights = cap.lights()
    rule = pairing.PairingRule()
    pairs = pairing.find_pairs(cap.keypoints, lights, rule)
    assert (pairs[:, 0] != pairs[:, 1]).all()
    diff = np.abs(lights[pairs[:, 0]] - lights[pairs[:, 1]]).reshape(len(pairs), -1).mean(1)
    assert (diff >= rule.min_light_difference).all()


def test_detector_noise_keeps_pairs_precise(sim_data):
    """Real keypoints come from a detector with pixel noise; pairing must stay precise."""
    cap = data.Capture.load(sim_data / "captures" / "session-000")
    rng = np.random.default_rng(0)
    noisy = cap.keypoints + rng.normal(0.0, 0.25, cap.keypoints.shape).astype(np.float32)
    report = pairing.pairing_report(noisy, cap.lights(), cap.truth, pairing.PairingRule())
    assert report["precision"] >= 0.85, report


def test_frames_without_a_face_never_pair():
    kp = np.zeros((3, 68, 2), dtype=np.float32)
    kp[:, 36] = [10, 10]
    kp[:, 45] = [50, 10]
    kp[1] = np.nan
    lights = np.stack([np.full((3, 16, 32), v, dtype=np.float32) for v in (0.1, 0.5, 0.9)])
    pairs = pairing.find_pairs(kp, lights, pairing.PairingRule())
    assert not (pairs == 1).any()
    assert {tuple(p) for p in pairs} == {(0, 2), (2, 0)}
