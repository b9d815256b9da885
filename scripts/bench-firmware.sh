#!/usr/bin/env bash
# Instructions per full compensator evaluation on Cortex-M4, measured under
# QEMU (-icount shift=0; method in boards/qemu-mps2/src/cycles.rs).
# Usage: scripts/bench-firmware.sh [--json]
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh
need_target >&2
need_debian qemu-system-arm:qemu-system-arm arm-none-eabi-nm:binutils-arm-none-eabi >&2
cargo build -q -p board-qemu-mps2 --profile "$FW_PROFILE" --target "$FW_TARGET" >&2
elf="$QEMU_ELF"
golden="${CARGO_TARGET_DIR:-target}/bench-golden.bin"
cargo run -q -p tcomp --release -- golden -o "$golden" --steps 10 >&2
# The FL_THERMAL model the demo serves (export's default: the fit's cross-validated choice per channel).
fl="${CARGO_TARGET_DIR:-target}/bench-fl-model.img"
cargo run -q -p tcomp --release -- export --model demo/fl-thermal-fit.json --run demo/trace.csv -o "$fl" >&2
json=$(QEMU_EXTRA="-icount shift=0" boards/runner.sh "$elf" bench "$golden" "$fl" | grep '^{' | tail -n 1)
[ -n "$json" ] || die "the bench firmware printed no figures"
# Flash taken by the math core: the symbols LTO left under its name in the
# bench image (its step, evaluation, parser, sigmoid table; inlined callers excluded).
core_flash=0
while read -r _ size kind name; do
  case "$kind:$name" in [tTrR]:*thermocomp_core*) core_flash=$((core_flash + 16#$size)) ;; esac
done < <(arm-none-eabi-nm -S --size-sort -C "$elf")
json="${json%\}},\"core_flash_bytes_qemu_image\":$core_flash}"
if [ "${1:-}" = "--json" ]; then
  echo "$json"
else
  python3 -c 'import json,sys; d=json.loads(sys.argv[1]); [print(f"{k:40s} {v}") for k,v in d.items()]' "$json"
fi
