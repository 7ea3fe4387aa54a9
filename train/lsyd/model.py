"""Relighting networks: the paper's LCFN U-Net and the two baselines.

All networks share one U-Net encoder (a 7x7 stem, then two 3x3 convolutions
per level, the first of each level strided) so that comparisons isolate what
the papers differ in:

- ``LcfnNet`` (Choi et al. 2024): the seven encoder features are de-lit by
  AdaIN conditioned on the source light's code (LCFN) before they skip to the
  decoder, which re-lights with AdaIN conditioned on the target light's code.
  A light decoder predicts the source monitor image from pooled encoder
  features fused by learned confidence.
- ``SunNet`` (Sun et al. 2019): a light bottleneck. The source light is
  predicted at the bottleneck by confidence-weighted fusion, and the target
  light's code is joined to the bottleneck features; skips are plain.
- ``SenguptaNet`` (Sengupta et al. 2021): source and target light codes are
  given at the bottleneck; skips are plain.

Widths follow the paper's figure scaled by ``width``: 32, 64, 128, 256, 512
at width 1.0. Images are sRGB in [0, 1], NCHW. Lights are linear RGB in
[0, 1], 3 x 16 x 32 (see ``contract.py``).
"""

from __future__ import annotations

import dataclasses

import torch
import torch.nn.functional as F
from torch import nn

from . import contract

PAPER_WIDTHS = (32, 64, 128, 256, 512)


@dataclasses.dataclass(frozen=True)
class NetConfig:
    """What a network is: architecture, size and ablation switches."""

    arch: str = "lcfn"  # "lcfn", "sun" or "sengupta"
    resolution: int = 128
    width: float = 0.25
    code_dim: int = contract.CODE_DIM
    delight: bool = True  # LCFN de-lighting of the skips (lcfn only)
    light_prediction: bool = True  # light decoder and monitor loss (lcfn only)
    light_field: bool = False  # a map of where the target light falls, drawn into the decoder (lcfn only)

    @property
    def widths(self) -> tuple[int, ...]:
        return tuple(max(4, round(c * self.width)) for c in PAPER_WIDTHS)


def act(x: torch.Tensor) -> torch.Tensor:
    return F.leaky_relu(x, 0.2)


class LightEncoder(nn.Module):
    """MLP from a monitor light image to a code (shared by source and target)."""

    def __init__(self, code_dim: int):
        super().__init__()
        n = 3 * contract.LIGHT_ROWS * contract.LIGHT_COLS
        self.fc1 = nn.Linear(n, 256)
        self.fc2 = nn.Linear(256, 256)
        self.fc3 = nn.Linear(256, code_dim)

    def forward(self, light: torch.Tensor) -> torch.Tensor:
        # A square root evens out the light's dynamic range, as gamma does for images.
        x = torch.sqrt(light.clamp(min=0.0) + 1e-6).flatten(1)
        return self.fc3(act(self.fc2(act(self.fc1(x)))))


class AdaIN(nn.Module):
    """3x3 convolution, instance normalisation, then scale and shift from a light code."""

    def __init__(self, cin: int, cout: int, code_dim: int):
        super().__init__()
        self.conv = nn.Conv2d(cin, cout, 3, padding=1)
        self.affine = nn.Linear(code_dim, 2 * cout)
        nn.init.zeros_(self.affine.weight)
        nn.init.zeros_(self.affine.bias)

    def forward(self, x: torch.Tensor, code: torch.Tensor) -> torch.Tensor:
        h = self.conv(x)
        # eps keeps flat regions (zero variance) finite; see the stability tests.
        h = F.instance_norm(h, eps=1e-5)
        gamma, beta = self.affine(code).chunk(2, dim=1)
        return act(h * (1.0 + gamma[:, :, None, None]) + beta[:, :, None, None])


class Encoder(nn.Module):
    """Stem (7x7 conv concatenated with the image) and seven 3x3 features e1..e7."""

    def __init__(self, w: tuple[int, ...]):
        super().__init__()
        c0, c1, c2, c3, c4 = w
        self.stem = nn.Conv2d(3, c0 - 3, 7, padding=3)
        chans = [(c0, c1, 2), (c1, c1, 1), (c1, c2, 2), (c2, c2, 1), (c2, c3, 2), (c3, c3, 1), (c3, c4, 2)]
        self.convs = nn.ModuleList(nn.Conv2d(a, b, 3, stride=s, padding=1) for a, b, s in chans)

    def forward(self, image: torch.Tensor) -> tuple[torch.Tensor, list[torch.Tensor]]:
        stem = torch.cat([act(self.stem(image)), image], dim=1)
        feats = []
        x = stem
        for conv in self.convs:
            x = act(conv(x))
            feats.append(x)
        return stem, feats


