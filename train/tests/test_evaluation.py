"""The evaluation commands: each starts as ``python -m lsyd.evaluation.<module>``, finds
the repository from where it lives, and reads runs without loading the training script."""

import json
import subprocess
import sys

import pytest
from conftest import ROOT

from lsyd import evaluation
from lsyd.evaluation import evaluate

COMMANDS = ("evaluate", "compare", "benchmark", "modelcard", "seeds", "detail_bound")


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


def _record(path, rows):
    path.write_text(json.dumps({"table1": {name: {"rmse": r, "flip": f} for name, (r, f) in rows.items()}}))
    return path


def _four_rows(sun, sengupta, ours_given, ours_predicted):
    """Table 1's four rows, each (RMSE, FLIP)."""
    return {
        evaluate.SUN_ROW: sun,
        evaluate.SENGUPTA_ROW: sengupta,
        evaluate.OURS_GIVEN_ROW: ours_given,
        evaluate.OURS_PREDICTED_ROW: ours_predicted,
    }


def test_seeds_reads_split_records_and_gives_the_margin_of_the_means(tmp_path):
    # Seed 0's jointly trained rows of ours, replaced by the fitted run's below.
    baselines = _record(tmp_path / "paper.json", _four_rows((12.0, 0.16), (10.0, 0.15), (9.9, 0.14), (11.0, 0.15)))
    fitted = _record(
        tmp_path / "fitted.json", {"Ours, source given": (8.0, 0.12), "Ours, source predicted": (9.0, 0.12)}
    )
    other = _record(tmp_path / "seed-1.json", _four_rows((12.0, 0.16), (12.0, 0.15), (8.0, 0.09), (9.0, 0.12)))
    out = python("-m", "lsyd.evaluation.seeds", f"0={baselines},{fitted}", f"1={other}")
    given_rmse = next(line for line in out.splitlines() if "Sengupta" in line and "| RMSE |" in line)
    # Seed 0: 8 against 10 (20%, the fitted row, not the joint one); seed 1: 8 against 12 (33.3%);
    # the means 8 against 11: 27.3%, not the mean of the margins (26.7%).
    assert "8.000 / 10.000: 20.0%" in given_rmse and "8.000 / 12.000: 33.3%" in given_rmse
    assert "**27.3%**" in given_rmse and "20.0% to 33.3%" in given_rmse
    given_flip = next(line for line in out.splitlines() if "Sengupta" in line and "| FLIP |" in line)
    assert "0.1200 / 0.1500: 20.0%" in given_flip and "0.0900 / 0.1500: 40.0%" in given_flip


def test_seeds_names_a_missing_row(tmp_path):
    partial = _record(tmp_path / "partial.json", {"Ours, source given": (8.0, 0.12)})
    out = subprocess.run(
        [sys.executable, "-m", "lsyd.evaluation.seeds", f"2={partial}"],
        cwd=ROOT / "train",
        capture_output=True,
        text=True,
    )
    assert out.returncode != 0 and "seed 2: no row 'Sengupta et al. 2021 (source given)'" in out.stderr
