#!/usr/bin/env bash
# Probe references on every displacement channel of the real run (issue 28):
# FL_THERMAL ch1-ch5, each fitted by the default pipeline on the first 60 %
# (ch3/ch5: the published fit demo/fl-thermal-fit.json; ch1, ch2, ch4: the
# same command for those channels), replayed through the board's fixed point
# and the core's update rule (`tcomp replay --reference-every`, bit-exact),
# scored on the test block (60-80 %) and the rest (80-100 %).
# Per channel and block: model alone / one reference per 1 h / per 4 h
# (also with one 10 or 30 min after every change of spindle speed),
# clean and with 5 % of the references +50 um (seeds 1..3), and two
# information floors from the same rows (no rule involved):
#  - hold exact: the true error at each reference instant, noise-free, held
#    until the next one (what a bias-only rule with gain 1 serves);
#  - interval mean: the true mean error of each interval between two
#    references (non-causal: it knows the future of the interval);
# and the 1 h residual split into the hour after a spindle-speed change and
# the rest; one re-zero at 60 % scored 60-100 % against the raw error;
# a sweep of the rule's constants; hourly references averaged over six clock
# phases, with the number of references each schedule took; on ch3/ch5,
# references when the board asks (`--reference-when-asked`) against no
# references, hourly (six phases) and the clock schedule at the same count
# (six phases), each with its count (issue 51), and on the board's very
# schedule the rule's information floors (hold exact, hold the noisy reading,
# interval mean): how much of the gap is the rule and how much the model.
# Usage: scripts/bench-probe-channels.sh [--json]
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
dir="$target/bench-probe-channels"; mkdir -p "$dir"
if [ ! -f "$dir/fit124.json" ]; then
  "$tcomp" fit "$run" --split-chrono 0.6,0.8 --channels dch1_um,dch2_um,dch4_um --out "$dir/fit124.json" --json >/dev/null
fi
"$tcomp" export --model demo/fl-thermal-fit.json --run "$run" -o "$dir/fl35.img" >&2
"$tcomp" export --model "$dir/fit124.json" --run "$run" -o "$dir/fl124.img" >&2
for img in fl35 fl124; do
  # A clock schedule, optionally with one reference 10 or 30 min after
  # every change of spindle speed (`--reference-after-change`).
  for sched in 1h 4h 1h+10min 4h+10min 1h+30min 4h+30min; do
    every=${sched%%+*}
    for s in 1 2 3; do
      for o in clean 5%:50; do
        extra=(); [ "$o" = clean ] || extra=(--reference-outliers "$o")
        [ "$sched" = "$every" ] || extra+=(--reference-after-change "${sched#*+}")
        tag="$img-$sched-$s-${o//[%:]/_}"
        # Scored on the test block in tcomp's own JSON: the script checks its
        # own scoring of the dump against it.
        "$tcomp" replay "$run" "$dir/$img.img" --from 0.6 --to 0.8 --json --reference-every "$every" \
          --reference-seed "$s" "${extra[@]}" --reference-dump "$dir/$tag.csv" >"$dir/$tag.json"
      done
    done
  done
done
# Hourly references at six clock phases (issue 51: the phase alone moves the
# figures; compare schedules averaged over phases, at equal counts): seed 1,
# clean, the first reference 0, 10, …, 50 min into the run.
for img in fl35 fl124; do
  for phase in 0 10min 20min 30min 40min 50min; do
    "$tcomp" replay "$run" "$dir/$img.img" --from 0.6 --to 0.8 --json --reference-every 1h \
      --reference-phase "$phase" --reference-seed 1 \
      --reference-dump "$dir/phase-$img-$phase.csv" >"$dir/phase-$img-$phase.json"
  done
done
# References when the board asks (issue 51 item 3: `--reference-when-asked`,
# the math core's rule with its suggested parameters, the PLC probing at the
# next sample), ch3/ch5, whole run dumped and scored per block from the dump;
# clean (seed 1) and with 5 % of the readings +50 um. Then the clock schedule
# at the same count per block and channel (interval = block length / the
# references the board asked for in it), at six phases: schedules compared at
# equal counts.
img=fl35
"$tcomp" replay "$run" "$dir/$img.img" --from 0.6 --to 0.8 --json --reference-when-asked \
  --reference-seed 1 --reference-dump "$dir/asked-$img.csv" >"$dir/asked-$img.json"
"$tcomp" replay "$run" "$dir/$img.img" --from 0.6 --to 0.8 --json --reference-when-asked \
  --reference-seed 1 --reference-outliers 5%:50 --reference-dump "$dir/asked-$img-5__50.csv" >"$dir/asked-$img-5__50.json"
python3 scripts/probe_channels.py --equal-count "$dir" | while read -r tag every; do
  for k in 0 1 2 3 4 5; do
    phase=$(python3 -c "print('0' if $k == 0 else '%.3fs' % ($every * $k / 6))")
    "$tcomp" replay "$run" "$dir/$img.img" --from 0.6 --to 0.8 --json --reference-every "${every}s" \
      --reference-phase "$phase" --reference-seed 1 \
      --reference-dump "$dir/eq-$tag-$k.csv" >"$dir/eq-$tag-$k.json"
  done
done
# Alternatives of the rule's constants (seed 1, clean), same rows: how far
# the rule's own family moves the figures.
sweep() { # name params...
  local name=$1; shift
  local args=()
  for p in "$@"; do args+=(--reference-param "$p"); done
  for img in fl35 fl124; do
    for every in 1h 4h; do
      "$tcomp" replay "$run" "$dir/$img.img" --from 0.6 --to 0.8 --json --reference-every "$every" \
        --reference-seed 1 "${args[@]}" --reference-dump "$dir/sweep-$name-$img-$every.csv" >/dev/null
    done
  done
}
# One re-zero at the start of the rest (60 %), scored 60-100 %: RMS against
# the raw error about the re-zero.
for img in fl35 fl124; do
  "$tcomp" replay "$run" "$dir/$img.img" --from 0.6 --to 1.0 --json --reference-at 60% >"$dir/rezero-$img.json"
done
sweep defaults
sweep bias-only sigma_rate_um_h=0
sweep bias-random-walk sigma_bias_um=10 tau_bias_h=48 sigma_rate_um_h=0
sweep noise-1um sigma_ref_um=1
sweep slow-drift sigma_rate_um_h=4 tau_rate_h=8
sweep fast-fade tau_bias_h=2
sweep slow-fade tau_bias_h=12
python3 scripts/probe_channels.py "$dir" "$run" "$json"
