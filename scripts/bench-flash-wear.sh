#!/usr/bin/env bash
# Flash wear (issue 47): the application on the mock flash for one simulated
# year — a probe reference every minute, a settings write every hour — and
# the erases per sector of the settings store (3 × 16 KiB) and of the model
# slots, with the most pages one store erased. Goal: ≤ 10,000 erases per
# sector in 10 years, 0 model-slot erases, ≤ 1 page erase per store.
#   Usage: scripts/bench-flash-wear.sh [--json] [--minutes N]
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh
say "building the wear bench (release, host)" >&2
cargo build -q --release -p host-tests --bin bench-flash-wear >&2
"${CARGO_TARGET_DIR:-target}/release/bench-flash-wear" "$@"
