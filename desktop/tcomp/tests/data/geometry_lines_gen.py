#!/usr/bin/env python3
"""Independent writer of displacement-line files (issue 14, "Done when").

Written from the file format (shared/formats/displacement-lines.md) and the
14-line plan in docs/geometry.md only: no code is shared with `tcomp`. A
random machine of the XY/Z structure with smooth geometric errors is
measured along the 14 lines by an interferometer with noise, beam
misalignment, a reflector offset and lost motion on the backward run; the
readings come from full 4x4 homogeneous transforms (every angle exact, not
the first-order sensitivities the identifier uses). Python standard library
only, so the test needs nothing beyond python3.

usage: geometry_lines_gen.py --seed N --noise-um S --out DIR
writes DIR/L01_forward.csv ... DIR/L14_backward.csv and DIR/truth.json
(the machine in the JSON form `tcomp geometry identify --truth` reads).
"""

import argparse
import json
import math
import os
import random

STROKE = (800.0, 500.0, 400.0)
TOOL, SIDE = 100.0, 100.0
# line: (from, to) as fractions of the strokes, reflector offset [mm]
PLAN = [
    ("L01", (0, 0, 0), (1, 1, 1), (SIDE, 0, TOOL)),
    ("L02", (1, 0, 0), (0, 1, 1), (SIDE, SIDE, TOOL)),
    ("L03", (0, 1, 0), (1, 0, 1), (SIDE, SIDE, TOOL)),
    ("L04", (1, 1, 0), (0, 0, 1), (0, 0, 250.0)),
    ("L05", (1, 0, 0), (0.5, 1, 1), (0, 0, 250.0)),
    ("L06", (0, 0, 0), (1, 1, 0), (0, SIDE, TOOL)),
    ("L07", (1, 0, 1), (0, 1, 1), (-SIDE, 0, TOOL)),
    ("L08", (0, 1, 0), (1, 1, 1), (0, 0, 250.0)),
    ("L09", (1, 0, 0), (0, 0, 1), (-SIDE, 0, TOOL)),
    ("L10", (1, 0, 0), (1, 1, 1), (-SIDE, 0, TOOL)),
    ("L11", (1, 1, 0), (1, 0, 1), (-SIDE, 0, TOOL)),
    ("L12", (0, 0, 0), (0, 1, 0), (SIDE, 0, TOOL)),
    ("L13", (1, 0, 1), (1, 1, 1), (0, 0, 250.0)),
    ("L14", (0, 0, 0), (0, 0, 1), (SIDE, SIDE, TOOL)),
]
AXES = "XYZ"
LOST_MOTION_UM = (3.0, 2.0, 4.0)
TARGETS = 41


# --- 4x4 homogeneous transforms -------------------------------------------
def matmul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(4)) for j in range(4)] for i in range(4)]


def apply(m, p):
    return [sum(m[i][k] * p[k] for k in range(3)) + m[i][3] for i in range(3)]


def trans(v):
    return [[1, 0, 0, v[0]], [0, 1, 0, v[1]], [0, 0, 1, v[2]], [0, 0, 0, 1]]


def rot(axis, a):
    c, s = math.cos(a), math.sin(a)
    i, j = {0: (1, 2), 1: (2, 0), 2: (0, 1)}[axis]
    m = [[1.0 if r == q else 0.0 for q in range(4)] for r in range(4)]
    m[i][i], m[i][j], m[j][i], m[j][j] = c, -s, s, c
    return m


def rot_vec(m, v):
    return [sum(m[i][k] * v[k] for k in range(3)) for i in range(3)]


# --- the random machine ----------------------------------------------------
def random_machine(rng):
    """Per term a polynomial in u = q/stroke without constant (zero at q = 0)."""
    terms = {}
    for k, axis in enumerate(AXES):
        for comp in "XYZABC":
            name = "E" + comp + axis
            angular = comp in "ABC"
            roll = angular and "ABC".index(comp) == k
            straight = (not angular) and "XYZ".index(comp) != k
            if straight:
                # a bow, zero at both ends: the slope of a straightness is a
                # squareness plus a frame rotation (ISO 230-1 end-point line)
                bow = rng.uniform(-6.0, 6.0)
                coeffs = [-4 * bow, 4 * bow]
            elif roll:
                coeffs = [rng.uniform(-20.0, 20.0)]
            else:
                peak = 20.0 if angular else 10.0
                raw = [rng.gauss(0, 1) / (d + 1) for d in range(3)]
                scale = peak * rng.uniform(0.5, 1.0) / max(
                    abs(sum(c * (i / 20) ** (d + 1) for d, c in enumerate(raw))) for i in range(21)
                )
                coeffs = [c * scale for c in raw]
            terms[name] = coeffs
    squareness = {n: rng.uniform(-20.0, 20.0) for n in ("EC0Y", "EB0Z", "EA0Z")}
    return terms, squareness


