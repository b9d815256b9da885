#!/usr/bin/env bash
# The README's first command: the compensator on the QEMU bench board, on the
# bundled demo data, with a real Modbus master (mbpoll) reading the
# corrections it computes; then the board taking probe references over
# Modbus (scripts/demo_references.py drives mbpoll) and the served error
# without and with them. Installs what it needs first.
#   scripts/demo.sh [trace.csv] [model.img]
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/setup.sh
need_target
need_debian qemu-system-arm:qemu-system-arm mbpoll:mbpoll
trace="${1:-demo/trace.csv}"
[ -f "$trace" ] || die "demo trace $trace is missing"
target="${CARGO_TARGET_DIR:-target}"

# Cargo prints each crate as it compiles it: the long step on a fresh machine.
say "building the bench firmware for QEMU (profile $FW_PROFILE, $FW_TARGET; about 1 min on a fresh 2-core machine, seconds once built)"
cargo build -p board-qemu-mps2 --profile "$FW_PROFILE" --target "$FW_TARGET"
say "building the desktop tool tcomp (release; about 4 CPU-minutes: 4-10 min on a fresh 2-core machine depending on its load, seconds once built)"
cargo build -p tcomp --release
tcomp="$target/release/tcomp"

model="${2:-}"
if [ -z "$model" ]; then
  model="$target/demo-model.img"
  chosen=$(python3 -c 'import json,sys; print(", ".join(f"{k}: {v}" for k,v in json.load(open(sys.argv[1])).get("chosen",{}).items()))' demo/fl-thermal-fit.json)
  say "exporting the fitted FL_THERMAL model (demo/fl-thermal-fit.json) to a board image, with no --use: the model blocked cross-validation chose on the training rows ($chosen)"
  "$tcomp" export --model demo/fl-thermal-fit.json --run "$trace" -o "$model"
fi

# demo/trace.csv is the first 80 % of the FL_THERMAL run; the fit trained on
# the first 60 %, so its last quarter (the run's 60-80 % test block) is held out.
heldout="${DEMO_HELDOUT_FROM:-0.75}"
pace="${DEMO_PACE_MS:-5}"
rows=$(grep -v '^#' "$trace" | tail -n +2 | grep -c .)
split_row=$(awk -v n="$rows" -v f="$heldout" 'BEGIN{printf "%d", n*f}')
split_t=$(grep -v '^#' "$trace" | tail -n +2 | sed -n "$((split_row + 1))p" | cut -d, -f1)

log="$target/demo-board.log"
say "running the demo (about 2.5 min): booting the firmware in qemu-system-arm (mps2-an386): Modbus RTU on a pty, the emulated DS18B20s replaying $trace ($rows samples 15 s apart, one every $pace ms); rows from $(awk -v t="$split_t" 'BEGIN{printf "%.1f h", t/3600}') on were never seen by the fit"
qemu-system-arm -cpu cortex-m4 -machine mps2-an386 -nographic -monitor none \
  -semihosting-config enable=on,target=native -serial pty \
  -kernel "$QEMU_ELF" -append "serve $trace $model $pace" >"$log" 2>&1 &
qemu=$!
trap 'kill $qemu 2>/dev/null || true' EXIT  # whichever board runs last
for _ in $(seq 100); do grep -q "serving Modbus RTU" "$log" && break; sleep 0.1; done
grep -q "serving Modbus RTU" "$log" || { cat "$log"; die "the bench board did not start"; }
pty=$(grep -o '/dev/pts/[0-9]*' "$log" | head -n 1)
# Held open while mbpoll runs: QEMU notices a pty closed and opened again
# only on its 1 s poll, so each mbpoll would otherwise wait about 1 s.
exec 9<>"$pty"
grep -E "model|serving" "$log"

