"""A training run's folder, as ``lsyd.train`` writes it and export and evaluation read it:
the configuration it was trained with (``config.json``: ``TrainConfig``, with the loss
weights ``LossWeights``), its trained network (``checkpoint.pt``), and ``hardware``, the
name of a machine as run records and model cards give it. A run whose light decoder was fitted
after training (``lsyd.light_refit --run``) also holds that fit's record (``LIGHT_FIT_RECORD``),
which the export carries into the model's manifest.

A saved network (``network.pt``) is a trained generator on its own, what fine-tuning starts
from (``lsyd.train --init``, ``lsydrelight train --from``). It is a ``torch.save`` dict of
plain types and tensors (``torch.load(..., weights_only=True)`` reads it):

- ``format``: ``"lsydrelight-network"``, ``version``: ``NETWORK_VERSION`` (1);
- ``net``: the ``model.NetConfig`` as a dict (arch, resolution, width, code_dim, delight,
  light_prediction): what ``model.build`` needs to make the network the weights fit;
- ``state_dict``: the generator's parameters and buffers (no discriminator, no optimiser);
- ``source``: free-form provenance (the run, its steps, its loss weights).

    python -m lsyd.runs save-network --run runs/starter --out models/starter/network.pt
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
from pathlib import Path

import torch

from . import model, pairing

LIGHT_FIT_RECORD = "light_fit.json"


@dataclasses.dataclass(frozen=True)
class LossWeights:
    """The lambdas of paper eqs. 3-6 (the paper does not give its values)."""

    l1: float = 1.0  # lambda_L1: L1 between relit and target image
    perceptual: float = 1.0  # lambda_P: offline perceptual stand-in (losses.perceptual)
    cycle: float = 0.5  # lambda_C: relighting the result back to the source light
    adversarial: float = 0.02  # lambda_D: LSGAN generator term
    monitor: float = 0.5  # lambda_G^M: weight of the monitor (illumination) loss
    unknown_source: float = 0.2  # share of steps that de-light with the predicted source light
    # Not in the paper: pulls the de-lit features of a pair's two images (same face, two
    # lights, each de-lit with its own light) together (losses.standardised_distance).
    # The paper's losses alone leave them as far apart as the raw features.
    delit_consistency: float = 0.0
    # Not in the paper: L1 between the predicted and true screens' mean colours, inside the
    # monitor loss. With the per-pixel terms alone the predicted screen's colour does not
    # follow the true one (docs/accuracy.md, "Beyond the paper").
    monitor_colour: float = 0.0
    # Not in the paper: L1 between the smooth log gains of relit and target over the source
    # (losses.change_l1), the part of the output the element pastes. With the image losses
    # alone a key from the left and one from the right change a face nearly alike.
    change: float = 0.0
    # Not in the paper: the same L1 on the changes averaged over 8 px cells
    # (losses.coarse_change_l1): which side of the face a light brightens.
    coarse_change: float = 0.0


def share(text: str) -> float:
    """A command line's share (``--rehearsal-share``): a number from 0 to 1."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number; give a share from 0 to 1") from None
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"{value:g} is not a share; give a number from 0 to 1 (0.1: a tenth)")
    return value


