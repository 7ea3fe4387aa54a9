"""Export a trained LCFN network to the model contract: five ONNX stages and a manifest.

    python -m lsyd.export --run runs/default --data data --out models/default

The stages let the engine keep the de-lit features between frames and smooth
them, encode a target light once, skip light prediction when nobody needs it,
and relight with an unknown source light (see ``contract.py``). Each stage is
rewritten for ONNX Runtime's kernels (``optimise.py``, exact up to rounding).
Every stage and the chained result are checked against PyTorch on real held-out
frames; the export fails when ONNX Runtime differs by more than ``PARITY_TOLERANCE``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import numpy as np
import onnx
import torch
from onnx import numpy_helper
from torch import nn

from . import contract, data, model, optimise
from .runs import LIGHT_FIT_RECORD, load_network

PARITY_TOLERANCE = 1e-4
OPSET = 17


class LightEncoderStage(nn.Module):
    def __init__(self, net: model.LcfnNet):
        super().__init__()
        self.net = net

    def forward(self, light):
        return self.net.light_encoder(light)


class EncoderStage(nn.Module):
    def __init__(self, net: model.LcfnNet):
        super().__init__()
        self.net = net

    def forward(self, image):
        stem, feats = self.net.encode(image)
        return (stem, *feats)


class LightDecoderStage(nn.Module):
    def __init__(self, net: model.LcfnNet):
        super().__init__()
        self.net = net

    def forward(self, e2, e4, e6):
        return self.net.light_decoder(e2, e4, e6)


class DelightStage(nn.Module):
    def __init__(self, net: model.LcfnNet):
        super().__init__()
        self.net = net

    def forward(self, e1, e2, e3, e4, e5, e6, e7, source_code):
        return tuple(self.net.delit([e1, e2, e3, e4, e5, e6, e7], source_code))


class DecoderStage(nn.Module):
    def __init__(self, net: model.LcfnNet):
        super().__init__()
        self.net = net

    def forward(self, f1, f2, f3, f4, f5, f6, f7, stem, target_code):
        relit = self.net.decode(stem, [f1, f2, f3, f4, f5, f6, f7], target_code)
        # The contract's output range; the clamp is part of the graph.
        return relit.clamp(0.0, 1.0)


def stage_modules(net: model.LcfnNet) -> dict[str, nn.Module]:
    return {
        "light_encoder": LightEncoderStage(net),
        "encoder": EncoderStage(net),
        "light_decoder": LightDecoderStage(net),
        "delight": DelightStage(net),
        "decoder": DecoderStage(net),
    }


def check_exportable(cfg: model.NetConfig) -> None:
    if cfg.arch != "lcfn" or not cfg.delight or not cfg.light_prediction:
        raise SystemExit(
            f"only the full LCFN network fits the model contract; this run is {cfg} "
            "(baselines and ablations are evaluated in Python only)"
        )


def reference_run(
    net: model.LcfnNet, image: torch.Tensor, src: torch.Tensor, tgt: torch.Tensor
) -> dict[str, np.ndarray]:
    """Every contract tensor for one frame, computed by PyTorch."""
    with torch.no_grad():
        stem, e = net.encode(image)
        out = {
            "image": image,
            "light": src,
            "target_light": tgt,
            "stem": stem,
            **{f"e{i + 1}": t for i, t in enumerate(e)},
        }
        out["predicted_light"] = net.predict_light(e)
        out["source_code"] = net.light_encoder(src)
        out["code"] = out["source_code"]  # the light encoder stage's output, for the source light
        out["target_code"] = net.light_encoder(tgt)
        f = net.delit(e, out["source_code"])
        out.update({f"f{i + 1}": t for i, t in enumerate(f)})
        out["relit"] = net.decode(stem, f, out["target_code"]).clamp(0.0, 1.0)
    return {k: v.numpy() for k, v in out.items()}


def export(run: Path, data_root: Path, out: Path) -> dict:
    net, cfg = load_network(run)
    check_exportable(cfg.net)
    held = data.Heldout.load(data_root / "heldout")
    image = data.to_tensor(data.area_resize(held.images[0, 0], cfg.net.resolution))[None]
    src = torch.from_numpy(held.lights[0])[None]
    tgt = torch.from_numpy(held.lights[4])[None]
    return {"config": cfg, "parity": export_network(net, cfg.net, image, src, tgt, out)}


def export_network(
    net: model.LcfnNet, cfg: model.NetConfig, image: torch.Tensor, src: torch.Tensor, tgt: torch.Tensor, out: Path
) -> dict[str, float]:
    """Writes the network's stages to ``out``, traced on one real frame (``image`` [1,3,R,R]
    lit by ``src``, relit to ``tgt``), and returns their parity with PyTorch (raises above
    ``PARITY_TOLERANCE``). The manifest is the caller's."""
    check_exportable(cfg)
    out.mkdir(parents=True, exist_ok=True)
    specs = contract.stage_specs(cfg.resolution, cfg.widths)
    ref = reference_run(net, image, src, tgt)
    write_stages(net, specs, out, ref)
    return parity(out, specs, ref)


def write_stages(net: model.LcfnNet, specs: dict, out: Path, ref: dict[str, np.ndarray], rewrite: bool = True) -> None:
    """The network's stages that ``specs`` names (all five, or fewer to replace some of a
    model's) as ONNX files in ``out``, traced on ``reference_run``'s tensors, and unless
    ``rewrite`` is off rewritten by ``optimise``."""
    modules = stage_modules(net)
    for name, spec in specs.items():
        module = modules[name]
        inputs = tuple(torch.from_numpy(ref[t["name"]]) for t in spec["inputs"])
        torch.onnx.export(
            module,
            inputs,
            str(out / spec["file"]),
            input_names=[t["name"] for t in spec["inputs"]],
            output_names=[t["name"] for t in spec["outputs"]],
            opset_version=OPSET,
            dynamo=False,
        )
    if rewrite:
        optimise.optimise_folder(out)


