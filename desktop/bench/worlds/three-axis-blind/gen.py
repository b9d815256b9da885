#!/usr/bin/env python3
"""Blind three-axis test world: independently drawn XY/Z machining centres.

Written without reading the identifier, the project's simulators or other
worlds; only from the line-file format, the conventions of docs/geometry.md
("Units and names", "Kinematics", "The 14 lines") and the CLI's printed plans.

    python3 gen.py --seed S --machines N --out DIR [--tcomp PATH]

DIR/plans/plan_{14,rich}.json   the plans as `tcomp geometry plan --json` printed them
DIR/mNN/lines_14/*.csv          forward and backward runs of the 14-line plan
DIR/mNN/lines_rich/*.csv        forward and backward runs of the rich plan
DIR/mNN/heldout/*.csv           held-out lines of this world's own design
DIR/mNN/truth.json              every error term at a grid, its parameters, each line's set-up
"""

import argparse
import json
import math
import os
import random
import subprocess
import sys

STROKE = {"X": 800.0, "Y": 600.0, "Z": 500.0}
AXES = "XYZ"
TOOL_MM = 100.0
SIDE_MM = 100.0
TARGETS = 41
NOISE_UM = 0.5
SCALE_PPM = 0.5
MISALIGN_URAD = 100.0
REFLECTOR_MM = 1.0
STRUCTURE = "XY/Z"
SQUARENESS = ["EC0Y", "EB0Z", "EA0Z"]
GRID_POINTS = 81  # truth grid per axis

# Amplitude ranges of the peak |value| of each kind (µm or µrad).
PEAK = {
    "positioning": (3.0, 15.0),
    "straightness": (1.5, 8.0),
    "angular": (5.0, 30.0),
}
SQUARENESS_MAX_URAD = 30.0

# Held-out lines: fractions of the strokes, reflector (0, 0, tool) so that
# `tcomp geometry predict` (tool along the spindle) can predict them.
HELDOUT = [
    ("H01", (0, 0, 0.5), (1, 1, 0.5), 150.0, "XY diagonal at mid height"),
    ("H02", (0, 0.5, 0), (1, 0.5, 1), 100.0, "XZ diagonal at mid Y"),
    ("H03", (0.5, 0, 0), (0.5, 1, 1), 200.0, "YZ diagonal at mid X"),
    ("H04", (0.125, 1 / 12, 0.1), (0.875, 11 / 12, 0.9), 120.0, "inner body diagonal"),
    ("H05", (0, 1, 1), (1, 0, 0.2), 80.0, "body line, shallow in Z"),
    ("H06", (0, 1, 1), (1, 1, 1), 150.0, "X at the back top"),
    ("H07", (1, 1, 0), (1, 1, 1), 100.0, "Z at the back right"),
    ("H08", (0.25, 1, 0), (1, 1 / 6, 0.8), 180.0, "odd-slope body line"),
    ("H09", (0.75, 0, 1), (0, 0.75, 0), 60.0, "odd-slope body line, short tool"),
    ("H10", (0, 0.25, 0.8), (1, 0.75, 0.2), 130.0, "body line across the middle"),
]


def term_names():
    names = []
    for k in AXES:
        for c in "XYZ":
            names.append("E" + c + k)
        for c in "ABC":
            names.append("E" + c + k)
    return names + SQUARENESS


def term_kind(name):
    if name in SQUARENESS:
        return "squareness"
    comp, axis = name[1], name[2]
    if comp in "ABC":
        return "angular"
    return "positioning" if comp == axis else "straightness"


def term_unit(name):
    return "um" if term_kind(name) in ("positioning", "straightness") else "urad"


# ---------------------------------------------------------------- functions


def raw_value(f, q):
    """The unscaled shape: a cubic in u = q/L, waves and local features."""
    u = q / f["L"]
    v = sum(c * u ** (j + 1) for j, c in enumerate(f["poly"]))
    for a, lam, ph in f["waves"]:
        v += a * math.sin(2.0 * math.pi * q / lam + ph)
    for a, centre, width in f["bumps"]:
        v += a * math.exp(-0.5 * ((q - centre) / width) ** 2)
    return v


