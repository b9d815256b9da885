#!/usr/bin/env bash
# cargo runner for thumbv7em-none-eabihf (see .cargo/config.toml): picks the
# tool by the firmware's name.
#   board-qemu-mps2 ELF      -> qemu-system-arm (mps2-an386, semihosting);
#                               extra arguments become the firmware's command
#                               line (selftest [golden.bin] | replay <run.csv> | ...)
#   board-nucleo-f446re ELF  -> probe-rs run (flash + defmt logs over RTT)
set -euo pipefail
elf="$1"; shift
case "$(basename "$elf")" in
  board-qemu-mps2*)
    command -v qemu-system-arm >/dev/null || {
      echo "runner: qemu-system-arm is missing: apt-get install qemu-system-arm" >&2; exit 127; }
    exec qemu-system-arm -cpu cortex-m4 -machine mps2-an386 -nographic \
      -semihosting-config enable=on,target=native \
      ${QEMU_EXTRA:-} -kernel "$elf" -append "$*" ;;
  board-nucleo-f446re*)
    command -v probe-rs >/dev/null || {
      echo "runner: probe-rs is missing: cargo install probe-rs-tools --locked" >&2; exit 127; }
    exec probe-rs run --chip STM32F446RETx "$elf" ;;
  *)
    echo "runner: don't know how to run $elf" >&2; exit 2 ;;
esac
