"""Scoring of scripts/bench-probe-channels.sh (issue 28): per channel and
block of FL_THERMAL, the board's served correction with probe references
(from `tcomp replay --reference-dump`) against the model alone, and the
information floors of a reference schedule. Standard library only.

Usage: probe_channels.py DIR RUN JSON(0|1)
       probe_channels.py --equal-count DIR   (per channel and block: the clock
       interval at the count the board asked for, for the script's replays)
"""
import csv
import json
import sys

BLOCKS = {"test 60-80 %": (0.6, 0.8), "rest 80-100 %": (0.8, 1.0)}
IMAGES = {"fl35": ["dch3_um", "dch5_um"], "fl124": ["dch1_um", "dch2_um", "dch4_um"]}
SEEDS = (1, 2, 3)
SCHEDULES = ("1h", "4h", "1h+10min", "4h+10min", "1h+30min", "4h+30min")


def read_csv(path):
    with open(path) as f:
        rows = [l for l in f if not l.startswith("#")]
    return list(csv.DictReader(rows))


def num(v):
    return float(v) if v not in ("", None) else None


def mae(pairs):
    pairs = list(pairs)
    return sum(abs(a - b) for a, b in pairs) / max(len(pairs), 1)


def reference_rows(time_s, measured, every_s):
    """Rows of the simulated references: as tcomp (k*every from the first time,
    first row at or after it with a measured value)."""
    out, k, row = [], 1, 0
    while True:
        due = time_s[0] + every_s * k
        while row < len(time_s) and time_s[row] < due:
            row += 1
        if row >= len(time_s):
            return out
        if measured[row] is not None:
            out.append(row)
        k += 1


def floors(time_s, meas, model, every_s, lo, hi):
    refs = reference_rows(time_s, meas, every_s)
    err = [None if m is None else m - p for m, p in zip(meas, model)]
    n = len(time_s)
    hold, mean = list(model), list(model)
    bounds = [0] + refs + [n]
    for a, b in zip(bounds, bounds[1:]):
        seg = [e for e in err[a:b] if e is not None]
        avg = sum(seg) / len(seg) if seg else 0.0
        for i in range(a, b):
            mean[i] = model[i] + avg
            if a in refs:
                hold[i] = model[i] + err[a]
    scored = [i for i in range(int(lo * n), int(hi * n)) if meas[i] is not None]
    return (
        mae((meas[i], hold[i]) for i in scored),
        mae((meas[i], mean[i]) for i in scored),
    )


SWEEP = ["defaults", "bias-only", "bias-random-walk", "noise-1um", "slow-drift", "fast-fade", "slow-fade"]


def sweep():
    """Per alternative: MAE per channel, block and cadence (seed 1, clean),
    and the mean ratio to the defaults over all of them."""
    cells = {}
    for name in SWEEP:
        for img, chans in IMAGES.items():
            for every in ("1h", "4h"):
                dump = read_csv(f"{sys.argv[1]}/sweep-{name}-{img}-{every}.csv")
                n = len(dump)
                for ch in chans:
                    meas = [num(r[f"{ch}_measured"]) for r in dump]
                    served = [float(r[f"{ch}_served"]) for r in dump]
                    for blk, (lo, hi) in BLOCKS.items():
                        idx = [i for i in range(int(lo * n), int(hi * n)) if meas[i] is not None]
                        cells[(name, ch, blk, every)] = mae((meas[i], served[i]) for i in idx)
    out = []
    for name in SWEEP:
        keys = [k for k in cells if k[0] == name]
        ratios = [cells[k] / cells[("defaults",) + k[1:]] for k in keys]
        by_every = {
            e: round(sum(r for k, r in zip(keys, ratios) if k[3] == e) / (len(ratios) / 2), 3)
            for e in ("1h", "4h")
        }
        out.append({
            "alternative": name,
            "mean_ratio_to_defaults_1h": by_every["1h"],
            "mean_ratio_to_defaults_4h": by_every["4h"],
            "cells_better": sum(r < 0.995 for r in ratios),
            "cells_worse": sum(r > 1.005 for r in ratios),
            "cells": len(ratios),
            "worst_ratio": round(max(ratios), 3),
            "test_ch3_ch5_1h_um": [round(cells[(name, c, "test 60-80 %", "1h")], 3) for c in ("dch3_um", "dch5_um")],
            "test_ch3_ch5_4h_um": [round(cells[(name, c, "test 60-80 %", "4h")], 3) for c in ("dch3_um", "dch5_um")],
        })
    return out


