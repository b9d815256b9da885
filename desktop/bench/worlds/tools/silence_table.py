#!/usr/bin/env python3
"""Issue 52: why `diagnose fit` stays silent (docs/notes/diagnose-silence.md).

Reads one run of
  TCOMP_BENCH_DUMP=DIR bench-diagnose --columns fit --worlds open,cross \
      --threads 1 --json --verbose 2> ERR
(the per-case lines and `tried` lines on stderr, the whole diagnosis per case
in DIR) and, optionally, the stderr of `--open-only --verbose --cases 180` and
`--cross-only --verbose --cases 200` (the same cases; they print each case's
effect RMS against the same runs without it).

For every silent case: the truth, the nominal's held-out residual against the
clean cases of the same machine (the empirical null: the truth sensor's
rms/noise for a sensor effect, else the mean over channels of (rms/noise)^2),
the truth-class candidate with the highest held-out z against the best z of
that class on the clean cases, the claim conditions (fitmode.rs `claim`) it
failed, what the report listed; a category a/b/c; then what candidate rules
for an "undetermined" answer would move, world by world, clean cases included.

Usage: silence_table.py ERR DIR [OPEN_ONLY_ERR CROSS_ONLY_ERR]
"""
import json
import os
import re
import sys
from collections import Counter, defaultdict

KIND = {"SensorStep": "sensor_offset", "SensorOffset": "sensor_offset",
        "SensorLag": "sensor_lag", "ChillerCycling": "coolant",
        "BearingNonlinear": "bearing_nonlinear", "AmbientDrift": "ambient_drift"}
Z_MIN = 2.33  # verdict::Z_MIN, the gate's one-sided 1 % line


def cls(name):
    return "periodic" if name in ("coolant", "chiller", "periodic") else name


def load(err, dump, vis_files):
    vis = {}
    for path, w in zip(vis_files, ["open_world", "cross_model"]):
        for line in open(path) if os.path.exists(path) else []:
            m = re.match(r"\s*(?:open|cross)\s+(\d+) (?:\S+ )?effect rms ([\d.]+) °C ([\d.]+) µm", line)
            if m:
                vis[(w, int(m.group(1)))] = (float(m.group(2)), float(m.group(3)))
    cases = []
    pat = r"(open_world|cross_model) seed \d+ case\s+(\d+) fit\s+(\S+(?: \S+)?)\s+[\d.]+ s .*truth (.*?)  got"
    for line in open(err):
        m = re.match(pat, line)
        if not m:
            continue
        w, ci, verdict, truth = m.group(1), int(m.group(2)), m.group(3).strip(), m.group(4)
        kind = KIND.get(truth.split(" ")[0]) if truth != "clean" else None
        sm = re.search(r'sensor: (?:Some\()?"?(\w+)"?', truth)
        sensor = (sm.group(1) if w == "cross_model" else "T_T" + sm.group(1)) if sm else None
        d = json.load(open(f"{dump}/{w}_fit_7_{ci}.json"))
        cases.append(dict(w=w, ci=ci, verdict=verdict, truth=truth, kind=kind,
                          sensor=sensor, d=d, vis=vis.get((w, ci))))
    return cases


def chans(c):
    return c["d"]["d"]["no_effect"]["channels"]


def machine(c):
    return (c["w"], tuple(sorted(chans(c))))


def m_all(c):
    r = [v["rms_over_noise"] ** 2 for v in chans(c).values()]
    return sum(r) / len(r)


def fails_of(f):
    """The claim conditions of fitmode.rs `claim` this tried candidate fails."""
    e, name = f["evidence"], f["name"]
    mb = (e.get("held_out_norm_gap_before") or float("nan")) ** 2
    ma = (e.get("held_out_norm_gap_after") or float("nan")) ** 2
    dbic = e.get("delta_bic")
    out = []
    rel = 0.4 if name in ("sensor_offset", "sensor_lag") else 0.3
    if not ma <= mb * (1 - rel):
        out.append(f"shrink<{rel:.0%}")
    if name == "sensor_lag":
        if not (e.get("fit_rel_gain") or -1) >= 0.25:
            out.append("fit gain<25%")
        if not (e.get("fit_rel_gain_least_run") or -1) >= 0.1:
            out.append("run gain<10%")
        if (e.get("own_reading") or {}).get("specific") is not True:
            out.append("not specific")
    elif not mb - ma >= 1.0:
        out.append("abs<1")
    bic_ok = dbic is not None and dbic <= -10
    if name == "bearing_nonlinear" and "held_out_norm_gap_nominal" in e:
        bic_ok = bic_ok or ma <= 0.5 * e["held_out_norm_gap_nominal"] ** 2
        if e.get("beats_nominal") is False:
            out.append("not over nominal")
    if name == "sensor_offset" and e.get("few_fit_rows_after") and ma <= 0.5 * mb:
        bic_ok = True
    if not bic_ok:
        out.append("dBIC")
    if name == "bearing_nonlinear" and not ma <= 0.45 * mb:
        out.append("left>45%")
    if e.get("at_bound"):
        out.append("at bound")
    if name == "coolant" and not (e.get("peak_over_median_power") or 0) >= 8:
        out.append("peak<8")
    for u in ("um", "c"):
        b, a = f.get(f"gap_before_{u}"), f.get(f"gap_after_{u}")
        if b is not None and a is not None and a > b * (1 + 1e-9):
            out.append(f"{u} grows")
    return out


