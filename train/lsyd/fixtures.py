"""Test fixtures made from a shipped model.

    python -m lsyd.fixtures nan-model --model models/default --out target/test-models/nan \\
        --trigger models/targets/left-key.png --normal models/targets/studio.png

``nan-model`` copies a model and changes its decoder so that its output is NaN
whenever the target light's code has a mean above a threshold set between the
two given target images: relighting to ``--trigger`` gives NaN, to ``--normal``
the usual result. The element's tests use it to show that NaN is never shown.
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

import numpy as np
import onnx
from onnx import TensorProto, helper
from PIL import Image

from . import contract


def _code(model: Path, image: Path) -> np.ndarray:
    light = contract.light_from_frames(np.asarray(Image.open(image).convert("RGB")))[None]
    return contract.open_session(model / contract.stage_file("light_encoder")).run(None, {"light": light})[0]


def nan_model(model: Path, out: Path, trigger: Path, normal: Path) -> float:
    """Writes the fixture and returns the threshold on the target code's mean."""
    if out.exists():
        shutil.rmtree(out)
    shutil.copytree(model, out)
    bad, good = float(_code(model, trigger).mean()), float(_code(model, normal).mean())
    if abs(bad - good) < 1e-6:
        raise SystemExit("the two targets have the same code mean; choose others")
    threshold = 0.5 * (bad + good)
    sign = 1.0 if bad > good else -1.0
    m = onnx.load(str(out / "decoder.onnx"))
    g = m.graph
    relit = g.output[0].name
    g.output[0].name = "relit_clean"
    for node in g.node:
        node.output[:] = ["relit_clean" if o == relit else o for o in node.output]
    g.initializer.extend(
        [
            helper.make_tensor("nan_threshold", TensorProto.FLOAT, [], [sign * threshold]),
            helper.make_tensor("nan_sign", TensorProto.FLOAT, [], [sign]),
            helper.make_tensor("nan_value", TensorProto.FLOAT, [], [float("nan")]),
            helper.make_tensor("zero", TensorProto.FLOAT, [], [0.0]),
        ]
    )
    g.node.extend(
        [
            helper.make_node("ReduceMean", ["target_code"], ["code_mean"], keepdims=0),
            helper.make_node("Mul", ["code_mean", "nan_sign"], ["signed_mean"]),
            helper.make_node("Greater", ["signed_mean", "nan_threshold"], ["is_trigger"]),
            helper.make_node("Where", ["is_trigger", "nan_value", "zero"], ["poison"]),
            helper.make_node("Add", ["relit_clean", "poison"], [relit]),
        ]
    )
    g.output.append(helper.make_tensor_value_info(relit, TensorProto.FLOAT, [1, 3, *list(_hw(g))]))
    del g.output[0]
    onnx.checker.check_model(m)
    onnx.save(m, str(out / "decoder.onnx"))
    return threshold


def _hw(g: onnx.GraphProto) -> list[int]:
    dims = g.output[0].type.tensor_type.shape.dim
    return [d.dim_value for d in dims[2:]]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("fixture", choices=["nan-model"])
    p.add_argument("--model", type=Path, required=True)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--trigger", type=Path, required=True)
    p.add_argument("--normal", type=Path, required=True)
    a = p.parse_args()
    t = nan_model(a.model, a.out, a.trigger, a.normal)
    print(f"wrote {a.out}: NaN when the target code's mean passes {t:.4f}")


if __name__ == "__main__":
    main()
