#!/usr/bin/env bash
# The run-time against error benchmark: exports the trained variants, runs every
# variant through the element, measures accuracy on the validation set (which the
# default configuration is chosen on) and the held-out test set, the PyTorch peer
# and the hardware limit, and writes results/benchmark/{table.md,skips.md,pareto.png}.
# Needs the trained runs (scripts/train-all.sh) and the data (deskstage all).
# Takes about half an hour on the 2-core machine; run it on an idle machine.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh full
cargo build --release -p deskstage
[ -f data/validation/clean.npy ] || target/release/deskstage validation --out data/validation
(cd train && ../.venv/bin/python -m lsyd.evaluation.benchmark export)
cargo run --release --example benchmark -- "$@"
(cd train && ../.venv/bin/python -m lsyd.evaluation.benchmark report)