def value(terms, name, q):
    u = q / STROKE[AXES.index(name[2])]
    return sum(c * u ** (d + 1) for d, c in enumerate(terms[name]))


def tool_point(terms, sq, pos, tool):
    """Actual tool point relative to the workpiece [mm]: chain X, Y, Z."""
    u_dirs = [
        [1.0, 0.0, 0.0],
        rot_vec(rot(2, sq["EC0Y"] * 1e-6), [0.0, 1.0, 0.0]),
        rot_vec(matmul(rot(1, sq["EB0Z"] * 1e-6), rot(0, sq["EA0Z"] * 1e-6)), [0.0, 0.0, 1.0]),
    ]
    m = trans([0, 0, 0])
    for k, axis in enumerate(AXES):
        q = pos[k]
        delta = [value(terms, "E" + c + axis, q) * 1e-3 for c in "XYZ"]
        move = [q * u_dirs[k][i] + delta[i] for i in range(3)]
        a, b, c = (value(terms, "E" + r + axis, q) * 1e-6 for r in "ABC")
        joint = matmul(trans(move), matmul(rot(2, c), matmul(rot(1, b), rot(0, a))))
        m = matmul(m, joint)
    return apply(m, tool)


def tilt(d, rng, sigma):
    """The beam: the line's direction turned by two small random angles."""
    v = rot_vec(matmul(rot(0, rng.gauss(0, sigma)), matmul(rot(1, rng.gauss(0, sigma)),
                                                          rot(2, rng.gauss(0, sigma)))), d)
    n = math.sqrt(sum(x * x for x in v))
    return [x / n for x in v]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--noise-um", type=float, default=0.5)
    ap.add_argument("--misalign-urad", type=float, default=200.0)
    ap.add_argument("--reflector-mm", type=float, default=1.0)
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    rng = random.Random(a.seed)
    terms, sq = random_machine(rng)
    os.makedirs(a.out, exist_ok=True)
    for line, f0, f1, offset in PLAN:
        start = [f0[k] * STROKE[k] for k in range(3)]
        end = [f1[k] * STROKE[k] for k in range(3)]
        length = math.sqrt(sum((end[k] - start[k]) ** 2 for k in range(3)))
        d = [(end[k] - start[k]) / length for k in range(3)]
        reflector = [offset[k] + rng.gauss(0, a.reflector_mm) for k in range(3)]
        beam = tilt(d, rng, a.misalign_urad * 1e-6)
        lost = sum(LOST_MOTION_UM[k] * abs(d[k]) for k in range(3))
        s_list = [length * i / (TARGETS - 1) for i in range(TARGETS)]
        pos_list = [[start[k] + s * d[k] for k in range(3)] for s in s_list]
        points = [tool_point(terms, sq, p, reflector) for p in pos_list]
        for run in ("forward", "backward"):
            rows = []
            for s, p, pt in zip(s_list, pos_list, points):
                along = sum(beam[k] * (pt[k] - points[0][k]) for k in range(3))
                disp = (along - s) * 1e3 + rng.gauss(0, a.noise_um)
                if run == "backward":
                    disp -= lost  # the carriages stop short on the way back
                rows.append("%.3f,%.3f,%.3f,%.3f,%.3f" % (s, p[0], p[1], p[2], disp))
            head = [
                "# line: " + line,
                "# start_mm: %g,%g,%g" % tuple(start),
                "# direction: %.15g,%.15g,%.15g" % tuple(d),
                "# tool_offset_mm: %g,%g,%g" % tuple(offset),
                "# structure: XY/Z",
                "# run: " + run,
                "# source: simulated",
                "s_mm,pos_x,pos_y,pos_z,disp_um",
            ]
            with open(os.path.join(a.out, "%s_%s.csv" % (line, run)), "w") as f:
                f.write("\n".join(head + rows) + "\n")
    errors = {}
    for name, coeffs in terms.items():
        stroke = STROKE[AXES.index(name[2])]
        qs = [stroke * i / 10 for i in range(11)]
        errors[name] = {
            "positions_mm": qs,
            "values": [value(terms, name, q) for q in qs],
            "unit": "urad" if name[1] in "ABC" else "um",
            "poly": {"scale_mm": stroke, "coeffs": coeffs},
        }
    truth = {"structure": "XY/Z", "stroke_mm": list(STROKE), "errors": errors,
             "squareness_urad": sq}
    with open(os.path.join(a.out, "truth.json"), "w") as f:
        json.dump(truth, f, indent=1)


if __name__ == "__main__":
    main()
