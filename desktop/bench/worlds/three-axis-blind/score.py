#!/usr/bin/env python3
"""Score `tcomp geometry identify` on the blind three-axis world, as a black box.

    python3 score.py DIR --tcomp PATH [--plan 14|rich] [--json] [--identify-args "..."]

Per machine: identify (default flags, or --identify-args) on the plan's lines;
its exit status; when it refuses, a diagnostic rerun with --accept-inadequate
(and --partial if it still refuses), reported apart and marked. From each
model: worst-term RMS error against the truth at the identifier's own
positions, share of terms x positions whose true error lies within the
printed 3 sigma, the held-out lines predicted by `tcomp geometry predict`,
and whether undetermined combinations are named.
"""

import argparse
import csv
import glob
import json
import math
import os
import shlex
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import gen  # noqa: E402  (the truth's own functions, evaluated exactly)

NOISE_UM = gen.NOISE_UM
MISFIT_K = 2.0  # held-out residual above MISFIT_K x reading noise: the model misfits


def run(cmd):
    res = subprocess.run(cmd, capture_output=True, text=True)
    return res.returncode, res.stdout, res.stderr.strip()


def last_line(text):
    lines = [x for x in text.splitlines() if x.strip()]
    return lines[-1] if lines else ""


def identify(tcomp, files, extra):
    cmd = [tcomp, "geometry", "identify"] + files + ["--json"] + extra
    rc, out, err = run(cmd)
    model = None
    if rc == 0 or out.strip():
        try:
            model = json.loads(out)
        except ValueError:
            model = None
    return {"exit": rc, "stderr": last_line(err), "model": model, "args": extra}


def machine_of(truth):
    return {"functions": truth["functions"], "squareness": truth["squareness_urad"]}


def term_accuracy(model, truth):
    """Per term: RMS error over the identifier's positions; 3 sigma coverage."""
    m = machine_of(truth)
    per_term, covered, counted = {}, 0, 0
    missing = []
    errors = model.get("errors", {})
    for name in gen.term_names():
        if name in gen.SQUARENESS:
            est = model.get("squareness_urad", {}).get(name)
            sig = model.get("squareness_sigma_urad", {}).get(name)
            if est is None:
                missing.append(name)
                continue
            diff = est - m["squareness"][name]
            per_term[name] = {"unit": "urad", "rms": abs(diff)}
            if sig is not None:
                counted += 1
                covered += abs(diff) <= 3.0 * sig
            continue
        e = errors.get(name)
        if not e or "values" not in e:
            missing.append(name)
            continue
        length = gen.STROKE[name[2]]
        sq, n = 0.0, 0
        sigmas = e.get("sigma")
        for i, (q, v) in enumerate(zip(e["positions_mm"], e["values"])):
            diff = v - gen.term_value(m, name, q)
            sq += diff * diff
            n += 1
            pinned = abs(q) < 1e-9 or (gen.term_kind(name) == "straightness" and abs(q - length) < 1e-6)
            if sigmas is not None and not pinned:  # a convention's zero cannot fail: not counted
                counted += 1
                covered += abs(diff) <= 3.0 * sigmas[i]
        per_term[name] = {"unit": e.get("unit", gen.term_unit(name)), "rms": math.sqrt(sq / n) if n else None}
    worst = {}
    for unit in ("um", "urad"):
        cands = [(v["rms"], k) for k, v in per_term.items() if v["unit"] == unit and v["rms"] is not None]
        if cands:
            val, name = max(cands)
            worst[unit] = {"rms": val, "term": name}
    return {
        "worst": worst,
        "per_term_rms": {k: v["rms"] for k, v in per_term.items()},
        "coverage_3sigma": {"covered": covered, "counted": counted, "share": covered / counted if counted else None},
        "terms_not_given": missing,
    }


def read_line_file(path):
    meta, rows = {}, []
    with open(path, encoding="utf-8") as fh:
        body = []
        for raw in fh:
            if raw.startswith("#"):
                key, _, val = raw[1:].partition(":")
                meta[key.strip()] = val.strip()
            elif raw.strip():
                body.append(raw)
    for r in csv.DictReader(body):
        rows.append({k: float(v) for k, v in r.items()})
    return meta, rows


def heldout_measured(mdir):
    """Held-out lines: forward and backward runs averaged per target."""
    lines = {}
    for path in sorted(glob.glob(os.path.join(mdir, "heldout", "*.csv"))):
        meta, rows = read_line_file(path)
        entry = lines.setdefault(meta["line"], {"meta": meta, "runs": []})
        entry["runs"].append(rows)
    out = []
    for name, entry in sorted(lines.items()):
        runs = entry["runs"]
        base = runs[0]
        disp = [sum(r[i]["disp_um"] for r in runs) / len(runs) for i in range(len(base))]
        tool = [float(v) for v in entry["meta"]["tool_offset_mm"].split(",")]
        direction = [float(v) for v in entry["meta"]["direction"].split(",")]
        poses = [(r["pos_x"], r["pos_y"], r["pos_z"]) for r in base]
        out.append({"line": name, "tool": tool, "direction": direction, "poses": poses, "disp": disp})
    return out


