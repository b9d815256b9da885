#!/usr/bin/env python3
"""extrap-blind diagnosis (issue 50): how much of the default's loss to the
ridge is the board's training-envelope hold, and how much is the model.

Not a scorer (score.py stays the measurement): run it on a directory score.py
has already scored (it reads DIR/case_*/run.csv, truth.json and score/fit.json,
score/dump.csv). Per case and channel, served RMS (µm) on the served rows:

  default      the board's `<ch>_model` from score.py's replay dump;
  no-hold      the same fitted linear models (mlr, mlr-static, ridge) with
               every input's envelope set to the whole run's range (the same
               function wherever the fit's range held; the board then holds
               nowhere in this run), through `tcomp export` and `tcomp
               replay` (the board's own code); a network is left as it is;
  ridge        score.py's forward-chained-CV ridge on all temperatures;
  ridge-held   that ridge with each temperature held at its training range's
               edge (the board's rule 4 applied to the ridge).

    python3 hold_check.py DIR --tcomp PATH

Writes DIR/case_*/hold_check/. Python 3.11 standard library only.
"""

import argparse
import glob
import json
import math
import os
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import score  # noqa: E402  (its ridge and run reader, unchanged)


def column(header, rows, name):
    j = header.index(name)
    return [r[j] for r in rows]


def feature(header, rows, spec):
    """The board's feature for `spec` on every row (rise from the first row,
    first-order lag filter over the elapsed time)."""
    kind, tau = spec["kind"], spec["tau_s"]
    t = column(header, rows, "time_s")
    if kind == "Spindle":
        x = column(header, rows, "spindle_rpm")
    elif "SensorRise" in kind:
        s = column(header, rows, kind["SensorRise"])
        x = [v - s[0] for v in s]
    else:
        a, b = kind["SensorDiff"]
        x = [p - q for p, q in zip(column(header, rows, a), column(header, rows, b))]
    if tau:
        y = [x[0]]
        for i in range(1, len(x)):
            k = 1.0 - math.exp(-(t[i] - t[i - 1]) / tau)
            y.append(y[-1] + k * (x[i] - y[-1]))
        x = y
    return x


def widened(fit, header, rows):
    """The fit file with every linear model's envelope set to the run's range
    (the same linear function: coefficients and intercept re-expressed)."""
    for key in ("mlr", "mlr_static", "ridge"):
        for m in fit.get(key, []):
            for i, f in enumerate(m["features"]):
                lo, hi = f["min"], f["max"]
                if hi <= lo:
                    continue
                x = feature(header, rows, f)
                lo2, hi2 = min(lo, min(x)), max(hi, max(x))
                c = m["coef"][i]
                c2 = c * (hi2 - lo2) / (hi - lo)
                m["c0"] += -c * (2 * lo / (hi - lo) + 1) + c2 * (2 * lo2 / (hi2 - lo2) + 1)
                m["coef"][i] = c2
                f["min"], f["max"] = lo2, hi2
    fit["envelope"] = {}
    return fit


def rms(v):
    v = [x for x in v if x is not None]
    return math.sqrt(sum(x * x for x in v) / len(v)) if v else float("nan")


def served(dump, ch, split):
    header, rows = dump
    return [
        None if m is None or c is None else m - c
        for m, c in zip(column(header, rows, ch + "_measured")[split:],
                        column(header, rows, ch + "_model")[split:])
    ]


def case_rows(case_dir, tcomp):
    truth = json.load(open(os.path.join(case_dir, "truth.json"), encoding="utf-8"))
    run = os.path.join(case_dir, "run.csv")
    header, rows = score.read_run(run)
    split = truth["served_rows"][0]
    work = os.path.join(case_dir, "hold_check")
    os.makedirs(work, exist_ok=True)
    fit = json.load(open(os.path.join(case_dir, "score", "fit.json"), encoding="utf-8"))
    wide = os.path.join(work, "fit_no_hold.json")
    json.dump(widened(fit, header, rows), open(wide, "w", encoding="utf-8"))
    img, dump = os.path.join(work, "model.img"), os.path.join(work, "dump.csv")
    frac, t_split = "%.6f" % (split / truth["rows"]), "%g" % truth["split_time_s"]
    for cmd in ([tcomp, "export", "--model", wide, "--run", run, "-o", img, "--json"],
                [tcomp, "replay", run, img, "--from", frac, "--reference-at", t_split,
                 "--reference-dump", dump, "--json"]):
        subprocess.run(cmd, capture_output=True, check=True, timeout=600)
    base = score.read_run(os.path.join(case_dir, "score", "dump.csv"))
    free = score.read_run(dump)
    tcols = [j for j, h in enumerate(header) if h.startswith("T_")]
    xs = [[r[j] for j in tcols] for r in rows]
    lo = [min(x[k] for x in xs[:split]) for k in range(len(tcols))]
    hi = [max(x[k] for x in xs[:split]) for k in range(len(tcols))]
    out = []
    for ch in truth["channels"]:
        y = column(header, rows, ch)
        lam, _, _ = score.ridge_choose(xs[:split], y[:split])
        pred, _ = score.ridge_solve(score.ridge_prepare(xs[:split], y[:split]), lam)
        held = [[min(max(v, lo[k]), hi[k]) for k, v in enumerate(x)] for x in xs]
        out.append({
            "case": truth["case"], "kind": truth["kind"], "channel": ch,
            "beyond": truth["beyond_by_design"], "chosen": fit["chosen"].get(ch),
            "default": rms(served(base, ch, split)),
            "no_hold": rms(served(free, ch, split)),
            "ridge": rms([y[i] - pred(xs[i]) for i in range(split, len(y))]),
            "ridge_held": rms([y[i] - pred(held[i]) for i in range(split, len(y))]),
        })
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("dir")
    ap.add_argument("--tcomp", required=True)
    a = ap.parse_args()
    allrows = []
    for case_dir in sorted(glob.glob(os.path.join(a.dir, "case_*"))):
        for r in case_rows(case_dir, a.tcomp):
            allrows.append(r)
            print("%s %-12s %s chosen %-10s served RMS um: default %5.2f  no-hold %5.2f  "
                  "ridge %5.2f  ridge-held %5.2f" % (r["case"], r["kind"], r["channel"], r["chosen"],
                                                    r["default"], r["no_hold"], r["ridge"],
                                                    r["ridge_held"]), flush=True)
    for name, sel in (("beyond", True), ("control", False)):
        g = [r for r in allrows if r["beyond"] == sel]
        if not g:
            continue
        mean = {k: sum(r[k] for r in g) / len(g) for k in ("default", "no_hold", "ridge", "ridge_held")}
        worse = {k: sum(r[k] > 1.05 * r["ridge"] for r in g) for k in ("default", "no_hold", "ridge_held")}
        print("%-7s %2d channel-cases: mean served RMS um default %.2f no-hold %.2f ridge %.2f "
              "ridge-held %.2f; worse than ridge by >5 %%: default %d, no-hold %d, ridge-held %d"
              % (name, len(g), mean["default"], mean["no_hold"], mean["ridge"], mean["ridge_held"],
                 worse["default"], worse["no_hold"], worse["ridge_held"]))


if __name__ == "__main__":
    main()