def eval_fn(f, q):
    """Error value at axis position q: zero at 0; straightness also at L."""
    v = raw_value(f, q) - raw_value(f, 0.0)
    if f["zero_at_end"]:
        end = raw_value(f, f["L"]) - raw_value(f, 0.0)
        v -= end * q / f["L"]
    return f["scale"] * v


def draw_fn(rng, kind, length):
    f = {
        "L": length,
        "poly": [rng.gauss(0.0, 1.0) for _ in range(3)],
        "waves": [],
        "bumps": [],
        "zero_at_end": kind == "straightness",
        "scale": 1.0,
    }
    for _ in range(rng.randint(1, 2)):
        f["waves"].append(
            (rng.uniform(0.1, 0.35), rng.uniform(length / 6.0, length / 1.5), rng.uniform(0, 2 * math.pi))
        )
    if rng.random() < 0.35:  # a worn zone or a local guideway feature
        width = rng.uniform(25.0, 60.0)
        f["bumps"].append((rng.choice([-1, 1]) * rng.uniform(0.2, 0.45), rng.uniform(0.1, 0.9) * length, width))
    grid = [length * i / 400.0 for i in range(401)]
    peak = max(abs(eval_fn(f, q)) for q in grid)
    lo, hi = PEAK[kind]
    f["scale"] = rng.uniform(lo, hi) / peak if peak > 0 else 0.0
    return f


def draw_machine(rng):
    m = {"functions": {}, "squareness": {}}
    for name in term_names():
        kind = term_kind(name)
        if kind == "squareness":
            m["squareness"][name] = rng.uniform(-SQUARENESS_MAX_URAD, SQUARENESS_MAX_URAD)
        else:
            m["functions"][name] = draw_fn(rng, kind, STROKE[name[2]])
    return m


def term_value(m, name, q):
    if name in SQUARENESS:
        return m["squareness"][name]
    return eval_fn(m["functions"][name], q)


# ---------------------------------------------------------------- the chain


def rx(a):
    c, s = math.cos(a), math.sin(a)
    return [[1, 0, 0], [0, c, -s], [0, s, c]]


def ry(b):
    c, s = math.cos(b), math.sin(b)
    return [[c, 0, s], [0, 1, 0], [-s, 0, c]]


def rz(g):
    c, s = math.cos(g), math.sin(g)
    return [[c, -s, 0], [s, c, 0], [0, 0, 1]]


def matmul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def matvec(a, v):
    return [sum(a[i][k] * v[k] for k in range(3)) for i in range(3)]


def axis_dirs(m):
    """u_X = x, u_Y = Rz(EC0Y) y, u_Z = Ry(EB0Z) Rx(EA0Z) z (squareness in rad)."""
    c0y = m["squareness"]["EC0Y"] * 1e-6
    b0z = m["squareness"]["EB0Z"] * 1e-6
    a0z = m["squareness"]["EA0Z"] * 1e-6
    ux = [1.0, 0.0, 0.0]
    uy = matvec(rz(c0y), [0.0, 1.0, 0.0])
    uz = matvec(matmul(ry(b0z), rx(a0z)), [0.0, 0.0, 1.0])
    return {"X": ux, "Y": uy, "Z": uz}


def tool_point(m, q, tool):
    """Exact chain p = M_X M_Y M_Z tool, M_k = Trans(q_k u_k + delta_k) Rz Ry Rx (mm)."""
    u = axis_dirs(m)
    p = list(tool)
    for k, qk in zip(reversed(AXES), reversed(q)):
        delta = [term_value(m, "E" + c + k, qk) * 1e-3 for c in "XYZ"]
        ea, eb, ec = (term_value(m, "E" + c + k, qk) * 1e-6 for c in "ABC")
        rot = matmul(matmul(rz(ec), ry(eb)), rx(ea))
        p = matvec(rot, p)
        p = [p[i] + qk * u[k][i] + delta[i] for i in range(3)]
    return p


