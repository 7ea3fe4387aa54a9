#!/usr/bin/env bash
# The main job on the shipped defaults: relights the shipped synthetic recorded
# call (examples/data/call) with the default model and writes the relit video,
# the predicted-monitor video and a side-by-side image to results/demo.
# Arguments are passed to the example (see examples/relight_recording.rs).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh runtime
cargo build --release --example relight_recording
exec target/release/examples/relight_recording "$@"
