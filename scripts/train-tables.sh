#!/usr/bin/env bash
# The paper's tables at a longer equal budget: ours, both baselines, the Table 3 ablations and
# ours with the losses beyond the paper, each trained STEPS steps from scratch with the same
# pipeline, data and seed as scripts/train-all.sh's 2000-step runs.
#
#   scripts/train-tables.sh STEPS [DATA] [RUNS] [RUN...]   (defaults: data runs/long-STEPS, all runs)
#
# RUN names a subset of the runs below. With SESSIONS set, DATA's captures are written with that
# many sessions (the first SESSIONS of train-all.sh's 16, the same frames) if it has none yet.
# With CUDA the runs train at once, one process each: the networks are small, so one run
# leaves a GPU mostly idle. On a CPU they train one after another. Each run resumes from its
# checkpoint if interrupted. PYTHON picks the interpreter (default .venv/bin/python). TRAIN_FLAGS
# adds lsyd.train flags to every run alike (say --weight-average 0.995), so the budget stays equal.
# Score them with lsyd.evaluation.evaluate (docs/accuracy.md, "The paper's tables"). The runs without light
# prediction get their light decoder afterwards: lsyd.light_refit --run (docs/accuracy.md, "The light decoder
# fitted after training").
set -euo pipefail
cd "$(dirname "$0")/.."
steps=$1
data=$(realpath -m "${2:-data}")
runs=$(realpath -m "${3:-runs/long-$steps}")
python=$(realpath -ms "${PYTHON:-.venv/bin/python}")
[ -x "$python" ] || python=$(command -v "${PYTHON}")
[ -d "$data/captures" ] || ./target/release/deskstage captures --out "$data/captures" --sessions "${SESSIONS:-16}"
mkdir -p "$runs"

declare -A variant=(
  [t-lcfn]=""
  [t-sun]="--arch sun"
  [t-sengupta]="--arch sengupta"
  [t-nodelight]="--no-delight"
  [t-nopred]="--no-light-prediction"
  [t-neither]="--no-delight --no-light-prediction"
  [e-lcfn]="--delit-consistency 0.1 --monitor-colour 1.0"
  [e-nopred]="--no-light-prediction --delit-consistency 0.1"
)
shift $(($# < 3 ? $# : 3))
names=("$@")
[ ${#names[@]} -gt 0 ] || names=("${!variant[@]}")
for name in "${names[@]}"; do
  [ -n "${variant[$name]+set}" ] || { echo "unknown run $name: one of ${!variant[*]}" >&2; exit 2; }
done
# Each session's frames at network resolution are cached next to it on first use; build the
# caches once here so that parallel runs do not write them at the same time.
(cd train && "$python" -c "
import sys
from pathlib import Path
from lsyd import data, pairing
pairs, _ = data.keypoint_pairs(Path(sys.argv[1]), 128, pairing.PairingRule())
print(f'{len(pairs.pairs)} keypoint pairs at 128 px')
" "$data/captures")

parallel=$("$python" -c "import torch; print(int(torch.cuda.is_available()))")

train() {
  local name=$1
  [ -f "$runs/$name/done" ] && return
  local resume=()
  [ -f "$runs/$name/checkpoint.pt" ] && resume=(--resume)
  # shellcheck disable=SC2086 # the variant's and TRAIN_FLAGS's flags are words
  (cd train && "$python" -m lsyd.train --data "$data" --out "$runs/$name" --steps "$steps" \
    --threads 2 --checkpoint-every 1000 ${variant[$name]} ${TRAIN_FLAGS:-} "${resume[@]}") >"$runs/$name.log" 2>&1
  touch "$runs/$name/done"
}

for name in "${names[@]}"; do
  if [ "$parallel" = 1 ]; then
    train "$name" &
  else
    train "$name"
  fi
done
wait
# The runs' own logs only: another log in the folder (say, this script's output) is not theirs.
for name in "${names[@]}"; do
  grep -h "^trained" "$runs/$name.log"
done
