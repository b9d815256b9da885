#!/usr/bin/env python3
"""Score `tcomp geometry identify-rotary` on five-axis-blind machines.

    python3 score.py /tmp/five-axis-blind [--tcomp target/release/tcomp] [--lines28] [--json]

Per machine mNN/ (written by gen.py): runs
    tcomp geometry identify-rotary rtest/*.csv --lines lines/*.csv [--drift all]
          --json --model-out M --linear-out E
(`--drift all` when truth.json has more than one temperature state), then
compares the eight location errors with the truth by name, EXOC<->XOC,
EYOC<->YOC, EAOC<->AOC, EBOC<->BOC, EYOA<->YOA, EZOA<->ZOA, EBOA<->BOA,
ECOA<->COA (rtest.md: where the axis crosses the plane, right-handed tilts;
gen.py's definitions are the same reading of it). Also scored: the
all-signs-flipped mapping (tool = -truth), and the truth with the spindle
tilt absorbed at the mean tool length (see README.md).

With drift, the tool prints the location errors at its reference
temperatures (model `drift[].reference_c`) and per-kelvin slopes; the truth is
evaluated at that reference (3-sigma coverage uses the printed sigma), the
slopes are compared with theirs, and each state's location errors are
compared (sigma there: sqrt(s_loc^2 + sum (s_k dT)^2), independence assumed,
marked approximate).

Tool tip: there is no `tcomp geometry predict`. `tcomp geometry tooltip
--turntable <identify-rotary model>` accepts the model file but evaluates
only its pivot and offset (score.py checks this at one pose per machine:
`tooltip_with_model_file_equals_bare_turntable`), and it ignores drift. So
the prediction is assembled here: the linear part from `tcomp geometry
tooltip --errors <linear-out> --at x,y,z --tool 0,0,L` (the tool's own
three-axis evaluation), the rotary part from the identified location errors
(moved to each state's temperatures with the printed drift) and component
errors through the rtest.md chain (gen.W_actual). Residual = truth -
predicted, workpiece frame; also with the spindle-tilt contribution taken
out of the truth (the model has no term for it).
"""
import argparse
import glob
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_TCOMP = os.path.normpath(os.path.join(HERE, "../../../../target/release/tcomp"))
LOC = ["EXOC", "EYOC", "EAOC", "EBOC", "EYOA", "EZOA", "EBOA", "ECOA"]
KEY = {"EXOC": "xoc_um", "EYOC": "yoc_um", "EAOC": "aoc_urad", "EBOC": "boc_urad",
       "EYOA": "yoa_um", "EZOA": "zoa_um", "EBOA": "boa_urad", "ECOA": "coa_urad"}


def tool_name(n):
    return n[1:]  # EXOC -> XOC


def truth_at(truth, temps):
    return {n: truth["location_ref"][n] + sum(truth["location_per_kelvin"][n][s]
                                              * (temps[s] - truth["temperature_reference_c"])
                                              for s in truth["sensors"]) for n in LOC}


def tilt_shift(truth, L):
    st = truth["spindle_tilt_urad"]
    dx, dy = st["about_y"] * L * 1e-3, -st["about_x"] * L * 1e-3  # um
    return {"EXOC": -dx, "EYOC": -dy, "EYOA": -dy, "EZOA": 0.0}


def run(cmd):
    p = subprocess.run(cmd, capture_output=True, text=True)
    return p.returncode, p.stdout, p.stderr


