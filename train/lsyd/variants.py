"""Lower-precision variants of an exported model: fp16 weights and int8 quantisation.

    python -m lsyd.variants --model models/default --data data --out target/bench-models
    python -m lsyd.variants --model models/starter --data data/starter --out target/variants \
        --no-fp16 [--int8-stages delight decoder] --heldout data/starter/unseen/person-200 ...

Both keep the contract's float32 inputs and outputs, so the element runs them
unchanged. fp16 stores weights and computes in half precision where ONNX
Runtime supports it; int8 is static QDQ quantisation (per-channel weights,
activations calibrated on training frames, never on the held-out set), of every stage or
of the ones named; ``--heldout`` scores fp32 and int8 on held-out sets and records both in
the int8 manifest's ``metrics.heldout_rmse``.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

import numpy as np
import onnx
from onnxruntime.quantization import CalibrationDataReader, QuantFormat, QuantType, quantize_static
from onnxruntime.transformers.float16 import convert_float_to_float16

from . import contract, data

# Bounds on the relit image's difference from fp32 (sRGB in [0, 1]): mean and max
# absolute difference over held-out relightings. ``tests/test_variants.py`` holds
# every variant to them. The shipped model measures fp16 7.5e-5 mean, 6.1e-4 max, and int8
# 0.0038 mean (about one 8-bit level), 0.07 max (`pytest -s tests/test_variants.py`).
ERROR_BOUNDS = {"fp16": (0.0005, 0.005), "int8": (0.01, 0.1)}


def check_close(folder: Path, ref: dict[str, np.ndarray], precision: str) -> float:
    """The mean absolute difference of ``folder``'s relit image from the reference's (a
    ``export.reference_run``), which must be within ``ERROR_BOUNDS[precision]``'s mean bound."""
    chain = contract.StageChain(folder)
    relit = chain.relight(ref["image"], ref["light"], chain.light_code(ref["target_light"]))
    diff = float(np.abs(relit - ref["relit"]).mean())
    if not diff <= ERROR_BOUNDS[precision][0]:
        raise ValueError(
            f"{folder}: the {precision} variant relights {diff:.4f} from the fp32 network on average, "
            f"more than {ERROR_BOUNDS[precision][0]}; make it again from this model with `python -m lsyd.variants`"
        )
    return diff


def chain_inputs(model: Path, images: np.ndarray, lights: np.ndarray) -> dict[str, list[dict]]:
    """Every stage's inputs for each (image, light) pair, from the fp32 model: calibration data."""
    chain = contract.StageChain(model)
    feeds: dict[str, list[dict]] = {k: [] for k in contract.STAGES}
    for img, light, tgt in zip(images, lights, lights[::-1]):
        for stage, feed in chain.stage_inputs(img[None], light[None], tgt[None]).items():
            feeds[stage].append(feed)
    return feeds


class _Reader(CalibrationDataReader):
    def __init__(self, feeds: list[dict]):
        self.it = iter(feeds)

    def get_next(self):
        return next(self.it, None)


def _copy_manifest(model: Path, out: Path, precision: str) -> None:
    out.mkdir(parents=True, exist_ok=True)
    m = json.loads((model / "model.json").read_text())
    m["precision"] = precision
    m["name"] = f"{m['name']}-{precision}"
    m["metrics"] = {}
    m.pop("parity", None)
    if "presence" in m["stages"]:
        shutil.copy(model / "presence.onnx", out / "presence.onnx")
    contract.write(out / "model.json", m)


def to_fp16(model: Path, out: Path) -> None:
    _copy_manifest(model, out, "fp16")
    for stage in contract.STAGES:
        m = onnx.load(str(model / contract.stage_file(stage)))
        onnx.save(convert_float_to_float16(m, keep_io_types=True), str(out / contract.stage_file(stage)))


