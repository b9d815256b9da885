#!/usr/bin/env bash
# Modbus RTU requests per second and latency at 115200 baud under QEMU: the
# bench board serves the register map on a TCP socket (RTU framing), pymodbus
# reads 54 input registers (status, sequence, corrections, predictions) N times.
# Usage: scripts/bench-modbus.sh [--json] [N]
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh
need_target >&2
need_debian qemu-system-arm:qemu-system-arm >&2
need_python pymodbus:pymodbus >&2
json=0; [ "${1:-}" = "--json" ] && { json=1; shift; }
n="${1:-1000}"
cargo build -q -p board-qemu-mps2 --profile "$FW_PROFILE" --target "$FW_TARGET" >&2
cargo build -q -p tcomp --release >&2
target="${CARGO_TARGET_DIR:-target}"
model="$target/bench-modbus-model.img"
"$target/release/tcomp" export --model demo/fl-thermal-fit.json --run demo/trace.csv -o "$model" >&2
port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
log="$target/bench-modbus-board.log"
qemu-system-arm -cpu cortex-m4 -machine mps2-an386 -nographic -monitor none \
  -semihosting-config enable=on,target=native \
  -serial "tcp:127.0.0.1:$port,server=on,wait=off,nodelay=on" \
  -kernel "$QEMU_ELF" -append "serve demo/trace.csv $model 100" >"$log" 2>&1 &
qemu=$!
trap 'kill $qemu 2>/dev/null || true' EXIT
for _ in $(seq 100); do grep -q "serving Modbus RTU" "$log" && break; sleep 0.1; done
out=$(python3 host-tests/py/modbus_master.py rate --port "$port" --n "$n")
if [ "$json" = 1 ]; then
  echo "$out"
else
  python3 -c 'import json,sys; d=json.loads(sys.argv[1]); [print(f"{k:28s} {v}") for k,v in d.items()]' "$out"
fi
