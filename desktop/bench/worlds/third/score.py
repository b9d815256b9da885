#!/usr/bin/env python3
"""Score `tcomp diagnose` on the third world's cases (stdlib only).

    python3 score.py --cases DIR [--tcomp PATH] [--sigma 0.15] [--perturb-seed 1] [--json]

Per case three columns:
  exact   tcomp diagnose machine.toml run_a.csv run_b.csv --json
  design  the same with machine_perturbed.toml: every design number x (1 + N(0, sigma)),
          seeded by (perturb-seed, case index); written beside the case
  fit     tcomp diagnose fit run_a.csv run_b.csv --json
The named cause is the first entry of "effects" (its "name"; a pair "a+b" names both).
Classes: right (a named part is in truth.accept, sensor matching when the finding gives
one), right_param (a released design value that states the same physics, listed in
truth.accept_parameters), honest (nothing named and the truth listed under "untestable"),
wrong (named something else), missed (nothing named, truth not listed), false_alarm
(clean case, something named), quiet (clean case, nothing named).
"""
import argparse
import json
import math
import os
import random
import re
import subprocess
import sys
import time
import tomllib

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_TCOMP = os.path.normpath(os.path.join(HERE, "..", "..", "..", "..", "target", "release", "tcomp"))

# design numbers that are perturbed (per section); everything else is kept:
# temperatures, speeds, exponents, alpha, noise, bearing dm (a drawing size), rated power
PERTURB = {
    "top": ["motor_loss_frac"],
    "node": ["c_j_per_k", "g_amb_w_per_k", "area_m2"],
    "link": ["g_w_per_k"],
    "bearing": ["f0", "f1", "load_n", "nu_cst"],
    "source": ["w_at_nmax"],
    "coolant": ["tank_c_j_per_k", "tank_g_amb_w_per_k"],
    "jacket": ["g_w_per_k"],
    "terms": ["length_mm"],
    "rod": ["g_amb_w_per_k", "k_w_per_mk", "cp_j_per_kgk"],
    "rod_end": ["g_w_per_k"],
}


def perturb(spec, rng, sigma):
    def f(v):
        return float(v) * max(0.1, 1.0 + rng.gauss(0.0, sigma))

    for k in PERTURB["top"]:
        if k in spec:
            spec[k] = f(spec[k])
    for sec, keys in (("node", PERTURB["node"]), ("link", PERTURB["link"]),
                      ("bearing", PERTURB["bearing"]), ("source", PERTURB["source"])):
        for item in spec.get(sec, []):
            for k in keys:
                if k in item:
                    item[k] = f(item[k])
    if "coolant" in spec:
        c = spec["coolant"]
        for k in PERTURB["coolant"]:
            if k in c:
                c[k] = f(c[k])
        for j in c.get("jacket", []):
            j["g_w_per_k"] = f(j["g_w_per_k"])
    if "rod" in spec:
        r = spec["rod"]
        for k in PERTURB["rod"]:
            if k in r:
                r[k] = f(r[k])
        for end in ("front", "rear"):
            if end in r:
                r[end]["g_w_per_k"] = f(r[end]["g_w_per_k"])
    for d in spec.get("direction", []):
        for t in d.get("terms", []):
            t["length_mm"] = f(t["length_mm"])
    return spec


