#!/usr/bin/env bash
# Flash and RAM use of each firmware image (release builds must exist).
# Usage: scripts/size.sh [--json]
# RAM is .data + .bss (static use); the stack grows down from the top of RAM
# and is not counted here.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh
need_debian arm-none-eabi-size:binutils-arm-none-eabi >&2
dir="${CARGO_TARGET_DIR:-target}/$FW_TARGET/release"
json=0; [ "${1:-}" = "--json" ] && json=1
# board, flash budget KiB, RAM budget KiB (from each board-memory.x)
boards=("board-nucleo-f446re 256 128" "board-qemu-mps2 3584 4096")
out="{"; first=1
for entry in "${boards[@]}"; do
  read -r name flash_kib ram_kib <<<"$entry"
  elf="$dir/$name"
  [ -f "$elf" ] || die "$elf not built: cargo build -p $name --release --target $FW_TARGET"
  read -r text data bss _ < <(arm-none-eabi-size "$elf" | tail -n 1)
  flash=$((text + data)); ram=$((data + bss))
  if [ $json -eq 1 ]; then
    [ $first -eq 1 ] || out+=","
    out+="\"$name\":{\"flash_bytes\":$flash,\"ram_bytes\":$ram,\"flash_budget_bytes\":$((flash_kib*1024)),\"ram_budget_bytes\":$((ram_kib*1024))}"
  else
    printf '%-22s flash %7d B of %4d KiB (%5.1f %%)   RAM %6d B of %4d KiB (%5.1f %%)\n' \
      "$name" "$flash" "$flash_kib" "$(awk "BEGIN{print 100*$flash/($flash_kib*1024)}")" \
      "$ram" "$ram_kib" "$(awk "BEGIN{print 100*$ram/($ram_kib*1024)}")"
  fi
  first=0
done
[ $json -eq 1 ] && echo "$out}"
exit 0