def to_int8(
    model: Path, out: Path, calibration: dict[str, list[dict]], stages: tuple[str, ...] = contract.STAGES
) -> None:
    """int8 ``stages`` (the others copied as they are, fp32)."""
    _copy_manifest(model, out, "int8")
    for stage in contract.STAGES:
        if stage not in stages:
            shutil.copy(model / contract.stage_file(stage), out / contract.stage_file(stage))
            continue
        quantize_static(
            str(model / contract.stage_file(stage)),
            str(out / contract.stage_file(stage)),
            _Reader(calibration[stage]),
            quant_format=QuantFormat.QDQ,
            per_channel=True,
            # 7-bit weights: x86 CPUs without VNNI (AVX2 only, e.g. many AMD EPYC)
            # multiply u8 x s8 pairs into saturating 16-bit sums, which 8-bit
            # per-channel weights overflow (max error 0.18 here, against 0.07 on VNNI).
            reduce_range=True,
            activation_type=QuantType.QUInt8,
            weight_type=QuantType.QInt8,
        )


def calibration_frames(data_root: Path, resolution: int, count: int = 48) -> tuple[np.ndarray, np.ndarray]:
    """Training frames and their lights, spread over the capture sessions."""
    images, lights = [], []
    dirs = data.capture_dirs(data_root / "captures")
    per = max(1, count // len(dirs))
    for d in dirs:
        cap = data.Capture.load(d)
        idx = np.linspace(0, len(cap.face) - 1, per).astype(int)
        images.append(data.to_tensor(data.area_resize(cap.face[idx], resolution)).numpy())
        lights.append(contract.light_from_frames(np.asarray(cap.monitor[idx])))
    return np.concatenate(images)[:count], np.concatenate(lights)[:count]


def heldout_rmse(folder: Path, sets: list[Path]) -> list[float]:
    """Face-crop RMSE (0-255) of ``folder`` on each 9 x 9 held-out set, source light known:
    the benchmark's scorer (``benchmark.test_set_accuracy``), the same path for every precision."""
    from .evaluation import benchmark

    return [benchmark.test_set_accuracy(folder, data.Heldout.load(s), ("rmse",))["rmse"] for s in sets]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", type=Path, required=True)
    p.add_argument("--data", type=Path, default=Path("data"), help="calibration: <data>/captures")
    p.add_argument("--out", type=Path, required=True, help="writes <out>/<model>-fp16 and <out>/<model>-int8")
    p.add_argument(
        "--int8-stages",
        nargs="+",
        choices=contract.STAGES,
        default=list(contract.STAGES),
        help="the stages to quantise; the others stay fp32",
    )
    p.add_argument("--no-fp16", action="store_true", help="write the int8 variant only")
    p.add_argument(
        "--heldout",
        type=Path,
        nargs="*",
        default=[],
        help="9 x 9 held-out sets to score fp32 and int8 on (RMSE), recorded in the int8 manifest",
    )
    a = p.parse_args()
    res = contract.read(a.model / "model.json")["resolution"]
    images, lights = calibration_frames(a.data, res)
    if not a.no_fp16:
        to_fp16(a.model, a.out / f"{a.model.name}-fp16")
        print(f"wrote {a.out / (a.model.name + '-fp16')}")
    int8 = a.out / f"{a.model.name}-int8"
    to_int8(a.model, int8, chain_inputs(a.model, images, lights), tuple(a.int8_stages))
    print(f"wrote {int8} (int8: {', '.join(a.int8_stages)})")
    if a.heldout:
        scores = {"fp32": heldout_rmse(a.model, a.heldout), "int8": heldout_rmse(int8, a.heldout)}
        m = contract.read(int8 / "model.json")
        m["metrics"]["heldout_rmse"] = {
            "command": "python -m lsyd.variants " + " ".join(sys.argv[1:]),
            "sets": [s.name for s in a.heldout],
            "int8_stages": a.int8_stages,
            "calibration": f"{len(images)} frames of {a.data.name}/captures",
            **{k: {"sets": v, "mean": float(np.mean(v))} for k, v in scores.items()},
        }
        contract.write(int8 / "model.json", m)
        for k, v in scores.items():
            print(f"{k}: held-out RMSE {np.mean(v):.4f} ({', '.join(f'{x:.4f}' for x in v)})")


if __name__ == "__main__":
    main()
