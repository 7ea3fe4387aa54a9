#!/usr/bin/env bash
# Every test: formatting and lints, the Rust tests (simulator, engine, element,
# end to end), and the Python tests (contract, pairing, de-lighting, export,
# training smoke test). Installs what they need first; safe to re-run.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh full

step() { printf '\n\033[1m== %s\033[0m\n' "$*"; }
step "cargo fmt"
cargo fmt --all --check
step "cargo clippy"
cargo clippy --workspace --all-targets -- -D warnings
step "Rust tests"
cargo build --release -p deskstage
cargo test --workspace
step "Live tests at 1080p, 2160p and four 480p calls (optimised build, one at a time: each measures real time on the cores)"
cargo test --release --test live -- --test-threads 1 a_1080p four_instances
step "ruff"
.venv/bin/ruff check train
.venv/bin/ruff format --check train
step "Python tests"
(cd train && ../.venv/bin/python -m pytest -q)
step "all tests passed"
