#!/usr/bin/env python3
"""extrap-blind scorer (issue 50): the user's path against two references.

Per case (DIR/case_*/run.csv + truth.json written by gen.py):
  1. the user's path, default pipeline, training rows only:
       tcomp fit run.csv --split-chrono 0.6,1 --out fit.json --json
       tcomp export --model fit.json --run run.csv -o model.img --json
       tcomp replay run.csv model.img --from F --reference-at <split time>
                    --reference-dump dump.csv --json
     the board's served correction per row is the dump's `<ch>_model`
     column (the model alone; the `--reference-at` re-zero only changes the
     `_served` column, which is not used); served error = measured − model
     on the served rows, about the run's reference (what the board serves);
  2. a ridge on all temperature inputs fitted on the same training rows, its
     penalty chosen by forward-chaining time-blocked CV on training rows only;
  3. the raw error about an operator's re-zero at the served part's start
     (no model: measured(t) − measured(t_split)).
Prints per case and channel, and a summary: channel-cases where the default
is worse than the ridge by more than 5 % (served RMS), and where it is worse
than the raw error after a re-zero. `--json` prints everything as one JSON
object instead.

    python3 score.py DIR --tcomp PATH [--json] [--timeout S]

Python 3.11 standard library only.
"""

import argparse
import csv
import glob
import json
import math
import os
import subprocess
import sys
import time

PENALTIES = [10.0 ** (-5.0 + 0.5 * k) for k in range(13)]  # 1e-5 .. 10
CV_BLOCKS = 8  # training rows cut into 8 time blocks; the later half is predicted


def read_run(path):
    """Header and rows of a run CSV (metadata lines skipped); None for empty."""
    with open(path, encoding="utf-8") as f:
        lines = [ln for ln in f if not ln.startswith("#")]
    reader = csv.reader(lines)
    header = next(reader)
    rows = []
    for rec in reader:
        rows.append([float(x) if x.strip() != "" else None for x in rec])
    return header, rows


def stats(res):
    """MAE and RMS of a residual list (None skipped)."""
    v = [x for x in res if x is not None]
    if not v:
        return None, None
    mae = sum(abs(x) for x in v) / len(v)
    rms = math.sqrt(sum(x * x for x in v) / len(v))
    return mae, rms


# ---------------------------------------------------------------- ridge


def solve(a, b):
    """Gaussian elimination with partial pivoting; a is n x n (copied)."""
    n = len(b)
    m = [row[:] + [b[i]] for i, row in enumerate(a)]
    for c in range(n):
        p = max(range(c, n), key=lambda r: abs(m[r][c]))
        m[c], m[p] = m[p], m[c]
        piv = m[c][c]
        if abs(piv) < 1e-300:
            raise ValueError("singular system")
        for r in range(c + 1, n):
            f = m[r][c] / piv
            if f != 0.0:
                for k in range(c, n + 1):
                    m[r][k] -= f * m[c][k]
    x = [0.0] * n
    for r in range(n - 1, -1, -1):
        s = m[r][n] - sum(m[r][k] * x[k] for k in range(r + 1, n))
        x[r] = s / m[r][r]
    return x


def ridge_prepare(xs, ys):
    """Standardised normal equations (independent of the penalty)."""
    n = len(ys)
    p = len(xs[0])
    mu = [sum(r[j] for r in xs) / n for j in range(p)]
    sd = []
    for j in range(p):
        var = sum((r[j] - mu[j]) ** 2 for r in xs) / n
        sd.append(math.sqrt(var) if var > 1e-12 else 1.0)
    ym = sum(ys) / n
    a = [[0.0] * p for _ in range(p)]
    b = [0.0] * p
    for r0, y in zip(xs, ys):
        r = [(r0[j] - mu[j]) / sd[j] for j in range(p)]
        dy = y - ym
        for i in range(p):
            ri = r[i]
            b[i] += ri * dy
            row = a[i]
            for k in range(i, p):
                row[k] += ri * r[k]
    for i in range(p):
        for k in range(i, p):
            a[i][k] /= n
            a[k][i] = a[i][k]
        b[i] /= n
    return mu, sd, ym, a, b


def ridge_solve(prep, lam):
    """Ridge on standardised inputs, unpenalised intercept. Returns a predictor."""
    mu, sd, ym, a, b = prep
    p = len(b)
    a2 = [row[:] for row in a]
    for i in range(p):
        a2[i][i] += lam
    beta = solve(a2, b)

    def predict(row):
        return ym + sum(beta[j] * (row[j] - mu[j]) / sd[j] for j in range(p))

    coef = [beta[j] / sd[j] for j in range(p)]  # um per K
    return predict, coef


