#!/usr/bin/env python3
"""The demo's probe-reference part (issue 28): a PLC's side of references,
played by mbpoll (a real Modbus RTU master) against the QEMU bench board.

The board replays a trace whose `dprobe_um` column is what its emulated
eddy-current probe reads at the gauge. This script commissions the fresh
board (its own unlock key), names the direction the probe measures
(holding register 40), then, while the trace runs, reads the served
corrections (input registers 3-53, one request: one consistent snapshot)
as often as it can and writes command 12 ("take a probe reference") once
per `--every-s` of trace time, or, with `--when-asked`, only while the
board asks for one (input register 23, by the rule holding registers 46-48
set: issue 51). It prints each reference as the board
reports it (input registers 300-311) and the served error against the
measured displacement of the trace (`--column`), without and with
references, from the snapshots it read.

"Without references" is the model's own prediction of the same snapshot
(input registers 42-53): what the board serves without references as long
as the compensator neither clamped nor rate-limited it nor lost a sensor
(status bits 1, 3, 7 clear). Snapshots with one of those bits are left out
of both figures (and counted).

  demo_references.py trace demo/trace.csv probe.csv --column dch3_um [--noise-um 0.3] [--seed 28]
      [--chip FROM_H:HOURS:UM]
  demo_references.py run --pty /dev/pts/N --trace probe.csv --column dch3_um
      [--direction 0] [--every-s 3600 | --when-asked 900:4200:500 [--retry-s 600]]
      [--split-s T] [--json OUT]
"""
import argparse
import csv
import json
import math
import os
import random
import secrets
import subprocess
import sys
import time

# Protocol addresses (protocol/src/holding.rs, registers.rs).
HR_UNLOCK, HR_COMMAND, HR_RESULT = 0, 1, 2
HR_PROBE_DIRECTION, HR_REFERENCE_SAMPLES = 40, 41
HR_ASK_SETTLE, HR_ASK_INTERVAL, HR_ASK_SPEED_STEP = 46, 47, 48
HR_KEY_STATE, HR_NEW_UNLOCK_KEY = 66, 67
FACTORY_UNLOCK_CODE = 0xA5C3
CMD_TAKE_PROBE_REFERENCE, CMD_RESET_REFERENCE_TERMS, CMD_SET_UNLOCK_KEY = 12, 13, 15
IR_STATUS, IR_SAMPLE_TIME, IR_CORRECTIONS, IR_PREDICTIONS = 3, 10, 30, 42
IR_PROBE, IR_REF_WANTED, IR_REF = 20, 23, 300
WANTED_NAMES = {1: "speed change", 2: "interval"}
OK, COMMIT_IN_PROGRESS, PROBE_REFERENCE_PENDING, REFERENCE_REFUSED = 0, 23, 60, 61
RESULT_NAMES = {0: "accepted", 61: "refused", 62: "probe not ready",
                63: "no probe direction", 64: "probe temperature missing"}
# Status bits after which the prediction is not what the model alone serves.
NOT_PLAIN = (1 << 1) | (1 << 3) | (1 << 7)
SNAPSHOT_FIRST, SNAPSHOT_COUNT = IR_STATUS, IR_PREDICTIONS + 12 - IR_STATUS