def tool_tip_error_um(m, q, tool):
    p = tool_point(m, q, tool)
    return [(p[i] - (q[i] + tool[i])) * 1e3 for i in range(3)]


# ---------------------------------------------------------------- lines


def line_targets(start, direction, length):
    out = []
    for i in range(TARGETS):
        s = length * i / (TARGETS - 1)
        out.append((s, [start[j] + s * direction[j] for j in range(3)]))
    return out


def perturbed_direction(rng, d):
    """The beam as aligned: the nominal direction tilted by two small angles."""
    a = [1.0, 0.0, 0.0] if abs(d[0]) < 0.9 else [0.0, 1.0, 0.0]
    e1 = [d[1] * a[2] - d[2] * a[1], d[2] * a[0] - d[0] * a[2], d[0] * a[1] - d[1] * a[0]]
    n1 = math.sqrt(sum(x * x for x in e1))
    e1 = [x / n1 for x in e1]
    e2 = [d[1] * e1[2] - d[2] * e1[1], d[2] * e1[0] - d[0] * e1[2], d[0] * e1[1] - d[1] * e1[0]]
    t1 = rng.gauss(0.0, MISALIGN_URAD) * 1e-6
    t2 = rng.gauss(0.0, MISALIGN_URAD) * 1e-6
    v = [d[i] + t1 * e1[i] + t2 * e2[i] for i in range(3)]
    n = math.sqrt(sum(x * x for x in v))
    return [x / n for x in v]


def line_setup(rng, line):
    """One set-up of the laser on a line: beam, reflector, scale (shared by both runs)."""
    return {
        "beam": perturbed_direction(rng, line["direction"]),
        "reflector": [line["tool_offset_mm"][i] + rng.gauss(0.0, REFLECTOR_MM) for i in range(3)],
        "scale_ppm": rng.gauss(0.0, SCALE_PPM),
    }


def true_reading_um(m, line, setup, targets):
    """Noise-free reading: displacement along the beam minus nominal, zeroed at the first target."""
    p0 = tool_point(m, targets[0][1], setup["reflector"])
    out = []
    for s, q in targets:
        p = tool_point(m, q, setup["reflector"])
        moved = sum(setup["beam"][i] * (p[i] - p0[i]) for i in range(3))
        out.append((moved * (1.0 + setup["scale_ppm"] * 1e-6) - s) * 1e3)
    return out


def noisy(rng, clean):
    raw = [c + rng.gauss(0.0, NOISE_UM) for c in clean]
    return [r - raw[0] for r in raw]


def fmt(v):
    return ("%.6f" % v).rstrip("0").rstrip(".") if abs(v) > 5e-7 else "0"


def write_line(path, line, run, targets, disp):
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("# line: %s\n" % line["line"])
        fh.write("# start_mm: %s\n" % ",".join(fmt(v) for v in line["start_mm"]))
        fh.write("# direction: %s\n" % ",".join(repr(float(v)) for v in line["direction"]))
        fh.write("# tool_offset_mm: %s\n" % ",".join(fmt(v) for v in line["tool_offset_mm"]))
        fh.write("# structure: %s\n" % STRUCTURE)
        fh.write("# source: simulated\n")
        fh.write("# run: %s\n" % run)
        fh.write("s_mm,pos_x,pos_y,pos_z,disp_um\n")
        for (s, q), d in zip(targets, disp):
            fh.write("%s,%s,%s,%s,%.4f\n" % (fmt(s), fmt(q[0]), fmt(q[1]), fmt(q[2]), d))


def measure_lines(rng, m, lines, out_dir):
    """Writes forward and backward runs; returns what was done per line (for selftest)."""
    os.makedirs(out_dir, exist_ok=True)
    record = []
    for line in lines:
        targets = line_targets(line["start_mm"], line["direction"], line["length_mm"])
        setup = line_setup(rng, line)
        clean = true_reading_um(m, line, setup, targets)
        for run in ("forward", "backward"):
            disp = noisy(rng, clean)
            write_line(os.path.join(out_dir, "%s_%s.csv" % (line["line"], run)), line, run, targets, disp)
        record.append({"line": line["line"], "setup": setup, "clean_um": clean})
    return record


