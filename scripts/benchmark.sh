#!/usr/bin/env bash
# The run-time against error benchmark: exports the trained variants, runs every
# variant through the element, measures held-out accuracy, the PyTorch peer and
# the hardware limit, and writes results/benchmark/{table.md,skips.md,pareto.png}.
# Needs the trained runs (scripts/train-all.sh) and the data (deskstage all).
# Takes about half an hour on the 2-core machine; run it on an idle machine.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh full
(cd train && ../.venv/bin/python -m lsyd.benchmark export)
cargo run --release --example benchmark -- "$@"
(cd train && ../.venv/bin/python -m lsyd.benchmark report)
