"""The training batches' box jitter (``data.jitter_crops``) and mirrored pairs (``data.mirror_pairs``)."""

import torch

from lsyd import contract, data

RES = 96
FACE_HEIGHT = RES / contract.CROP["side"]


def face_disc(n: int) -> torch.Tensor:
    """``n`` crops, black but for a white disc one face high where the crop rule puts the face."""
    centre = (RES / 2, RES / 2 + contract.CROP["lift"] * FACE_HEIGHT)
    y, x = torch.meshgrid(torch.arange(RES) + 0.5, torch.arange(RES) + 0.5, indexing="ij")
    disc = ((x - centre[0]) ** 2 + (y - centre[1]) ** 2 <= (FACE_HEIGHT / 2) ** 2).float()
    return disc.expand(n, 3, RES, RES).clone()


def disc_place(images: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Per image, the disc's centre (x, y) and diameter, in pixels, from its first moments and area."""
    mass = images[:, 0]
    area = mass.sum(dim=(1, 2))
    y, x = torch.meshgrid(torch.arange(RES) + 0.5, torch.arange(RES) + 0.5, indexing="ij")
    cx, cy = (mass * x).sum(dim=(1, 2)) / area, (mass * y).sum(dim=(1, 2)) / area
    return cx, cy, 2.0 * torch.sqrt(area / torch.pi)


def test_a_pair_is_moved_alike_and_its_lights_kept():
    faces = face_disc(16)
    lights = torch.rand(16, 3, contract.LIGHT_ROWS, contract.LIGHT_COLS)
    src, l_src, tgt, l_tgt = data.jitter_crops(
        (faces, lights, faces * 0.5, lights.flip(0)), 0.1, torch.Generator().manual_seed(0)
    )
    assert torch.allclose(tgt, src * 0.5, atol=1e-6), "the two images of a pair show one pose"
    assert torch.equal(l_src, lights) and torch.equal(l_tgt, lights.flip(0))


def test_the_face_is_zoomed_and_shifted_within_the_jitter():
    jitter = 0.1
    faces = face_disc(64)
    moved = data.jitter_crops((faces, None, faces, None), jitter, torch.Generator().manual_seed(1))[0]
    x0, y0, size0 = (v[0] for v in disc_place(faces))
    x, y, size = disc_place(moved)
    pixel = 1.0 / FACE_HEIGHT  # measuring a disc of 33 px to a pixel
    zoom = size / size0
    assert zoom.min() >= 1 - jitter - pixel and zoom.max() <= 1 + jitter + pixel, zoom
    assert zoom.max() - zoom.min() > jitter, "the zooms spread over the range"
    # A zoom about the face keeps its centre; the shift moves it by up to half the jitter.
    reach = (0.5 * jitter + pixel) * FACE_HEIGHT
    assert (x - x0).abs().max() <= reach and (y - y0).abs().max() <= reach
    assert (x - x0).abs().max() > 0.25 * jitter * FACE_HEIGHT, "the face is shifted"


def test_no_jitter_leaves_the_crops_as_they_are():
    faces = face_disc(4)
    assert torch.allclose(data.jitter_crops((faces, None, faces, None), 0.0, torch.Generator())[0], faces, atol=1e-5)


def lit_from_the_left(n: int) -> tuple[torch.Tensor, torch.Tensor]:
    """``n`` crops brighter on their left half, and ``n`` lights bright in their left columns."""
    images = torch.full((n, 3, RES, RES), 0.2)
    images[..., : RES // 2] = 0.8
    lights = torch.zeros(n, 3, contract.LIGHT_ROWS, contract.LIGHT_COLS)
    lights[..., : contract.LIGHT_COLS // 4] = 1.0
    return images, lights


def left_heavy(x: torch.Tensor) -> torch.Tensor:
    """Per item, whether its left half outweighs its right."""
    half = x.shape[-1] // 2
    return x[..., :half].sum(dim=(1, 2, 3)) > x[..., half:].sum(dim=(1, 2, 3))


def test_a_mirrored_pair_keeps_its_light_on_the_side_its_face_is_lit():
    images, lights = lit_from_the_left(64)
    src, l_src, tgt, l_tgt = data.mirror_pairs(
        (images, lights, images * 0.5, lights * 0.25), torch.Generator().manual_seed(0)
    )
    flipped = ~left_heavy(src)
    # The pair's two images and two lights are mirrored together, or not at all.
    for x in (l_src, tgt, l_tgt):
        assert torch.equal(~left_heavy(x), flipped)
    assert torch.allclose(tgt, src * 0.5) and torch.allclose(l_tgt, l_src * 0.25)
    assert 16 <= int(flipped.sum()) <= 48, "about half the pairs are mirrored"
    assert torch.equal(src[flipped], images[flipped].flip(-1)) and torch.equal(src[~flipped], images[~flipped])
    assert torch.equal(images, lit_from_the_left(64)[0]), "the batch given is left as it was"


def test_a_box_jitter_out_of_range_is_refused_naming_the_range():
    import subprocess
    import sys

    for bad in ("-0.1", "0.5", "lots"):
        run = subprocess.run(
            [sys.executable, "-m", "lsyd.train", "--out", "unused", "--box-jitter", bad],
            capture_output=True,
            text=True,
            check=False,
        )
        assert run.returncode == 2, run.stderr
        assert "--box-jitter" in run.stderr and "0.5" in run.stderr, run.stderr
