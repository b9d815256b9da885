#!/usr/bin/env bash
# Issue 50, item 6: do the thermal models hold outside their training
# envelope? Per case (one channel of one run, fitted on its training part,
# scored on the part it serves), MAE and RMS of the default pipeline (what
# `tcomp fit` + `tcomp export` ship, no hand pick, replayed on the board's
# fixed-point arithmetic) beside a ridge with its penalty chosen by
# time-blocked forward-chaining CV on the training rows, the plain MLR, the
# GA-BPN network and the raw error after an operator's re-zero at the start
# of the served part. Cases: FL_THERMAL (the repository's real run, its
# published split 60 / 20 %), every channel; simulated turning-centre runs
# whose served 40 % is 2 K warmer or at spindle speeds never trained on
# (3 seeds each). Headline: on how many cases the default is worse than the
# ridge by more than 5 % and worse than the raw error after a re-zero.
# Issue 50 item 4 ("a re-zero is a promise"): per case, a re-zero (command 2,
# as `tcomp replay --reference-at`) at the start of every steady block of the
# served part (spindle unchanged, median temperature rate < 1 K/h over 15
# min, >= 30 min), the board's residual against the raw error about it over
# the block; blocks worse by MAE / RMS, by how much, with their envelope
# share and the inputs outside their training range.
# Usage: scripts/bench-extrapolation.sh [--json]   (about a minute or two)
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh
json=""
for a in "$@"; do case "$a" in --json) json="--json";; *) die "unknown argument $a (only --json)";; esac; done
run=../shared/data/caiviac-fl-thermal/run.csv
[ -f "$run" ] || die "$run is missing (the shared data directory sits beside this repository)"
say "building bench-extrapolation (cargo --release)" >&2
cargo build -q -p tcomp-bench --release --bin bench-extrapolation >&2
target="${CARGO_TARGET_DIR:-target}"
"$target/release/bench-extrapolation" --data "$run" $json
