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
say "booting the firmware in qemu-system-arm (mps2-an386) on $trace"
exec boards/runner.sh "$QEMU_ELF" replay "$trace"
