#!/usr/bin/env python3
"""scikit-learn side of `bench-fit`: train MLPRegressor(11, logistic) on the
CSV the bench writes (columns x1..xn, y, split with split = train|test;
inputs already normalized to [-1, 1] exactly as for our network) and print
JSON {train_s, mae_um, n_iter} for the test rows.

Usage: bench-sklearn.py data.csv [--max-iter 200] [--seed 0]
"""
import argparse
import json
import sys
import time

import numpy as np
from sklearn.neural_network import MLPRegressor


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("csv")
    ap.add_argument("--max-iter", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    with open(a.csv) as f:
        header = f.readline().strip().split(",")
    raw = np.genfromtxt(a.csv, delimiter=",", skip_header=1, dtype=str)
    xcols = [i for i, h in enumerate(header) if h.startswith("x")]
    yi, si = header.index("y"), header.index("split")
    x = raw[:, xcols].astype(float)
    y = raw[:, yi].astype(float)
    train = raw[:, si] == "train"
    test = raw[:, si] == "test"
    # Target standardized on the training rows (same as our trainer does).
    mu, sd = y[train].mean(), y[train].std() or 1.0
    m = MLPRegressor(hidden_layer_sizes=(11,), activation="logistic",
                     max_iter=a.max_iter, random_state=a.seed)
    t0 = time.perf_counter()
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m.fit(x[train], (y[train] - mu) / sd)
    train_s = time.perf_counter() - t0
    pred = m.predict(x[test]) * sd + mu
    mae = float(np.mean(np.abs(pred - y[test])))
    json.dump({"train_s": train_s, "mae_um": mae, "n_iter": int(m.n_iter_),
               "train_rows": int(train.sum()), "test_rows": int(test.sum())}, sys.stdout)
    print()


if __name__ == "__main__":
    main()
