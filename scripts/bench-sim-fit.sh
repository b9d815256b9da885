#!/usr/bin/env bash
# Accuracy on held-out simulated runs (issue 6): simulate calibration runs of
# the turning center (seed 003's 16-sensor machine) under two duty cycles,
# fit every candidate on them (tcomp fit: MLR, lagged MLR, 5-11-1 GA-BPN,
# chosen per channel by blocked CV on the training rows), export the chosen
# models to a board image (export's default, no --use) and score them on
# runs under duties and noise seeds the fit never saw, with
# the board's own fixed-point arithmetic (tcomp replay). RMS reduction =
# 1 - RMS(residual)/RMS(thermal error).  Usage: scripts/bench-sim-fit.sh [--json]
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh
cargo build -q -p tcomp --release >&2
target="${CARGO_TARGET_DIR:-target}"
tcomp="$target/release/tcomp"
dir="$target/bench-sim-fit"; mkdir -p "$dir"
m=examples/machines/turning-center-16.toml
sim() { "$tcomp" sim "$m" --duty "$1" --seed "$2" --sample-period 10 -o "$dir/$3.csv" >&2; }
sim examples/duty/warmup-steps.toml 1 train1
sim examples/duty/production-mixed.toml 2 train2
sim examples/duty/heldout-varied.toml 11 heldout1
sim examples/duty/production-mixed.toml 12 heldout2
fit_json=$("$tcomp" fit "$dir/train1.csv" "$dir/train2.csv" --validate "$dir/heldout1.csv" "$dir/heldout2.csv" --out "$dir/fit.json" --json)
"$tcomp" export --model "$dir/fit.json" --run "$dir/train1.csv" -o "$dir/model.img" >&2
board1=$("$tcomp" replay "$dir/heldout1.csv" "$dir/model.img" --json)
board2=$("$tcomp" replay "$dir/heldout2.csv" "$dir/model.img" --json)
python3 - "$fit_json" "$board1" "$board2" "${1:-}" <<'PY'
import json, sys
fit, b1, b2, mode = json.loads(sys.argv[1]), json.loads(sys.argv[2]), json.loads(sys.argv[3]), sys.argv[4]
out = {"machine": "turning-center-16", "train_runs": ["warmup-steps/1", "production-mixed/2"],
       "heldout_runs": ["heldout-varied/11", "production-mixed/12"], "float_models": {}, "chosen": fit.get("chosen", {}), "board_chosen": {}}
for m in fit["models"]:
    out["float_models"][m["name"]] = {c: round(v["reduction_pct"], 1) for c, v in m["channels"].items()}
for name, b in (("heldout-varied/11", b1), ("production-mixed/12", b2)):
    out["board_chosen"][name] = {c["column"]: {"rms_um": round(c["rms_um"], 2), "reduction_pct": round(c["reduction_pct"], 1)} for c in b["channels"]}
if mode == "--json":
    print(json.dumps(out))
else:
    print("held-out RMS reduction, float models (validation runs pooled):")
    for k, v in out["float_models"].items():
        print(f"  {k:12s} {v}")
    print(f"held-out, the chosen models {out['chosen']} on the board's fixed-point arithmetic:")
    for k, v in out["board_chosen"].items():
        print(f"  {k:22s} {v}")
PY