say "mbpoll (Modbus RTU master) on $pty reads, every 2 s, input registers 3-33 in one request (one consistent sample): the status (IR 3), the sample time (IR 10-11) and the corrections of ch3 and ch5 (IR 30-33, int32, 0.1 um, high word first)"
printf '%10s %-9s %8s %16s %16s\n' "trace time" "part" "status" "ch3 corr/meas" "ch5 corr/meas"
div() { awk -v a="$1" -v b="$2" 'BEGIN{printf "%.4f", a/b}'; }
measured() { # the trace's measured error of column $2 at time_s $1 (what the compensation should cancel)
  awk -F, -v t="$1" -v col="$2" '/^#/{next} !h{for(i=1;i<=NF;i++) if($i==col) c=i; h=1; next} $1==t{print $c; exit}' "$trace"
}
part() { awk -v t="$1" -v s="$split_t" 'BEGIN{print (t >= s ? "held-out" : "training")}'; }
u32() { echo $(( (16#${1#0x} << 16) | 16#${2#0x} )); }
i32() { local v; v=$(u32 "$1" "$2"); ((v >= 2147483648)) && v=$((v - 4294967296)); echo "$v"; }
last=""
for _ in $(seq 60); do
  sleep 2
  mapfile -t r < <(mbpoll -m rtu -a 1 -b 115200 -P none -t 3:hex -r 4 -c 31 -1 -o 1 -q "$pty" 2>/dev/null | sed -n 's/^\[[0-9]*\]:[[:space:]]*//p')
  [ "${#r[@]}" -eq 31 ] || { echo "  (no answer)"; continue; }
  t=$(u32 "${r[7]}" "${r[8]}")
  [ "$t" = "$last" ] && break  # the trace is over; the board keeps serving its last state
  last="$t"
  printf '%8.2f h %-9s %8s %7.1f/%-7.1f %7.1f/%-7.1f\n' "$(div "$t" 3600)" "$(part "$t")" "${r[0]}" \
    "$(div "$(i32 "${r[27]}" "${r[28]}")" 10)" "$(measured "$t" dch3_um)" \
    "$(div "$(i32 "${r[29]}" "${r[30]}")" 10)" "$(measured "$t" dch5_um)"
done
for _ in $(seq 300); do grep -q "trace done" "$log" && break; sleep 0.2; done

say "the held-out part, hour by hour, from the board's own log: what it served (um) next to what the probe measured"
printf '%10s %16s %16s\n' "trace time" "ch3 served/meas" "ch5 served/meas"
grep '^t=' "$log" | awk -v s="$split_t" -F'[ =]' '
  { t = $2 / 1000; if (t < s || t < next_t) next; next_t = t + 3600;
    c3 = ""; c5 = "";
    for (i = 1; i <= NF; i++) { if ($i == "ch3") c3 = $(i+1); if ($i == "ch5") c5 = $(i+1) }
    sub(/\(.*/, "", c3); sub(/\(.*/, "", c5); print t, c3, c5 }' |
while read -r t c3 c5; do
  printf '%8.2f h %7.1f/%-7.1f %7.1f/%-7.1f\n' "$(div "$t" 3600)" "$c3" "$(measured "$t" dch3_um)" "$c5" "$(measured "$t" dch5_um)"
done

say "the board's error over the whole held-out part ($(awk -v t="$split_t" 'BEGIN{printf "%.1f h", t/3600}') to the end; tcomp replay runs the same fixed-point core, bit for bit):"
"$tcomp" replay "$trace" "$model" --from "$heldout" --to 1.0
exec 9>&-
kill "$qemu" 2>/dev/null || true
wait "$qemu" 2>/dev/null || true

# Probe references (issue 28): the same model and trace, the bench board's
# emulated eddy-current probe reading at the gauge what the trace measured.
# The board asks for references (issue 51): settle s : interval s : speed
# step rpm, holding registers 46-48 (AskParams::SUGGESTED).
ask="${DEMO_ASK:-900:4200:500}"
IFS=: read -r ask_settle ask_interval ask_step <<<"$ask"
desk="$target/demo-references-desktop.json"
"$tcomp" replay "$trace" "$model" --from "$heldout" --to 1.0 --reference-when-asked \
  --ask-settle "${ask_settle}s" --ask-interval "${ask_interval}s" --ask-speed-step "$ask_step" --json >"$desk"
column=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["references"]["channels"][0]["column"])' "$desk")
probe_trace="$target/demo-probe-trace.csv"
python3 scripts/demo_references.py trace "$trace" "$probe_trace" --column "$column" --noise-um 0.3 --seed 28 --chip 20:1:50
say "probe references over Modbus: the board boots again on the same model; its emulated probe reads at the gauge the trace's measured $column + 0.3 um noise (seeded), with a chip on the gauge (+50 um) from 20 h to 21 h. mbpoll plays the PLC: it commissions the fresh board (its own unlock key), writes holding register 40 = 0 (the probe measures direction 0, $column), and holding registers 46-48 = $ask (the board asks for a reference $((ask_settle / 60)) min after a spindle-speed change of $ask_step rpm or more, and when $((ask_interval / 60)) min have passed since the last one), then writes command 12 (take a probe reference) only while input register 23 says the board asks (after a refusal it waits 10 min of trace time), and reads input registers 3-53 (served correction, model prediction) as often as it can"
log2="$target/demo-board-references.log"
qemu-system-arm -cpu cortex-m4 -machine mps2-an386 -nographic -monitor none \
  -semihosting-config enable=on,target=native -serial pty \
  -kernel "$QEMU_ELF" -append "serve $probe_trace $model $pace" >"$log2" 2>&1 &
qemu=$!
for _ in $(seq 100); do grep -aq "serving Modbus RTU" "$log2" && break; sleep 0.1; done
grep -aq "serving Modbus RTU" "$log2" || { cat "$log2"; die "the bench board did not start"; }
pty=$(grep -ao '/dev/pts/[0-9]*' "$log2" | head -n 1)
python3 scripts/demo_references.py run --pty "$pty" --trace "$probe_trace" --column "$column" \
  --direction 0 --when-asked "$ask" --split-s "$split_t" --json "$target/demo-references.json"
python3 - "$desk" <<'PY'
import json, sys
c = json.load(open(sys.argv[1]))["references"]["channels"][0]
print(f"  the desktop's replay of the same rules (tcomp replay --reference-when-asked: the board's own ask rule,"
      f" the PLC probing at the next sample, its own simulated 0.3 um noise, no chip; {c['references']} references),"
      f" {c['column']} over the held-out part, every row:"
      f" MAE {c['mae_without_um']:.2f} -> {c['mae_um']:.2f} um, RMS {c['rms_without_um']:.2f} -> {c['rms_um']:.2f} um")
PY
say "done: the corrections above are what a PLC reads; the register map is in docs/register-map.md, references in README.md (Probe references)"
