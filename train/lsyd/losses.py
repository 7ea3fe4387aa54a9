"""Training losses (paper section 3.4) and the substitutes used offline.

The paper's perceptual loss uses an ImageNet network (LPIPS/VGG), whose
weights cannot be downloaded here. Its stand-in, ``perceptual``, compares
images at several scales: an L1 on a Laplacian pyramid (edges and texture
at each scale) plus a structural term (1 - SSIM). For the 16 x 32 light
images the stand-in is L1 on their gradients.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn


def _gauss_kernel(size: int = 11, sigma: float = 1.5) -> torch.Tensor:
    x = torch.arange(size, dtype=torch.float32) - (size - 1) / 2
    g = torch.exp(-(x**2) / (2 * sigma**2))
    g = g / g.sum()
    return (g[:, None] * g[None, :])[None, None]


def ssim_maps(a: torch.Tensor, b: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """SSIM's luminance and contrast-structure maps of images in [0, 1]
    (Wang et al. 2004, 11x11 Gaussian window of sigma 1.5)."""
    c = a.shape[1]
    k = _gauss_kernel().to(a).expand(c, 1, -1, -1)

    def blur(x):
        return F.conv2d(x, k, groups=c)

    mu_a, mu_b = blur(a), blur(b)
    var_a = blur(a * a) - mu_a**2
    var_b = blur(b * b) - mu_b**2
    cov = blur(a * b) - mu_a * mu_b
    c1, c2 = 0.01**2, 0.03**2
    luminance = (2 * mu_a * mu_b + c1) / (mu_a**2 + mu_b**2 + c1)
    contrast_structure = (2 * cov + c2) / (var_a + var_b + c2)
    return luminance, contrast_structure


def ssim(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Mean SSIM of images in [0, 1]."""
    luminance, contrast_structure = ssim_maps(a, b)
    return (luminance * contrast_structure).mean()


def laplacian_l1(a: torch.Tensor, b: torch.Tensor, levels: int = 4) -> torch.Tensor:
    """L1 between Laplacian pyramids, each level weighted equally."""
    loss = a.new_zeros(())
    for _ in range(levels):
        da, db = F.avg_pool2d(a, 2), F.avg_pool2d(b, 2)
        ua = F.interpolate(da, size=a.shape[-2:], mode="bilinear", align_corners=False)
        ub = F.interpolate(db, size=b.shape[-2:], mode="bilinear", align_corners=False)
        loss = loss + F.l1_loss(a - ua, b - ub)
        a, b = da, db
    return loss + F.l1_loss(a, b)