def network_from_model(folder: Path) -> model.LcfnNet:
    """The PyTorch network of an exported model folder, from its stages' weights: the ONNX
    initializers keep the parameters' names (``net.<name>``), also where ``optimise`` changed a
    convolution's layout (``optimise.original_parameter``). Lets the benchmark time PyTorch on
    the very network it times in ONNX Runtime, without the run."""
    m = contract.read(folder / "model.json")
    initializers = [
        t for stage in contract.STAGES for t in onnx.load(folder / contract.stage_file(stage)).graph.initializer
    ]
    # The manifest does not say whether the decoder draws a light field; its weights do.
    light_field = any(t.name.startswith("net.decoder.light_field.") for t in initializers)
    width = m["widths"][1] / model.PAPER_WIDTHS[1]
    net = model.build(model.NetConfig(resolution=m["resolution"], width=width, light_field=light_field))
    params = net.state_dict()
    state = {}
    for t in initializers:
        name = t.name.removeprefix("net.")
        if name not in params:
            continue
        value, shape = numpy_helper.to_array(t), tuple(params[name].shape)
        if value.shape != shape:
            value = optimise.original_parameter(value, shape)
        state[name] = torch.from_numpy(value.copy())
    net.load_state_dict(state)  # strict: every parameter is in the stages
    return net.eval()


def parity(folder: Path, specs: dict, ref: dict[str, np.ndarray]) -> dict[str, float]:
    """Max abs difference of each stage's outputs (given PyTorch's inputs) and of the
    whole chain run in ONNX Runtime alone; raises when over the tolerance."""
    chain = contract.StageChain(folder)
    diffs = {}
    for name, spec in specs.items():
        feed = {t["name"]: ref[t["name"]] for t in spec["inputs"]}
        outs = chain.sessions[name].run([t["name"] for t in spec["outputs"]], feed)
        diffs[name] = max(float(np.abs(o - ref[t["name"]]).max()) for o, t in zip(outs, spec["outputs"]))
    # The chain: ONNX Runtime's own intermediate tensors feed the next stage.
    relit = chain.relight(ref["image"], ref["light"], chain.light_code(ref["target_light"]))
    diffs["chain"] = float(np.abs(relit - ref["relit"]).max())
    worst = max(diffs.values())
    if worst > PARITY_TOLERANCE:
        raise SystemExit(f"ONNX Runtime differs from PyTorch by {worst:.2e} > {PARITY_TOLERANCE:.0e}: {diffs}")
    return diffs


def training_data(run: Path, data_root: Path) -> str:
    """One line on what the run trained on, from its pairing record and the captures' metadata."""
    sessions = json.loads((run / "pairing.json").read_text())["sessions"] if (run / "pairing.json").exists() else []
    metas = [json.loads(p.read_text()) for p in sorted((data_root / "captures").glob("*/meta.json"))]
    frames = sum(m.get("frames", 0) for m in metas)
    subjects = sorted({m["spec"]["subject_seed"] for m in metas if "spec" in m})
    pairs = sum(s["pairs"] for s in sessions)
    return (
        f"{len(metas)} capture sessions ({frames} frames) of subject seed(s) {subjects}; "
        f"{pairs} training pairs by facial keypoints"
    )


def pairing_summary(run: Path) -> dict | None:
    """The run's training pairs from its pairing record (``lsyd.train`` writes it): the rule's
    threshold, the pairs, and the share of them the simulator's truth confirms (``precision``)."""
    path = run / "pairing.json"
    if not path.exists():
        return None
    record = json.loads(path.read_text())
    sessions = record["sessions"]
    pairs = sum(x["pairs"] for x in sessions)
    return {
        "max_keypoint_distance": record["rule"]["max_keypoint_distance"],
        "pairs": pairs,
        "precision": sum(x["pairs"] * x["precision"] for x in sessions) / max(pairs, 1),
    }


def machine_record(run: Path) -> list[dict]:
    """Which machine trained which steps (``lsyd.train`` writes it)."""
    path = run / "machine.json"
    return json.loads(path.read_text()) if path.exists() else []


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--run", type=Path, required=True)
    p.add_argument("--data", type=Path, default=Path("data"))
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--name", default=None, help="model name in the manifest (default: the folder name)")
    p.add_argument("--metrics", type=Path, default=None, help="metrics JSON to record in the manifest")
    a = p.parse_args()
    result = export(a.run, a.data, a.out)
    cfg = result["config"]
    training = {
        "run": a.run.name,
        "arch": cfg.net.arch,
        "steps": cfg.steps,
        "batch": cfg.batch,
        "lr": cfg.lr,
        "seed": cfg.seed,
        "pairs": cfg.pairs,
        "losses": dataclasses.asdict(cfg.weights),
        "data": training_data(a.run, a.data),
        "pairing": pairing_summary(a.run),
        "machine": machine_record(a.run),
    }
    fitted = a.run / LIGHT_FIT_RECORD
    if fitted.exists():
        training["light_refit"] = json.loads(fitted.read_text())
    metrics = json.loads(a.metrics.read_text()) if a.metrics else {}
    m = contract.manifest(a.name or a.out.name, cfg.net.resolution, cfg.net.widths, "fp32", training, metrics)
    m["parity"] = result["parity"]
    contract.write(a.out / "model.json", m)
    print(f"exported {a.out}: parity max abs diff {max(result['parity'].values()):.2e}")


if __name__ == "__main__":
    main()
