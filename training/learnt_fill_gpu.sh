#!/usr/bin/env bash
# The learnt fill's measurement (training/learnt_fill.py) in one command, sized for a lent GPU machine
# (about 7 minutes of one H100 with 16 cores at the defaults):
#   1. the `make model` dataset's val split (256 scenes) and its first TRAIN_SCENES train scenes;
#   2. their fill-feature caches (true geometry, relit fill, normals, joints: training/fill_features.py);
#   3. two fill nets, each scored on the 256 held-out scenes: one on every training view for SECONDS,
#      one on the first half of them for SECONDS/2 (does more data help?).
#
#   bash training/learnt_fill_gpu.sh WORK REPORT [TRAIN_SCENES=2560] [SECONDS=180]
#
# WORK holds the data and caches (several GB); REPORT gets the nets, their scores and the log.
# MODEL=<GHNeRF checkpoint> takes the geometry and the picture from that model instead of the truth
# (the net then reads and starts from the model's picture); HALF=0 skips the second net.
# Runs on a CPU as well (slowly: give it hours, or fewer scenes and seconds).
set -euo pipefail
WORK=${1:?work folder}; REPORT=${2:?report folder}; N=${3:-2560}; SECS=${4:-180}
PY=${PYTHON:-$( [ -x .venv/bin/python ] && echo .venv/bin/python || echo python3 )}; W=${WORKERS:-$(nproc)}; VAL=${VAL:-256}; HALF=${HALF:-1}
GEOMETRY=(); NET=()
if [ -n "${MODEL:-}" ]; then GEOMETRY=(--model "$MODEL"); NET=(--set net.shown_input=true); fi
mkdir -p "$WORK" "$REPORT"
t0=$(date +%s)
"$PY" -m training.data.generate --out "$WORK/data" --train "$N" --val "$VAL" --res 128 --workers "$W" --freestyle-share 0.5
echo "data: $(( $(date +%s) - t0 )) s"
"$PY" -m training.learnt_fill cache --data "$WORK/data" --split val --limit "$VAL" --workers "$W" "${GEOMETRY[@]}" --out "$WORK/fill_val.npz"
"$PY" -m training.learnt_fill cache --data "$WORK/data" --split train --limit "$N" --workers "$W" "${GEOMETRY[@]}" --out "$WORK/fill_train.npz"
echo "caches: $(( $(date +%s) - t0 )) s"
VIEWS=$("$PY" -c "import sys, numpy as np; print(len(np.load(sys.argv[1])['angle']))" "$WORK/fill_train.npz")
"$PY" -m training.learnt_fill train --train-cache "$WORK/fill_train.npz" --val-cache "$WORK/fill_val.npz" \
    --out "$WORK/all" --set steps=1000000 --set max_seconds="$SECS" "${NET[@]}"
cp "$WORK/all/fill_net.pt" "$REPORT/fill_net_all.pt"; cp "$WORK/all/score.md" "$REPORT/score_all.md"
cp "$WORK/all/score.json" "$REPORT/score_all.json"
[ "$HALF" = 0 ] && { echo "total: $(( $(date +%s) - t0 )) s"; exit 0; }
"$PY" -m training.learnt_fill train --train-cache "$WORK/fill_train.npz" --val-cache "$WORK/fill_val.npz" \
    --out "$WORK/half" --train-views $(( VIEWS / 2 )) --set steps=1000000 --set max_seconds=$(( SECS / 2 )) "${NET[@]}"
cp "$WORK/half/score.md" "$REPORT/score_half.md"; cp "$WORK/half/score.json" "$REPORT/score_half.json"
echo "total: $(( $(date +%s) - t0 )) s"
