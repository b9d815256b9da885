#!/usr/bin/env python3
"""How much the FL_THERMAL published test block depends on how a lagged
linear model was chosen on the training rows alone (issue 11, ch3 target).

Features as the board computes them (rise from the first row rounded to
1/16 degC, first-order lags with tau in {0, 900, ..., 21600} s, and the
spindle speed with the same lags); greedy forward selection on the first
60 % of the rows, stopping when the CV RMS no longer improves by 2 %, under
two training-only CV schemes: blocked k-fold (k = 4..10) and forward
chaining (fit on all earlier blocks, score the next; blocks after 40 % of
the training rows). Prints each choice's CV RMS and its float test MAE on
the published test block (rows 60-80 %). Float least squares, no board
quantisation. numpy only.

Usage: scripts/fl-selection-spread.py [--json] [--data run.csv]
"""
import json
import sys

import numpy as np

TAUS = [0, 900, 1800, 3600, 7200, 10800, 21600]


def load(path):
    with open(path) as f:
        lines = [l for l in f if not l.startswith("#")]
    hdr = lines[0].strip().split(",")
    data = np.array([[float(x) for x in l.strip().split(",")] for l in lines[1:]])
    col = {h: i for i, h in enumerate(hdr)}
    dt = float(np.median(np.diff(data[:, 0])))
    temps = [h for h in hdr if h.startswith("T_")]
    rise = np.round((data[:, [col[t] for t in temps]] - data[0, [col[t] for t in temps]]) * 16) / 16
    raw = np.c_[rise, data[:, col["spindle_rpm"]]]
    names_raw = [t[2:] for t in temps] + ["n"]
    feats, names = [], []
    for tau in TAUS:
        if tau == 0:
            lagged = raw.copy()
        else:
            a = np.exp(-dt / tau)
            lagged = np.empty_like(raw)
            s = raw[0].copy()
            for i in range(len(raw)):
                s = a * s + (1 - a) * raw[i]
                lagged[i] = s
        feats.append(lagged)
        names += [f"{n}@{tau}" for n in names_raw]
    ys = {h: data[:, col[h]] for h in hdr if h.endswith("_um")}
    return np.hstack(feats), names, ys


def select(F, y, tr, folds, forward):
    n_feat = F.shape[1]
    A = np.c_[np.ones(len(F)), F, y]
    yi = n_feat + 1
    gram = lambda rows: A[rows].T @ A[rows]
    held = [gram(f) for f in folds]
    if forward:
        use = [k for k, f in enumerate(folds) if f[0] >= 0.4 * tr]
        fit = {k: gram(np.arange(folds[k][0])) for k in use}
    else:
        g_all = gram(np.arange(tr))
        use = list(range(len(folds)))
        fit = {k: g_all - held[k] for k in use}

    def cv(cols):
        c = [0] + [j + 1 for j in cols]
        sse, m = 0.0, 0
        for k in use:
            G, H = fit[k], held[k]
            b = np.linalg.solve(G[np.ix_(c, c)] + 1e-9 * np.eye(len(c)), G[c, yi])
            sse += H[yi, yi] - 2 * b @ H[c, yi] + b @ H[np.ix_(c, c)] @ b
            m += len(folds[k])
        return float(np.sqrt(max(sse, 0.0) / m))

    sel, best = [], np.inf
    while len(sel) < 8:
        s, j = min((cv(sel + [j]), j) for j in range(n_feat) if j not in sel)
        if s > best / 1.02:
            break
        best, sel = s, sel + [j]
    return sel, best


def main():
    args = sys.argv[1:]
    path = "../shared/data/caiviac-fl-thermal/run.csv"
    if "--data" in args:
        path = args[args.index("--data") + 1]
    F, names, ys = load(path)
    n = len(F)
    tr, te = int(0.6 * n), int(0.8 * n)
    out = {"data": path, "test_rows": [tr, te], "channels": {}}
    for ch in ["dch3_um", "dch5_um"]:
        y = ys[ch]
        rows = []
        for forward in (False, True):
            for k in range(4, 11):
                folds = np.array_split(np.arange(tr), k)
                sel, cv = select(F, y, tr, folds, forward)
                X = np.c_[np.ones(tr), F[:tr][:, sel]]
                b = np.linalg.lstsq(X, y[:tr], rcond=None)[0]
                p = np.c_[np.ones(te - tr), F[tr:te][:, sel]] @ b
                rows.append({
                    "cv": "forward" if forward else "blocked", "folds": k,
                    "inputs": [names[i] for i in sel], "cv_rms_um": cv,
                    "test_mae_um": float(np.mean(np.abs(p - y[tr:te]))),
                })
        maes = [r["test_mae_um"] for r in rows]
        out["channels"][ch] = {"choices": rows, "test_mae_min_um": min(maes),
                               "test_mae_median_um": float(np.median(maes)),
                               "test_mae_max_um": max(maes)}
    if "--json" in args:
        print(json.dumps(out))
        return
    for ch, v in out["channels"].items():
        print(f"{ch}: float test MAE over {len(v['choices'])} training-only choices: "
              f"min {v['test_mae_min_um']:.2f}, median {v['test_mae_median_um']:.2f}, max {v['test_mae_max_um']:.2f} µm")
        for r in v["choices"]:
            print(f"  {r['cv']:>7} k={r['folds']:>2}: CV {r['cv_rms_um']:.2f}  test MAE {r['test_mae_um']:.2f}  {' '.join(r['inputs'])}")


if __name__ == "__main__":
    main()