def perceptual(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Offline stand-in for the perceptual loss on images."""
    return laplacian_l1(a, b) + 0.5 * (1.0 - ssim(a, b))


def light_perceptual(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Offline stand-in for the perceptual loss on light images: L1 of their gradients."""
    dx = F.l1_loss(a[..., 1:] - a[..., :-1], b[..., 1:] - b[..., :-1])
    dy = F.l1_loss(a[..., 1:, :] - a[..., :-1, :], b[..., 1:, :] - b[..., :-1, :])
    return dx + dy


# Added to images in [0, 1] before the log of a ratio: the element's `GAIN_EPSILON`.
CHANGE_EPSILON = 0.02
# Standard deviation, in pixels of the network's image, of the blur of the change:
# the scale of a light's shading over a face 33 px across (a side lit, a nose's shadow),
# and about what the element keeps of the change.
CHANGE_SIGMA = 2.0


def lighting_change(src: torch.Tensor, out: torch.Tensor) -> torch.Tensor:
    """The smooth part of the per-channel log gain that makes ``out`` of ``src``: the
    lighting change the element takes from the network and pastes onto the frame. The
    network's output is not bounded below; a negative value counts as black."""
    ratio = torch.log(out.clamp(min=0.0) + CHANGE_EPSILON) - torch.log(src.clamp(min=0.0) + CHANGE_EPSILON)
    c = ratio.shape[1]
    size = 2 * int(3 * CHANGE_SIGMA) + 1
    k = _gauss_kernel(size, CHANGE_SIGMA).to(ratio).expand(c, 1, -1, -1)
    return F.conv2d(F.pad(ratio, [size // 2] * 4, mode="replicate"), k, groups=c)


def change_l1(src: torch.Tensor, relit: torch.Tensor, tgt: torch.Tensor) -> torch.Tensor:
    """L1 between the lighting changes of the relit and the target image from the source.
    The image losses are dominated by detail the network copies through; this one weighs
    only what the element uses, where a light falls and how strongly."""
    return F.l1_loss(lighting_change(src, relit), lighting_change(src, tgt))


# Side, in pixels of the network's image, of the cells the coarse change is averaged over:
# a quarter of a face 33 px across, so a cell tells one side of the face from the other.
COARSE_CELL = 8


def coarse_change_l1(src: torch.Tensor, relit: torch.Tensor, tgt: torch.Tensor) -> torch.Tensor:
    """L1 between the relit and the target image's lighting changes averaged over cells of
    ``COARSE_CELL`` pixels: which side of the face a light brightens, and by how much. In
    ``change_l1`` this part is a small share of every pixel's error, and a network trained on
    it alone learnt a light's side slowly (docs/training.md)."""
    return F.l1_loss(
        F.avg_pool2d(lighting_change(src, relit), COARSE_CELL), F.avg_pool2d(lighting_change(src, tgt), COARSE_CELL)
    )


def monitor_match(pred: torch.Tensor, light: torch.Tensor, l1: float, perceptual: float, colour: float) -> torch.Tensor:
    """How far a predicted monitor light is from the true one: L1, the gradient L1 as its
    perceptual term, and L1 between the two screens' mean colours, each at its weight."""
    return (
        l1 * F.l1_loss(pred, light)
        + perceptual * light_perceptual(pred, light)
        + colour * F.l1_loss(pred.mean(dim=(2, 3)), light.mean(dim=(2, 3)))
    )


def standardised_distance(a: list[torch.Tensor], b: list[torch.Tensor]) -> torch.Tensor:
    """Mean over feature levels of the RMS difference of paired features (a[i] against
    b[i], each (N, C, H, W)), each channel in units of its standard deviation over both.
    Instance normalisation changes a channel's offset and scale, so raw distances would
    compare two representations' units rather than their content."""
    out = []
    for x, y in zip(a, b):
        std = torch.cat([x, y]).std(dim=(0, 2, 3), correction=0, keepdim=True) + 1e-6
        out.append((((x - y) / std) ** 2).mean().add(1e-12).sqrt())
    return torch.stack(out).mean()


class PatchDiscriminator(nn.Module):
    """A PatchGAN discriminator (Isola et al. 2017) scoring overlapping patches, trained as an LSGAN."""

    def __init__(self, width: int = 32):
        super().__init__()
        c = width
        self.net = nn.Sequential(
            nn.Conv2d(3, c, 4, 2, 1),
            nn.LeakyReLU(0.2),
            nn.Conv2d(c, 2 * c, 4, 2, 1),
            nn.InstanceNorm2d(2 * c),
            nn.LeakyReLU(0.2),
            nn.Conv2d(2 * c, 4 * c, 4, 2, 1),
            nn.InstanceNorm2d(4 * c),
            nn.LeakyReLU(0.2),
            nn.Conv2d(4 * c, 1, 4, 1, 1),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x * 2.0 - 1.0)


def lsgan_generator(d_fake: torch.Tensor) -> torch.Tensor:
    return ((d_fake - 1.0) ** 2).mean()


def lsgan_discriminator(d_real: torch.Tensor, d_fake: torch.Tensor) -> torch.Tensor:
    return ((d_real - 1.0) ** 2).mean() + (d_fake**2).mean()
