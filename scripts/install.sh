#!/usr/bin/env bash
# Installs the desktop CLI `tcomp` on this machine (Linux, macOS or Windows
# with a Rust toolchain: https://rustup.rs) into ~/.cargo/bin, the release
# profile's build (no debug info, about 9.4 MB). No firmware tools needed.
#   scripts/install.sh [extra cargo install arguments, e.g. --root DIR]
set -euo pipefail
cd "$(dirname "$0")/.."
say() { printf '\033[1m==> %s\033[0m\n' "$*"; }
command -v cargo >/dev/null || { echo "error: cargo is missing: install Rust from https://rustup.rs" >&2; exit 1; }
say "building and installing tcomp (cargo install --path desktop/tcomp --locked; about 4 CPU-minutes: 4-10 min on a 2-core machine, cargo prints each crate)"
cargo install --path desktop/tcomp --locked "$@"
say "installed: $(command -v tcomp || echo "tcomp (add ~/.cargo/bin to PATH)"); try: tcomp --help"
