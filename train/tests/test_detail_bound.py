"""The detail band's bound (``lsyd.evaluation.detail_bound``): the band split, and what a change
sampled at a resolution can and cannot remove."""

import numpy as np
import pytest

from lsyd.evaluation import detail_bound

SIDE = 96
RADIUS = detail_bound.detail_radius(SIDE)


def face_and_truth(shading: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A textured face (1, SIDE, SIDE, 3) and the same face under ``shading`` (SIDE, SIDE)."""
    rng = np.random.default_rng(3)
    y, x = np.mgrid[0:SIDE, 0:SIDE] / SIDE
    albedo = 120 + 40 * np.sin(6 * x) * np.cos(5 * y) + rng.uniform(-10, 10, (SIDE, SIDE))
    colour = np.array([1.0, 0.8, 0.7])
    face = np.rint(albedo[..., None] * colour).clip(0, 255)
    truth = np.rint(face * shading[..., None]).clip(0, 255)
    return face[None].astype(np.uint8), truth[None].astype(np.uint8)


def test_the_radius_rounds_as_the_rust_scorer():
    # Halves round up, as Rust's f64::round: 120 / 48 = 2.5 is 3 there (Python's round gives 2).
    assert detail_bound.detail_radius(360) == 8
    assert detail_bound.detail_radius(120) == 3
    assert detail_bound.detail_radius(10) == 1


def test_a_fine_error_is_detail_and_a_uniform_one_smooth():
    truth = np.full((SIDE, SIDE, 3), 100.0)
    checker = (np.indices((SIDE, SIDE)).sum(0) % 2 * 2 - 1)[..., None] * 4.0
    smooth, detail, n = detail_bound.band_sums(truth + checker, truth, RADIUS)
    assert np.sqrt(detail / n) == pytest.approx(4.0, rel=0.02)
    assert np.sqrt(smooth / n) < 0.2
    smooth, detail, n = detail_bound.band_sums(truth + 5.0, truth, RADIUS)
    assert np.sqrt(smooth / n) == pytest.approx(5.0)
    assert np.sqrt(detail / n) < 1e-9


def test_the_exact_change_at_full_resolution_leaves_only_rounding():
    y = np.mgrid[0:SIDE, 0:SIDE][0] / SIDE
    face, truth = face_and_truth(0.6 + 0.6 * y)
    change = detail_bound.exact_change(face, truth, SIDE)
    out = detail_bound.apply(face, detail_bound.upsample(change, SIDE))
    smooth, detail = detail_bound.bands(out, truth, RADIUS)
    assert smooth < 0.1 and detail < 0.6


def test_a_coarse_change_takes_smooth_shading_but_not_fine_shading():
    y, x = np.mgrid[0:SIDE, 0:SIDE]
    smooth_shading = 0.6 + 0.6 * y / SIDE
    stripes = 1.0 + 0.3 * (x % 4 < 2)  # a shadow pattern 4 px across: finer than 24 samples reach
    face, truth = face_and_truth(smooth_shading * stripes)
    untouched = detail_bound.bands(face, truth, RADIUS)
    change = detail_bound.exact_change(face, truth, 24)
    coarse = detail_bound.bands(detail_bound.apply(face, detail_bound.upsample(change, SIDE)), truth, RADIUS)
    assert coarse[0] < 0.2 * untouched[0]  # the smooth band: taken
    assert coarse[1] > 0.8 * untouched[1]  # the detail band: left


def test_guided_upsampling_recovers_shading_that_follows_the_input_luma():
    # Where the fine gain is a fixed power of the input's luma (fine shadows darkening what is
    # darker), the local fit at low resolution carries it to the fine scale; bilinear does not.
    face, _ = face_and_truth(np.ones((SIDE, SIDE)))
    luma = detail_bound.log_luma(face)
    log_gain = np.repeat((-0.5 * (luma - luma.mean()))[..., None], 3, -1)
    truth = detail_bound.apply(face, log_gain).astype(np.uint8)
    change = detail_bound.exact_change(face, truth, 24)
    bilinear = detail_bound.bands(detail_bound.apply(face, detail_bound.upsample(change, SIDE)), truth, RADIUS)
    guided = detail_bound.bands(detail_bound.apply(face, detail_bound.guided_upsample(change, face)), truth, RADIUS)
    assert guided[1] < 0.5 * bilinear[1]


def test_a_missing_recording_says_which_command_writes_it(tmp_path, monkeypatch):
    monkeypatch.setattr("sys.argv", ["detail_bound", "--recording", str(tmp_path / "call-90")])
    with pytest.raises(SystemExit, match="example flicker -- --recordings NAME --frames N --clean"):
        detail_bound.main()