def predict_heldout(tcomp, model, lines, extra):
    """Predicted readings from `tcomp geometry predict` (tool along the spindle)."""
    for ln in lines:
        if abs(ln["tool"][0]) > 1e-9 or abs(ln["tool"][1]) > 1e-9:
            return {"available": False, "why": "predict takes a tool along the spindle only; line %s has a lateral reflector" % ln["line"]}
    with tempfile.TemporaryDirectory() as tmp:
        mpath = os.path.join(tmp, "model.json")
        with open(mpath, "w") as fh:
            json.dump(model, fh)
        ppath = os.path.join(tmp, "poses.csv")
        with open(ppath, "w") as fh:
            fh.write("id,x,y,z,tool\n")
            for ln in lines:
                for i, p in enumerate(ln["poses"]):
                    fh.write("%s_%d,%r,%r,%r,%r\n" % (ln["line"], i, p[0], p[1], p[2], ln["tool"][2]))
        rc, out, err = run([tcomp, "geometry", "predict", "--model", mpath, "--poses", ppath, "--json"] + extra)
    if rc != 0:
        return {"available": False, "why": "predict exit %d: %s" % (rc, last_line(err))}
    rows = {r["id"]: r for r in json.loads(out)["rows"]}
    sq_res, sq_meas, n = 0.0, 0.0, 0
    per_line = {}
    for ln in lines:
        e0 = rows["%s_0" % ln["line"]]["error_workpiece_um"]
        lres, lmeas = 0.0, 0.0
        for i in range(1, len(ln["poses"])):
            e = rows["%s_%d" % (ln["line"], i)]["error_workpiece_um"]
            pred = sum(ln["direction"][j] * (e[j] - e0[j]) for j in range(3))
            lres += (pred - ln["disp"][i]) ** 2
            lmeas += ln["disp"][i] ** 2
            n += 1
        per_line[ln["line"]] = 1.0 - math.sqrt(lres / lmeas) if lmeas > 0 else None
        sq_res += lres
        sq_meas += lmeas
    return {
        "available": True,
        "sum_sq_residual": sq_res,
        "sum_sq_measured": sq_meas,
        "readings": n,
        "residual_rms_um": math.sqrt(sq_res / n),
        "measured_rms_um": math.sqrt(sq_meas / n),
        "score": 1.0 - math.sqrt(sq_res / sq_meas),
        "per_line": per_line,
    }


def named_undetermined(ident):
    model = ident["model"] or {}
    unobs = model.get("unobservable") or []
    weak = (model.get("adequacy") or {}).get("weak") or []
    in_message = "do not determine" in ident["stderr"] or "unobservable" in ident["stderr"]
    return {
        "unobservable_terms": unobs,
        "weak_combinations": [w.get("words", "") for w in weak],
        "named_in_refusal": in_message,
        "names_any": bool(unobs or weak or in_message),
    }


def evaluate(tcomp, ident, truth, held, predict_extra):
    model = ident["model"]
    out = {"identify_args": ident["args"], "exit": ident["exit"], "message": ident["stderr"]}
    if model is None:
        out["model"] = False
        return out
    out["model"] = True
    out["adequate_flag"] = model.get("adequate")
    out["accuracy"] = term_accuracy(model, truth)
    out["heldout"] = predict_heldout(tcomp, model, held, predict_extra)
    out["undetermined"] = named_undetermined(ident)
    return out


def score_machine(tcomp, mdir, plan, extra):
    with open(os.path.join(mdir, "truth.json")) as fh:
        truth = json.load(fh)
    files = sorted(glob.glob(os.path.join(mdir, "lines_" + plan, "*.csv")))
    if not files:
        sys.exit("score.py: no line files in %s" % os.path.join(mdir, "lines_" + plan))
    held = heldout_measured(mdir)
    default = identify(tcomp, files, extra)
    result = {"machine": os.path.basename(mdir), "default": evaluate(tcomp, default, truth, held, [])}
    if default["exit"] != 0:
        diag_args = extra + ["--accept-inadequate"]
        diag = identify(tcomp, files, diag_args)
        if diag["exit"] != 0:
            diag_args = diag_args + ["--partial"]
            diag = identify(tcomp, files, diag_args)
        result["diagnostic"] = evaluate(tcomp, diag, truth, held, ["--accept-inadequate", "--allow-unobservable"])
    d = result["default"]
    h = d.get("heldout") or {}
    result["exit0_on_misfit"] = bool(
        d["exit"] == 0 and h.get("available") and h["residual_rms_um"] > MISFIT_K * NOISE_UM
    )
    return result


