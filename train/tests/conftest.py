"""Shared fixtures: small simulator datasets, rendered once per checkout into target/test-data."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "target" / "test-data"


def release_binary(package: str, name: str) -> Path:
    """A program of the workspace as scripts/test.sh's one optimised build leaves it; built if missing."""
    binary = ROOT / "target" / "release" / name
    if not binary.exists():
        subprocess.run(["cargo", "build", "--release", "-p", package], cwd=ROOT, check=True)
    return binary


def lsydrelight() -> Path:
    return release_binary("lsydrelight-cli", "lsydrelight")


def deskstage(*args: str) -> None:
    subprocess.run([str(release_binary("deskstage", "deskstage")), *args], cwd=ROOT, check=True)


@pytest.fixture(scope="session")
def sim_data() -> Path:
    """One 30 s capture session at 10 fps (256 x 256), 24 paired poses, the held-out and validation sets."""
    if not (DATA / "captures" / "session-000" / "keypoints.npy").exists():
        deskstage("captures", "--out", str(DATA / "captures"), "--sessions", "1", "--seconds", "30")
    if not (DATA / "paired" / "truth.npy").exists():
        deskstage("paired", "--out", str(DATA / "paired"), "--poses", "24", "--size", "128")
    if not (DATA / "heldout" / "clean.npy").exists():
        deskstage("heldout", "--out", str(DATA / "heldout"))
    if not (DATA / "validation" / "clean.npy").exists():
        deskstage("validation", "--out", str(DATA / "validation"))
    return DATA


@pytest.fixture(scope="session")
def shipped_model() -> Path:
    model = ROOT / "models" / "default"
    assert (model / "model.json").exists(), "models/default is missing"
    return model