PHASES = ("0", "10min", "20min", "30min", "40min", "50min")


def phases(d):
    """Per channel and block: hourly references (seed 1, clean) at six clock
    phases: MAE per phase, their mean and spread, and the references taken
    (whole run, in the block), so schedules compare at equal counts."""
    out = []
    for img, chans in IMAGES.items():
        dumps = {p: read_csv(f"{d}/phase-{img}-{p}.csv") for p in PHASES}
        reps = {p: json.load(open(f"{d}/phase-{img}-{p}.json"))["references"]["channels"] for p in PHASES}
        for ch in chans:
            for blk, (lo, hi) in BLOCKS.items():
                maes, counts = [], []
                for p in PHASES:
                    dump = dumps[p]
                    meas = [num(r[f"{ch}_measured"]) for r in dump]
                    served = [float(r[f"{ch}_served"]) for r in dump]
                    n = len(dump)
                    idx = [i for i in range(int(lo * n), int(hi * n)) if meas[i] is not None]
                    maes.append(mae((meas[i], served[i]) for i in idx))
                    c = next(c for c in reps[p] if c["column"] == ch)
                    counts.append(c["references"])
                out.append({
                    "channel": ch, "block": blk,
                    "mae_1h_by_phase_um": [round(v, 3) for v in maes],
                    "mae_1h_phase_mean_um": round(sum(maes) / len(maes), 3),
                    "mae_1h_phase_min_max_um": [round(min(maes), 3), round(max(maes), 3)],
                    "references_by_phase": counts,
                })
    return out


ASKED = ("dch3_um", "dch5_um")  # the fl35 image's channels
BLOCK_TAG = {"test 60-80 %": "60_80", "rest 80-100 %": "80_100"}


def block_rows(dump, lo, hi):
    n = len(dump)
    return range(int(lo * n), int(hi * n))


def scored(dump, ch, lo, hi):
    """MAE of the served correction in the block and the references taken
    in it (rows with a reading in the dump's `_reference` column)."""
    meas = [num(r[f"{ch}_measured"]) for r in dump]
    served = [float(r[f"{ch}_served"]) for r in dump]
    rows = block_rows(dump, lo, hi)
    idx = [i for i in rows if meas[i] is not None]
    refs = sum(1 for i in rows if dump[i].get(f"{ch}_reference", "") != "")
    return mae((meas[i], served[i]) for i in idx), refs


def asked_floors(dump, ch, lo, hi):
    """The same schedule as the board's rule (the rows where it accepted a
    reference), served without the rule: the model plus the error at the
    reference held until the next, noise-free (hold exact) and as the probe
    read it (hold reading, what a bias-only rule of gain 1 serves), and the
    non-causal mean error of each interval; MAE in the block each."""
    n = len(dump)
    meas = [num(r[f"{ch}_measured"]) for r in dump]
    model = [float(r[f"{ch}_model"]) for r in dump]
    reading = [num(r[f"{ch}_reference"]) for r in dump]
    refs = [i for i, r in enumerate(dump) if r.get(f"{ch}_accepted") == "1" and meas[i] is not None]
    exact, held, mean = list(model), list(model), list(model)
    bounds = [0] + refs + [n]
    for a, b in zip(bounds, bounds[1:]):
        seg = [meas[i] - model[i] for i in range(a, b) if meas[i] is not None]
        avg = sum(seg) / len(seg) if seg else 0.0
        for i in range(a, b):
            mean[i] = model[i] + avg
            if a in refs:
                exact[i] = model[i] + meas[a] - model[a]
                held[i] = model[i] + reading[a] - model[a]
    idx = [i for i in block_rows(dump, lo, hi) if meas[i] is not None]
    return [mae((meas[i], v[i]) for i in idx) for v in (exact, held, mean)]


