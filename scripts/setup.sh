# Sourced by the README's commands: installs what the project needs on a fresh
# Debian machine, saying what it does; stops with a clear message otherwise.
# Usage: source scripts/setup.sh; need_target; need_debian qemu-system-arm ...

say() { printf '\033[1m==> %s\033[0m\n' "$*"; }
die() { printf 'error: %s\n' "$*" >&2; exit 1; }

need_target() {
  if ! rustup target list --installed 2>/dev/null | grep -qx thumbv7em-none-eabihf; then
    say "installing the Rust target thumbv7em-none-eabihf (rustup target add)"
    rustup target add thumbv7em-none-eabihf || die "could not install thumbv7em-none-eabihf: run 'rustup target add thumbv7em-none-eabihf'"
  fi
  # The firmware's linker (.cargo/config.toml): the stack at the bottom of
  # RAM, so an overflow faults instead of corrupting RAM.
  if ! command -v flip-link >/dev/null 2>&1; then
    say "installing flip-link, the firmware's linker (cargo install flip-link, about 15 s)"
    cargo install flip-link --locked --quiet || die "could not install flip-link: run 'cargo install flip-link --locked'"
  fi
}

# need_debian CMD:PACKAGE ...  installs PACKAGE when CMD is not on PATH.
need_debian() {
  local missing=()
  for pair in "$@"; do
    command -v "${pair%%:*}" >/dev/null 2>&1 || missing+=("${pair#*:}")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  say "installing Debian packages: ${missing[*]}"
  local sudo=""
  [ "$(id -u)" -ne 0 ] && sudo="sudo"
  if ! { $sudo apt-get update -qq && DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq "${missing[@]}" >/dev/null; }; then
    die "could not install ${missing[*]}: install them with apt-get and run again"
  fi
}

# need_cargo CMD:CRATE ...  cargo-installs CRATE (--locked: its own tested
# dependency versions) when CMD is not on PATH. A build from source:
# cargo-machete 0.9.2 took 1 min 51 s (99 s CPU) on 2 cores shared with
# other builds.
need_cargo() {
  local missing=()
  for pair in "$@"; do
    command -v "${pair%%:*}" >/dev/null 2>&1 || missing+=("${pair#*:}")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  for crate in "${missing[@]}"; do
    say "installing $crate (cargo install --locked $crate: built from source, about 2 min for cargo-machete on 2 cores)"
    cargo install --locked --quiet "$crate" || die "could not install $crate: run 'cargo install --locked $crate'"
  done
}

# need_python MODULE:PACKAGE ...  pip-installs PACKAGE when MODULE does not import.
need_python() {
  local missing=()
  for pair in "$@"; do
    python3 -c "import ${pair%%:*}" >/dev/null 2>&1 || missing+=("${pair#*:}")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  say "installing Python packages: ${missing[*]}"
  python3 -m pip install -q "${missing[@]}" || die "could not pip install ${missing[*]}"
}

# The firmware is built with its own cargo profile (Cargo.toml
# [profile.firmware]: fat LTO, "s"/"z", full debug info in the ELF), the host
# tools with [profile.release]: `cargo build -p <board> --profile firmware
# --target thumbv7em-none-eabihf` puts the ELFs in FW_DIR.
FW_TARGET=thumbv7em-none-eabihf
FW_PROFILE=firmware
FW_DIR="${CARGO_TARGET_DIR:-target}/$FW_TARGET/$FW_PROFILE"
QEMU_ELF="$FW_DIR/board-qemu-mps2"
STM32_ELF="$FW_DIR/board-nucleo-f446re"
