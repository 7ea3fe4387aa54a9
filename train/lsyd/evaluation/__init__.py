"""Evaluation of trained runs and exported models, each module a command
(``python -m lsyd.evaluation.<module>``):

- ``evaluate``: the paper's Tables 1-3, in PyTorch, on exact ground truth;
- ``compare``: runs side by side on the validation set, de-lighting included;
- ``benchmark``: the model side of the run-time against error benchmark, and its report;
- ``modelcard``: a model's held-out figures, and its card;
- ``seeds``: issue 16's four cells over several seeds, from ``evaluate``'s records;
- ``real_direction``: how much of a light's side the network itself draws on real faces;
- ``detail_bound``: how much of the detail band a change at a given resolution can remove;
- ``key_colour``: how much of a local light's colour a model gives a face, against the same
  light spread evenly;
- ``metrics``: the image and temporal metrics they share, and the one loop that scores
  a network on a 9 x 9 test set.

Nothing here trains: runs are read through ``lsyd.runs``, exported models through
``lsyd.contract``.
"""

from pathlib import Path

# The repository's root: the commands' default paths are under it.
ROOT = Path(__file__).resolve().parents[3]


def report(text: str, out: Path | None) -> None:
    """Prints a command's markdown report and, with ``out``, writes it there too."""
    print(text, end="")
    if out:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text)