def equal_count(d):
    """Per channel and block: the clock interval (s) giving the block as many
    references as the board asked for in it (block length / count)."""
    dump = read_csv(f"{d}/asked-fl35.csv")
    time_s = [float(r["time_s"]) for r in dump]
    for ch in ASKED:
        for blk, (lo, hi) in BLOCKS.items():
            rows = block_rows(dump, lo, hi)
            _, n = scored(dump, ch, lo, hi)
            length = time_s[min(rows.stop, len(dump) - 1)] - time_s[rows.start]
            print(f"{ch}-{BLOCK_TAG[blk]} {length / max(n, 1):.3f}")


def when_asked(d):
    """Per channel and block: no references, hourly (six phases), when the
    board asks (clean; 5 %:+50), and the clock schedule at the board's count
    (six phases): MAE and references in the block each."""
    out = []
    asked = read_csv(f"{d}/asked-fl35.csv")
    asked_bad = read_csv(f"{d}/asked-fl35-5__50.csv")
    rep = json.load(open(f"{d}/asked-fl35.json"))["references"]
    rep_bad = json.load(open(f"{d}/asked-fl35-5__50.json"))["references"]["channels"]
    hourly = {p: read_csv(f"{d}/phase-fl35-{p}.csv") for p in PHASES}
    for ch in ASKED:
        c = next(c for c in rep["channels"] if c["column"] == ch)
        cb = next(c for c in rep_bad if c["column"] == ch)
        for blk, (lo, hi) in BLOCKS.items():
            meas = [num(r[f"{ch}_measured"]) for r in asked]
            model = [float(r[f"{ch}_model"]) for r in asked]
            idx = [i for i in block_rows(asked, lo, hi) if meas[i] is not None]
            none = mae((meas[i], model[i]) for i in idx)
            a_mae, a_n = scored(asked, ch, lo, hi)
            b_mae, b_n = scored(asked_bad, ch, lo, hi)
            h = [scored(hourly[p], ch, lo, hi) for p in PHASES]
            tag = f"{ch}-{BLOCK_TAG[blk]}"
            eq = [scored(read_csv(f"{d}/eq-{tag}-{k}.csv"), ch, lo, hi) for k in range(6)]
            every = json.load(open(f"{d}/eq-{tag}-0.json"))["references"]["every_s"]
            h_mae = sum(v for v, _ in h) / 6
            h_n = sum(n for _, n in h) / 6
            e_mae = sum(v for v, _ in eq) / 6
            target = {"dch3_um": 1.2, "dch5_um": 0.8}[ch]
            f_exact, f_held, f_mean = asked_floors(asked, ch, lo, hi)
            out.append({
                "channel": ch, "block": blk,
                "none_mae_um": round(none, 3), "none_references": 0,
                "hourly_phase_mean_mae_um": round(h_mae, 3),
                "hourly_references_by_phase": [n for _, n in h],
                "hourly_references_phase_mean": round(h_n, 2),
                "asked_mae_um": round(a_mae, 3), "asked_references": a_n,
                "asked_5pct_50um_mae_um": round(b_mae, 3), "asked_5pct_50um_references": b_n,
                "asked_5pct_50um_corrupted_refused_whole_run": f"{cb['corrupted_refused']}/{cb['corrupted']}",
                "asked_requests_whole_run": {"speed_change": c["asked_speed_change"], "interval": c["asked_interval"]},
                "asked_references_whole_run": c["references"],
                "equal_count_every_s": round(every, 1),
                "equal_count_phase_mean_mae_um": round(e_mae, 3),
                "equal_count_mae_by_phase_um": [round(v, 3) for v, _ in eq],
                "equal_count_references_by_phase": [n for _, n in eq],
                "target_asked_mae_um": target,
                "asked_meets_target": a_mae <= target,
                "asked_floor_hold_exact_um": round(f_exact, 3),
                "asked_floor_hold_reading_um": round(f_held, 3),
                "asked_floor_interval_mean_um": round(f_mean, 3),
                "asked_no_more_references_than_hourly": a_n <= h_n,
                "never_worse_than_none": all(v <= none for v in (a_mae, b_mae, h_mae, e_mae)),
            })
    return out, rep["when_asked"]


