"""The evaluation commands: each starts as ``python -m lsyd.evaluation.<module>``, finds
the repository from where it lives, and reads runs without loading the training script."""

import subprocess
import sys

import pytest
from conftest import ROOT

from lsyd import evaluation

COMMANDS = ("evaluate", "compare", "benchmark", "modelcard")


def python(*args: str) -> str:
    """What this interpreter prints, run from ``train/`` as the README's commands are."""
    out = subprocess.run([sys.executable, *args], cwd=ROOT / "train", capture_output=True, text=True, check=True)
    return out.stdout


@pytest.mark.parametrize("command", COMMANDS)
def test_command_starts(command):
    assert f"python -m lsyd.evaluation.{command}" in python("-m", f"lsyd.evaluation.{command}", "--help")


def test_default_paths_are_under_the_repository():
    assert evaluation.ROOT == ROOT


def test_evaluation_does_not_import_the_training_script():
    imports = "; ".join(f"import lsyd.evaluation.{c}" for c in COMMANDS)
    assert python("-c", f"import sys; {imports}; print('lsyd.train' in sys.modules)").strip() == "False"
