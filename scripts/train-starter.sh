#!/usr/bin/env bash
# Trains the starter model: one network for anybody, from many simulated people.
#
#   scripts/train-starter.sh [DATA] [RUN]      (defaults: data/starter runs/starter)
#
# The simulator's people 100-131 (skin tones, face shapes, hair, each in their own
# outfit and room) sit two 30 s capture sessions each: one in front of the desk light
# stage, and one under the dome the light code stands for (the same kind of pictures as
# lights from up to 90 degrees to each side; docs/simulator.md), which teaches which side
# a light comes from. Pairs are found by facial keypoints within each session, as on real
# captures. People 200-207 are never trained on: their held-out sets (9 poses x 9 lights,
# on the desk and under the dome) measure the model on strangers, and a desk session each
# the colour tracking of its predicted light (lsyd.evaluation.colour_tracking). Training has
# three stages, all with the light field (a map of where the target light falls, drawn into
# the decoder): the paper's losses (with the de-lit consistency and monitor colour
# terms) for 3000 steps, 6000 more from those weights (a second cosine schedule), then
# 1500 more with the lighting-change loss (docs/training.md): models/starter-next. A fourth
# stage fine-tunes that on the desk sessions (1500 steps at a third of the rate), the
# sessions the element's users sit, with the dome sessions kept as rehearsal for a tenth of
# each batch: models/starter, the element's default, is more accurate at the desk than
# starter-next and keeps most of the side it learnt under the dome.
# Every step is skipped when its output exists, so the script resumes where it stopped.
# Personal models fine-tune from this one.
set -euo pipefail
cd "$(dirname "$0")/.."
data=${1:-data/starter}
run=${2:-runs/starter}
seconds=${STARTER_SECONDS:-30}
steps=${STARTER_STEPS:-3000}
train_people=$(seq 100 131)
unseen_people=$(seq 200 207)
py=$PWD/.venv/bin/python

cargo build --release -p deskstage
stage=target/release/deskstage
mkdir -p "$data/captures" "$data/unseen"
for person in $train_people; do
  session="$data/captures/person-$person"
  if [ ! -f "$session/face.npy" ]; then
    rm -rf "$data/tmp"
    "$stage" captures --subject "$person" --seed "$person" --sessions 1 --seconds "$seconds" --out "$data/tmp"
    mv "$data/tmp/session-000" "$session"
  fi
  if [ ! -f "$session-dome/face.npy" ]; then
    rm -rf "$data/tmp"
    "$stage" captures --subject "$person" --seed "$((person + 1000))" --sessions 1 --seconds "$seconds" \
      --stage dome --out "$data/tmp"
    mv "$data/tmp/session-000" "$session-dome"
  fi
done
for person in $unseen_people; do
  [ -f "$data/unseen/person-$person/clean.npy" ] || "$stage" heldout --subject "$person" --out "$data/unseen/person-$person"
  [ -f "$data/unseen-dome/person-$person/clean.npy" ] ||
    "$stage" heldout --subject "$person" --stage dome --out "$data/unseen-dome/person-$person"
  # A desk session of each unseen person, never trained on: the colour tracking's test
  # (lsyd.evaluation.colour_tracking) needs frames in time order.
  session="$data/unseen-captures/person-$person"
  if [ ! -f "$session/face.npy" ]; then
    rm -rf "$data/tmp"
    "$stage" captures --subject "$person" --seed "$((person + 5000))" --sessions 1 --seconds "$seconds" --out "$data/tmp"
    mkdir -p "$data/unseen-captures"
    mv "$data/tmp/session-000" "$session"
  fi
done

losses=(--delit-consistency 0.1 --monitor-colour 1.0)
# Trains the run folder $1 on the data folder $2 with lsyd.train's further arguments,
# resuming from its checkpoint; skipped once done.
train_stage() {
  local out=$1 on=$2
  shift 2
  [ -f "$out/done" ] && return
  local resume=()
  [ -f "$out/checkpoint.pt" ] && resume=(--resume)
  (cd train && "$py" -m lsyd.train --data "../$on" --out "../$out" "$@" "${resume[@]}")
  touch "$out/done"
}
# The network a finished run trained (written once), as lsyd.train's --init from train/.
network_of() {
  [ -f "$1/network.pt" ] || (cd train && "$py" -m lsyd.runs save-network --run "../$1" --out "../$1/network.pt" >&2)
  echo "../$1/network.pt"
}

train_stage "$run" "$data" --steps "$steps" --resolution 96 --light-field "${losses[@]}"
train_stage "$run-long" "$data" --steps 6000 --init "$(network_of "$run")" "${losses[@]}"
train_stage "$run-long-change" "$data" --steps 1500 --init "$(network_of "$run-long")" "${losses[@]}" --change 1.0
run=$run-long-change

# Export: the contract's stages (checked against PyTorch on a stranger's held-out frames),
# the saved network personal models fine-tune from, and the test on strangers.
[ -e "$data/heldout" ] || ln -s unseen/person-200 "$data/heldout"
(cd train && "$py" -m lsyd.export --run "../$run" --data "../$data" --out ../models/starter-next --name starter-next)
(cd train && "$py" -m lsyd.runs save-network --run "../$run" --out ../models/starter-next/network.pt)

# The fourth stage: the desk sessions, from starter-next's weights, with the dome sessions
# drawn for a tenth of each batch (named as lsydrelight train names rehearsal sessions).
desk="$data-rehearsal"
mkdir -p "$desk/captures"
for person in $train_people; do
  [ -e "$desk/captures/person-$person" ] || ln -s "../../$(basename "$data")/captures/person-$person" "$desk/captures/person-$person"
  [ -e "$desk/captures/rehearsal-dome-$person" ] ||
    ln -s "../../$(basename "$data")/captures/person-$person-dome" "$desk/captures/rehearsal-dome-$person"
done
[ -e "$desk/heldout" ] || ln -s "../$(basename "$data")/heldout" "$desk/heldout"
desk_run="$run-rehearsal"
train_stage "$desk_run" "$desk" --steps 1500 --lr 6e-5 --init ../models/starter-next/network.pt "${losses[@]}" --change 1.0 \
  --rehearsal-share 0.1
(cd train && "$py" -m lsyd.export --run "../$desk_run" --data "../$desk" --out ../models/starter --name starter)
(cd train && "$py" -m lsyd.runs save-network --run "../$desk_run" --out ../models/starter/network.pt)
for stage in desk dome; do
  (cd train && "$py" -m lsyd.evaluation.starter --data "../$data" --models ../models/starter ../models/starter-next --stage "$stage")
done
(cd train && "$py" -m lsyd.evaluation.colour_tracking --data "../$data" --model ../models/starter)
