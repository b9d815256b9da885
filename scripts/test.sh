#!/usr/bin/env bash
# The README's second command: every test. Installs what it needs first.
#   host unit and integration tests (math core, application, desktop tools,
#   pin-level 1-Wire emulator, mock flash), then the bench firmware under QEMU
#   (boot, self-test, golden vectors, Modbus with real masters).
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh

need_target
need_debian qemu-system-arm:qemu-system-arm arm-none-eabi-size:binutils-arm-none-eabi mbpoll:mbpoll
need_python pymodbus:pymodbus serial:pyserial

say "checking the structure rules (no import circle between files, files <= 800 and functions <= 150 lines)"
python3 scripts/check-structure.py --self-test
python3 scripts/check-structure.py

say "building the bench firmware for QEMU (release, $FW_TARGET)"
cargo build -p board-qemu-mps2 --release --target "$FW_TARGET"

say "running every test (host, then the firmware under qemu-system-arm)"
# Host crates only (workspace default-members; boards build for the chip).
# The QEMU tests are #[ignore]d for plain `cargo test`; here they run too.
cargo test -- --include-ignored
