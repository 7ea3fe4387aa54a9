"""A training run's folder, as ``lsyd.train`` writes it and export and evaluation read it:
the configuration it was trained with (``config.json``: ``TrainConfig``, with the loss
weights ``LossWeights``), its trained network (``checkpoint.pt``), and ``hardware``, the
name of a machine as run records and model cards give it.
"""

from __future__ import annotations

import dataclasses
import json
import os
import platform
from pathlib import Path

import torch

from . import model, pairing


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
    # follow the true one (README, "Beyond the paper").
    monitor_colour: float = 0.0


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
        )


def read_config(run: Path) -> TrainConfig:
    """The configuration a run folder was trained with."""
    return TrainConfig.from_json(json.loads((run / "config.json").read_text()))


def load_network(run: Path, device: str = "cpu") -> tuple[torch.nn.Module, TrainConfig]:
    """The trained network of a run folder, in evaluation mode."""
    cfg = read_config(run)
    net = model.build(cfg.net)
    state = torch.load(run / "checkpoint.pt", map_location=device, weights_only=False)
    net.load_state_dict(state["net"])
    return net.eval(), cfg


def hardware(device: torch.device) -> str:
    """The GPU's name, or the CPU's model and core count."""
    if device.type == "cuda":
        return torch.cuda.get_device_name(device)
    info = Path("/proc/cpuinfo")
    lines = info.read_text().splitlines() if info.exists() else []
    names = [ln.split(":", 1)[1].strip() for ln in lines if ln.startswith("model name")]
    return f"{names[0] if names else platform.machine()}, {os.cpu_count()} cores"
