#!/usr/bin/env bash
# The README's first command: the compensator on the QEMU bench board, on the
# bundled demo data, with a real Modbus master (mbpoll) reading the
# corrections it computes. Installs what it needs first.
#   scripts/demo.sh [trace.csv] [model.img]
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh
need_target
need_debian qemu-system-arm:qemu-system-arm mbpoll:mbpoll
trace="${1:-demo/trace.csv}"
[ -f "$trace" ] || die "demo trace $trace is missing"
target="${CARGO_TARGET_DIR:-target}"

say "building the bench firmware for QEMU (release, $FW_TARGET) and the desktop tool tcomp"
cargo build -q -p board-qemu-mps2 --release --target "$FW_TARGET"
cargo build -q -p tcomp --release
tcomp="$target/release/tcomp"

model="${2:-}"
if [ -z "$model" ]; then
  model="$target/demo-model.img"
  say "exporting the fitted FL_THERMAL model (demo/fl-thermal-fit.json) to a board image: the model blocked cross-validation chose per channel on the training rows"
  "$tcomp" export --model demo/fl-thermal-fit.json --run "$trace" -o "$model"
fi

log="$target/demo-board.log"
say "booting the firmware in qemu-system-arm (mps2-an386): Modbus RTU on a pty, the emulated DS18B20s replaying $trace (one 15 s sample every 20 ms)"
qemu-system-arm -cpu cortex-m4 -machine mps2-an386 -nographic -monitor none \
  -semihosting-config enable=on,target=native -serial pty \
  -kernel "$QEMU_ELF" -append "serve $trace $model 20" >"$log" 2>&1 &
qemu=$!
trap 'kill $qemu 2>/dev/null || true' EXIT
for _ in $(seq 100); do grep -q "serving Modbus RTU" "$log" && break; sleep 0.1; done
grep -q "serving Modbus RTU" "$log" || { cat "$log"; die "the bench board did not start"; }
pty=$(grep -o '/dev/pts/[0-9]*' "$log" | head -n 1)
grep -E "model|serving" "$log"

say "mbpoll (Modbus RTU master) on $pty reads, every 3 s: the sample time (IR 10-11), the status (IR 3) and the corrections of ch3 and ch5 (IR 30-33, int32, 0.1 um, high word first)"
printf '%10s %8s %16s %16s\n' "trace time" "status" "ch3 corr/meas" "ch5 corr/meas"
div() { awk -v a="$1" -v b="$2" 'BEGIN{printf "%.4f", a/b}'; }
measured() { # the trace's measured error of column $2 at time_s $1 (what the compensation should cancel)
  awk -F, -v t="$1" -v col="$2" '/^#/{next} !h{for(i=1;i<=NF;i++) if($i==col) c=i; h=1; next} $1==t{print $c; exit}' "$trace"
}
read_int32() { # start register (1-based for mbpoll), count
  mbpoll -m rtu -a 1 -b 115200 -P none -t 3:int -B -r "$1" -c "$2" -1 -o 1 -q "$pty" 2>/dev/null | sed -n 's/^\[[0-9]*\]:[[:space:]]*//p'
}
last=""
for _ in $(seq 15); do
  sleep 3
  t=$(read_int32 11 1 | head -n 1)
  [ "$t" = "$last" ] && break  # the trace is over; the board keeps serving its last state
  last="$t"
  status=$(mbpoll -m rtu -a 1 -b 115200 -P none -t 3:hex -r 4 -c 1 -1 -o 1 -q "$pty" 2>/dev/null | sed -n 's/^\[[0-9]*\]:[[:space:]]*//p')
  mapfile -t c < <(read_int32 31 2)
  [ -n "$t" ] && [ "${#c[@]}" -eq 2 ] || { echo "  (no answer)"; continue; }
  printf '%8.2f h %8s %7.1f/%-7.1f %7.1f/%-7.1f\n' "$(div "$t" 3600)" "$status" \
    "$(div "${c[0]}" 10)" "$(measured "$t" dch3_um)" "$(div "${c[1]}" 10)" "$(measured "$t" dch5_um)"
done
say "the board's own log (every 50th sample):"
grep '^t=' "$log" | tail -n 12
say "done: the corrections above are what a PLC reads; the register map is in README.md"
