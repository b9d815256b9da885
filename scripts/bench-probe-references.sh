#!/usr/bin/env bash
# Closing the loop with the probe (issue 28): the board's fixed-point
# output with simulated probe references at a gauge (the core's update
# rule, bit-exact) and operator re-zeros, scored on FL_THERMAL.
#  - test block (published 60-80 %, default fit demo/fl-thermal-fit.json):
#    no reference / every 1 h / every 4 h, probe noise 0.3 um, clean and
#    with 5 % of the references +50 um, seeds 1..5;
#  - the tuning part (80-100 %, where the rule's defaults were chosen);
#  - re-zero at the start of the rest (60 %) after a fit on the first 60 %:
#    FL_THERMAL (scored 60-80 % and 60-100 %) and the demo trace refitted on
#    its own first 60 % (scored 60-100 % of the trace).
# Usage: scripts/bench-probe-references.sh [--json]
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh
json=0
for a in "$@"; do case "$a" in --json) json=1;; esac; done
run=../shared/data/caiviac-fl-thermal/run.csv
[ -f "$run" ] || die "$run is missing (the shared data directory sits beside this repository)"
cargo build -q -p tcomp --release >&2
target="${CARGO_TARGET_DIR:-target}"
tcomp="$target/release/tcomp"
dir="$target/bench-probe"; mkdir -p "$dir"
"$tcomp" export --model demo/fl-thermal-fit.json --run "$run" -o "$dir/fl.img" >&2
# The demo trace refitted on its own first 60 % (the default pipeline).
if [ ! -f "$dir/trace-fit.json" ]; then
  "$tcomp" fit demo/trace.csv --split-chrono 0.6,0.8 --channels dch3_um,dch5_um --out "$dir/trace-fit.json" --json >/dev/null
fi
"$tcomp" export --model "$dir/trace-fit.json" --run demo/trace.csv -o "$dir/trace.img" >&2
out="$dir/cases.jsonl"; : >"$out"
case_() { # label run img from to args...
  local label=$1 r=$2 img=$3 from=$4 to=$5; shift 5
  "$tcomp" replay "$r" "$img" --from "$from" --to "$to" --json "$@" |
    python3 -c 'import json,sys; d=json.load(sys.stdin); print(json.dumps({"label": sys.argv[1], "references": d["references"]}))' "$label" >>"$out"
}
for blk in "test 0.6 0.8" "tune 0.8 1.0"; do
  set -- $blk
  for s in 1 2 3 4 5; do
    for every in 1h 4h; do
      case_ "$1 every $every seed $s" "$run" "$dir/fl.img" "$2" "$3" --reference-every $every --reference-seed $s
      case_ "$1 every $every 5%:50 seed $s" "$run" "$dir/fl.img" "$2" "$3" --reference-every $every --reference-seed $s --reference-outliers 5%:50
    done
  done
done
case_ "rezero fl 60% scored 60-80" "$run" "$dir/fl.img" 0.6 0.8 --reference-at 60%
case_ "rezero fl 60% scored 60-100" "$run" "$dir/fl.img" 0.6 1.0 --reference-at 60%
case_ "rezero trace 60% scored 60-100" demo/trace.csv "$dir/trace.img" 0.6 1.0 --reference-at 60%
case_ "rezero fl 60% + every 4h scored 60-100" "$run" "$dir/fl.img" 0.6 1.0 --reference-at 60% --reference-every 4h
case_ "rezero trace 60% + every 4h scored 60-100" demo/trace.csv "$dir/trace.img" 0.6 1.0 --reference-at 60% --reference-every 4h
python3 - "$out" "$json" <<'PY'
import json, sys, collections
cases = [json.loads(l) for l in open(sys.argv[1])]
agg = collections.OrderedDict()
for c in cases:
    lab = c["label"]
    key = lab.split(" seed ")[0]
    for ch in c["references"]["channels"]:
        a = agg.setdefault((key, ch["column"]), collections.defaultdict(list))
        for k in ("mae_um", "rms_um", "mae_without_um", "rms_without_um", "raw_mae_um", "raw_rms_um",
                  "references_in_block", "corrupted", "corrupted_refused", "clean_refused"):
            a[k].append(ch[k])
rows = []
for (key, col), a in agg.items():
    n = len(a["mae_um"])
    mean = lambda k: sum(a[k]) / n
    rows.append({"case": key, "channel": col, "seeds": n,
                 "mae_um": round(mean("mae_um"), 3), "mae_max_um": round(max(a["mae_um"]), 3),
                 "rms_um": round(mean("rms_um"), 3), "mae_without_um": round(mean("mae_without_um"), 3),
                 "rms_without_um": round(mean("rms_without_um"), 3), "raw_rms_um": round(mean("raw_rms_um"), 3),
                 "references_in_block": a["references_in_block"][0],
                 "corrupted": sum(a["corrupted"]), "corrupted_refused": sum(a["corrupted_refused"]),
                 "clean_refused": sum(a["clean_refused"])})
if sys.argv[2] == "1":
    print(json.dumps({"cases": rows}))
else:
    print("| case | channel | MAE µm (mean / worst of seeds) | RMS µm | model alone MAE / RMS | raw RMS | refs in block | corrupted refused | clean refused |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['case']} | {r['channel']} | {r['mae_um']:.2f} / {r['mae_max_um']:.2f} | {r['rms_um']:.2f} | {r['mae_without_um']:.2f} / {r['rms_without_um']:.2f} | {r['raw_rms_um']:.2f} | {r['references_in_block']} | {r['corrupted_refused']}/{r['corrupted']} | {r['clean_refused']} |")
PY
