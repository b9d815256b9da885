#!/usr/bin/env python3
"""Self-consistency of the blind three-axis world (no tcomp needed).

    python3 selftest.py [--dir DIR]    (DIR: a world written by gen.py, checked too)

1. gen's chain against an independent 4x4 homogeneous-matrix chain (Rodrigues rotations);
2. the first-order form of docs/geometry.md against the exact chain: second order
   (halving every error quarters the difference);
3. a line file's readings against the independent chain with the set-up used
   (noise off: to the file's rounding; noise on: residual of the stated size);
4. the truth: zeros where the conventions put them, amplitudes in their ranges,
   truth.json equal to the functions, reproducible per seed;
5. with --dir: held-out lines unlike every plan line, and every file of the
   world consistent with its truth.json within the noise.
"""

import argparse
import glob
import json
import math
import os
import random
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import gen  # noqa: E402

FAILS = []


def check(ok, what):
    print(("ok    " if ok else "FAIL  ") + what)
    if not ok:
        FAILS.append(what)


# ---------------------------------------------------------- independent chain


def rodrigues(axis, angle):
    x, y, z = axis
    c, s, t = math.cos(angle), math.sin(angle), 1.0 - math.cos(angle)
    return [
        [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
        [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
        [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
    ]


def homog(rot, trans):
    return [rot[0] + [trans[0]], rot[1] + [trans[1]], rot[2] + [trans[2]], [0.0, 0.0, 0.0, 1.0]]


def mul4(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(4)) for j in range(4)] for i in range(4)]


def mul3(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def apply3(a, v):
    return [sum(a[i][k] * v[k] for k in range(3)) for i in range(3)]


def value(truth_m, name, q):
    """Term value from the function parameters, re-implemented here."""
    if name in gen.SQUARENESS:
        return truth_m["squareness"][name]
    f = truth_m["functions"][name]

    def raw(x):
        u = x / f["L"]
        v = sum(c * u ** (j + 1) for j, c in enumerate(f["poly"]))
        v += sum(a * math.sin(2 * math.pi * x / lam + ph) for a, lam, ph in f["waves"])
        v += sum(a * math.exp(-0.5 * ((x - c0) / w) ** 2) for a, c0, w in f["bumps"])
        return v

    v = raw(q) - raw(0.0)
    if f["zero_at_end"]:
        v -= (raw(f["L"]) - raw(0.0)) * q / f["L"]
    return f["scale"] * v


def chain_point(m, q, tool):
    ex, ey, ez = [1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]
    u = {
        "X": ex,
        "Y": apply3(rodrigues(ez, m["squareness"]["EC0Y"] * 1e-6), ey),
        "Z": apply3(mul3(rodrigues(ey, m["squareness"]["EB0Z"] * 1e-6), rodrigues(ex, m["squareness"]["EA0Z"] * 1e-6)), ez),
    }
    total = homog([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]], [0.0, 0.0, 0.0])
    for k, qk in zip("XYZ", q):
        d = [value(m, "E%s%s" % (c, k), qk) * 1e-3 for c in "XYZ"]
        a, b, c = (value(m, "E%s%s" % (c, k), qk) * 1e-6 for c in "ABC")
        rot = mul3(mul3(rodrigues(ez, c), rodrigues(ey, b)), rodrigues(ex, a))
        total = mul4(total, homog(rot, [qk * u[k][i] + d[i] for i in range(3)]))
    p = [sum(total[i][j] * tool[j] for j in range(3)) + total[i][3] for i in range(3)]
    return p


def first_order_um(m, q, tool):
    """Delta = sum_k [delta_k + eps_k x r_k] - EC0Y y x + EB0Z z x - EA0Z z y (docs/geometry.md)."""
    out = [0.0, 0.0, 0.0]
    arms = {"X": [0.0, q[1], q[2]], "Y": [0.0, 0.0, q[2]], "Z": [0.0, 0.0, 0.0]}
    for k, qk in zip("XYZ", q):
        r = [arms[k][i] + tool[i] for i in range(3)]
        d = [value(m, "E%s%s" % (c, k), qk) for c in "XYZ"]
        e = [value(m, "E%s%s" % (c, k), qk) * 1e-3 for c in "ABC"]  # µrad x mm = 1e-3 µm
        cross = [e[1] * r[2] - e[2] * r[1], e[2] * r[0] - e[0] * r[2], e[0] * r[1] - e[1] * r[0]]
        out = [out[i] + d[i] + cross[i] for i in range(3)]
    s = m["squareness"]
    out[0] += (-s["EC0Y"] * q[1] + s["EB0Z"] * q[2]) * 1e-3
    out[1] += -s["EA0Z"] * q[2] * 1e-3
    return out


def scaled(m, k):
    out = json.loads(json.dumps(m))
    for f in out["functions"].values():
        f["scale"] *= k
    for n in out["squareness"]:
        out["squareness"][n] *= k
    return out


def random_poses(rng, n):
    return [([rng.uniform(0, gen.STROKE[a]) for a in "XYZ"], [rng.uniform(-150, 150), rng.uniform(-150, 150), rng.uniform(0, 250)]) for _ in range(n)]


# ---------------------------------------------------------- checks


def check_chain(machines, rng):
    worst = 0.0
    for m in machines:
        for q, t in random_poses(rng, 30):
            a = gen.tool_point(m, q, t)
            b = chain_point(m, q, t)
            worst = max(worst, max(abs(a[i] - b[i]) for i in range(3)))
    check(worst < 1e-10, "gen's chain equals an independent 4x4 chain (worst %.2e mm)" % worst)


def check_first_order(machines, rng):
    ratios, worst = [], 0.0
    for m in machines:
        for q, t in random_poses(rng, 20):
            full = gen.tool_tip_error_um(m, q, t)
            lin = first_order_um(m, q, t)
            d1 = math.sqrt(sum((full[i] - lin[i]) ** 2 for i in range(3)))
            h = scaled(m, 0.5)
            d2 = math.sqrt(sum((gen.tool_tip_error_um(h, q, t)[i] - first_order_um(h, q, t)[i]) ** 2 for i in range(3)))
            worst = max(worst, d1)
            if d1 > 1e-5:
                ratios.append(d2 / d1)
    check(worst < 0.05, "first-order form within %.4f µm of the exact chain (second order only)" % worst)
    check(bool(ratios) and all(0.2 < r < 0.3 for r in ratios), "halving every error quarters that difference (%d poses)" % len(ratios))


def setup_reading(m, setup, q0, q, s):
    """Reading of one target with the line's set-up (beam, reflector, scale), noise-free."""
    p0, p = chain_point(m, q0, setup["reflector"]), chain_point(m, q, setup["reflector"])
    moved = sum(setup["beam"][i] * (p[i] - p0[i]) for i in range(3))
    return (moved * (1 + setup["scale_ppm"] * 1e-6) - s) * 1e3


def read_runs(path_glob):
    out = {}
    for path in sorted(glob.glob(path_glob)):
        meta, rows = {}, []
        with open(path, encoding="utf-8") as fh:
            for raw in fh:
                if raw.startswith("#"):
                    k, _, v = raw[1:].partition(":")
                    meta[k.strip()] = v.strip()
                elif not raw.startswith("s_mm") and raw.strip():
                    rows.append([float(x) for x in raw.split(",")])
        out.setdefault(meta["line"], []).append((meta, rows))
    return out


def check_line_files(m, rng_seed):
    lines = gen.heldout_lines()
    with tempfile.TemporaryDirectory() as tmp:
        saved = gen.NOISE_UM
        gen.NOISE_UM = 0.0
        rec = gen.measure_lines(random.Random(rng_seed), m, lines, os.path.join(tmp, "quiet"))
        gen.NOISE_UM = saved
        rec_noisy = gen.measure_lines(random.Random(rng_seed), m, lines, os.path.join(tmp, "noisy"))
        quiet = read_runs(os.path.join(tmp, "quiet", "*.csv"))
        noisy = read_runs(os.path.join(tmp, "noisy", "*.csv"))
    worst_q, worst_pos, res, n, zero_first, meta_ok = 0.0, 0.0, 0.0, 0, True, True
    for line, r, rn in zip(lines, rec, rec_noisy):
        setup = r["setup"]
        meta_ok &= setup == rn["setup"]
        for runs, quiet_case in ((quiet[line["line"]], True), (noisy[line["line"]], False)):
            meta_ok &= len(runs) == 2 and {mt["run"] for mt, _ in runs} == {"forward", "backward"}
            for meta, rows in runs:
                d = [float(v) for v in meta["direction"].split(",")]
                meta_ok &= max(abs(d[i] - line["direction"][i]) for i in range(3)) < 1e-12
                meta_ok &= meta["structure"] == "XY/Z" and meta["source"] == "simulated"
                zero_first &= rows[0][4] == 0.0
                q0 = rows[0][1:4]
                p0 = chain_point(m, q0, setup["reflector"])
                for row in rows:
                    s, q = row[0], row[1:4]
                    want = [line["start_mm"][i] + s * line["direction"][i] for i in range(3)]
                    worst_pos = max(worst_pos, max(abs(q[i] - want[i]) for i in range(3)))
                    p = chain_point(m, q, setup["reflector"])
                    moved = sum(setup["beam"][i] * (p[i] - p0[i]) for i in range(3))
                    expect = (moved * (1 + setup["scale_ppm"] * 1e-6) - s) * 1e3
                    if quiet_case:
                        worst_q = max(worst_q, abs(row[4] - expect))
                    elif s > 0:
                        res += (row[4] - expect) ** 2
                        n += 1
    check(meta_ok, "line files: metadata and set-up as written, forward and backward runs")
    check(zero_first, "every run zeroed at its first target")
    check(worst_pos < 2e-6, "pos_x,y,z = start + s·direction (worst %.1e mm)" % worst_pos)
    check(worst_q < 2e-3, "noise off: readings equal the independent chain (worst %.1e µm)" % worst_q)
    rms = math.sqrt(res / n)
    expect = gen.NOISE_UM * math.sqrt(2.0)  # n_i - n_0 of one run
    check(abs(rms - expect) < 0.15 * expect, "noise on: residual %.3f µm RMS, stated %.3f µm (reading minus first)" % (rms, expect))


def check_truth(machines):
    zeros, ends, ranges, sq = 0.0, 0.0, True, True
    for m in machines:
        for name, f in m["functions"].items():
            kind = gen.term_kind(name)
            zeros = max(zeros, abs(gen.term_value(m, name, 0.0)))
            if kind == "straightness":
                ends = max(ends, abs(gen.term_value(m, name, f["L"])))
            peak = max(abs(gen.term_value(m, name, f["L"] * i / 400)) for i in range(401))
            lo, hi = gen.PEAK[kind]
            ranges &= lo - 1e-9 <= peak <= hi + 1e-9
        sq &= all(abs(v) <= gen.SQUARENESS_MAX_URAD for v in m["squareness"].values())
    check(zeros < 1e-12, "every function zero at its axis zero")
    check(ends < 1e-9, "every straightness zero at its stroke end")
    check(ranges, "peaks within positioning %s µm, straightness %s µm, angular %s µrad" % (gen.PEAK["positioning"], gen.PEAK["straightness"], gen.PEAK["angular"]))
    check(sq, "squareness within ±%g µrad" % gen.SQUARENESS_MAX_URAD)
    t = gen.truth_json(machines[0], 1, 0)
    worst = max(abs(v - value(machines[0], n, q)) for n, e in t["terms"].items() for q, v in zip(e["positions_mm"], e["values"]))
    check(len(t["terms"]) == 18 and len(t["squareness_urad"]) == 3 and worst < 1e-12, "truth.json: 18 functions + 3 squareness, grid equal to the functions")
    a = gen.draw_machine(random.Random("three-axis-blind/7/0"))
    b = gen.draw_machine(random.Random("three-axis-blind/7/0"))
    c = gen.draw_machine(random.Random("three-axis-blind/8/0"))
    check(a == b and a != c, "a seed gives one machine; another seed another")


def check_world(d):
    plans = [json.load(open(p)) for p in glob.glob(os.path.join(d, "plans", "plan_*.json"))]
    segs = set()
    for p in plans:
        for ln in p["lines"]:
            a = tuple(round(v, 3) for v in ln["start_mm"])
            b = tuple(round(v, 3) + 0.0 for v in ln["end_mm"])
            segs.add((a, b))
            segs.add((b, a))
    held = gen.heldout_lines()
    clash = [h["line"] for h in held if (tuple(round(v, 3) for v in h["start_mm"]), tuple(round(v, 3) + 0.0 for v in h["end_mm"])) in segs]
    check(len(plans) == 2 and not clash, "held-out lines unlike every line of both plans %s" % clash)
    # forward and backward runs averaged, each run's zeroing noise removed by the line's mean
    expect = gen.NOISE_UM / math.sqrt(2.0)
    worst, machines = 0.0, 0
    for tpath in sorted(glob.glob(os.path.join(d, "m*", "truth.json"))):
        t = json.load(open(tpath))
        m = {"functions": t["functions"], "squareness": t["squareness_urad"]}
        sq, n = 0.0, 0
        for sub in ("lines_14", "lines_rich", "heldout"):
            for name, runs in read_runs(os.path.join(os.path.dirname(tpath), sub, "*.csv")).items():
                setup = t["setups"][sub][name]
                rows = runs[0][1]
                res = []
                for i in range(1, len(rows)):
                    avg = sum(r[i][4] for _, r in runs) / len(runs)
                    res.append(avg - setup_reading(m, setup, rows[0][1:4], rows[i][1:4], rows[i][0]))
                mean = sum(res) / len(res)  # the runs' shared zeroing noise
                sq += sum((r - mean) ** 2 for r in res)
                n += len(res) - 1
        machines += 1
        rms = math.sqrt(sq / n)
        worst = max(worst, abs(rms - expect) / expect)
    check(machines > 0 and worst < 0.1, "every file of %s equals its truth and set-up within the stated noise (%d machines, "
          "RMS off the expected %.3f µm by at most %.1f %%)" % (d, machines, expect, 100 * worst))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dir", help="a world written by gen.py, checked against its truth")
    args = ap.parse_args()
    rng = random.Random(12345)
    machines = [gen.draw_machine(random.Random("selftest/%d" % i)) for i in range(4)]
    check_chain(machines, rng)
    check_first_order(machines, rng)
    check_line_files(machines[0], "selftest-lines")
    check_truth(machines)
    if args.dir:
        check_world(args.dir)
    if FAILS:
        sys.exit("selftest: %d check(s) failed" % len(FAILS))
    print("selftest: all checks passed")


if __name__ == "__main__":
    main()