def summarise(results, which):
    """Pooled figures over the machines that have a model in `which` (default or best available)."""
    picks = []
    for r in results:
        ev = r["default"] if which == "default" else (r["default"] if r["default"]["exit"] == 0 else r.get("diagnostic"))
        if ev and ev.get("model"):
            picks.append((r["machine"], ev))
    s = {"machines_with_model": len(picks)}
    if not picks:
        return s
    for unit in ("um", "urad"):
        cands = [(ev["accuracy"]["worst"][unit]["rms"], m, ev["accuracy"]["worst"][unit]["term"])
                 for m, ev in picks if unit in ev["accuracy"]["worst"]]
        if cands:
            v, m, t = max(cands)
            s["worst_term_" + unit] = {"rms": v, "machine": m, "term": t}
    cov, cnt = 0, 0
    for _, ev in picks:
        cov += ev["accuracy"]["coverage_3sigma"]["covered"]
        cnt += ev["accuracy"]["coverage_3sigma"]["counted"]
    s["coverage_3sigma"] = cov / cnt if cnt else None
    hs = [(m, ev["heldout"]) for m, ev in picks if ev["heldout"].get("available")]
    if hs:
        res = sum(h["sum_sq_residual"] for _, h in hs)
        meas = sum(h["sum_sq_measured"] for _, h in hs)
        worst = min(hs, key=lambda mh: mh[1]["score"])
        s["heldout_pooled"] = 1.0 - math.sqrt(res / meas)
        s["heldout_worst_machine"] = {"score": worst[1]["score"], "machine": worst[0]}
        s["heldout_machines"] = len(hs)
    else:
        s["heldout"] = "not available: " + "; ".join(
            sorted({ev["heldout"].get("why", "") for _, ev in picks})
        )
    s["names_undetermined"] = sum(1 for _, ev in picks if ev["undetermined"]["names_any"])
    return s


def done_when(plan, results, best):
    if plan == "rich":
        w_um = best.get("worst_term_um", {}).get("rms")
        w_ur = best.get("worst_term_urad", {}).get("rms")
        exit0 = all(r["default"]["exit"] == 0 for r in results)
        return {
            "all_exit_0": exit0,
            "worst_term_le_1.2um_5urad": bool(exit0 and w_um is not None and w_um <= 1.2 and w_ur <= 5.0),
            "heldout_ge_93_pooled_88_worst": bool(
                exit0 and "heldout_pooled" in best and best["heldout_pooled"] >= 0.93
                and best["heldout_worst_machine"]["score"] >= 0.88
            ),
        }
    cov = best.get("coverage_3sigma")
    return {
        "never_exit0_on_misfit": not any(r["exit0_on_misfit"] for r in results),
        "coverage_ge_95": bool(cov is not None and cov >= 0.95),
    }


def fmt_num(v, pct=False):
    if v is None:
        return "n/a"
    return "%.1f %%" % (100 * v) if pct else "%.3f" % v


def print_text(report):
    print("plan %s, %d machines, tcomp %s" % (report["plan"], len(report["machines"]), report["tcomp"]))
    for r in report["machines"]:
        d = r["default"]
        line = "%s  exit %d" % (r["machine"], d["exit"])
        ev = d if d["exit"] == 0 else r.get("diagnostic", {})
        tag = "" if d["exit"] == 0 else " [diagnostic %s]" % " ".join(ev.get("identify_args", []))
        if ev.get("model"):
            acc = ev["accuracy"]
            w = acc["worst"]
            line += "  worst %s µm (%s) %s µrad (%s)  3σ %s" % (
                fmt_num(w.get("um", {}).get("rms")), w.get("um", {}).get("term"),
                fmt_num(w.get("urad", {}).get("rms")), w.get("urad", {}).get("term"),
                fmt_num(acc["coverage_3sigma"]["share"], True))
            h = ev["heldout"]
            line += "  held-out %s" % (fmt_num(h["score"], True) if h.get("available") else h.get("why"))
        print(line + tag)
        if d["exit"] != 0:
            print("    refused: %s" % d["message"][:200])
    for key in ("summary_default", "summary_best_available"):
        print("%s: %s" % (key, json.dumps(report[key])))
    print("done_when: %s" % json.dumps(report["done_when"]))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dir")
    ap.add_argument("--tcomp", required=True)
    ap.add_argument("--plan", choices=["14", "rich"], default="rich")
    ap.add_argument("--identify-args", default="", help="extra identify flags (default: none = default flags)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    mdirs = sorted(d for d in glob.glob(os.path.join(args.dir, "m*")) if os.path.isfile(os.path.join(d, "truth.json")))
    if not mdirs:
        sys.exit("score.py: no machines (mNN/truth.json) in %s" % args.dir)
    extra = shlex.split(args.identify_args)
    results = [score_machine(args.tcomp, d, args.plan, extra) for d in mdirs]
    best = summarise(results, "best")
    report = {
        "world": "three-axis-blind",
        "plan": args.plan,
        "tcomp": args.tcomp,
        "identify_args": extra,
        "noise_um": NOISE_UM,
        "misfit_test": "held-out residual RMS > %.1f x %.1f µm (reading noise of the averaged runs)" % (MISFIT_K, NOISE_UM),
        "exit_0": sum(1 for r in results if r["default"]["exit"] == 0),
        "machines": results,
        "summary_default": summarise(results, "default"),
        "summary_best_available": best,
        "done_when": done_when(args.plan, results, best),
    }
    if args.json:
        json.dump(report, sys.stdout, indent=1)
        print()
    else:
        print_text(report)


if __name__ == "__main__":
    main()
