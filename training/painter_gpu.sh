#!/usr/bin/env bash
# `make painter`'s recipe (the runtime's learnt painter of the novel view) sized for a lent GPU machine
# (16 cores, one H100 or H200), with several widths trained side by side on the one GPU, so the
# speed-for-accuracy trade of the painter's width is measured in one run:
#   1. the `make model` dataset's val split (VAL=256 scenes) and its first TRAIN_SCENES train scenes;
#   2. the device's joints of both splits through the shipped int8 graphs (training.device_joints);
#   3. the painter's caches over the body proxies of those joints (learnt_fill cache --no-relit);
#   4. one painter per width in WIDTHS, trained for SECONDS each, all at once, batches of 32, with the
#      shipped recipe's settings otherwise (shown picture in, no relit fill, around_weight=0.03), each
#      scored on the held-out cache.
#
#   bash training/painter_gpu.sh WORK REPORT [TRAIN_SCENES=2048] [SECONDS=240]
#
# WORK holds the data and caches (a few GB); REPORT (WORK itself will do) gets each width's fill_net_w<W>.pt,
# score and log, and the val split's joints. Export the nets on any machine with `python -m training.learnt_fill
# export` (docs/training.md, "The painter on a GPU"). MODELS=<folder> reads that folder's model instead
# of models/; WIDTHS="32 16" by default. VIEWS="all 4096" trains each width once per entry, on all the cache's
# training views and on its first 4096 (two per scene), so what more training scenes give is measured in the same
# run; a net of VIEWS=all (the default, alone) is w<W>, any other w<W>_v<N>. Runs on a CPU as well, slowly.
set -euo pipefail
WORK=${1:?work folder}; REPORT=${2:?report folder}; N=${3:-2048}; SECS=${4:-240}
PY=${PYTHON:-$( [ -x .venv/bin/python ] && echo .venv/bin/python || echo python3 )}; W=${WORKERS:-$(nproc)}; VAL=${VAL:-256}; MODELS=${MODELS:-models}
WIDTHS=${WIDTHS:-32 16}; VIEWS=${VIEWS:-all}
for v in $VIEWS; do [[ $v == all || $v =~ ^[1-9][0-9]*$ ]] || { echo "VIEWS: '$v' is neither all nor a count" >&2; exit 2; }; done
mkdir -p "$WORK" "$REPORT"
t0=$(date +%s)
stamp() { echo "$1: $(( $(date +%s) - t0 )) s"; }
# A background job's failure stops the script too (plain `wait` would not), and whatever still runs beside
# it is stopped with it (a leftover trainer would hold the lent GPU).
wait_all() { local p; for p in "$@"; do wait "$p"; done; }
trap 'kill $(jobs -p) 2>/dev/null || true' EXIT

"$PY" -m training.data.generate --out "$WORK/data" --train "$N" --val "$VAL" --res 128 --workers "$W" --freestyle-share 0.5
stamp data

"$PY" -m training.device_joints --data "$WORK/data" --split train --limit "$N" --model "$MODELS/ghnerf" \
    --threads 4 --out "$WORK/joints_train.npz" & a=$!
"$PY" -m training.device_joints --data "$WORK/data" --split val --limit "$VAL" --model "$MODELS/ghnerf" \
    --threads 2 --out "$WORK/joints_val.npz" & b=$!
wait_all $a $b
[ "$WORK/joints_val.npz" -ef "$REPORT/joints_val.npz" ] || cp "$WORK/joints_val.npz" "$REPORT/joints_val.npz"
stamp joints

VW=$(( W / 4 > 1 ? W / 4 : 1 )); TW=$(( W - VW > 1 ? W - VW : 1 ))
"$PY" -m training.learnt_fill cache --data "$WORK/data" --split train --limit "$N" --workers "$TW" --no-relit \
    --model "$MODELS/ghnerf/ghnerf.pt" --joints "$WORK/joints_train.npz" --out "$WORK/fill_train.npz" & a=$!
"$PY" -m training.learnt_fill cache --data "$WORK/data" --split val --limit "$VAL" --workers "$VW" --no-relit \
    --model "$MODELS/ghnerf/ghnerf.pt" --joints "$WORK/joints_val.npz" --out "$WORK/fill_val.npz" & b=$!
wait_all $a $b
stamp caches

# one name per net: w<W> on every training view, w<W>_v<N> on the first N
name() { [ "$2" = all ] && echo "w$1" || echo "w$1_v$2"; }
pids=()
for w in $WIDTHS; do
    for v in $VIEWS; do
        n=$(name "$w" "$v")
        "$PY" -m training.learnt_fill train --train-cache "$WORK/fill_train.npz" --val-cache "$WORK/fill_val.npz" \
            --out "$WORK/$n" --threads 2 --train-views "$([ "$v" = all ] && echo 0 || echo "$v")" \
            --set net.width="$w" --set batch=32 --set steps=1000000 \
            --set max_seconds="$SECS" --set net.shown_input=true --set net.relit_input=false \
            --set around_weight=0.03 >"$REPORT/train_$n.log" 2>&1 & pids+=($!)
    done
done
wait_all "${pids[@]}"
for w in $WIDTHS; do
    for v in $VIEWS; do
        n=$(name "$w" "$v")
        cp "$WORK/$n/fill_net.pt" "$REPORT/fill_net_$n.pt"; cp "$WORK/$n/score.md" "$REPORT/score_$n.md"
        echo "== width $w, training views $v"; tail -n 12 "$REPORT/train_$n.log"
    done
done
stamp total
