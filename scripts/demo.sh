#!/usr/bin/env bash
# The main job on the shipped defaults: relights the shipped synthetic recorded call
# (examples/data/call) with its person's own model, models/default, through
# `lsydrelight relight`, which keeps audio and every other stream, and writes the relit
# video, the predicted-monitor video and a side-by-side image of one frame to results/demo.
# Also builds the plugin into target/release, where `GST_PLUGIN_PATH=$PWD/target/release`
# finds it.
#
#   scripts/demo.sh [--face FILE] [--monitor FILE] [--target PNG] [--model DIR] [--out DIR] [--frame N]
set -euo pipefail
cd "$(dirname "$0")/.."

face=examples/data/call/face.mp4
monitor=examples/data/call/monitor.mp4
target=models/targets/sunset.png
model=models/default
out=results/demo
frame=150
while [ $# -gt 0 ]; do
    [ $# -ge 2 ] || { echo "error: $1 needs a value" >&2; exit 2; }
    case $1 in
        --face) face=$2 ;;
        --monitor | --screen) monitor=$2 ;;
        --target) target=$2 ;;
        --model) model=$2 ;;
        --out) out=$2 ;;
        --frame) frame=$2 ;;
        *) echo "error: unknown argument $1; see the top of $0" >&2; exit 2 ;;
    esac
    shift 2
done

scripts/setup.sh runtime
cargo build --release -p gst-plugin-lsydrelight -p lsydrelight-cli --lib --bins --example side_by_side

# MP4 in, MP4 out; any other container keeps its streams in MKV.
case $face in
    *.mp4 | *.MP4) relit=$out/relit.mp4 ;;
    *) relit=$out/relit.mkv ;;
esac
mkdir -p "$out"
target/release/lsydrelight relight --face "$face" --screen "$monitor" --target "$target" \
    --model "$model" --predicted-monitor "$out/predicted-monitor.mp4" --out "$relit"
target/release/examples/side_by_side --frame "$frame" --out "$out/side-by-side.png" \
    "$monitor" "$face" "$relit" "$out/predicted-monitor.mp4"
echo "relit video:        $relit"
echo "predicted monitor:  $out/predicted-monitor.mp4"
echo "side by side:       $out/side-by-side.png (frame $frame: what the monitor showed, the face as filmed, relit to $(basename "${target%.*}"), the predicted monitor)"
echo "the plugin:         $PWD/target/release/libgstlsydrelight.so (export GST_PLUGIN_PATH=$PWD/target/release)"
