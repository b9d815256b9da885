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
# Unused dependencies fail the tests (issue 48); a crate used only through a
# macro's expansion is listed in its Cargo.toml's
# [package.metadata.cargo-machete] ignored, with the reason.
need_cargo cargo-machete:cargo-machete

say "checking the structure rules (no import circle between files, files <= 800 and functions <= 150 lines)"
python3 scripts/check-structure.py --self-test
python3 scripts/check-structure.py

say "checking for unused dependencies in every Cargo.toml (cargo machete; under a second)"
cargo machete || die "cargo machete found unused dependencies (above): remove them, or list a macro-only use in [package.metadata.cargo-machete] ignored with its reason"

say "building the bench firmware for QEMU (profile $FW_PROFILE, $FW_TARGET; about 1 min on a fresh 2-core machine, seconds once built)"
cargo build -p board-qemu-mps2 --profile "$FW_PROFILE" --target "$FW_TARGET"
say "building the NUCLEO firmware and checking both boards' flash, RAM and stack budgets (scripts/size.sh --check; about 1 min)"
cargo build -p board-nucleo-f446re --profile "$FW_PROFILE" --target "$FW_TARGET"
scripts/size.sh --check

# Host crates only (workspace default-members; boards build for the chip).
say "building every host crate's tests (test profile; the long step on a fresh machine: several minutes on 2 cores, cargo prints each crate; seconds once built)"
cargo test --no-run
say "running every test (host, then the firmware under qemu-system-arm; a few minutes)"
# The QEMU tests are #[ignore]d for plain `cargo test`; here they run too.
cargo test -- --include-ignored