class MbpollMaster:
    """Modbus RTU over a pty through mbpoll, one process per request,
    protocol (0-based) addresses."""

    def __init__(self, pty, unit=1, baud=115200, timeout_s=1.0):
        self.base = ["mbpoll", "-m", "rtu", "-a", str(unit), "-b", str(baud), "-P", "none",
                     "-0", "-1", "-o", str(timeout_s), "-q"]
        self.pty = pty
        # Held open (never read) while the master runs: QEMU notices a pty
        # that was closed and opened again only on its 1 s poll, so one
        # mbpoll process per request would wait about 1 s for each answer.
        self.hold = os.open(pty, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        time.sleep(1.1)

    def _run(self, args, values=()):
        p = subprocess.run(self.base + args + [self.pty] + [str(v) for v in values],
                           capture_output=True, text=True, timeout=10)
        return p.returncode, p.stdout

    def _read(self, kind, addr, count):
        rc, out = self._run(["-t", f"{kind}:hex", "-r", str(addr), "-c", str(count)])
        words = [int(line.split(":", 1)[1].strip(), 16)
                 for line in out.splitlines() if line.startswith("[")]
        return words if rc == 0 and len(words) == count else None

    def read_inputs(self, addr, count):
        return self._read(3, addr, count)

    def read_holdings(self, addr, count):
        return self._read(4, addr, count)

    def write(self, addr, value):
        """One holding register; True when the board answered without an exception."""
        rc, _ = self._run(["-t", "4", "-r", str(addr)], [value])
        return rc == 0


def i32(hi, lo):
    v = (hi << 16) | lo
    return v - (1 << 32) if v >= 1 << 31 else v


def i16(v):
    return v - (1 << 16) if v >= 1 << 15 else v


def wait_result(master, timeout_s=10.0, between=None):
    """Holding register 2 once it is neither pending (60) nor storing (23);
    `between()` runs between two reads (the demo keeps reading snapshots
    while the board stores its state, about 1 s of flash erase)."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        r = master.read_holdings(HR_RESULT, 1)
        if r and r[0] not in (PROBE_REFERENCE_PENDING, COMMIT_IN_PROGRESS):
            return r[0]
        if between:
            between()
        else:
            time.sleep(0.02)
    return None


def write_unlocked(master, key, addr, value, tries=3):
    """Unlock with the board's key, then one holding register (a command is
    written alone); a lost reply is tried again (a second command 12 in the
    same cycle is the same reference)."""
    for _ in range(tries):
        if master.write(HR_UNLOCK, key) and master.write(addr, value):
            return True
    return False


def commission(master):
    """A fresh bench board takes the factory code for commissioning only:
    give it its own key (random, never printed) and unlock with that."""
    key = 1 + secrets.randbelow(0xFFFE)
    while key == FACTORY_UNLOCK_CODE:
        key = 1 + secrets.randbelow(0xFFFE)
    ok = (master.write(HR_UNLOCK, FACTORY_UNLOCK_CODE) and master.write(HR_NEW_UNLOCK_KEY, key)
          and master.write(HR_COMMAND, CMD_SET_UNLOCK_KEY))
    if not ok or wait_result(master) != OK:
        sys.exit("error: the board refused commissioning (factory code, HR 67, command 15)")
    return key


def measured_column(trace, column):
    """time_s -> measured value (µm) of `column` in the trace."""
    rows = (line for line in open(trace) if not line.startswith("#"))
    out = {}
    for r in csv.DictReader(rows):
        if r.get(column) not in (None, ""):
            out[int(float(r["time_s"]))] = float(r[column])
    return out


def snapshot(master, d):
    """(status, sample time s, served, model prediction) of direction d (µm) and
    input register 23 (a reference wanted, and why), one request."""
    w = master.read_inputs(SNAPSHOT_FIRST, SNAPSHOT_COUNT)
    if w is None:
        return None
    at = lambda a: a - SNAPSHOT_FIRST  # noqa: E731
    t = (w[at(IR_SAMPLE_TIME)] << 16) | w[at(IR_SAMPLE_TIME) + 1]
    served = i32(w[at(IR_CORRECTIONS) + 2 * d], w[at(IR_CORRECTIONS) + 2 * d + 1]) / 10
    model = i32(w[at(IR_PREDICTIONS) + 2 * d], w[at(IR_PREDICTIONS) + 2 * d + 1]) / 10
    return w[at(IR_STATUS)], t, served, model, w[at(IR_REF_WANTED)]


def take_reference(master, key, d, between=None):
    """Command 12, its result, and the board's reference registers 300-311."""
    if not write_unlocked(master, key, HR_COMMAND, CMD_TAKE_PROBE_REFERENCE):
        return {"result": None, "outcome": "no answer"}
    code = wait_result(master, between=between)
    w = master.read_inputs(IR_REF, 12)
    ref = {"result": code, "outcome": RESULT_NAMES.get(code, f"result {code}")}
    if w:
        ref.update(time_s=(w[0] << 16) | w[1], innovation_um=i32(w[2], w[3]) / 10,
                   accepted=w[4], refused=w[5], bias_um=i16(w[6 + d]) / 10)
    return ref


