#!/usr/bin/env bash
# Installs what lsydrelight needs on Debian 12. Safe to re-run: each step is
# skipped when what it makes is already there.
#
#   scripts/setup.sh runtime   GStreamer, the Rust build's needs, and ONNX Runtime's library
#   scripts/setup.sh full      runtime, plus the pinned Python stack for training and tests
set -euo pipefail
cd "$(dirname "$0")/.."

level=${1:-full}
case "$level" in runtime | full) ;; *) echo "usage: $0 runtime|full" >&2; exit 2 ;; esac

# The one ONNX Runtime the element loads: the library inside the onnxruntime wheel, pinned by hash.
ORT_VERSION=1.31.1
ORT_WHEEL=onnxruntime-${ORT_VERSION}-cp311-cp311-manylinux_2_28_x86_64.whl
ORT_SHA256=5752bd508126ae7c49894d3b9d2e83f0c3d487319246d04c444b393308d7ad7f
ORT_DIR=target/onnxruntime

APT=(
  pkg-config
  libgstreamer1.0-dev libgstreamer-plugins-base1.0-dev gstreamer1.0-tools
  gstreamer1.0-plugins-base gstreamer1.0-plugins-good gstreamer1.0-plugins-bad
  gstreamer1.0-plugins-ugly gstreamer1.0-libav
  python3-venv python3-pip unzip
)

say() { printf '\033[1m[setup]\033[0m %s\n' "$*"; }

sudo_=""
[ "$(id -u)" -eq 0 ] || sudo_=sudo
missing=()
for p in "${APT[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  say "installing Debian packages: ${missing[*]}"
  $sudo_ apt-get update -q
  DEBIAN_FRONTEND=noninteractive $sudo_ apt-get install -y -q --no-install-recommends "${missing[@]}"
fi

if ! command -v cargo >/dev/null; then
  echo "cargo is missing: install Rust (rustup, 1.92 or newer) first" >&2
  exit 1
fi

if [ ! -f "$ORT_DIR/libonnxruntime.so.$ORT_VERSION" ]; then
  say "fetching ONNX Runtime $ORT_VERSION's library from the PyPI wheel"
  mkdir -p "$ORT_DIR"
  python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.11 \
    --platform manylinux_2_28_x86_64 -d "$ORT_DIR" "onnxruntime==$ORT_VERSION"
  echo "$ORT_SHA256  $ORT_DIR/$ORT_WHEEL" | sha256sum -c --quiet
  unzip -q -o -j "$ORT_DIR/$ORT_WHEEL" "onnxruntime/capi/libonnxruntime.so.$ORT_VERSION" -d "$ORT_DIR"
  rm "$ORT_DIR/$ORT_WHEEL"
fi
ln -sf "libonnxruntime.so.$ORT_VERSION" "$ORT_DIR/libonnxruntime.so"

if [ "$level" = full ]; then
  if [ ! -x .venv/bin/python ]; then
    say "creating the Python environment .venv"
    python3 -m venv .venv
  fi
  say "installing the pinned Python packages (torch is about 3 GB the first time; quick after)"
  .venv/bin/python -m pip install -q --disable-pip-version-check -r train/requirements.txt

  # Real faces for the no-ground-truth measures (examples/real_footage.rs), from
  # packages and never committed: scikit-image's astronaut portrait (public
  # domain, in the pinned wheel) and opencv-doc's Megamind clip (Debian; a film
  # clip, used for robustness only).
  MEDIA=target/real-media
  mkdir -p "$MEDIA"
  cp -u .venv/lib/python3.11/site-packages/skimage/data/astronaut.png "$MEDIA/"
  if [ ! -f "$MEDIA/Megamind.avi" ]; then
    say "fetching Megamind.avi from Debian's opencv-doc package"
    deb_dir=$(mktemp -d)
    # apt-get download needs the package lists, which a fresh image may not have yet.
    (cd "$deb_dir" && { apt-get download -q opencv-doc >/dev/null 2>&1 ||
      { $sudo_ apt-get update -q >/dev/null && apt-get download -q opencv-doc >/dev/null; }; })
    dpkg-deb --fsys-tarfile "$deb_dir"/opencv-doc_*.deb |
      tar -x -O ./usr/share/doc/opencv-doc/examples/data/Megamind.avi >"$MEDIA/Megamind.avi"
    rm -r "$deb_dir"
  fi
fi
say "ready ($level): ONNX Runtime at $ORT_DIR/libonnxruntime.so"
