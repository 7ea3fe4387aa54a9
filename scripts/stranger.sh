#!/usr/bin/env bash
# A simulated stranger through the light-stage tools, scored against exact ground truth,
# beside a model trained on the simulator's own dataset of the same person for the same
# budget.
#
#   scripts/stranger.sh [OUT]      (default target/stranger; STRANGER_STEPS=100, STRANGER_SUBJECT=200)
#
# 1. `lsydrelight capture` records the simulated person (the deskstagecam webcam, lit by
#    exactly what the capture's screen branch shows) in three sessions: 30 s moving
#    naturally, 20 s holding still (both for training) and 10 s held out.
# 2. `lsydrelight train` makes a personal model from that folder, fine-tuned from the
#    starter model for STRANGER_STEPS steps, timed stage by stage (models/tool/training/times.json).
# 3. The same person's dataset as the simulator writes it directly (two 25 s sessions:
#    the same 50 s of training capture, exact keypoints) trains the same recipe from the
#    same starter for the same steps (lsyd.personal train).
# 4. Both, and the starter, are scored on the person's held-out set (9 poses x 9 lights,
#    every ordered pair, face-crop RMSE against exact ground truth).
# Every step is skipped when its output exists, so the script resumes where it stopped.
set -euo pipefail
cd "$(dirname "$0")/.."
out=$(realpath -m "${1:-target/stranger}")
steps=${STRANGER_STEPS:-100}
person=${STRANGER_SUBJECT:-200}
py=$PWD/.venv/bin/python
export OMP_WAIT_POLICY=PASSIVE

cargo build --release -p lsydrelight-cli -p deskstage
tool=target/release/lsydrelight
stage=target/release/deskstage

# The screen content: the simulator's monitor videos (varied scenes, patches and cuts).
for name in cuts slow steady walkaway; do
  [ -f "$out/screen/$name/monitor.y4m" ] || "$stage" recording --name "$name" --frames 300 --out "$out/screen"
done

capture=$out/capture
if [ ! -f "$capture/done" ]; then
  rm -rf "$capture"
  cam="screen. ! queue ! deskstagecam subject=$person"
  show=(--display "fakesink sync=false" --playlist)
  "$tool" capture --out "$capture" "${show[@]}" "$out"/screen/{cuts,slow,steady}/monitor.y4m --camera "$cam seed=1"
  "$tool" capture --out "$capture" --held-out "${show[@]}" "$out/screen/walkaway/monitor.y4m" --camera "$cam seed=2"
  "$tool" capture --out "$capture" "${show[@]}" "$out"/screen/{cuts,slow}/monitor.y4m --camera "$cam seed=3 motion=frozen"
  touch "$capture/done"
fi
[ -f "$out/models/tool/model.json" ] || "$tool" train --capture "$capture" --out "$out/models/tool" --steps "$steps"

eval_data=$out/eval
[ -f "$eval_data/unseen/person-$person/clean.npy" ] || "$stage" heldout --subject "$person" --out "$eval_data/unseen/person-$person"
[ -e "$eval_data/heldout" ] || ln -s "unseen/person-$person" "$eval_data/heldout"

direct=$out/direct
if [ ! -f "$direct/data/captures/done" ]; then
  rm -rf "$direct/data"
  "$stage" captures --subject "$person" --seed 11 --sessions 2 --seconds 25 --out "$direct/data/captures"
  touch "$direct/data/captures/done"
fi
if [ ! -f "$out/models/direct/model.json" ]; then
  # Resumes from the run's checkpoint when there is one.
  (cd train && "$py" -m lsyd.personal train --work "$direct" --init ../models/starter/network.pt --steps "$steps")
  (cd train && "$py" -m lsyd.export --run "$direct/run" --data "$eval_data" --out "$out/models/direct" --name direct)
fi

(cd train && "$py" -m lsyd.evaluation.starter --data "$eval_data" --out "$out/results" \
  --models "$out/models/tool" "$out/models/direct" ../models/starter)