def figures(samples, measured, split_s):
    """MAE / RMS of measured − served, with and without references, per part."""
    parts = {"whole trace": lambda t: True}
    if split_s is not None:
        parts["held-out"] = lambda t: t >= split_s
    out = {}
    for name, keep in parts.items():
        rows = [(measured[t], s, m) for (st, t, s, m, _) in samples
                if keep(t) and t in measured and not st & NOT_PLAIN]
        left_out = sum(1 for (st, t, *_) in samples if keep(t) and st & NOT_PLAIN)
        n = max(len(rows), 1)
        err = lambda f: ([abs(f(r)) for r in rows], [f(r) ** 2 for r in rows])  # noqa: E731
        (a_w, q_w), (a_m, q_m) = err(lambda r: r[0] - r[1]), err(lambda r: r[0] - r[2])
        out[name] = {"snapshots": len(rows), "left_out": left_out,
                     "mae_without_um": sum(a_m) / n, "rms_without_um": math.sqrt(sum(q_m) / n),
                     "mae_with_um": sum(a_w) / n, "rms_with_um": math.sqrt(sum(q_w) / n)}
    return out


def probe_trace(src, dst, column, noise_um, seed, chip=None):
    """Copy the trace with a `dprobe_um` column: what the probe reads at the
    gauge at that row, the measured `column` plus seeded Gaussian noise
    (rounded to 0.1 µm); comment lines kept. `chip` = (from_s, to_s, um):
    a chip on the gauge adds um to the readings of those rows."""
    rng = random.Random(seed)
    with open(src) as f, open(dst, "w") as out:
        lines = f.read().splitlines()
        head = [x for x in lines if x.startswith("#")]
        body = [x for x in lines if x and not x.startswith("#")]
        cols = body[0].split(",")
        if column not in cols:
            sys.exit(f"error: {src} has no column {column}")
        c, t_col = cols.index(column), cols.index("time_s")
        out.write("\n".join(head + [body[0] + ",dprobe_um"]) + "\n")
        for row in body[1:]:
            cells = row.split(",")
            v, t = cells[c], float(cells[t_col])
            extra = chip[2] if chip and chip[0] <= t < chip[1] else 0.0
            probe = f"{float(v) + rng.gauss(0.0, noise_um) + extra:.1f}" if v else ""
            out.write(f"{row},{probe}\n")


class Poller:
    """Snapshots by sample time; `quiet()` once the sample time stood
    still for `quiet_s` (the trace is over; the board keeps serving)."""

    def __init__(self, master, d, quiet_s):
        self.master, self.d, self.quiet_s = master, d, quiet_s
        self.samples, self.last_t, self.last_change = {}, None, time.monotonic()

    def poll(self):
        s = snapshot(self.master, self.d)
        if s is not None and s[1] != self.last_t:
            self.last_t, self.last_change = s[1], time.monotonic()
            self.samples[s[1]] = s
        return s

    def quiet(self):
        return time.monotonic() - self.last_change > self.quiet_s


