"""The model contract between the trainer and the Rust engine (version 1).

A model is a folder with ``model.json`` (the manifest) and one ONNX graph per
stage. ``models/CONTRACT.md`` documents it for people; this module and
``plugin/engine/contract.rs`` implement it, and tests on both sides check
that they agree. Change them together and raise ``VERSION`` when a field's
meaning changes.

Stages (names, inputs -> outputs; N = 1, R = resolution, c* = widths):

- ``light_encoder``: ``light`` [N,3,16,32] -> ``code`` [N,256]
- ``encoder``: ``image`` [N,3,R,R] -> ``stem`` [N,c0,R,R], ``e1`` .. ``e7``
- ``light_decoder``: ``e2``, ``e4``, ``e6`` -> ``predicted_light`` [N,3,16,32]
- ``delight``: ``e1`` .. ``e7``, ``source_code`` [N,256] -> ``f1`` .. ``f7``
- ``decoder``: ``f1`` .. ``f7``, ``stem``, ``target_code`` [N,256] -> ``relit`` [N,3,R,R]

Smoothing applies to the de-lit features ``f1`` .. ``f7``. ``StageChain`` runs a
model folder's stages in that order in ONNX Runtime; every Python user of an exported
model relights through it.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import onnxruntime as ort

NAME = "lsydrelight-model"
# 2: the manifest states the crop rule (`crop`).
VERSION = 2
CODE_DIM = 256
LIGHT_ROWS = 16
LIGHT_COLS = 32
SMOOTHED = [f"f{i}" for i in range(1, 8)]
# The square the network sees, from the face detector's box (BlazeFace): CROP["side"]
# face heights square, its centre CROP["lift"] face heights above the box's centre.
# Measured so that it gives the simulator's capture framing
# (tests/face.rs::the_crop_rule_gives_the_training_framing); the element follows
# the face by the rule its model states.
CROP = {"side": 2.9, "lift": 0.22}
RAW = [f"e{i}" for i in range(1, 8)]
STAGES = ("light_encoder", "encoder", "light_decoder", "delight", "decoder")
# The encoder features the light decoder predicts the source light from.
LIGHT_DECODER_INPUTS = ("e2", "e4", "e6")

IMAGE = {
    "layout": "NCHW",
    "dtype": "float32",
    "colour": "sRGB",
    "range": [0.0, 1.0],
    "crop": "square; the face region given by `crop`, area-resampled to the resolution",
}
LIGHT = {
    "layout": "NCHW",
    "dtype": "float32",
    "rows": LIGHT_ROWS,
    "cols": LIGHT_COLS,
    "colour": "linear",
    "range": [0.0, 1.0],
    "definition": (
        "the monitor frame as shown (a screen capture, not mirrored), 8-bit sRGB decoded to linear "
        "light, box-averaged over a 16 x 32 grid with area weights; row 0 is the top of the screen, "
        "column 0 its left edge as the user sees it"
    ),
}


def stage_file(stage: str) -> str:
    """The file of a stage in a model folder, as the manifest records it."""
    return f"{stage}.onnx"


def stage_specs(resolution: int, widths: tuple[int, ...]) -> dict:
    """Tensor names and shapes of every stage for a network configuration."""
    r = resolution
    c0, c1, c2, c3, c4 = widths
    raw_shapes = {
        "e1": [1, c1, r // 2, r // 2],
        "e2": [1, c1, r // 2, r // 2],
        "e3": [1, c2, r // 4, r // 4],
        "e4": [1, c2, r // 4, r // 4],
        "e5": [1, c3, r // 8, r // 8],
        "e6": [1, c3, r // 8, r // 8],
        "e7": [1, c4, r // 16, r // 16],
    }
    delit_shapes = {f: raw_shapes[e] for e, f in zip(RAW, SMOOTHED)}
    light = [1, 3, LIGHT_ROWS, LIGHT_COLS]
    code = [1, CODE_DIM]
    stem = [1, c0, r, r]

    def t(names_shapes: dict) -> list[dict]:
        return [{"name": n, "shape": s, "dtype": "float32"} for n, s in names_shapes.items()]

    return {
        "light_encoder": {
            "file": stage_file("light_encoder"),
            "inputs": t({"light": light}),
            "outputs": t({"code": code}),
        },
        "encoder": {
            "file": stage_file("encoder"),
            "inputs": t({"image": [1, 3, r, r]}),
            "outputs": t({"stem": stem, **raw_shapes}),
        },
        "light_decoder": {
            "file": stage_file("light_decoder"),
            "inputs": t({k: raw_shapes[k] for k in LIGHT_DECODER_INPUTS}),
            "outputs": t({"predicted_light": light}),
        },
        "delight": {
            "file": stage_file("delight"),
            "inputs": t({**raw_shapes, "source_code": code}),
            "outputs": t(delit_shapes),
        },
        "decoder": {
            "file": stage_file("decoder"),
            "inputs": t({**delit_shapes, "stem": stem, "target_code": code}),
            "outputs": t({"relit": [1, 3, r, r]}),
        },
    }


def manifest(
    name: str, resolution: int, widths: tuple[int, ...], precision: str, training: dict, metrics: dict
) -> dict:
    return {
        "contract": NAME,
        "version": VERSION,
        "name": name,
        "resolution": resolution,
        "widths": list(widths),
        "precision": precision,
        "code_dim": CODE_DIM,
        "image": IMAGE,
        "light": LIGHT,
        "smoothed": SMOOTHED,
        "crop": CROP,
        "stages": stage_specs(resolution, widths),
        "training": training,
        "metrics": metrics,
    }


def write(path: Path, m: dict) -> None:
    path.write_text(json.dumps(m, indent=2) + "\n")


def read(path: Path) -> dict:
    m = json.loads(path.read_text())
    if m.get("contract") != NAME or m.get("version") != VERSION:
        raise ValueError(f"{path}: not a {NAME} version {VERSION} manifest")
    if not isinstance(m.get("crop"), dict) or m["crop"].get("side", 0) <= 0:
        raise ValueError(f"{path}: the manifest states no crop rule")
    return m


def srgb_to_linear(v: np.ndarray) -> np.ndarray:
    """sRGB values in [0, 1] as linear light (the sRGB transfer function inverted)."""
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


_SRGB_TO_LINEAR = srgb_to_linear(np.arange(256) / 255.0).astype(np.float32)


def light_from_frames(frames: np.ndarray) -> np.ndarray:
    """Monitor frames (..., H, W, 3) uint8 sRGB to lights (..., 3, 16, 32) float32.

    Box average in linear light with area weights, so any frame size works;
    the Rust element computes the same (``plugin/light.rs``)."""
    lin = _SRGB_TO_LINEAR[frames]
    h, w = frames.shape[-3], frames.shape[-2]
    ry = _area_matrix(h, LIGHT_ROWS)
    rx = _area_matrix(w, LIGHT_COLS)
    # (rows, H) @ (..., H, W, 3) @ (W, cols) per channel.
    out = np.einsum("rh,...hwc,kw->...crk", ry, lin, rx, optimize=True)
    return out.astype(np.float32)


def _area_matrix(n_in: int, n_out: int) -> np.ndarray:
    """Row i averages input samples [i * n_in / n_out, (i + 1) * n_in / n_out) with area weights."""
    m = np.zeros((n_out, n_in), dtype=np.float64)
    scale = n_in / n_out
    for i in range(n_out):
        a, b = i * scale, (i + 1) * scale
        for j in range(int(np.floor(a)), min(int(np.ceil(b)), n_in)):
            m[i, j] = min(b, j + 1) - max(a, j)
    return (m / m.sum(axis=1, keepdims=True)).astype(np.float32)


def open_session(path: Path | bytes, threads: int = 1) -> ort.InferenceSession:
    """An ONNX Runtime CPU session of one stage file (or serialised graph) with the element's settings
    (``plugin/engine/runtime.rs``): ``threads`` threads within an operator, none across
    operators, and no spinning, since stages run one after another and a spinning stage
    would starve the next."""
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = threads
    opts.inter_op_num_threads = 1
    opts.add_session_config_entry("session.intra_op.allow_spinning", "0")
    return ort.InferenceSession(
        path if isinstance(path, bytes) else str(path), opts, providers=["CPUExecutionProvider"]
    )


class StageChain:
    """A model folder's five stages in ONNX Runtime, run in the contract's order as the element
    runs them. The export's parity check, the variants' calibration, the benchmark and the
    evaluation all relight through it.

    Tensors are the contract's, batch 1: images [1,3,R,R] sRGB in [0, 1], lights [1,3,16,32]
    linear, codes [1,256]. ``encoded`` is the encoder's outputs by name (``stem``, ``e1`` ..
    ``e7``); ``delit`` the de-lit features ``f1`` .. ``f7`` in order.
    """

    def __init__(self, folder: Path, threads: int = 1):
        self.sessions = {stage: open_session(folder / stage_file(stage), threads) for stage in STAGES}
        self._encoder_outputs = [o.name for o in self.sessions["encoder"].get_outputs()]
        # From the graph, not the manifest: the export checks its stages before it writes one.
        self.resolution: int = self.sessions["encoder"].get_inputs()[0].shape[-1]

    def light_code(self, light: np.ndarray) -> np.ndarray:
        """``light_encoder``: a light's code, for the source or the target."""
        return self.sessions["light_encoder"].run(None, {"light": light})[0]

    def encode(self, image: np.ndarray) -> dict[str, np.ndarray]:
        """``encoder``: the image's stem and raw features by name."""
        return dict(zip(self._encoder_outputs, self.sessions["encoder"].run(None, {"image": image})))

    def predict_light(self, image: np.ndarray) -> np.ndarray:
        """``encoder`` then ``light_decoder``: the source light predicted from the image alone."""
        return self.sessions["light_decoder"].run(None, _light_decoder_feed(self.encode(image)))[0]

    def delight(self, encoded: dict[str, np.ndarray], source_code: np.ndarray) -> list[np.ndarray]:
        """``delight``: the raw features with the source light's code removed."""
        return self.sessions["delight"].run(None, _delight_feed(encoded, source_code))

    def relight(self, image: np.ndarray, source_light: np.ndarray, target_code: np.ndarray) -> np.ndarray:
        """One frame relit from its source light (known, or from ``predict_light``) to the light
        whose code is ``target_code``: ``encoder``, ``light_encoder`` on the source, ``delight``,
        ``decoder``. Returns ``relit`` [1,3,R,R] in [0, 1]."""
        encoded = self.encode(image)
        delit = self.delight(encoded, self.light_code(source_light))
        return self.sessions["decoder"].run(None, _decoder_feed(encoded, delit, target_code))[0]

    def stage_inputs(
        self, image: np.ndarray, source_light: np.ndarray, target_light: np.ndarray
    ) -> dict[str, dict[str, np.ndarray]]:
        """Every stage's inputs by name, as ``relight`` and ``predict_light`` feed them for one
        frame relit from ``source_light`` to ``target_light`` (``light_encoder``'s are the source
        light's): the data the int8 variant is calibrated on."""
        encoded = self.encode(image)
        delight = _delight_feed(encoded, self.light_code(source_light))
        delit = self.sessions["delight"].run(None, delight)
        return {
            "light_encoder": {"light": source_light},
            "encoder": {"image": image},
            "light_decoder": _light_decoder_feed(encoded),
            "delight": delight,
            "decoder": _decoder_feed(encoded, delit, self.light_code(target_light)),
        }


def _light_decoder_feed(encoded: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    return {k: encoded[k] for k in LIGHT_DECODER_INPUTS}


def _delight_feed(encoded: dict[str, np.ndarray], source_code: np.ndarray) -> dict[str, np.ndarray]:
    return {**{e: encoded[e] for e in RAW}, "source_code": source_code}


def _decoder_feed(
    encoded: dict[str, np.ndarray], delit: list[np.ndarray], target_code: np.ndarray
) -> dict[str, np.ndarray]:
    return {**dict(zip(SMOOTHED, delit)), "stem": encoded["stem"], "target_code": target_code}
