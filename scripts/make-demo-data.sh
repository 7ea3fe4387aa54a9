#!/usr/bin/env bash
# Makes the shipped demo recording, examples/data/call/{face,monitor}.mp4: the
# simulator's standard "call" recording (deskstage recording --name call),
# encoded as a webcam and a screen recorder would (H.264 in MP4).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -p deskstage
tmp=$(mktemp -d)
./target/release/deskstage recording --name call --out "$tmp"
mkdir -p examples/data/call
for v in face monitor; do
  gst-launch-1.0 -q filesrc location="$tmp/call/$v.y4m" ! y4mdec ! videoconvert ! video/x-raw,format=I420 \
    ! x264enc speed-preset=slow pass=quant quantizer=25 threads=1 ! video/x-h264,profile=high \
    ! mp4mux ! filesink location="examples/data/call/$v.mp4"
done
cp "$tmp/call/meta.json" examples/data/call/meta.json
rm -rf "$tmp"
ls -la examples/data/call
