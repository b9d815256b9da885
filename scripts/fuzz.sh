#!/usr/bin/env bash
# Fuzz every cargo-fuzz target for SECONDS each (default 30: the CI smoke run)
# with overflow checks ON: without -O, cargo fuzz builds optimised but with
# debug assertions and overflow checks (-O would turn them off, so an
# overflow would wrap silently instead of being a finding).
# Usage: scripts/fuzz.sh [SECONDS]. Prints one line per target: executions,
# and stops with the target's output when it finds something.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh
secs="${1:-30}"

if ! rustup toolchain list 2>/dev/null | grep -q '^nightly'; then
  say "installing the nightly Rust toolchain (cargo fuzz needs it: rustup toolchain install nightly)"
  rustup toolchain install nightly --profile minimal || die "could not install nightly: run 'rustup toolchain install nightly'"
fi
if ! cargo +nightly fuzz --version >/dev/null 2>&1; then
  say "installing cargo-fuzz (cargo install cargo-fuzz --locked)"
  cargo install cargo-fuzz --locked || die "could not install cargo-fuzz: run 'cargo install cargo-fuzz'"
fi

cd fuzz
for target in $(cargo +nightly fuzz list); do
  say "fuzzing $target for ${secs} s (overflow checks on)"
  mkdir -p "corpus/$target"
  log="$(mktemp)"
  # corpus/ collects what the fuzzer finds (not in git); seeds/ are real images and frames.
  if ! cargo +nightly fuzz run "$target" "corpus/$target" "seeds/$target" -- \
      -max_total_time="$secs" -max_len=2048 >"$log" 2>&1; then
    tail -n 60 "$log"
    die "fuzz target $target found a crash (input saved under fuzz/artifacts/$target)"
  fi
  runs="$(grep -o 'Done [0-9]* runs in [0-9]* second' "$log" | tail -n 1)"
  echo "$target: ${runs:-no summary line} (corpus $(ls "corpus/$target" | wc -l) inputs)"
  rm -f "$log"
done
