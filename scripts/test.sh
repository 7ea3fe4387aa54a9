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
# One optimised build for every Rust test: the live tests measure real time and need
# it, the Python tests use its simulator and CLI, and a second, unoptimised build of the same
# crates cost CI about eight minutes more (docs/reliability.md). The live
# tests take their turns by a lock of their own.
step "Rust tests, optimised (the simulator, engine, element, end to end, and live at 1080p, 2160p and four 480p calls)"
cargo test --release --workspace
step "ruff"
.venv/bin/ruff check train
.venv/bin/ruff format --check train
step "Python tests"
(cd train && ../.venv/bin/python -m pytest -q)
step "all tests passed"
