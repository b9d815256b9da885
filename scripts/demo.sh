#!/usr/bin/env bash
# The README's first command: the compensator on the QEMU bench board, on the
# bundled demo data. Installs what it needs first.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh

need_target
need_debian qemu-system-arm:qemu-system-arm

say "building the bench firmware for QEMU (release, $FW_TARGET)"
cargo build -p board-qemu-mps2 --release --target "$FW_TARGET"

trace="${1:-demo/trace.csv}"
[ -f "$trace" ] || die "demo trace $trace is missing"
model="${2:-}"
if [ -z "$model" ]; then
  model="${CARGO_TARGET_DIR:-target}/demo-model.img"
  say "exporting the demo model image with tcomp (quantized by the math core)"
  cargo run -q -p tcomp --release -- export --demo -o "$model"
fi
say "booting the firmware in qemu-system-arm (mps2-an386): replay $trace with model $model"
say "each line: time, sensors ok/faulty, T0, spindle | served correction per direction in um (model prediction in brackets when a limit acted), status bits"
exec boards/runner.sh "$QEMU_ELF" replay "$trace" "$model"
