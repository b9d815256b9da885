#!/usr/bin/env bash
# FL_THERMAL on the board's own arithmetic: export the fitted models
# (demo/fl-thermal-fit.json, or fit them again with --refit) to a model
# image and replay the whole measured run through the fixed-point core the
# firmware runs (bit-exact); score the published test block (60-80 %).
# Usage: scripts/bench-fl-thermal.sh [--json] [--refit]
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh
json=""; refit=0
for a in "$@"; do case "$a" in --json) json="--json";; --refit) refit=1;; esac; done
run=../shared/data/caiviac-fl-thermal/run.csv
[ -f "$run" ] || die "$run is missing (the shared data directory sits beside this repository)"
cargo build -q -p tcomp --release >&2
target="${CARGO_TARGET_DIR:-target}"
tcomp="$target/release/tcomp"
fit=demo/fl-thermal-fit.json
if [ "$refit" = 1 ]; then
  fit="$target/fl-thermal-fit.json"
  "$tcomp" fit "$run" --split-chrono 0.6,0.8 --channels dch3_um,dch5_um --out "$fit" --json >/dev/null
fi
img="$target/fl-thermal.img"
"$tcomp" export --model "$fit" --run "$run" -o "$img" >&2
"$tcomp" replay "$run" "$img" --from 0.6 --to 0.8 $json