def score_machine(tcomp, mdir, lines28, work):
    truth = json.load(open(os.path.join(mdir, "truth.json")))
    rfiles = sorted(glob.glob(os.path.join(mdir, "rtest", "*.csv")))
    lfiles = sorted(glob.glob(os.path.join(mdir, "lines", "*.csv")))
    if lines28:
        lfiles += sorted(glob.glob(os.path.join(mdir, "lines_extra", "*.csv")))
    model_p, lin_p = os.path.join(work, "model.json"), os.path.join(work, "linear.json")
    states = truth["states"]
    cmd = [tcomp, "geometry", "identify-rotary", *rfiles, "--lines", *lfiles, "--json",
           "--model-out", model_p, "--linear-out", lin_p]
    if len(states) > 1:
        cmd += ["--drift", "all"]
    rc, out, err = run(cmd)
    res = {"machine": os.path.basename(mdir), "exit_status": rc,
           "command": "tcomp geometry identify-rotary rtest/*.csv --lines "
                      + ("lines/*.csv lines_extra/*.csv" if lines28 else "lines/*.csv")
                      + " --json" + (" --drift all" if len(states) > 1 else ""),
           "stderr": err.strip()[-600:]}
    try:
        ident = json.loads(out)
    except json.JSONDecodeError:
        res["error"] = "no JSON on stdout"
        return res
    res["unobservable"] = ident.get("unobservable")
    res["residual_rms_um"] = ident.get("residual_rms_um")
    res["condition_number"] = ident.get("condition_number")
    loc = {d["name"]: d for d in ident.get("location", [])}
    drift = {d["name"]: d for d in ident.get("drift", [])}
    model = json.load(open(model_p)) if os.path.exists(model_p) else None
    ref = {d["sensor"]: d["reference_c"] for d in (model or {}).get("drift", [])}
    sensors = truth["sensors"]
    if ref:
        t_ref = {s: ref.get(s, truth["temperature_reference_c"]) for s in sensors}
    else:
        t_ref = states[0]["temps"]
    res["tool_reference_c"] = t_ref
    tr = truth_at(truth, t_ref)
    Lmean = statistics.mean(float(os.path.basename(f).split("_T")[1][:-4]) for f in rfiles)
    shift = tilt_shift(truth, Lmean)
    res["apparent_tool_mm"] = Lmean
    rows = {}
    for n in LOC:
        d = loc.get(tool_name(n))
        t = tr[n]
        r = {"truth": t, "unit": "um" if n[1] in "XYZ" else "urad"}
        if d is None or d.get("value") is None:
            r["identified"] = None
            rows[n] = r
            continue
        v, s = d["value"], d.get("sigma")
        ta = t + shift.get(n, 0.0)
        r.update(identified=v, sigma=s, err=v - t, abs_err=abs(v - t),
                 covered_3sigma=(s is not None and abs(v - t) <= 3 * s),
                 flipped_abs_err=abs(v + t), flipped_covered_3sigma=(s is not None and abs(v + t) <= 3 * s),
                 truth_tilt_absorbed=ta, tilt_absorbed_abs_err=abs(v - ta),
                 tilt_absorbed_covered_3sigma=(s is not None and abs(v - ta) <= 3 * s))
        # slopes
        if drift:
            sl = {}
            for sname in sensors:
                dd = drift.get(f"{tool_name(n)}/T_{sname}")
                if dd is None:
                    continue
                k = truth["location_per_kelvin"][n][sname]
                sl[sname] = {"truth": k, "identified": dd["value"], "sigma": dd["sigma"],
                             "abs_err": abs(dd["value"] - k),
                             "covered_3sigma": abs(dd["value"] - k) <= 3 * dd["sigma"]}
            r["per_kelvin"] = sl
            st_rows = []
            for st in states:
                tv = truth_at(truth, st["temps"])[n]
                iv, var = v, (s or 0.0) ** 2
                for sname, q in sl.items():
                    dT = st["temps"][sname] - t_ref[sname]
                    iv += q["identified"] * dT
                    var += (q["sigma"] * dT) ** 2
                st_rows.append({"state": st["name"], "truth": tv, "identified": iv,
                                "abs_err": abs(iv - tv), "sigma_approx": math.sqrt(var),
                                "covered_3sigma_approx": abs(iv - tv) <= 3 * math.sqrt(var)})
            r["states"] = st_rows
        rows[n] = r
    res["location"] = rows
    # tool tip at truth_poses.csv
    if model is not None and os.path.exists(lin_p):
        res["tooltip"] = tooltip_residuals(tcomp, mdir, model, lin_p, t_ref, work)
    return res