def heldout_lines():
    lines = []
    for name, a, b, tool, purpose in HELDOUT:
        start = [a[i] * STROKE[AXES[i]] for i in range(3)]
        end = [b[i] * STROKE[AXES[i]] for i in range(3)]
        vec = [end[i] - start[i] for i in range(3)]
        length = math.sqrt(sum(v * v for v in vec))
        lines.append(
            {
                "line": name,
                "start_mm": start,
                "end_mm": end,
                "direction": [v / length for v in vec],
                "length_mm": length,
                "tool_offset_mm": [0.0, 0.0, tool],
                "purpose": purpose,
            }
        )
    return lines


# ---------------------------------------------------------------- plans, truth


def default_tcomp():
    here = os.path.dirname(os.path.abspath(__file__))
    return os.path.normpath(os.path.join(here, "..", "..", "..", "..", "target", "release", "tcomp"))


def fetch_plan(tcomp, plan):
    cmd = [tcomp, "geometry", "plan", "--plan", plan, "--json"]
    cmd += ["--stroke", ",".join("%g" % STROKE[a] for a in AXES), "--tool", "%g" % TOOL_MM, "--side", "%g" % SIDE_MM]
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode != 0:
        sys.exit("gen.py: `%s` failed: %s" % (" ".join(cmd), res.stderr.strip().splitlines()[-1:]))
    return json.loads(res.stdout)


def truth_json(m, seed, index):
    grid = {}
    for name in term_names():
        if name in SQUARENESS:
            continue
        length = STROKE[name[2]]
        pos = [length * i / (GRID_POINTS - 1) for i in range(GRID_POINTS)]
        grid[name] = {"unit": term_unit(name), "kind": term_kind(name), "positions_mm": pos,
                      "values": [term_value(m, name, q) for q in pos]}
    return {
        "world": "three-axis-blind",
        "seed": seed,
        "machine": index,
        "structure": STRUCTURE,
        "stroke_mm": [STROKE[a] for a in AXES],
        "noise_um": NOISE_UM,
        "conventions": "ISO 230-1 names; each function zero at its axis zero, straightness also at the "
        "stroke end (its end-point line is the squareness); chain X, Y, Z (docs/geometry.md, Kinematics)",
        "squareness_urad": m["squareness"],
        "terms": grid,
        "functions": m["functions"],
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--machines", type=int, required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--tcomp", default=default_tcomp(), help="tcomp binary (only to print the plans)")
    args = ap.parse_args()
    if args.machines < 1:
        sys.exit("gen.py: --machines must be at least 1")
    os.makedirs(os.path.join(args.out, "plans"), exist_ok=True)
    plans = {}
    for plan in ("14", "rich"):
        plans[plan] = fetch_plan(args.tcomp, plan)
        with open(os.path.join(args.out, "plans", "plan_%s.json" % plan), "w") as fh:
            json.dump(plans[plan], fh, indent=1)
    held = heldout_lines()
    with open(os.path.join(args.out, "plans", "heldout.json"), "w") as fh:
        json.dump(held, fh, indent=1)
    for index in range(args.machines):
        rng = random.Random("three-axis-blind/%d/%d" % (args.seed, index))
        m = draw_machine(rng)
        mdir = os.path.join(args.out, "m%02d" % index)
        setups = {}
        for plan in ("14", "rich"):
            rec = measure_lines(rng, m, plans[plan]["lines"], os.path.join(mdir, "lines_" + plan))
            setups["lines_" + plan] = {r["line"]: r["setup"] for r in rec}
        rec = measure_lines(rng, m, held, os.path.join(mdir, "heldout"))
        setups["heldout"] = {r["line"]: r["setup"] for r in rec}
        truth = truth_json(m, args.seed, index)
        truth["setups"] = setups
        with open(os.path.join(mdir, "truth.json"), "w") as fh:
            json.dump(truth, fh, indent=1)
    print("gen.py: %d machines in %s (plans 14 and rich, %d held-out lines each)" % (args.machines, args.out, len(held)))


if __name__ == "__main__":
    main()