def ridge_choose(xs, ys):
    """Penalty by forward-chaining time-blocked CV on the training rows."""
    n = len(ys)
    edges = [round(k * n / CV_BLOCKS) for k in range(CV_BLOCKS + 1)]
    folds = [(ridge_prepare(xs[: edges[k]], ys[: edges[k]]), edges[k], edges[k + 1])
             for k in range(CV_BLOCKS // 2, CV_BLOCKS)]
    best = None
    table = []
    for lam in PENALTIES:
        sse = 0.0
        cnt = 0
        for prep, a, b in folds:
            pred, _ = ridge_solve(prep, lam)
            for r, y in zip(xs[a:b], ys[a:b]):
                e = y - pred(r)
                sse += e * e
                cnt += 1
        rms = math.sqrt(sse / cnt)
        table.append({"penalty": lam, "cv_rms_um": rms})
        if best is None or rms < best[1]:
            best = (lam, rms)
    return best[0], best[1], table


def references(header, rows, ch, split):
    """The ridge and the raw re-zero on the served rows of one channel."""
    tcols = [j for j, h in enumerate(header) if h.startswith("T_")]
    cj = header.index(ch)
    train = [r for r in rows[:split] if r[cj] is not None and all(r[j] is not None for j in tcols)]
    xs = [[r[j] for j in tcols] for r in train]
    ys = [r[cj] for r in train]
    lam, cv_rms, table = ridge_choose(xs, ys)
    pred, coef = ridge_solve(ridge_prepare(xs, ys), lam)
    served = rows[split:]
    res_ridge = []
    for r in served:
        if r[cj] is None or any(r[j] is None for j in tcols):
            res_ridge.append(None)
        else:
            res_ridge.append(r[cj] - pred([r[j] for j in tcols]))
    zero = next((r[cj] for r in served if r[cj] is not None), 0.0)
    res_raw = [None if r[cj] is None else r[cj] - zero for r in served]
    res_uncomp = [r[cj] for r in served]
    names = [header[j] for j in tcols]
    return {
        "ridge_penalty": lam,
        "ridge_cv_rms_um": cv_rms,
        "ridge_cv_table": table,
        "ridge_coef_um_per_k": dict(zip(names, coef)),
        "res_ridge": res_ridge,
        "res_raw_rezero": res_raw,
        "res_uncompensated": res_uncomp,
    }


# ---------------------------------------------------------------- tcomp


def run_tool(cmd, timeout):
    """Run one tcomp command; (ok, stdout, one-line reason)."""
    try:
        cp = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return False, "", "timed out after %d s" % timeout
    if cp.returncode != 0:
        first = (cp.stderr.strip().splitlines() or ["(no stderr)"])[0]
        return False, cp.stdout, "exit %d: %s" % (cp.returncode, first)
    return True, cp.stdout, ""


def parse_json(text):
    try:
        return json.loads(text)
    except ValueError:
        i = text.find("{")
        j = text.rfind("}")
        if i >= 0 and j > i:
            try:
                return json.loads(text[i : j + 1])
            except ValueError:
                return None
    return None


def user_path(tcomp, case_dir, truth, timeout):
    """fit (training 60 %), export, replay; per-row board corrections."""
    run = os.path.join(case_dir, "run.csv")
    work = os.path.join(case_dir, "score")
    os.makedirs(work, exist_ok=True)
    fit_json = os.path.join(work, "fit.json")
    img = os.path.join(work, "model.img")
    dump = os.path.join(work, "dump.csv")
    out = {"ok": False}
    t0 = time.time()
    ok, so, why = run_tool([tcomp, "fit", run, "--split-chrono", "0.6,1", "--out", fit_json, "--json"], timeout)
    out["fit_s"] = round(time.time() - t0, 1)
    if not ok:
        out["failed"] = "fit: " + why
        return out
    fit = parse_json(so) or {}
    out["chosen"] = fit.get("chosen", {})
    out["train_segments"] = fit.get("train_segments")
    out["notes"] = fit.get("notes", [])
    ok, so, why = run_tool([tcomp, "export", "--model", fit_json, "--run", run, "-o", img, "--json"], timeout)
    if not ok:
        out["failed"] = "export: " + why
        return out
    out["export"] = parse_json(so)
    split = truth["served_rows"][0]
    frac = "%.6f" % (split / truth["rows"])
    t_split = "%g" % truth["split_time_s"]
    cmd = [tcomp, "replay", run, img, "--from", frac, "--reference-at", t_split,
           "--reference-dump", dump, "--json"]
    ok, so, why = run_tool(cmd, timeout)
    if not ok:
        out["failed"] = "replay: " + why
        return out
    out["replay"] = parse_json(so)
    if not os.path.exists(dump):
        out["failed"] = "replay wrote no --reference-dump file"
        return out
    out["dump"] = read_run(dump)
    out["ok"] = True
    return out


def served_residual(dump, ch, t_from):
    """measured − model from the replay dump, rows from t_from on."""
    header, rows = dump
    ti = header.index("time_s")
    mi = header.index(ch + "_measured")
    ci = header.index(ch + "_model")
    res = []
    for r in rows:
        if r[ti] is None or r[ti] < t_from - 1e-6:
            continue
        if r[mi] is None or r[ci] is None:
            res.append(None)
        else:
            res.append(r[mi] - r[ci])
    return res


def rezeroed(res):
    z = next((x for x in res if x is not None), 0.0)
    return [None if x is None else x - z for x in res]


# ---------------------------------------------------------------- per case


def score_case(case_dir, tcomp, timeout):
    with open(os.path.join(case_dir, "truth.json"), encoding="utf-8") as f:
        truth = json.load(f)
    header, rows = read_run(os.path.join(case_dir, "run.csv"))
    split = truth["served_rows"][0]
    t_split = truth["split_time_s"]
    up = user_path(tcomp, case_dir, truth, timeout)
    case = {
        "case": truth["case"],
        "kind": truth["kind"],
        "beyond_by_design": truth["beyond_by_design"],
        "group_beyond_k": truth["group_beyond_k"],
        "rows": truth["rows"],
        "split_row": split,
        "fit_s": up.get("fit_s"),
        "tcomp_failed": up.get("failed"),
        "chosen": up.get("chosen"),
        "notes": up.get("notes", []),
        "channels": [],
    }
    seg = up.get("train_segments")
    if seg and isinstance(seg, list) and isinstance(seg[0], dict) and seg[0].get("end") != split:
        case["notes"] = case["notes"] + ["scorer: tcomp trained on rows [0,%s), the truth's training part is [0,%d)" % (seg[0].get("end"), split)]
    for ch in truth["channels"]:
        ref = references(header, rows, ch, split)
        c = {"channel": ch, "ridge_penalty": ref["ridge_penalty"], "ridge_cv_rms_um": ref["ridge_cv_rms_um"]}
        c["ridge_mae_um"], c["ridge_rms_um"] = stats(ref["res_ridge"])
        c["ridge_rezero_mae_um"], c["ridge_rezero_rms_um"] = stats(rezeroed(ref["res_ridge"]))
        c["raw_rezero_mae_um"], c["raw_rezero_rms_um"] = stats(ref["res_raw_rezero"])
        c["uncompensated_mae_um"], c["uncompensated_rms_um"] = stats(ref["res_uncompensated"])
        c["ridge_coef_um_per_k"] = ref["ridge_coef_um_per_k"]
        c["default_mae_um"] = c["default_rms_um"] = None
        if up["ok"]:
            try:
                res = served_residual(up["dump"], ch, t_split)
                c["default_mae_um"], c["default_rms_um"] = stats(res)
                c["default_rezero_mae_um"], c["default_rezero_rms_um"] = stats(rezeroed(res))
                c["served_rows_scored"] = len(res)
            except ValueError as e:
                c["default_error"] = "dump has no column for %s: %s" % (ch, e)
            rep = up.get("replay") or {}
            for rc in rep.get("channels", []):
                if rc.get("column") == ch:
                    c["replay_rms_um"] = rc.get("rms_um")
                    c["replay_out_of_envelope_share"] = rc.get("out_of_envelope_share")
        c["chosen"] = (up.get("chosen") or {}).get(ch)
        d, rr, raw = c["default_rms_um"], c["ridge_rms_um"], c["raw_rezero_rms_um"]
        c["worse_than_ridge_5pct"] = None if d is None else d > 1.05 * rr
        c["worse_than_raw_rezero"] = None if d is None else d > raw
        case["channels"].append(c)
    return case


def fmt(x):
    return "  n/a" if x is None else "%5.2f" % x


def print_case(case):
    head = "%s %-12s beyond K amb %.2f tab %.2f spin %.2f  fit %ss" % (
        case["case"], case["kind"], case["group_beyond_k"]["ambient"],
        case["group_beyond_k"]["table"], case["group_beyond_k"]["spindle"], case["fit_s"])
    print(head)
    if case["tcomp_failed"]:
        print("  tcomp failed: %s" % case["tcomp_failed"])
    for c in case["channels"]:
        flags = []
        if c["worse_than_ridge_5pct"]:
            flags.append("WORSE-THAN-RIDGE")
        if c["worse_than_raw_rezero"]:
            flags.append("WORSE-THAN-RAW-REZERO")
        print("  %-6s chosen %-10s served RMS um: default %s (re-zeroed %s)  ridge %s [pen %.0e]  raw re-zero %s  uncomp %s  %s" % (
            c["channel"], c["chosen"] or "-", fmt(c["default_rms_um"]), fmt(c.get("default_rezero_rms_um")),
            fmt(c["ridge_rms_um"]), c["ridge_penalty"], fmt(c["raw_rezero_rms_um"]),
            fmt(c["uncompensated_rms_um"]), " ".join(flags)))


def summarize(cases):
    s = {"cases": len(cases), "tcomp_failed": sum(1 for c in cases if c["tcomp_failed"])}
    for label, pick in (("all", lambda c: True), ("beyond", lambda c: c["beyond_by_design"]),
                        ("control", lambda c: not c["beyond_by_design"])):
        chs = [x for c in cases if pick(c) for x in c["channels"] if x["default_rms_um"] is not None]
        if not chs:
            s[label] = {"channel_cases": 0}
            continue
        d = [x["default_rms_um"] for x in chs]
        r = [x["ridge_rms_um"] for x in chs]
        w = [x["raw_rezero_rms_um"] for x in chs]
        s[label] = {
            "channel_cases": len(chs),
            "default_worse_than_ridge_5pct": sum(1 for x in chs if x["worse_than_ridge_5pct"]),
            "default_worse_than_raw_rezero": sum(1 for x in chs if x["worse_than_raw_rezero"]),
            "ridge_worse_than_raw_rezero": sum(1 for a, b in zip(r, w) if a > b),
            "mean_rms_um": {"default": sum(d) / len(d), "ridge": sum(r) / len(r), "raw_rezero": sum(w) / len(w)},
            "max_default_over_ridge": max(a / b for a, b in zip(d, r) if b > 0),
        }
    return s


def print_summary(s):
    print("summary: %d cases, tcomp failed on %d" % (s["cases"], s["tcomp_failed"]))
    for label in ("all", "beyond", "control"):
        x = s[label]
        if not x["channel_cases"]:
            print("  %-7s no scored channel-cases" % label)
            continue
        m = x["mean_rms_um"]
        print("  %-7s %2d channel-cases: default worse than ridge by >5 %%: %d; default worse than raw re-zero: %d; "
              "ridge worse than raw re-zero: %d; mean served RMS um default %.2f ridge %.2f raw re-zero %.2f; "
              "worst default/ridge %.2f" % (
                  label, x["channel_cases"], x["default_worse_than_ridge_5pct"], x["default_worse_than_raw_rezero"],
                  x["ridge_worse_than_raw_rezero"], m["default"], m["ridge"], m["raw_rezero"],
                  x["max_default_over_ridge"]))


def main():
    ap = argparse.ArgumentParser(description="score the extrap-blind world")
    ap.add_argument("dir")
    ap.add_argument("--tcomp", required=True)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--timeout", type=int, default=1800, help="seconds per tcomp command")
    a = ap.parse_args()
    dirs = sorted(d for d in glob.glob(os.path.join(a.dir, "case_*")) if os.path.isdir(d))
    if not dirs:
        print("error: %s: no case_* directories (run gen.py --out %s first)" % (a.dir, a.dir), file=sys.stderr)
        return 1
    cases = []
    for d in dirs:
        case = score_case(d, a.tcomp, a.timeout)
        cases.append(case)
        if not a.json:
            print_case(case)
            sys.stdout.flush()
    s = summarize(cases)
    if a.json:
        json.dump({"cases": cases, "summary": s}, sys.stdout, indent=1)
        print()
    else:
        print_summary(s)
    return 0


if __name__ == "__main__":
    sys.exit(main())
