"""A tiny personalised classifier: is the person in the face region at all?

    python -m lsyd.presence --data data --model models/default

The element skips the relighting network when nobody is there (the user walked
away) and passes the frame through. Positives are the capture frames; negatives
the simulator's frames of the empty desk (``deskstage absent``). Held-out scores
use frames neither was trained on: the held-out set (present) and the
``walkaway`` recording's absent stretch. The classifier is exported as the model
contract's optional ``presence`` stage: ``image`` [1,3,64,64] sRGB in [0,1] ->
``presence`` [1,1], a logit (positive: someone is there).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from . import contract, data

SIZE = 64


class Presence(nn.Module):
    def __init__(self):
        super().__init__()
        self.convs = nn.Sequential(
            nn.Conv2d(3, 16, 3, 2, 1),
            nn.LeakyReLU(0.2),
            nn.Conv2d(16, 32, 3, 2, 1),
            nn.LeakyReLU(0.2),
            nn.Conv2d(32, 64, 3, 2, 1),
            nn.LeakyReLU(0.2),
            nn.Conv2d(64, 64, 3, 2, 1),
            nn.LeakyReLU(0.2),
        )
        self.head = nn.Linear(64, 1)

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        return self.head(self.convs(image).mean(dim=(2, 3)))


def small(frames: np.ndarray) -> torch.Tensor:
    """(N, H, W, 3) uint8 -> (N, 3, 64, 64) in [0, 1]."""
    return data.to_tensor(data.resize_frames(frames, SIZE))


def load(root: Path) -> tuple[torch.Tensor, torch.Tensor]:
    present = [np.load(d / "face.npy", mmap_mode="r")[::4] for d in data.capture_dirs(root / "captures")]
    absent = np.load(root / "absent" / "face.npy")
    x = torch.cat([small(np.concatenate(present)), small(absent)])
    y = torch.cat([torch.ones(sum(len(p) for p in present)), torch.zeros(len(absent))])
    return x, y


def heldout(root: Path) -> tuple[torch.Tensor, torch.Tensor]:
    """Present: the held-out set. Absent: the walkaway recording's empty stretch."""
    held = np.load(root / "heldout" / "images.npy")
    present = small(held.reshape(-1, *held.shape[2:]))
    meta = json.loads((root / "recordings" / "walkaway" / "meta.json").read_text())
    start, end = meta["spec"]["away"]
    fps = meta["spec"]["fps"]
    frames, _ = data.read_y4m(root / "recordings" / "walkaway" / "face.y4m")
    crops = data.centre_square(frames)
    away = crops[int(np.ceil(start * fps)) : int(end * fps)]
    there = np.concatenate([crops[: int(start * fps)], crops[int(np.ceil(end * fps)) :]])
    x = torch.cat([present, small(there), small(away)])
    y = torch.cat([torch.ones(len(present) + len(there)), torch.zeros(len(away))])
    return x, y


def train(x: torch.Tensor, y: torch.Tensor, steps: int, seed: int) -> Presence:
    torch.manual_seed(seed)
    g = torch.Generator().manual_seed(seed)
    net = Presence()
    opt = torch.optim.Adam(net.parameters(), 2e-3)
    pos, neg = torch.nonzero(y == 1)[:, 0], torch.nonzero(y == 0)[:, 0]
    for _ in range(steps):
        # Balanced batches: the empty desk is rarer than the person in the data.
        idx = torch.cat(
            [pos[torch.randint(len(pos), (32,), generator=g)], neg[torch.randint(len(neg), (32,), generator=g)]]
        )
        xb = x[idx]
        # Any exposure the monitor and room give, and either side of the screen.
        xb = (xb * torch.empty(len(xb), 1, 1, 1).uniform_(0.3, 1.6, generator=g)).clamp(0, 1)
        flip = torch.rand(len(xb), generator=g) < 0.5
        xb[flip] = xb[flip].flip(-1)
        loss = F.binary_cross_entropy_with_logits(net(xb)[:, 0], y[idx])
        opt.zero_grad()
        loss.backward()
        opt.step()
    return net.eval()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", type=Path, default=Path("data"))
    p.add_argument("--model", type=Path, required=True, help="model folder to add the presence stage to")
    p.add_argument("--steps", type=int, default=1500)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args()

    x, y = load(a.data)
    net = train(x, y, a.steps, a.seed)
    hx, hy = heldout(a.data)
    with torch.no_grad():
        logits = net(hx)[:, 0]
    accuracy = float(((logits > 0).float() == hy).float().mean())
    missed = int(((logits <= 0) & (hy == 1)).sum())
    false_alarm = int(((logits > 0) & (hy == 0)).sum())

    path = a.model / "presence.onnx"
    example = torch.zeros(1, 3, SIZE, SIZE)
    torch.onnx.export(net, (example,), str(path), input_names=["image"], output_names=["presence"], dynamo=False)
    sess = contract.open_session(path)
    onnx_logits = np.array([sess.run(None, {"image": hx.numpy()[i : i + 1]})[0][0, 0] for i in range(8)])
    parity = float(np.abs(onnx_logits - logits[:8].numpy()).max())
    if parity > 1e-4:
        raise SystemExit(f"presence.onnx differs from PyTorch by {parity:.2e}")

    m = json.loads((a.model / "model.json").read_text())
    m["stages"]["presence"] = {
        "file": "presence.onnx",
        "inputs": [{"name": "image", "shape": [1, 3, SIZE, SIZE], "dtype": "float32"}],
        "outputs": [{"name": "presence", "shape": [1, 1], "dtype": "float32"}],
    }
    m.setdefault("metrics", {})["presence"] = {
        "command": f"python -m lsyd.presence --data {a.data} --model {a.model}",
        "heldout_frames": len(hy),
        "accuracy": accuracy,
        "missed_person": missed,
        "false_person": false_alarm,
    }
    m.setdefault("parity", {})["presence"] = parity
    contract.write(a.model / "model.json", m)
    print(f"presence: held-out accuracy {accuracy:.4f} ({missed} missed, {false_alarm} false) -> {path}")


if __name__ == "__main__":
    main()