def tv(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(float(v)) if isinstance(v, float) else str(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[ " + ", ".join(tv(x) for x in v) + " ]"
    if isinstance(v, dict):
        return "{ " + ", ".join("%s = %s" % (qk(k), tv(x)) for k, x in v.items()) + " }"
    raise TypeError(v)


def qk(k):
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else json.dumps(k)


def dump_toml(spec):
    out = []
    tables, arrays = [], []
    for k, v in spec.items():
        if isinstance(v, dict):
            tables.append(k)
        elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            arrays.append(k)
        else:
            out.append("%s = %s" % (qk(k), tv(v)))
    for k in tables:
        out.append("")
        out.append("[%s]" % qk(k))
        for kk, vv in spec[k].items():
            out.append("%s = %s" % (qk(kk), tv(vv)))
    for k in arrays:
        for item in spec[k]:
            out.append("")
            out.append("[[%s]]" % qk(k))
            for kk, vv in item.items():
                out.append("%s = %s" % (qk(kk), tv(vv)))
    return "\n".join(out) + "\n"


def run_json(cmd, cwd):
    t0 = time.time()
    p = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=1800)
    dt = time.time() - t0
    if p.returncode != 0:
        return None, dt, p.stderr.strip()[-500:]
    try:
        return json.loads(p.stdout), dt, None
    except json.JSONDecodeError as e:
        return None, dt, "bad json: %s" % e


def first_token(name):
    return re.split(r"[ /(]", name.strip(), maxsplit=1)[0]


def listed_untestable(d, truth):
    """Is the truth among the untestable entries (or an ambiguous set)?"""
    acc = truth["accept"]
    sensor = truth.get("sensor")
    p = truth.get("params", {})
    for u in d.get("untestable", []) or []:
        name = u.get("name", "") if isinstance(u, dict) else str(u)
        text = json.dumps(u)
        tok = first_token(name)
        if tok in acc:
            if truth["effect"] == "sensor_lag":
                if sensor not in name:
                    continue
                m = re.search(r"shorter than ([0-9.]+) s", name)
                if m and p.get("tau_s", 0) >= float(m.group(1)):
                    continue
            if truth["effect"] == "sensor_offset":
                if "constant over a run" in name and p.get("at_s", 1) != 0:
                    continue
                if sensor and "T_" in name and sensor not in name:
                    continue
            return True
        if "ambiguous" in text.lower() and any(a in text for a in acc):
            return True
    return False


def classify(d, truth):
    effects = d.get("effects") or []
    if truth["clean"]:
        return ("false_alarm", effects[0]["name"]) if effects else ("quiet", "")
    if not effects:
        return ("honest", "") if listed_untestable(d, truth) else ("missed", "")
    e = effects[0]
    name = e.get("name", "")
    if name in truth.get("accept_parameters", []):
        return "right_param", name
    parts = name.split("+")
    hit = [x for x in parts if x in truth["accept"]]
    if hit:
        sensor = truth.get("sensor")
        if sensor:
            prm = e.get("params") or {}
            s = prm.get("sensor")
            if s is None and isinstance(prm.get(hit[0]), dict):
                s = prm[hit[0]].get("sensor")
            if s is not None and s != sensor:
                return "wrong", name + " (sensor %s)" % s
        return "right", name
    return "wrong", name


CLASSES = ["right", "right_param", "honest", "wrong", "missed", "false_alarm", "quiet"]


def main():
    ap = argparse.ArgumentParser(description="score tcomp diagnose on the third world")
    ap.add_argument("--cases", required=True, help="directory written by gen.py")
    ap.add_argument("--tcomp", default=DEFAULT_TCOMP)
    ap.add_argument("--sigma", type=float, default=0.15)
    ap.add_argument("--perturb-seed", type=int, default=1)
    ap.add_argument("--columns", default="exact,design,fit")
    ap.add_argument("--json", action="store_true", help="print the tally as JSON")
    a = ap.parse_args()
    cols = a.columns.split(",")
    cases = sorted(x for x in os.listdir(a.cases) if x.startswith("case_"))
    per_case = []
    tally = {c: {k: 0 for k in CLASSES} for c in cols}
    by_kind = {}
    for cname in cases:
        cdir = os.path.join(a.cases, cname)
        truth = json.load(open(os.path.join(cdir, "truth.json")))
        idx = int(cname.split("_")[1])
        row = {"case": cname, "effect": truth["effect"], "sensor": truth.get("sensor")}
        for col in cols:
            if col == "exact":
                cmd = [a.tcomp, "diagnose", "machine.toml", "run_a.csv", "run_b.csv", "--json"]
            elif col == "design":
                with open(os.path.join(cdir, "machine.toml"), "rb") as fh:
                    spec = tomllib.load(fh)
                rng = random.Random(a.perturb_seed * 100003 + idx)
                spec = perturb(spec, rng, a.sigma)
                with open(os.path.join(cdir, "machine_perturbed.toml"), "w") as fh:
                    fh.write("# design file perturbed by score.py: sigma %g, perturb-seed %d\n" % (a.sigma, a.perturb_seed))
                    fh.write(dump_toml(spec))
                cmd = [a.tcomp, "diagnose", "machine_perturbed.toml", "run_a.csv", "run_b.csv", "--json"]
            elif col == "fit":
                cmd = [a.tcomp, "diagnose", "fit", "run_a.csv", "run_b.csv", "--json"]
            else:
                sys.exit("unknown column " + col)
            d, dt, err = run_json(cmd, cdir)
            if d is None:
                cls, named = "error", err
            else:
                cls, named = classify(d, truth)
            row[col] = {"class": cls, "named": named, "seconds": round(dt, 1)}
            tally[col].setdefault(cls, 0)
            tally[col][cls] += 1
            bk = by_kind.setdefault(truth["effect"], {c: {} for c in cols})
            bk[col][cls] = bk[col].get(cls, 0) + 1
        per_case.append(row)
        if not a.json:
            print("%s %-18s %s" % (cname, truth["effect"] + ("" if not truth.get("sensor") else "@" + truth["sensor"]),
                                   "  ".join("%s=%s[%s]" % (c, row[c]["class"], row[c]["named"]) for c in cols)),
                  flush=True)
    out = {"cases": len(cases), "columns": cols, "tally": tally, "by_kind": by_kind, "per_case": per_case,
           "tcomp": a.tcomp, "sigma": a.sigma, "perturb_seed": a.perturb_seed}
    if a.json:
        print(json.dumps(out, indent=1))
    else:
        for c in cols:
            print(c, " ".join("%s %d" % (k, v) for k, v in tally[c].items() if v))


if __name__ == "__main__":
    main()