def cands(c):
    out = []
    for f in c["d"]["tried"]:
        e = f["evidence"]
        if e.get("held_out_norm_gap_before") is None or e.get("held_out_norm_gap_after") is None:
            continue
        mb, ma = e["held_out_norm_gap_before"] ** 2, e["held_out_norm_gap_after"] ** 2
        z = e.get("held_out_z")
        out.append(dict(name=f["name"], sensor=(f["params"] or {}).get("sensor") or e.get("channel"),
                        rel=1 - ma / mb if mb > 0 else 0.0, z=float("nan") if z is None else z,
                        gain=len(e.get("affected") or [1]) * (mb - ma), fails=fails_of(f), f=f))
    return out


def truth_cands(c):
    return [k for k in cands(c) if cls(k["name"]) == cls(c["kind"])
            and (not c["sensor"] or k["sensor"] == c["sensor"])]


def nulls(cases):
    n = defaultdict(lambda: dict(m=[], ch=defaultdict(list), z=defaultdict(lambda: -99.0)))
    for c in cases:
        if c["kind"] is None:
            x = n[machine(c)]
            x["m"].append(m_all(c))
            for k, v in chans(c).items():
                x["ch"][k].append(v["rms_over_noise"])
            for k in cands(c):
                if k["z"] == k["z"]:
                    x["z"][cls(k["name"])] = max(x["z"][cls(k["name"])], k["z"])
    return n


def categorise(c, null):
    x = null[machine(c)]
    if c["sensor"]:
        stat = chans(c)[c["sensor"]]["rms_over_noise"]
        ref = max(x["ch"][c["sensor"]])
    else:
        stat, ref = m_all(c), max(x["m"])
    tc = truth_cands(c)
    zs = [k for k in tc if k["z"] == k["z"]]
    best = max(zs, key=lambda k: k["z"]) if zs else (tc[0] if tc else None)
    zref = x["z"][cls(c["kind"])]
    r_det = stat > ref
    c_det = best is not None and best["z"] == best["z"] and best["z"] > zref and best["rel"] > 0
    cat = "a" if not (r_det or c_det) else ("b" if tc else "c")
    return cat, stat, ref, best, zref


def periodic_line(c):
    return next((f for f in c["d"]["tried"] if f["name"] == "periodic"
                 and f["evidence"].get("significant") is True), None)


def rule_generic(c, relmin):
    """Undetermined: nothing claimed, yet unclaimed candidates whose held-out
    improvement is significant by the gate's z (≥ relmin shrink, not at a
    bound, no gap grows): their classes, ranked by gain, at most 3."""
    s = [k for k in cands(c) if k["z"] == k["z"] and k["z"] >= Z_MIN and k["rel"] >= relmin
         and not {"at bound", "um grows", "c grows"} & set(k["fails"])]
    s.sort(key=lambda k: -k["gain"])
    names = []
    for k in s:
        if cls(k["name"]) not in names:
            names.append(cls(k["name"]))
    return names[:3]


def rule_step(c):
    """P1: a sensor step passing every held-out condition (shrink ≥ 40 %,
    ≥ 1 noise variance, z ≥ Z_MIN, no gap grows), failing only the fit-row BIC."""
    return ["sensor_offset"] if any(k["name"] == "sensor_offset" and k["fails"] == ["dBIC"]
                                    and k["z"] >= Z_MIN for k in cands(c)) else []


def rule_chiller(c):
    """P2: the residual's line significant and a chiller candidate passing the
    fit-row tests (spectral peak ≥ 8, ΔBIC ≤ −10), failing on held-out rows."""
    ok = periodic_line(c) and any(
        f["name"] == "coolant" and (f["evidence"].get("peak_over_median_power") or 0) >= 8
        and (f["evidence"].get("delta_bic") or 0) <= -10 for f in c["d"]["tried"])
    return ["periodic"] if ok else []


def moves(cases, rule):
    t = Counter()
    for c in cases:
        dj = c["d"]["d"]
        if c["verdict"] in ("named", "wrong") or dj["effects"] or dj["ambiguous"]:
            continue
        names = rule(c)
        if not names:
            continue
        before = c["verdict"] if c["kind"] else "clean"
        after = "FA" if c["kind"] is None else ("honest" if cls(c["kind"]) in names else "wrong")
        if before != after:
            t[(c["w"][:5], f"{before}->{after}")] += 1
    return dict(sorted(t.items()))


def main():
    cases = load(sys.argv[1], sys.argv[2], sys.argv[3:5])
    null = nulls(cases)
    for (w, ch), x in null.items():
        print(f"null {w} {len(ch)} channels: {len(x['m'])} clean, mean (rms/noise)^2 max {max(x['m']):.1f}")
    print("| case | truth | residual (clean max) | best own candidate: shrink, z (clean best z) | fails | vis °C/µm | cat |")
    cnt = Counter()
    for c in cases:
        if c["verdict"] != "silent":
            continue
        cat, stat, ref, best, zref = categorise(c, null)
        cnt[(c["w"][:5], c["kind"], cat)] += 1
        t = re.sub(r"(\d+\.\d\d)\d+", r"\1", c["truth"]).replace(", node: None", "").replace(", run: None", "")
        b = f"{best['name']} {best['rel']:.2f}, {best['z']:.1f} ({zref:.1f})" if best else "none"
        print(f"| {c['w'][:5]} {c['ci']} | {t} | {stat:.1f} ({ref:.1f}) | {b} | "
              f"{','.join(best['fails']) if best else '-'} | {c['vis']} | {cat} |")
    for k, v in sorted(cnt.items()):
        print(k, v)
    for label, rule in [("generic z>=2.33", lambda c: rule_generic(c, -9.0)),
                        ("generic z>=2.33, shrink>=30%", lambda c: rule_generic(c, 0.3)),
                        ("P1 step held-out only", rule_step),
                        ("P2 chiller line, not stationary", rule_chiller)]:
        print(label, moves(cases, rule))


if __name__ == "__main__":
    main()