class ConfidenceLight(nn.Module):
    """Predicts a light image at every location of a feature map and fuses the
    predictions by learned positive confidence (Sun et al. 2019's light bottleneck)."""

    def __init__(self, cin: int, hidden: int):
        super().__init__()
        n = 3 * contract.LIGHT_ROWS * contract.LIGHT_COLS
        self.hidden = nn.Conv2d(cin, hidden, 1)
        self.light = nn.Conv2d(hidden, n, 1)
        self.confidence = nn.Conv2d(hidden, 1, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = act(self.hidden(x))
        light = torch.sigmoid(self.light(h))  # (B, 3*16*32, H, W), linear light in [0, 1]
        fused = (light.flatten(2) * self.weights(h)).sum(dim=2)
        return fused.view(-1, 3, contract.LIGHT_ROWS, contract.LIGHT_COLS)

    def weights(self, h: torch.Tensor) -> torch.Tensor:
        """(B, 1, H*W): each location's share of the fused light, positive, summing to 1."""
        return F.softmax(self.confidence(h).flatten(2), dim=2)

    def confidence_map(self, x: torch.Tensor) -> torch.Tensor:
        """(B, H, W): where in the picture the fused light is read, as ``forward`` weighs it."""
        return self.weights(act(self.hidden(x))).view(x.shape[0], *x.shape[-2:])


class LightDecoder(nn.Module):
    """The paper's light decoder: the second feature of levels 1-3 (e2, e4, e6),
    max-pooled to the bottleneck's size, stacked, and fused by confidence."""

    def __init__(self, w: tuple[int, ...]):
        super().__init__()
        _, c1, c2, c3, c4 = w
        self.fuse = ConfidenceLight(c1 + c2 + c3, max(64, c4))

    @staticmethod
    def pool(e2: torch.Tensor, e4: torch.Tensor, e6: torch.Tensor) -> torch.Tensor:
        """The three features max-pooled to the bottleneck's size and stacked: what ``fuse`` reads."""
        return torch.cat([F.max_pool2d(e2, 8), F.max_pool2d(e4, 4), F.max_pool2d(e6, 2)], dim=1)

    def forward(self, e2: torch.Tensor, e4: torch.Tensor, e6: torch.Tensor) -> torch.Tensor:
        return self.fuse(self.pool(e2, e4, e6))

    def confidence_map(self, e2: torch.Tensor, e4: torch.Tensor, e6: torch.Tensor) -> torch.Tensor:
        """(B, H, W) at the bottleneck's size: where in the crop the light is read."""
        return self.fuse.confidence_map(self.pool(e2, e4, e6))


class LightField(nn.Module):
    """Where the target light falls on the crop: a coarse map drawn from the light's code
    and added to the decoder's features at each re-light level.

    AdaIN scales and shifts a channel by the same amount everywhere in the picture, so
    through it alone a light's code says how bright and what colour the light is but
    hardly which side of the face it lights. The map says that directly, in the crop's
    coordinates (the crop rule puts the face at the same place in every crop), and the
    decoder's convolutions shape it by the face they see. Its outputs start at zero, so a
    trained network grows one without changing what it does."""

    GRID = 8
    MAPS = 8

    def __init__(self, code_dim: int, level_chans: tuple[int, ...]):
        super().__init__()
        self.draw = nn.Linear(code_dim, self.MAPS * self.GRID * self.GRID)
        self.inject = nn.ModuleList(nn.Conv2d(self.MAPS, c, 1) for c in level_chans)
        for conv in self.inject:
            nn.init.zeros_(conv.weight)
            nn.init.zeros_(conv.bias)

    def forward(self, code: torch.Tensor) -> torch.Tensor:
        return act(self.draw(code)).view(-1, self.MAPS, self.GRID, self.GRID)

    def at(self, level: int, field: torch.Tensor, like: torch.Tensor) -> torch.Tensor:
        """The field's contribution to re-light level ``level`` of size ``like``."""
        resized = F.interpolate(field, size=like.shape[-2:], mode="bilinear", align_corners=False)
        return self.inject[level](resized)


def up(x: torch.Tensor) -> torch.Tensor:
    return F.interpolate(x, scale_factor=2.0, mode="bilinear", align_corners=False)


class Decoder(nn.Module):
    """The figure's decoder: re-light blocks at each upsampling, 3x3 convs between,
    the two skips of each level concatenated in turn, then the stem and a 7x7 conv.

    With ``code_dim`` zero the re-light blocks are plain convolutions (baselines); with
    ``light_field`` a ``LightField`` adds where the light falls at each re-light block."""

    def __init__(self, w: tuple[int, ...], code_dim: int, light_field: bool = False):
        super().__init__()
        c0, c1, c2, c3, c4 = w

        def relight(cin: int, cout: int) -> nn.Module:
            return AdaIN(cin, cout, code_dim) if code_dim else nn.Conv2d(cin, cout, 3, padding=1)

        self.relight = nn.ModuleList([relight(c4, c3), relight(2 * c3, c2), relight(2 * c2, c1)])
        self.convs = nn.ModuleList(
            [
                nn.Conv2d(2 * c3, c3, 3, padding=1),
                nn.Conv2d(2 * c2, c2, 3, padding=1),
                nn.Conv2d(2 * c1, c1, 3, padding=1),
            ]
        )
        self.last = nn.Conv2d(2 * c1, c0, 3, padding=1)
        self.out = nn.Conv2d(2 * c0, 3, 7, padding=3)
        self.light_field = LightField(code_dim, (c3, c2, c1)) if light_field and code_dim else None

    def forward(self, stem: torch.Tensor, f: list[torch.Tensor], code: torch.Tensor | None) -> torch.Tensor:
        field = self.light_field(code) if self.light_field is not None and code is not None else None

        def rl(level: int, x: torch.Tensor) -> torch.Tensor:
            block = self.relight[level]
            x = block(x, code) if isinstance(block, AdaIN) else act(block(x))
            return x if field is None else x + self.light_field.at(level, field, x)

        x = up(rl(0, f[6]))  # bottleneck to level 3
        x = act(self.convs[0](torch.cat([f[5], x], 1)))
        x = up(rl(1, torch.cat([f[4], x], 1)))  # level 3 to 2
        x = act(self.convs[1](torch.cat([f[3], x], 1)))
        x = up(rl(2, torch.cat([f[2], x], 1)))  # level 2 to 1
        x = act(self.convs[2](torch.cat([f[1], x], 1)))
        x = up(act(self.last(torch.cat([f[0], x], 1))))  # level 1 to full size
        return self.out(torch.cat([stem, x], 1))


class LcfnNet(nn.Module):
    """The paper's network. ``forward`` returns (relit image, predicted source light).

    When ``source_light`` is None the predicted light stands in for it
    (unknown-source mode, paper section 4.2)."""

    def __init__(self, cfg: NetConfig):
        super().__init__()
        self.cfg = cfg
        w = cfg.widths
        self.encoder = Encoder(w)
        self.light_encoder = LightEncoder(cfg.code_dim)
        self.light_decoder = LightDecoder(w) if cfg.light_prediction else None
        skip_chans = [w[1], w[1], w[2], w[2], w[3], w[3], w[4]]
        if cfg.delight:
            self.delight = nn.ModuleList(AdaIN(c, c, cfg.code_dim) for c in skip_chans)
        else:
            self.delight = nn.ModuleList(nn.Conv2d(c, c, 3, padding=1) for c in skip_chans)
        self.decoder = Decoder(w, cfg.code_dim, cfg.light_field)

    def encode(self, image: torch.Tensor) -> tuple[torch.Tensor, list[torch.Tensor]]:
        return self.encoder(image)

    def predict_light(self, feats: list[torch.Tensor]) -> torch.Tensor:
        if self.light_decoder is None:
            raise RuntimeError("this network was built without light prediction")
        return self.light_decoder(feats[1], feats[3], feats[5])

    def delit(self, feats: list[torch.Tensor], source_code: torch.Tensor) -> list[torch.Tensor]:
        if self.cfg.delight:
            return [blk(e, source_code) for blk, e in zip(self.delight, feats)]
        return [act(blk(e)) for blk, e in zip(self.delight, feats)]

    def delit_image(self, image: torch.Tensor, light: torch.Tensor) -> list[torch.Tensor]:
        """The de-lit skip features of images whose source lights are given."""
        return self.delit(self.encode(image)[1], self.light_encoder(light))

    def decode(self, stem: torch.Tensor, f: list[torch.Tensor], target_code: torch.Tensor) -> torch.Tensor:
        return self.decoder(stem, f, target_code)

    def forward(
        self, image: torch.Tensor, source_light: torch.Tensor | None, target_light: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor | None]:
        stem, feats = self.encode(image)
        predicted = self.predict_light(feats) if self.light_decoder is not None else None
        source = source_light if source_light is not None else predicted
        if source is None:
            raise ValueError("no source light given and this network cannot predict one")
        f = self.delit(feats, self.light_encoder(source))
        return self.decode(stem, f, self.light_encoder(target_light)), predicted


class SunNet(nn.Module):
    """Sun et al. 2019: the light is a bottleneck. The source light is predicted from
    the bottleneck by confidence fusion; the target's code is joined to the bottleneck."""

    def __init__(self, cfg: NetConfig):
        super().__init__()
        self.cfg = cfg
        w = cfg.widths
        self.encoder = Encoder(w)
        self.light_encoder = LightEncoder(cfg.code_dim)
        self.bottleneck_light = ConfidenceLight(w[4], max(64, w[4]))
        self.inject = nn.Conv2d(w[4] + cfg.code_dim, w[4], 3, padding=1)
        self.decoder = Decoder(w, 0)

    def forward(self, image, source_light, target_light):
        stem, feats = self.encoder(image)
        predicted = self.bottleneck_light(feats[6])
        bottleneck = act(self.inject(with_codes(feats[6], self.light_encoder(target_light))))
        return self.decoder(stem, feats[:6] + [bottleneck], None), predicted


class SenguptaNet(nn.Module):
    """Sengupta et al. 2021: a U-Net given the source and target lights at the
    bottleneck, with plain skips."""

    def __init__(self, cfg: NetConfig):
        super().__init__()
        self.cfg = cfg
        w = cfg.widths
        self.encoder = Encoder(w)
        self.light_encoder = LightEncoder(cfg.code_dim)
        self.inject = nn.Conv2d(w[4] + 2 * cfg.code_dim, w[4], 3, padding=1)
        self.decoder = Decoder(w, 0)

    def forward(self, image, source_light, target_light):
        if source_light is None:
            raise ValueError("Sengupta et al. 2021 needs the source light")
        stem, feats = self.encoder(image)
        codes = torch.cat([self.light_encoder(source_light), self.light_encoder(target_light)], 1)
        bottleneck = act(self.inject(with_codes(feats[6], codes)))
        return self.decoder(stem, feats[:6] + [bottleneck], None), None


def with_codes(features: torch.Tensor, codes: torch.Tensor) -> torch.Tensor:
    """Light codes tiled over a feature map's positions and stacked onto its channels."""
    return torch.cat([features, codes[:, :, None, None].expand(-1, -1, *features.shape[2:])], 1)


def build(cfg: NetConfig) -> nn.Module:
    if cfg.resolution % 16:
        raise ValueError(f"resolution must be a multiple of 16, got {cfg.resolution}")
    nets = {"lcfn": LcfnNet, "sun": SunNet, "sengupta": SenguptaNet}
    if cfg.arch not in nets:
        raise ValueError(f"unknown architecture {cfg.arch!r}; one of {sorted(nets)}")
    return nets[cfg.arch](cfg)


def frame_flops(net: LcfnNet, resolution: int) -> int:
    """FLOPs (multiply-accumulates x 2 of convolutions and linear layers) of one frame as
    the engine runs it with the source light known: the encoder, one light code (the
    target's is computed once), de-lighting and the decoder; no light prediction."""
    total = 0

    def hook(mod, inp, out):
        nonlocal total
        if isinstance(mod, nn.Conv2d):
            k = mod.kernel_size[0] * mod.kernel_size[1] * (mod.in_channels // mod.groups)
            total += 2 * k * out.numel()
        elif isinstance(mod, nn.Linear):
            total += 2 * mod.in_features * out.numel()

    light = torch.zeros(1, 3, contract.LIGHT_ROWS, contract.LIGHT_COLS)
    with torch.no_grad():
        target_code = net.light_encoder(light)
        handles = [m.register_forward_hook(hook) for m in net.modules() if isinstance(m, (nn.Conv2d, nn.Linear))]
        stem, feats = net.encode(torch.zeros(1, 3, resolution, resolution))
        net.decode(stem, net.delit(feats, net.light_encoder(light)), target_code)
    for h in handles:
        h.remove()
    return total