def main():
    if sys.argv[1] == "--equal-count":
        equal_count(sys.argv[2])
        return
    d, run_path, as_json = sys.argv[1], sys.argv[2], sys.argv[3] == "1"
    run = read_csv(run_path)
    rpm = [num(r["spindle_rpm"]) for r in run]
    time_s = [float(r["time_s"]) for r in run]
    # Hours since the last change of spindle speed, per row.
    since, last = [], None
    for i, t in enumerate(time_s):
        if i > 0 and rpm[i] != rpm[i - 1]:
            last = t
        since.append(1e9 if last is None else (t - last) / 3600.0)
    rows = []
    for img, chans in IMAGES.items():
        for ch in chans:
            for blk, (lo, hi) in BLOCKS.items():
                row = {"channel": ch, "block": blk}
                for every in SCHEDULES:
                    for o in ("clean", "5__50"):
                        vals, near, far, refused, corrupted = [], [], [], 0, 0
                        for s in SEEDS:
                            tag = f"{img}-{every}-{s}-{o}"
                            dump = read_csv(f"{d}/{tag}.csv")
                            meas = [num(r[f"{ch}_measured"]) for r in dump]
                            model = [float(r[f"{ch}_model"]) for r in dump]
                            served = [float(r[f"{ch}_served"]) for r in dump]
                            n = len(dump)
                            idx = [i for i in range(int(lo * n), int(hi * n)) if meas[i] is not None]
                            v = mae((meas[i], served[i]) for i in idx)
                            vals.append(v)
                            rep = json.load(open(f"{d}/{tag}.json"))["references"]["channels"]
                            c = next(c for c in rep if c["column"] == ch)
                            if (lo, hi) == (0.6, 0.8) and abs(c["mae_um"] - v) > 1e-6:
                                sys.exit(f"{tag} {ch}: own scoring {v} differs from tcomp's {c['mae_um']}")
                            refused += c["corrupted_refused"]
                            corrupted += c["corrupted"]
                            if o == "clean":
                                row["model_alone_mae_um"] = round(mae((meas[i], model[i]) for i in idx), 3)
                                if s == 1 and every in ("1h", "4h"):
                                    hold, mean = floors(time_s, meas, model, 3600.0 * int(every[0]), lo, hi)
                                    row[f"floor_hold_exact_{every}_um"] = round(hold, 3)
                                    row[f"floor_interval_mean_{every}_um"] = round(mean, 3)
                                    if every == "1h":
                                        near += [abs(meas[i] - served[i]) for i in idx if since[i] < 1.0]
                                        far += [abs(meas[i] - served[i]) for i in idx if since[i] >= 1.0]
                        key = f"{every}" + ("" if o == "clean" else "_5pct_50um")
                        row[f"mae_{key}_um"] = round(sum(vals) / len(vals), 3)
                        row[f"mae_{key}_worst_um"] = round(max(vals), 3)
                        if o != "clean":
                            row[f"corrupted_refused_{every}"] = f"{refused}/{corrupted}"
                        if near:
                            row["mae_1h_hour_after_speed_change_um"] = round(sum(near) / len(near), 3)
                            row["share_rows_hour_after_speed_change"] = round(len(near) / (len(near) + len(far)), 3)
                            row["mae_1h_elsewhere_um"] = round(sum(far) / len(far), 3)
                rows.append(row)
    rezero = []
    for img, chans in IMAGES.items():
        rep = json.load(open(f"{d}/rezero-{img}.json"))["references"]["channels"]
        for c in rep:
            rezero.append({
                "channel": c["column"], "rms_um": round(c["rms_um"], 3),
                "raw_rms_um": round(c["raw_rms_um"], 3),
                "never_worse_than_raw": c["never_worse_than_raw"],
            })
    if as_json:
        asked, rule = when_asked(d)
        print(json.dumps({"seeds": list(SEEDS), "rows": rows, "rezero_60pct_scored_60_100": rezero,
                          "sweep": sweep(), "hourly_over_clock_phases": phases(d),
                          "when_asked": {"rule": rule, "rows": asked}}))
        return
    print("| channel | block | model alone | 1 h | 1 h 5 %:+50 (refused) | 4 h | 4 h 5 %:+50 (refused) | floor 1 h: hold exact / interval mean | floor 4 h | 1 h: hour after a speed change (share) / elsewhere |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['channel']} | {r['block']} | {r['model_alone_mae_um']:.2f} | {r['mae_1h_um']:.2f} | "
            f"{r['mae_1h_5pct_50um_um']:.2f} ({r['corrupted_refused_1h']}) | {r['mae_4h_um']:.2f} | "
            f"{r['mae_4h_5pct_50um_um']:.2f} ({r['corrupted_refused_4h']}) | "
            f"{r['floor_hold_exact_1h_um']:.2f} / {r['floor_interval_mean_1h_um']:.2f} | "
            f"{r['floor_hold_exact_4h_um']:.2f} / {r['floor_interval_mean_4h_um']:.2f} | "
            f"{r['mae_1h_hour_after_speed_change_um']:.2f} ({r['share_rows_hour_after_speed_change'] * 100:.0f} %) / {r['mae_1h_elsewhere_um']:.2f} |"
        )
    print()
    print("| channel | block | 1 h + 10 min after a change (5 %:+50) | 1 h + 30 min (5 %:+50) | 4 h + 10 min (5 %:+50) | 4 h + 30 min (5 %:+50) |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        cells = " | ".join(
            f"{r[f'mae_{k}_um']:.2f} ({r[f'mae_{k}_5pct_50um_um']:.2f})"
            for k in ("1h+10min", "1h+30min", "4h+10min", "4h+30min")
        )
        print(f"| {r['channel']} | {r['block']} | {cells} |")
    print()
    print("| channel | block | hourly, mean over 6 clock phases (min – max) | references per phase (whole run) |")
    print("|---|---|---|---|")
    for r in phases(d):
        lo_, hi_ = r["mae_1h_phase_min_max_um"]
        print(f"| {r['channel']} | {r['block']} | {r['mae_1h_phase_mean_um']:.2f} ({lo_:.2f} – {hi_:.2f}) | {r['references_by_phase']} |")
    print()
    asked, rule = when_asked(d)
    print(f"When the board asks ({rule['settle_s'] // 60} min after a change of >= {rule['speed_step_rpm']} rpm, "
          f"at most {rule['max_interval_s'] // 60} min apart, the PLC probing at the next sample); MAE um (references in the block):")
    print()
    print("| channel | block | none | hourly, 6 phases | when asked | when asked, 5 %:+50 (refused) | clock at the same count, 6 phases (interval) | same schedule: hold exact / hold reading / interval mean |")
    print("|---|---|---|---|---|---|---|---|")
    for r in asked:
        print(
            f"| {r['channel']} | {r['block']} | {r['none_mae_um']:.2f} (0) | {r['hourly_phase_mean_mae_um']:.2f} ({r['hourly_references_phase_mean']:.1f}) | "
            f"{r['asked_mae_um']:.2f} ({r['asked_references']}) | {r['asked_5pct_50um_mae_um']:.2f} ({r['asked_5pct_50um_references']}; "
            f"{r['asked_5pct_50um_corrupted_refused_whole_run']}) | {r['equal_count_phase_mean_mae_um']:.2f} "
            f"({sum(r['equal_count_references_by_phase']) / 6:.1f}; {r['equal_count_every_s'] / 60:.0f} min) | "
            f"{r['asked_floor_hold_exact_um']:.2f} / {r['asked_floor_hold_reading_um']:.2f} / {r['asked_floor_interval_mean_um']:.2f} |"
        )
    print()
    print("| channel | re-zero at 60 %, scored 60-100 %: RMS with the model / raw RMS about the re-zero | never above raw |")
    print("|---|---|---|")
    for r in rezero:
        print(f"| {r['channel']} | {r['rms_um']:.2f} / {r['raw_rms_um']:.2f} | {r['never_worse_than_raw']} |")
    print()
    print("| alternative (seed 1, clean) | mean MAE ratio to defaults 1 h / 4 h | cells better / worse of 20 | worst ratio | test ch3 / ch5 1 h | test ch3 / ch5 4 h |")
    print("|---|---|---|---|---|---|")
    for r in sweep():
        print(
            f"| {r['alternative']} | {r['mean_ratio_to_defaults_1h']:.3f} / {r['mean_ratio_to_defaults_4h']:.3f} | "
            f"{r['cells_better']} / {r['cells_worse']} | {r['worst_ratio']:.3f} | "
            f"{r['test_ch3_ch5_1h_um'][0]:.2f} / {r['test_ch3_ch5_1h_um'][1]:.2f} | "
            f"{r['test_ch3_ch5_4h_um'][0]:.2f} / {r['test_ch3_ch5_4h_um'][1]:.2f} |"
        )


if __name__ == "__main__":
    main()