def tooltip_residuals(tcomp, mdir, model, lin_p, t_ref, work):
    """Tool-tip residual at truth_poses.csv from the identified model.

    `tcomp geometry tooltip --turntable <identify-rotary model>` accepts the
    model file but uses only its pivot and offset (checked below: its output
    equals that of a bare {pivot_a_mm, offset_c_mm} file), so the rotary part
    is evaluated here: the identified location errors (at the state's
    temperatures through the printed drift) and component errors through the
    rtest.md chain (gen.W_actual, the documented convention), the linear part
    from `tcomp geometry tooltip --errors <linear-out> --at x,y,z --tool` (the
    tool's own three-axis evaluation, machine frame)."""
    import csv
    sys.path.insert(0, HERE)
    import gen
    rows = list(csv.DictReader(open(os.path.join(mdir, "truth_poses.csv"))))
    assert list(model["pivot_a_mm"]) == list(gen.PIVOT_A) and list(model["offset_c_mm"]) == list(gen.OFFSET_C)
    comps = model.get("components", {})
    zero = {"cos": [], "sin": []}
    mrot = {"components": {"C": {n: comps.get(n, zero) for n in gen.C_COMP},
                           "A": {n: comps.get(n, zero) for n in gen.A_COMP}}}
    out = {}
    # the tooltip path with the model file itself, at the first pose
    r0 = rows[0]
    at0 = ",".join(r0[k] for k in ("x_mm", "y_mm", "z_mm", "a_deg", "c_deg"))
    bare = os.path.join(work, "bare.json")
    json.dump({"pivot_a_mm": model["pivot_a_mm"], "offset_c_mm": model["offset_c_mm"]}, open(bare, "w"))
    mfile = os.path.join(work, "model.json")
    tt = []
    for tfile in (mfile, bare):
        rc, o, _ = run([tcomp, "geometry", "tooltip", "--errors", lin_p, "--turntable", tfile,
                        "--at", at0, "--tool", f"0,0,{r0['tool_mm']}", "--json"])
        tt.append(json.loads(o)["exact_um"] if rc == 0 else None)
    out["tooltip_with_model_file_equals_bare_turntable"] = tt[0] is not None and tt[0] == tt[1]
    lin_cache = {}
    per_state = {}
    for row in rows:
        per_state.setdefault(row["state"], []).append(row)
    for st, rs in per_state.items():
        loc = dict(model["location"])
        for d in model.get("drift", []):
            T = float(rs[0][f"T_{d['sensor']}"])
            for k, v in d["per_kelvin"].items():
                loc[k] += v * (T - d["reference_c"])
        locE = {n: loc.get(KEY[n], 0.0) for n in LOC}
        res2, res2_nt, before = [], [], []
        fails = 0
        for r in rs:
            xyz = ",".join(r[k] for k in ("x_mm", "y_mm", "z_mm"))
            key = (xyz, r["tool_mm"])
            if key not in lin_cache:
                rc, o, _ = run([tcomp, "geometry", "tooltip", "--errors", lin_p, "--at", xyz,
                                "--tool", f"0,0,{r['tool_mm']}", "--json"])
                lin_cache[key] = json.loads(o)["exact_um"] if rc == 0 else None
            e_lin = lin_cache[key]
            if e_lin is None:
                fails += 1
                continue
            pos = [float(r[k]) for k in ("x_mm", "y_mm", "z_mm")]
            a, c, L = float(r["a_deg"]), float(r["c_deg"]), float(r["tool_mm"])
            p_act = [pos[0] + e_lin[0] * 1e-3, pos[1] + e_lin[1] * 1e-3, pos[2] + L + e_lin[2] * 1e-3]
            w_act = gen.apply(gen.inv(gen.W_actual(mrot, locE, a, c)), p_act)
            w_nom = gen.apply(gen.inv(gen.W_nominal(a, c)), [pos[0], pos[1], pos[2] + L])
            pred = [(w_act[i] - w_nom[i]) * 1e3 for i in range(3)]
            tv = [float(r[k]) for k in ("dx_um", "dy_um", "dz_um")]
            tilt = [float(r[k]) for k in ("tilt_dx_um", "tilt_dy_um", "tilt_dz_um")]
            res2.append(sum((tv[i] - pred[i]) ** 2 for i in range(3)))
            res2_nt.append(sum((tv[i] - tilt[i] - pred[i]) ** 2 for i in range(3)))
            before.append(sum(x * x for x in tv))
        n = len(res2)
        out[st] = {"poses": n, "tooltip_failures": fails,
                   "before_rms_um": math.sqrt(sum(before) / n) if n else None,
                   "after_rms_um": math.sqrt(sum(res2) / n) if n else None,
                   "after_max_um": math.sqrt(max(res2)) if n else None,
                   "after_rms_um_spindle_tilt_removed_from_truth": math.sqrt(sum(res2_nt) / n) if n else None}
    return out