def jitter(text: str) -> float:
    """A command line's box jitter (``--box-jitter``): from 0 to 0.5; a zoom of 1 - 0.5 or less
    would show the picture's edge continued over most of the crop."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number; give a jitter from 0 to 0.5") from None
    if not 0.0 <= value < 0.5:
        raise argparse.ArgumentTypeError(f"{value:g} is out of range; give a number from 0 to under 0.5 (0.1: 10%)")
    return value


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """How a run trains: the network, the schedule, the pairs and the loss weights."""

    net: model.NetConfig
    steps: int = 6000
    batch: int = 8
    lr: float = 2e-4
    seed: int = 0
    pairs: str = "keypoints"  # "keypoints", "exact" or "both"
    pairing: pairing.PairingRule = pairing.PairingRule()
    weights: LossWeights = LossWeights()
    # A saved network (``network.pt``) the generator starts from instead of random weights.
    init: str | None = None
    # The decay of an exponential moving average of the generator's weights, kept beside them;
    # the run's trained network is then the average (``load_network``). 0: the last weights.
    weight_average: float = 0.0
    # The share of the batches' pairs drawn from rehearsal sessions (``data.REHEARSAL_PREFIX``)
    # whatever their number of pairs; None: every pair alike.
    rehearsal_share: float | None = None
    # How far the face detector's box may err: each pair is zoomed about the face by a factor
    # within 1 +- this and shifted by up to half of it in face heights, the same for its
    # source and target (``data.jitter_crops``), so the network meets faces a little larger,
    # smaller or off their place in the crop, as a real detector's box puts them. 0: none.
    box_jitter: float = 0.0
    # Each pair shown mirrored left to right half of the time, its face and both its lights
    # alike (``data.mirror_pairs``): a person under a screen is as likely as their mirror
    # image under the mirrored screen. Tried for the starter, not kept (docs/training.md).
    mirror: bool = False

    def to_json(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, d: dict) -> TrainConfig:
        return cls(
            net=model.NetConfig(**d["net"]),
            steps=d["steps"],
            batch=d["batch"],
            lr=d["lr"],
            seed=d["seed"],
            pairs=d["pairs"],
            pairing=pairing.PairingRule(**d["pairing"]),
            weights=LossWeights(**d["weights"]),
            init=d.get("init"),
            weight_average=d.get("weight_average", 0.0),
            rehearsal_share=d.get("rehearsal_share"),
            box_jitter=d.get("box_jitter", 0.0),
            mirror=d.get("mirror", False),
        )


def read_config(run: Path) -> TrainConfig:
    """The configuration a run folder was trained with."""
    return TrainConfig.from_json(json.loads((run / "config.json").read_text()))


def load_network(run: Path, device: str = "cpu", last_weights: bool = False) -> tuple[torch.nn.Module, TrainConfig]:
    """The trained network of a run folder, in evaluation mode: the average of its weights
    where it kept one (``TrainConfig.weight_average``) unless ``last_weights``, else its last
    weights (the same steps without the average: the average's control)."""
    cfg = read_config(run)
    net = model.build(cfg.net)
    state = torch.load(run / "checkpoint.pt", map_location=device, weights_only=False)
    averaged = cfg.weight_average > 0 and not last_weights
    net.load_state_dict(averaged_weights(state["average"]) if averaged else state["net"])
    return net.eval(), cfg


def averaged_weights(average: dict) -> dict:
    """The network's weights out of a ``torch.optim.swa_utils.AveragedModel``'s state."""
    return {k.removeprefix("module."): v for k, v in average.items() if k != "n_averaged"}


def hardware(device: torch.device) -> str:
    """The GPU's name, or the CPU's model and core count."""
    if device.type == "cuda":
        return torch.cuda.get_device_name(device)
    info = Path("/proc/cpuinfo")
    lines = info.read_text().splitlines() if info.exists() else []
    names = [ln.split(":", 1)[1].strip() for ln in lines if ln.startswith("model name")]
    return f"{names[0] if names else platform.machine()}, {os.cpu_count()} cores"


NETWORK_FORMAT = "lsydrelight-network"
NETWORK_VERSION = 1


def save_network(net: torch.nn.Module, cfg: model.NetConfig, path: Path, source: dict) -> None:
    """Writes ``net`` and the configuration it needs as a saved network (the module's doc)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    saved = {
        "format": NETWORK_FORMAT,
        "version": NETWORK_VERSION,
        "net": dataclasses.asdict(cfg),
        "state_dict": {k: v.detach().cpu() for k, v in net.state_dict().items()},
        "source": source,
    }
    tmp = path.with_name(path.name + ".tmp")
    torch.save(saved, tmp)
    os.replace(tmp, path)


def read_network(path: Path, expected: model.NetConfig | None = None) -> tuple[model.NetConfig, dict]:
    """A saved network's configuration and weights. Raises ``ValueError`` naming what is wrong:
    not a saved network, an unknown version, or (with ``expected``) a configuration that differs."""
    if not path.is_file():
        raise ValueError(f"{path}: no such saved network (network.pt)")
    try:
        saved = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # torch raises many kinds for a file that is not its own
        raise ValueError(f"{path}: not a saved network: {e}") from e
    if not isinstance(saved, dict) or saved.get("format") != NETWORK_FORMAT:
        raise ValueError(f"{path}: not a saved network (no format {NETWORK_FORMAT!r})")
    if saved.get("version") != NETWORK_VERSION:
        raise ValueError(
            f"{path}: saved network version {saved.get('version')}, this trainer reads version {NETWORK_VERSION}"
        )
    cfg = model.NetConfig(**saved["net"])
    if expected is not None and cfg != expected:
        diff = {k: (v, getattr(expected, k)) for k, v in dataclasses.asdict(cfg).items() if getattr(expected, k) != v}
        raise ValueError(
            f"{path}: the saved network's configuration differs from the one asked for "
            + ", ".join(f"{k}: saved {a!r}, asked {b!r}" for k, (a, b) in diff.items())
        )
    net = model.build(cfg)
    try:
        net.load_state_dict(saved["state_dict"])
    except RuntimeError as e:
        raise ValueError(f"{path}: the weights do not fit the network {cfg}: {e}") from e
    return cfg, saved["state_dict"]


def initial_weights(path: Path, expected: model.NetConfig) -> dict:
    """The weights of the saved network at ``path`` for a network configured as ``expected``:
    its own, or with a light field grown onto it (``model.LightField``), whose layers start at
    zero so that the grown network relights as the saved one did. Raises ``ValueError`` as
    ``read_network`` does for any other difference."""
    try:
        return read_network(path, expected=expected)[1]
    except ValueError:
        cfg, state = read_network(path)
        if cfg.light_field or dataclasses.replace(cfg, light_field=True) != expected:
            raise
    grown = model.build(expected).state_dict()
    grown.update(state)
    return grown


def load_saved_network(path: Path) -> tuple[torch.nn.Module, model.NetConfig]:
    """A saved network, built and in evaluation mode."""
    cfg, state = read_network(path)
    net = model.build(cfg)
    net.load_state_dict(state)
    return net.eval(), cfg


def save_run_network(run: Path, out: Path) -> model.NetConfig:
    """The trained network of a run folder as a saved network."""
    net, cfg = load_network(run)
    steps = torch.load(run / "checkpoint.pt", map_location="cpu", weights_only=False)["step"]
    source = {"run": run.name, "steps": steps, "of_steps": cfg.steps, "losses": dataclasses.asdict(cfg.weights)}
    save_network(net, cfg.net, out, source)
    return cfg.net


def main() -> None:
    p = argparse.ArgumentParser(description="Run folders and saved networks.")
    sub = p.add_subparsers(dest="command", required=True)
    save = sub.add_parser("save-network", help="write a run's trained network as network.pt")
    save.add_argument("--run", type=Path, required=True, help="run folder written by lsyd.train")
    save.add_argument("--out", type=Path, required=True, help="the network.pt to write")
    a = p.parse_args()
    cfg = save_run_network(a.run, a.out)
    print(f"saved {a.out}: {cfg}")


if __name__ == "__main__":
    main()
