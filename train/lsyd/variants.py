"""Lower-precision variants of an exported model: fp16 weights and int8 quantisation.

    python -m lsyd.variants --model models/default --data data --out target/variants
    python -m lsyd.variants --model models/default --data data --out target/variants --no-fp16 \
        --validation data/validation --max-cost 0.5 [--heldout data/heldout]

Both keep the contract's float32 inputs and outputs, so the element runs them
unchanged. fp16 stores weights and computes in half precision where ONNX
Runtime supports it. int8 is static QDQ quantisation of the convolutions of the
encoder, delight and decoder stages (or those named with ``--int8-stages``): per-channel
weights, activations calibrated on training frames, never on the held-out set. Everything
else stays fp32: the decoder's image head, a convolution on few channels (the encoder's stem
unless ``lsyd.optimise`` rewrote it by blocks), the light decoder, and the AdaIN's light-code
arithmetic that gives the normalisations their scale and shift (see ``INT8_OPS``,
``INT8_STAGES``, ``MIN_INT8_INPUTS``).

``--validation`` chooses which convolutions to quantise: each is quantised alone and
scored on the validation sets, and the cheapest are taken, in that order, as long as
the whole variant's RMSE stays within ``--max-cost`` percent of fp32's
(``choose_int8_convs``). ``--heldout`` then scores fp32 and int8 on held-out sets; both
choices and scores go into the int8 manifest's ``metrics``.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import onnx
from onnx import numpy_helper
from onnxruntime.quantization import CalibrationDataReader, QuantFormat, QuantType, quantize_static
from onnxruntime.transformers.float16 import convert_float_to_float16

from . import contract, data

# Bounds on the relit image's difference from fp32 (sRGB in [0, 1]): mean and max
# absolute difference over held-out relightings. ``tests/test_variants.py`` holds
# every variant to them. The shipped model measures fp16 7.4e-5 mean, 6.4e-4 max, and int8
# (every candidate convolution) 0.0028 mean (under one 8-bit level), 0.034 max on an AVX-512
# VNNI Xeon (`pytest -s tests/test_variants.py`; 0.0038 and 0.07 when every operation of every
# stage was quantised). The bounds
# leave room for CPUs without VNNI, whose int8 kernels round differently.
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


def check_made_from(model: Path, int8: Path) -> list[str]:
    """Raises unless ``int8`` is an int8 variant of ``model`` as it is now: its manifest says int8
    and some convolution is int8; each stage without one is the model's file byte for byte; in
    the others each int8 weight is the model's own rounded to its channel's step, and every
    float parameter both graphs hold by name (the fp32 convolutions', the normalisations', the
    light code's) is the model's. Returns the int8 convolutions' names. Unlike ``check_close`` it
    needs no input, so it holds on any face."""
    remake = f"make it again from {model} with `python -m lsyd.variants`"
    if contract.read(int8 / "model.json").get("precision") != "int8":
        raise ValueError(f"{int8}: its manifest does not say int8; {remake}")
    names = []
    for stage in contract.STAGES:
        file = contract.stage_file(stage)
        graph = onnx.load(str(int8 / file)).graph
        convs = quantised_convs(graph)
        if not convs:
            if (int8 / file).read_bytes() != (model / file).read_bytes():
                raise ValueError(f"{int8}: its {stage} stage is not {model}'s; {remake}")
            continue
        fp32 = onnx.load(str(model / file)).graph
        params = {t.name: numpy_helper.to_array(t) for t in fp32.initializer}
        weights = {n.name: params.get(n.input[1]) for n in fp32.node if n.op_type == "Conv"}
        stored = {t.name: numpy_helper.to_array(t) for t in graph.initializer}
        producer = {o: n for n in graph.node for o in n.output}
        for conv in (n for n in graph.node if n.name in convs):
            parts = [stored.get(t) for t in producer[conv.input[1]].input]
            weight = weights.get(conv.name)
            if len(parts) != 3 or any(part is None for part in parts) or weight is None:
                raise ValueError(f"{int8}: the int8 weights of {conv.name} are not {model}'s; {remake}")
            q, scale, zero = parts
            step = scale.reshape(-1, 1, 1, 1)
            restored = (q.astype(np.float32) - zero.reshape(-1, 1, 1, 1)) * step
            if weight.shape != restored.shape or np.any(np.abs(restored - weight) > 0.5001 * step):
                raise ValueError(f"{int8}: the int8 weights of {conv.name} are not {model}'s; {remake}")
        for name, value in stored.items():
            if value.dtype.kind == "f" and name in params and not np.array_equal(value, params[name]):
                raise ValueError(f"{int8}: {name} of its {stage} stage is not {model}'s; {remake}")
        names += convs
    if not names:
        raise ValueError(f"{int8}: no convolution is int8; {remake}")
    return names


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


def int8_card(model: Path, int8: Path) -> str:
    """The int8 variant's model card (``README.md``), from its manifest's ``metrics``."""
    m = contract.read(int8 / "model.json")["metrics"]
    record = m["int8"]
    lines = [
        f"# Model card: `{int8.name}`",
        "",
        f"`{model.name}` with {len(record['quantised'])} of its convolutions in int8 (`python -m lsyd.variants`):",
        "static QDQ quantisation, per-channel 7-bit weights (so CPUs without VNNI do not saturate), activations",
        f"calibrated on {record['calibration']}. Everything else is `{model.name}`'s, fp32: the element",
        f"loads it as it loads `{model.name}` (`model-location`). Its network was measured faster on a CPU",
        'with AVX-512 VNNI, at a small cost in error; docs/benchmark.md\'s "int8 variants" has the',
        "timings.",
        "",
        f"Made by: `{record['command']}`",
        "",
    ]
    if "validation" in record:
        v = record["validation"]
        lines += [
            f"Chosen on the validation set ({', '.join(v['sets'])}): each candidate convolution quantised alone and",
            f"scored, the cheapest taken while the RMSE rose at most {v['max_rise_percent']}% over fp32's; it rose",
            f"{v['rise_percent']:.2f}%. Kept fp32: {', '.join(f'`{c}`' for c in v['kept_fp32']) or 'none'}.",
            "",
        ]
    if "heldout_rmse" in m:
        h = m["heldout_rmse"]
        fp32, q = h["fp32"]["mean"], h["int8"]["mean"]
        lines += [
            f"Held out ({', '.join(h['sets'])}), face-crop RMSE (0-255) against exact ground truth, source light",
            f"known: {fp32:.3f} fp32, {q:.3f} int8 ({100 * (q / fp32 - 1):+.2f}%).",
            "",
        ]
    lines += [f"Quantised: {', '.join(f'`{c}`' for c in record['quantised'])}.", ""]
    return "\n".join(lines)


def to_fp16(model: Path, out: Path) -> None:
    _copy_manifest(model, out, "fp16")
    for stage in contract.STAGES:
        m = onnx.load(str(model / contract.stage_file(stage)))
        onnx.save(convert_float_to_float16(m, keep_io_types=True), str(out / contract.stage_file(stage)))


# Quantised in an int8 variant: convolutions, nothing else. Measured on the default model's
# delight and decoder stages with the decoder's image head fp32 (validation / held-out RMSE, fp32
# 7.737 / 8.273; CPU ms a run of the delight / decoder on 1 thread of an AVX-512 VNNI Xeon,
# `benchmark stages`): every operation quantised, the AdaIN's light-code Gemm, add and split on
# their way to the normalisations' scale and shift among them, 7.834 / 8.346 at 0.516 / 1.769 ms;
# convolutions only 7.814 / 8.312 at 0.450 / 1.593 ms, where fp32 takes 0.817 / 2.03.
INT8_OPS = ("Conv",)
# Quantised unless told otherwise: the stages whose int8 convolutions were measured faster
# (CPU ms a run, 1 thread, default model): the encoder 0.968 to 0.793 (its stem fp32, below),
# the delight 0.817 to 0.450, the decoder 2.03 to 1.593. The light decoder runs only when the
# source light is unknown, and the validation cost, relit with the source known, cannot see its
# error; it stays fp32 (all three of its 1x1 convolutions int8, a one-off run: 0.209 to 0.144).
INT8_STAGES = ("encoder", "delight", "decoder")
# Convolutions with fewer input channels stay fp32: the encoder's stem (3 channels, 7x7)
# in int8 took the encoder from 0.968 to 1.040 ms instead of 0.793. Rewritten by blocks
# (``optimise.convs_by_blocks``: 48 input channels), it is a candidate like the others.
MIN_INT8_INPUTS = 8
# Stages whose output is an image; their image head stays fp32 (``image_heads``).
IMAGE_STAGES = ("decoder", "light_decoder")


def image_heads(model: onnx.ModelProto) -> list[str]:
    """The convolutions that draw a stage's output: those from which an output of the graph is
    reached without passing another convolution. Quantised, their output is 8-bit steps of its
    calibrated range: with the decoder's image head int8 too, the delight and decoder stages'
    convolutions cost +1.24% RMSE on the default model's validation set, against +0.99% with
    it fp32."""
    producer = {o: n for n in model.graph.node for o in n.output}
    heads, seen = [], set()
    todo = [o.name for o in model.graph.output]
    while todo:
        node = producer.get(todo.pop())
        if node is None or id(node) in seen:
            continue
        seen.add(id(node))
        if node.op_type == "Conv":
            heads.append(node.name)
        else:
            todo.extend(node.input)
    return heads


def int8_candidates(model: Path, stages: tuple[str, ...] = INT8_STAGES) -> list[str]:
    """The convolutions an int8 variant of ``stages`` may quantise: all but the image heads and
    those with fewer than ``MIN_INT8_INPUTS`` input channels."""
    names = []
    for stage in stages:
        graph = onnx.load(str(model / contract.stage_file(stage)))
        heads = image_heads(graph) if stage in IMAGE_STAGES else []
        in_channels_per_group = {t.name: t.dims[1] for t in graph.graph.initializer if len(t.dims) == 4}
        names += [
            n.name
            for n in graph.graph.node
            if n.op_type in INT8_OPS
            and n.name not in heads
            and in_channels_per_group.get(n.input[1], 0) >= MIN_INT8_INPUTS
        ]
    return names


def quantised_convs(graph: onnx.GraphProto) -> list[str]:
    """The convolutions of a QDQ graph whose weights are int8 (dequantised on their way in)."""
    producer = {o: n.op_type for n in graph.node for o in n.output}
    return [n.name for n in graph.node if n.op_type == "Conv" and producer.get(n.input[1]) == "DequantizeLinear"]


def to_int8(model: Path, out: Path, calibration: dict[str, list[dict]], convs: list[str] | None = None) -> None:
    """int8 ``convs`` (by node name; ``int8_candidates()`` when None), each stage without one of
    them copied as it is, fp32. A name no stage has, or more than one has, is an error."""
    convs = int8_candidates(model) if convs is None else convs
    graphs = {stage: onnx.load(str(model / contract.stage_file(stage))).graph for stage in contract.STAGES}
    for name in convs:
        holders = [stage for stage, g in graphs.items() if any(n.name == name and n.op_type == "Conv" for n in g.node)]
        if len(holders) != 1:
            raise ValueError(f"{model}: convolution {name!r} is in {len(holders)} stages, not one; name one per stage")
    _copy_manifest(model, out, "int8")
    for stage in contract.STAGES:
        path = model / contract.stage_file(stage)
        stage_convs = [n.name for n in graphs[stage].node if n.name in convs]
        if not stage_convs:
            shutil.copy(path, out / contract.stage_file(stage))
            continue
        quantize_static(
            str(path),
            str(out / contract.stage_file(stage)),
            _Reader(calibration[stage]),
            quant_format=QuantFormat.QDQ,
            op_types_to_quantize=list(INT8_OPS),
            nodes_to_quantize=stage_convs,
            per_channel=True,
            # 7-bit weights: x86 CPUs without VNNI (AVX2 only, e.g. many AMD EPYC)
            # multiply u8 x s8 pairs into saturating 16-bit sums, which 8-bit
            # per-channel weights overflow (max error 0.18 here, against 0.07 on VNNI).
            reduce_range=True,
            activation_type=QuantType.QUInt8,
            weight_type=QuantType.QInt8,
        )


def choose_int8_convs(candidates: list[str], cost: Callable[[list[str]], float], max_cost: float) -> dict:
    """Which ``candidates`` to quantise: each alone is scored by ``cost`` (the relative rise of the
    validation error over fp32's), and the cheapest are taken in that order, as many as keep the
    whole variant's cost at most ``max_cost``. How many is found by bisection over the prefixes,
    which assumes that a longer prefix costs more: quantisation errors of separate layers mostly
    add, though a few layers alone lower the error a little. Every prefix the bisection settles
    on is measured, not assumed; the empty one is fp32 (cost 0)."""
    if max_cost < 0:
        raise ValueError(f"max_cost is {max_cost}: a bound on the rise of the error cannot be negative")
    alone = {c: cost([c]) for c in candidates}
    order = sorted(candidates, key=alone.__getitem__)
    measured = {0: 0.0}

    def prefix_cost(k: int) -> float:
        if k not in measured:
            measured[k] = cost(order[:k])
        return measured[k]

    lo, hi = 0, len(order)
    if prefix_cost(hi) <= max_cost:
        lo = hi
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if prefix_cost(mid) <= max_cost:
            lo = mid
        else:
            hi = mid
    return {
        "quantised": order[:lo],
        "kept_fp32": order[lo:],
        "cost": measured[lo],
        "cost_alone": alone,
        "max_cost": max_cost,
    }


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


def set_rmse(folder: Path, sets: list[Path]) -> list[float]:
    """Face-crop RMSE (0-255) of ``folder`` on each 9 x 9 set (held-out or validation), source light known:
    the benchmark's scorer (``benchmark.test_set_accuracy``), the same path for every precision."""
    from .evaluation import benchmark

    return [benchmark.test_set_accuracy(folder, data.Heldout.load(s), ("rmse",))["rmse"] for s in sets]


def validation_cost(model: Path, calibration: dict[str, list[dict]], sets: list[Path]) -> Callable[[list[str]], float]:
    """The cost that ``choose_int8_convs`` minimises: how much higher the mean RMSE over ``sets``
    is with the given convolutions int8 than with none, as a fraction of fp32's."""
    fp32 = float(np.mean(set_rmse(model, sets)))

    def cost(convs: list[str]) -> float:
        with tempfile.TemporaryDirectory() as scratch:
            to_int8(model, Path(scratch), calibration, convs)
            return float(np.mean(set_rmse(Path(scratch), sets))) / fp32 - 1.0

    return cost


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", type=Path, required=True)
    p.add_argument("--data", type=Path, default=Path("data"), help="calibration: <data>/captures")
    p.add_argument("--out", type=Path, required=True, help="writes <out>/<model>-fp16 and <out>/<model>-int8")
    p.add_argument(
        "--int8-stages",
        nargs="+",
        choices=contract.STAGES,
        default=list(INT8_STAGES),
        help="the stages whose convolutions may be quantised; the others stay fp32",
    )
    p.add_argument("--no-fp16", action="store_true", help="write the int8 variant only")
    p.add_argument(
        "--validation",
        type=Path,
        nargs="+",
        help="9 x 9 sets to choose the int8 convolutions on (never the held-out set)",
    )
    p.add_argument(
        "--max-cost",
        type=float,
        help="with --validation: the most the int8 variant may add to the validation RMSE, in percent (default 0.5)",
    )
    p.add_argument(
        "--heldout",
        type=Path,
        nargs="*",
        default=[],
        help="9 x 9 held-out sets to score fp32 and int8 on (RMSE), recorded in the int8 manifest",
    )
    a = p.parse_args()
    if a.max_cost is not None and not a.validation:
        p.error("--max-cost bounds the choice on --validation sets; give them, or leave --max-cost out")
    max_cost = 0.5 if a.max_cost is None else a.max_cost
    if max_cost < 0:
        p.error(f"--max-cost {max_cost}: give the most the error may rise, in percent, 0 or more")
    convs = int8_candidates(a.model, tuple(a.int8_stages))
    if not convs:
        p.error(
            f"{', '.join(a.int8_stages)}: no convolution to quantise (none, or only image heads and "
            f"convolutions of fewer than {MIN_INT8_INPUTS} input channels); name other --int8-stages"
        )
    command = f"cd train && python -m lsyd.variants {' '.join(sys.argv[1:])}"
    res = contract.read(a.model / "model.json")["resolution"]
    images, lights = calibration_frames(a.data, res)
    if not a.no_fp16:
        to_fp16(a.model, a.out / f"{a.model.name}-fp16")
        print(f"wrote {a.out / (a.model.name + '-fp16')}")
    int8 = a.out / f"{a.model.name}-int8"
    calibration = chain_inputs(a.model, images, lights)
    record = {"command": command, "calibration": f"{len(images)} frames of {a.data.name}/captures"}
    if a.validation:
        choice = choose_int8_convs(convs, validation_cost(a.model, calibration, a.validation), max_cost / 100)
        convs = choice["quantised"]
        record["validation"] = {
            "sets": [s.name for s in a.validation],
            "max_rise_percent": max_cost,
            "rise_percent": 100 * choice["cost"],
            "rise_alone_percent": {c: 100 * v for c, v in choice["cost_alone"].items()},
            "kept_fp32": choice["kept_fp32"],
        }
        print(
            f"validation: {len(convs)} convolutions int8, RMSE +{100 * choice['cost']:.2f}%; "
            f"fp32: {', '.join(choice['kept_fp32']) or 'none'}"
        )
    to_int8(a.model, int8, calibration, convs)
    print(f"wrote {int8} (int8: {len(convs)} convolutions of {', '.join(a.int8_stages)})")
    m = contract.read(int8 / "model.json")
    m["metrics"]["int8"] = {**record, "quantised": convs}
    if a.heldout:
        scores = {"fp32": set_rmse(a.model, a.heldout), "int8": set_rmse(int8, a.heldout)}
        m["metrics"]["heldout_rmse"] = {
            "command": command,
            "sets": [s.name for s in a.heldout],
            **{k: {"sets": v, "mean": float(np.mean(v))} for k, v in scores.items()},
        }
        for k, v in scores.items():
            print(f"{k}: held-out RMSE {np.mean(v):.4f} ({', '.join(f'{x:.4f}' for x in v)})")
    contract.write(int8 / "model.json", m)
    (int8 / "README.md").write_text(int8_card(a.model, int8))


if __name__ == "__main__":
    main()