def summarise(results):
    s = {"machines": len(results),
         "exit_status": [r["exit_status"] for r in results]}
    for n in LOC:
        errs = [r["location"][n]["abs_err"] for r in results
                if "location" in r and r["location"][n].get("identified") is not None]
        if not errs:
            continue
        cov = [r["location"][n]["covered_3sigma"] for r in results if "location" in r
               and r["location"][n].get("identified") is not None]
        fl = [r["location"][n]["flipped_abs_err"] for r in results if "location" in r
              and r["location"][n].get("identified") is not None]
        ta = [r["location"][n]["tilt_absorbed_abs_err"] for r in results if "location" in r
              and r["location"][n].get("identified") is not None]
        tac = [r["location"][n]["tilt_absorbed_covered_3sigma"] for r in results if "location" in r
               and r["location"][n].get("identified") is not None]
        s[n] = {"median_abs_err": statistics.median(errs), "max_abs_err": max(errs),
                "covered_3sigma": f"{sum(cov)}/{len(cov)}",
                "flipped_median_abs_err": statistics.median(fl),
                "tilt_absorbed_median_abs_err": statistics.median(ta),
                "tilt_absorbed_max_abs_err": max(ta),
                "tilt_absorbed_covered_3sigma": f"{sum(tac)}/{len(tac)}"}
    sl = [q for r in results if "location" in r for n in LOC
          for q in r["location"][n].get("per_kelvin", {}).values()]
    if sl:
        s["per_kelvin_covered_3sigma"] = f"{sum(q['covered_3sigma'] for q in sl)}/{len(sl)}"
        s["per_kelvin_median_abs_err"] = statistics.median(q["abs_err"] for q in sl)
    stc = [q for r in results if "location" in r for n in LOC for q in r["location"][n].get("states", [])]
    if stc:
        s["state_values_covered_3sigma_approx"] = f"{sum(q['covered_3sigma_approx'] for q in stc)}/{len(stc)}"
    s["tooltip_with_model_file_equals_bare_turntable"] = [
        r.get("tooltip", {}).get("tooltip_with_model_file_equals_bare_turntable") for r in results]
    tt = [v for r in results for v in r.get("tooltip", {}).values() if isinstance(v, dict) and v["poses"]]
    if tt:
        s["tooltip_before_rms_um_median"] = statistics.median(v["before_rms_um"] for v in tt)
        s["tooltip_after_rms_um_median"] = statistics.median(v["after_rms_um"] for v in tt)
        s["tooltip_after_rms_um_max"] = max(v["after_rms_um"] for v in tt)
        s["tooltip_after_max_um"] = max(v["after_max_um"] for v in tt)
        s["tooltip_after_rms_um_median_spindle_tilt_removed"] = statistics.median(
            v["after_rms_um_spindle_tilt_removed_from_truth"] for v in tt)
    return s


def text(results, summ):
    o = []
    for r in results:
        o.append(f"{r['machine']}  exit {r['exit_status']}  residual {r.get('residual_rms_um')}  "
                 f"unobservable {r.get('unobservable')}")
        if "error" in r:
            o.append(f"  {r['error']}: {r['stderr']}")
            continue
        for n in LOC:
            q = r["location"][n]
            if q.get("identified") is None:
                o.append(f"  {n:5s} truth {q['truth']:9.3f}  NOT IDENTIFIED")
                continue
            o.append(f"  {n:5s} truth {q['truth']:9.3f}  id {q['identified']:9.3f} ±{q['sigma']:.3f}  "
                     f"|err| {q['abs_err']:7.3f} {q['unit']:4s} 3σ {'yes' if q['covered_3sigma'] else 'NO ':3s}  "
                     f"flipped |err| {q['flipped_abs_err']:7.3f}  tilt-absorbed |err| {q['tilt_absorbed_abs_err']:7.3f} "
                     f"3σ {'yes' if q['tilt_absorbed_covered_3sigma'] else 'NO'}")
        for st, v in r.get("tooltip", {}).items():
            if isinstance(v, dict) and v["poses"]:
                o.append(f"  tool tip {st}: before {v['before_rms_um']:.3f} after {v['after_rms_um']:.3f} RMS µm "
                         f"(max {v['after_max_um']:.3f}; tilt removed {v['after_rms_um_spindle_tilt_removed_from_truth']:.3f}), "
                         f"failures {v['tooltip_failures']}")
    o.append("summary: " + json.dumps(summ, indent=1, ensure_ascii=False))
    return "\n".join(o)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("world")
    ap.add_argument("--tcomp", default=DEFAULT_TCOMP)
    ap.add_argument("--lines28", action="store_true", help="also give the 14 shifted lines")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    mdirs = sorted(d for d in glob.glob(os.path.join(a.world, "m*")) if os.path.isdir(d))
    results = []
    with tempfile.TemporaryDirectory() as work:
        for d in mdirs:
            w = os.path.join(work, os.path.basename(d))
            os.makedirs(w)
            results.append(score_machine(a.tcomp, d, a.lines28, w))
    summ = summarise(results)
    if a.json:
        json.dump({"world": a.world, "lines": 28 if a.lines28 else 14, "machines": results,
                   "summary": summ}, sys.stdout, indent=1, ensure_ascii=False)
        print()
    else:
        print(text(results, summ))
    sys.exit(0 if all(r["exit_status"] == 0 for r in results) else 1)


if __name__ == "__main__":
    main()
