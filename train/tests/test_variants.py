"""Lower-precision variants of the shipped model: finite on any input, and within the
error bounds ``variants.ERROR_BOUNDS`` states against fp32."""

import numpy as np

from lsyd import contract, data, variants


def relight_all(folder, images: np.ndarray, lights: np.ndarray) -> np.ndarray:
    """Each image relit from its light to the next image's light."""
    chain = contract.StageChain(folder)
    outs = [
        chain.relight(img[None], src[None], chain.light_code(tgt[None]))[0]
        for img, src, tgt in zip(images, lights, np.roll(lights, 1, axis=0))
    ]
    return np.stack(outs)


def test_fp16_and_int8_stay_finite_and_close_to_fp32(sim_data, shipped_model, tmp_path):
    res = contract.read(shipped_model / "model.json")["resolution"]
    calibration_images, calibration_lights = variants.calibration_frames(sim_data, res, count=8)
    variants.to_fp16(shipped_model, tmp_path / "fp16")
    variants.to_int8(
        shipped_model,
        tmp_path / "int8",
        variants.chain_inputs(shipped_model, calibration_images, calibration_lights),
    )
    held = data.Heldout.load(sim_data / "heldout")
    faces = data.to_tensor(data.area_resize(held.images[:, 0], res)).numpy()
    lights = held.lights
    reference = relight_all(shipped_model, faces, lights)

    rng = np.random.default_rng(0)
    extreme_faces = np.stack(
        [
            np.zeros((3, res, res), np.float32),
            np.ones((3, res, res), np.float32),
            rng.random((3, res, res), dtype=np.float32),
        ]
    )
    extreme_lights = np.stack([np.zeros_like(lights[0]), np.ones_like(lights[0]), lights[0]])
    for precision, (mean_bound, max_bound) in variants.ERROR_BOUNDS.items():
        out = relight_all(tmp_path / precision, faces, lights)
        err = np.abs(out - reference)
        print(f"{precision}: mean error {err.mean():.2g}, max {err.max():.2g}")  # shown with pytest -s
        assert err.mean() <= mean_bound, f"{precision}: mean error {err.mean():.4f} > {mean_bound}"
        assert err.max() <= max_bound, f"{precision}: max error {err.max():.4f} > {max_bound}"
        extreme = relight_all(tmp_path / precision, extreme_faces, extreme_lights)
        assert np.isfinite(extreme).all(), f"{precision}: NaN or Inf on extreme inputs"