def run(master, args):
    d = args.direction
    measured = measured_column(args.trace, args.column)
    if not measured:
        sys.exit(f"error: {args.trace} has no column {args.column}")
    key = commission(master)
    if not write_unlocked(master, key, HR_PROBE_DIRECTION, d) or wait_result(master) != OK:
        sys.exit("error: the board refused holding register 40 (probe direction)")
    asked = None
    if args.when_asked:
        asked = [int(x) for x in args.when_asked.split(":")]
        for reg, v in zip((HR_ASK_SETTLE, HR_ASK_INTERVAL, HR_ASK_SPEED_STEP), asked):
            if not write_unlocked(master, key, reg, v) or wait_result(master) != OK:
                sys.exit(f"error: the board refused holding register {reg} (when to ask)")
    poller, refs = Poller(master, d, args.quiet_s), []
    next_ref, end_s = args.every_s, max(measured)
    retry_at = 0
    print("each reference as the board reports it: when the PLC asked (trace time), when the board"
          " took it (IR 300-301), the innovation (IR 302-303: probe reading - model - bias, um),"
          " the outcome (HR 2), the bias term b after it (IR 306 + direction, um), accepted/refused"
          " so far (IR 304/305)")
    print(f"{'asked at':>10} {'taken at':>10} {'innovation':>10} {'outcome':>9} {'bias b':>7} {'acc/ref':>7}")
    while not poller.quiet():
        s = poller.poll()
        if s is not None and s[1] >= end_s:
            break  # the trace's last row: the board keeps serving it
        if s is None:
            continue
        t = s[1]
        if asked is not None:
            # The PLC probes only when the board asks (input register 23);
            # after a refusal it waits --retry-s of trace time.
            if s[4] == 0 or t < retry_at:
                continue
        elif t < next_ref:
            continue
        ref = take_reference(master, key, d, between=poller.poll)
        ref["asked_at_s"] = t
        if asked is not None:
            ref["wanted"] = WANTED_NAMES.get(s[4], str(s[4]))
            if ref["result"] != OK:
                retry_at = t + args.retry_s
        refs.append(ref)
        if "time_s" in ref:
            taken = "-" if ref["result"] != OK else f"{ref['time_s'] / 3600:8.2f} h"
            print(f"{t / 3600:8.2f} h {taken:>10} {ref['innovation_um']:10.1f} {ref['outcome']:>9}"
                  f" {ref['bias_um']:7.1f} {ref['accepted']:>3}/{ref['refused']:<3}"
                  + (f"  (asked: {ref['wanted']})" if "wanted" in ref else ""))
        else:
            print(f"{t / 3600:8.2f} h  {ref['outcome']}")
        next_ref = (t // args.every_s + 1) * args.every_s
    return {"direction": d, "column": args.column,
            "every_s": None if asked else args.every_s, "when_asked": asked,
            "split_s": args.split_s, "references": refs,
            "figures": figures(list(poller.samples.values()), measured, args.split_s)}


def print_figures(report):
    print(f"error of what the board served against the displacement the trace measured"
          f" ({report['column']}: the error the compensation should cancel), measured - served,"
          f" over the snapshots mbpoll read; no references = the model's own prediction in the same"
          f" snapshot (IR 42+), references = the served correction (IR 30+); MAE / RMS um:")
    print(f"{'part':>12} {'snapshots':>9} {'no references':>16} {'references':>16}")
    for name, f in report["figures"].items():
        print(f"{name:>12} {f['snapshots']:>9} {f['mae_without_um']:7.2f} / {f['rms_without_um']:<6.2f}"
              f" {f['mae_with_um']:7.2f} / {f['rms_with_um']:<6.2f}"
              + (f"  ({f['left_out']} clamped/rate-limited/sensor-fault left out)" if f["left_out"] else ""))


def main():
    root = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = root.add_subparsers(dest="cmd", required=True)
    tr = sub.add_parser("trace", help="the trace with the probe's reading at the gauge")
    tr.add_argument("src")
    tr.add_argument("dst")
    tr.add_argument("--column", required=True)
    tr.add_argument("--noise-um", type=float, default=0.3)
    tr.add_argument("--seed", type=int, default=28)
    tr.add_argument("--chip", metavar="FROM_H:HOURS:UM",
                    help="a chip on the gauge: readings + UM for HOURS from FROM_H")
    ap = sub.add_parser("run", help="the PLC's side over Modbus (mbpoll)")
    ap.add_argument("--pty", required=True)
    ap.add_argument("--trace", required=True)
    ap.add_argument("--column", required=True, help="measured displacement the probe direction serves")
    ap.add_argument("--direction", type=int, default=0)
    ap.add_argument("--every-s", type=int, default=3600, help="probe once per this much trace time")
    ap.add_argument("--when-asked", metavar="SETTLE_S:INTERVAL_S:STEP_RPM",
                    help="instead of --every-s: set holding registers 46-48 and probe only while"
                         " input register 23 says a reference is wanted")
    ap.add_argument("--retry-s", type=int, default=600,
                    help="with --when-asked: after a refused reference wait this much trace time")
    ap.add_argument("--split-s", type=int, default=None, help="held-out part from this trace time")
    ap.add_argument("--quiet-s", type=float, default=2.5, help="stop when the sample time stands still this long")
    ap.add_argument("--json", help="write the report here")
    args = root.parse_args()
    if args.cmd == "trace":
        chip = None
        if args.chip:
            f, h, um = (float(x) for x in args.chip.split(":"))
            chip = (f * 3600, (f + h) * 3600, um)
        probe_trace(args.src, args.dst, args.column, args.noise_um, args.seed, chip)
        return
    report = run(MbpollMaster(args.pty), args)
    print_figures(report)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(report, f, indent=1)


if __name__ == "__main__":
    main()
