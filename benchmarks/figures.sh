#!/usr/bin/env bash
# Reproduces the accuracy figures of the issues (extract, accumulate, track) on the bundled
# sample, on fresh simulated recordings and on the real chessboard recording. About 5 minutes.
# Speed and memory figures come from `make bench`.
set -euo pipefail
A=${ACCUM:-.venv/bin/accum}
O=out/figures
mkdir -p "$O"
run() { echo "\$ $*"; "$@"; echo; }
sim() { [ -f "$O/$1.mcap" ] || "$A" -q simulate --scene classic -o "$O/$1.mcap" "${@:2}" > /dev/null; }

sim prism --shape prism --seed 1
sim house --shape house --seed 2
sim prism_raw --shape prism --seed 1 --raw
sim prism_tf --shape prism --seed 1 --tf-tree
sim box_exact --seed 7
sim box_noisy --seed 7 --pose-noise 1.5,4
sim track_box --count 60 --seed 5
sim track_prism --count 60 --seed 8 --shape prism
SAMPLE=sample_data/sim_box
BOARD=sample_data/chessboard/chessboard

echo "== extract: single frames"
for r in $SAMPLE "$O/prism" "$O/house"; do
  run "$A" -q extract "$r.mcap" -o "$O/$(basename "$r").jsonl"
  run "$A" eval "$O/$(basename "$r").jsonl" "$r.truth.json"
done
run "$A" -q extract "$BOARD.mcap" --object-frame board -o "$O/chessboard.jsonl"
run "$A" eval "$O/chessboard.jsonl" "$BOARD.truth.json"

echo "== accumulate"
for r in $SAMPLE "$O/prism" "$O/house" "$O/prism_raw" "$O/prism_tf"; do
  n=$(basename "$r")
  run "$A" -q accumulate "$r.mcap" -o "$O/$n.model.json" --truth "$r.truth.json" --history "$O/$n.history.jsonl"
  python3 - "$O/$n.history.jsonl" <<'PY'
import json, sys
rows = [json.loads(line) for line in open(sys.argv[1])]
curve = [round(r["background"], 3) if r["accepted"] else None for r in rows]
late = [b for r, b in zip(rows, curve) if r["frame_index"] >= 4 and b is not None]
print("background of accepted, frame by frame:", curve)
print(f"max from the 5th frame on: {max(late):.3f}\n")
PY
done
run "$A" -q accumulate "$BOARD.mcap" --object-frame board -o "$O/chessboard.model.json"
run "$A" eval "$O/chessboard.model.json" "$BOARD.truth.json"

echo "== noisy gripper poses"
run "$A" -q accumulate "$O/box_exact.mcap" -o "$O/box_exact.model.json" --truth "$O/box_exact.truth.json"
run "$A" -q accumulate "$O/box_noisy.mcap" -o "$O/box_noisy.model.json" --truth "$O/box_exact.truth.json"
run "$A" -q accumulate "$O/box_noisy.mcap" -o "$O/box_tracked.model.json" --truth "$O/box_exact.truth.json" --motion tracked

echo "== track: model from the first 20 frames, then all 60 from the first pose only"
for r in track_box track_prism; do
  run "$A" -q accumulate "$O/$r.mcap" --frames 0:20 -o "$O/$r.model.json"
  run "$A" -q track "$O/$r.model.json" "$O/$r.mcap" -o "$O/$r.poses.json"
  run "$A" eval --poses "$O/$r.poses.json" "$O/$r.truth.json"
done
run "$A" -q track "$O/chessboard.model.json" "$BOARD.mcap" --object-frame board -o "$O/chessboard.poses.json"
run "$A" eval --poses "$O/chessboard.poses.json" "$BOARD.truth.json"
