"""The lighting-change loss: it tells a light from one side from a light from the other."""

import torch

from lsyd import losses


def _face(seed: int = 0) -> torch.Tensor:
    """A textured grey image, 1 x 3 x 32 x 32, in [0.2, 0.6]."""
    g = torch.Generator().manual_seed(seed)
    return 0.2 + 0.4 * torch.rand(1, 3, 32, 32, generator=g)


def _lit_from(image: torch.Tensor, side: str) -> torch.Tensor:
    """``image`` brightened by half on one side, fading to none on the other."""
    ramp = torch.linspace(1.5, 1.0, image.shape[-1])
    return image * (ramp if side == "left" else ramp.flip(0))


def test_the_change_loss_is_zero_for_the_target_and_tells_the_sides_apart():
    src = _face()
    left, right = _lit_from(src, "left"), _lit_from(src, "right")
    assert losses.change_l1(src, left, left).item() == 0.0
    wrong_side = losses.change_l1(src, right, left).item()
    even = losses.change_l1(src, src * 1.25, left).item()
    # Half the mean gain, on the wrong side, is further from the truth than an even one.
    assert wrong_side > 1.5 * even > 0.0


def test_the_change_loss_ignores_texture_the_change_does_not_make():
    # The relit image's own fine noise is blurred away; the same noise as a change of
    # light over the whole face would not be.
    src = _face()
    noisy = src * (1.0 + 0.05 * torch.randn(src.shape, generator=torch.Generator().manual_seed(1)))
    assert losses.change_l1(src, noisy, src).item() < 0.01
    assert losses.change_l1(src, src * 1.05, src).item() > 0.04


def test_the_change_loss_stays_finite_where_the_network_goes_below_black():
    src = _face()
    relit = src.clone().requires_grad_(True)
    below = relit - 0.5
    loss = losses.change_l1(src, below, src)
    loss.backward()
    assert torch.isfinite(loss) and torch.isfinite(relit.grad).all()


def test_the_coarse_change_loss_keeps_the_side_and_drops_pixel_noise():
    # The side's error is as large averaged over 8 px cells as pixel by pixel; noise in
    # the relit image's change (the mottling the element must not paste) mostly cancels.
    src = _face()
    left, right = _lit_from(src, "left"), _lit_from(src, "right")
    noisy = left * torch.exp(0.6 * torch.randn(src.shape, generator=torch.Generator().manual_seed(2)))
    assert losses.coarse_change_l1(src, left, left).item() == 0.0

    def coarse_share(relit: torch.Tensor) -> float:
        return losses.coarse_change_l1(src, relit, left).item() / losses.change_l1(src, relit, left).item()

    assert coarse_share(right) > 0.95
    assert coarse_share(noisy) < 0.7
