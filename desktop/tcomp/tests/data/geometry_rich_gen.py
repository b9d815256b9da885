#!/usr/bin/env python3
"""Independent writer of displacement-line files from machines RICHER than
the identifier's model (issue 29, "An independent test writer").

Written from the file format (shared/formats/displacement-lines.md) and the
14-line plan of docs/geometry.md only; no code is shared with `tcomp`, and
nothing here tells the identifier what class the machine comes from.

Every one of the 18 error functions of the XY/Z machine is
    f(u) = P(u) + W(u),   u = q / stroke,  f(0) = 0,
P a random polynomial of degree 5 (coefficients falling as 1/(d+1)),
W a wave a * (sin(2 pi u / lam + phi) - sin(phi)) with wavelength lam drawn
in [0.5, 1.5] strokes and amplitude 10-30 % of the term's size. Straightness
has a random end-point slope on top (squareness in the ISO reference), roll
is as rich as pitch and yaw. Sizes: positioning 10 um, straightness 6 um,
angles and roll 20 urad, squareness +-20 urad.

Measurement: full 4x4 homogeneous transforms (every angle exact), the
reflector 1 mm off its planned offset, the beam 200 urad off the line, lost
motion 3/2/4 um on the backward run, N(0, sigma) noise, and a per-line
laser scale error (beam misalignment cosine, wavelength compensation) drawn
N(0, 0.5 ppm), the same for both runs of a line.

Also writes DIR/heldout/H01.csv ... H20.csv: 20 lines in random directions
between random points of the volume with random reflector offsets,
noise-free and without setup errors, for scoring predictions; and
DIR/truth.json with every function tabulated at 401 positions (and its
squareness), in the JSON shape of `tcomp geometry identify --json` minus
the polynomial (the truth is not a polynomial).

With --plan FILE the lines are those of FILE instead (a JSON list of
{"line", "start_mm", "end_mm", "tool_offset_mm"}, e.g. what
`tcomp geometry plan --plan rich --json` prints under "lines"); the machine
is the same for the same seed, and the held-out lines are drawn from a
stream of their own, so two plans are scored on the same held-out lines.
A plan line with "sense": [x, y, z] (unit, perpendicular to the travel) is
a straightness-optics line (our format extension, `measures: straightness`):
it reads the tool point's motion along the sense, the optic turned towards
the travel by N(0, 200 urad) (a slope) and set at an offset N(0, 5 um), the
lost motion projected on the sense, no laser scale.

usage: geometry_rich_gen.py --seed N [--noise-um S] [--scale-ppm P]
                            [--wave 1|0] [--plan FILE] --out DIR
"""

import argparse
import json
import math
import os
import random

STROKE = (800.0, 500.0, 400.0)
TOOL, SIDE = 100.0, 100.0
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
HELDOUT = 20


def mul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(4)) for j in range(4)] for i in range(4)]


def trans(v):
    return [[1, 0, 0, v[0]], [0, 1, 0, v[1]], [0, 0, 1, v[2]], [0, 0, 0, 1]]


def rot(axis, a):
    c, s = math.cos(a), math.sin(a)
    i, j = {0: (1, 2), 1: (2, 0), 2: (0, 1)}[axis]
    m = [[1.0 if r == q else 0.0 for q in range(4)] for r in range(4)]
    m[i][i], m[i][j], m[j][i], m[j][j] = c, -s, s, c
    return m


def rvec(m, v):
    return [sum(m[i][k] * v[k] for k in range(3)) for i in range(3)]


class Fn:
    """f(u) = sum c_d u^(d+1) + a (sin(2 pi u / lam + phi) - sin phi)."""

    def __init__(self, coeffs, wave):
        self.coeffs, self.wave = coeffs, wave

    def __call__(self, u):
        v = sum(c * u ** (d + 1) for d, c in enumerate(self.coeffs))
        a, lam, phi = self.wave
        return v + a * (math.sin(2 * math.pi * u / lam + phi) - math.sin(phi))


def shape(rng, size, zero_at_end, wave_on):
    raw = [rng.gauss(0, 1) / (d + 1) for d in range(5)]
    if zero_at_end:  # P(1) = 0: subtract its end-point line
        raw[0] -= sum(raw)
    peak = max(abs(sum(c * (i / 50) ** (d + 1) for d, c in enumerate(raw))) for i in range(51))
    k = size * rng.uniform(0.5, 1.0) / max(peak, 1e-9)
    coeffs = [c * k for c in raw]
    wave = (0.0, 1.0, 0.0)
    if wave_on:
        lam = rng.uniform(0.5, 1.5)
        phi = rng.uniform(0, 2 * math.pi)
        amp = size * rng.uniform(0.1, 0.3)
        wave = (amp, lam, phi)
        if zero_at_end:  # the wave's own end value goes into the slope below
            pass
    return coeffs, wave


def random_machine(rng, wave_on):
    terms = {}
    for k, axis in enumerate(AXES):
        for comp in "XYZABC":
            name = "E" + comp + axis
            angular = comp in "ABC"
            straight = (not angular) and "XYZ".index(comp) != k
            if straight:
                coeffs, wave = shape(rng, 6.0, True, wave_on)
                coeffs[0] += rng.uniform(-6.0, 6.0)  # end-point slope [um at the end]
            else:
                coeffs, wave = shape(rng, 20.0 if angular else 10.0, False, wave_on)
            terms[name] = Fn(coeffs, wave)
    sq = {n: rng.uniform(-20.0, 20.0) for n in ("EC0Y", "EB0Z", "EA0Z")}
    return terms, sq


def value(terms, name, q):
    return terms[name](q / STROKE[AXES.index(name[2])])


def tool_point(terms, sq, pos, tool):
    dirs = [
        [1.0, 0.0, 0.0],
        rvec(rot(2, sq["EC0Y"] * 1e-6), [0.0, 1.0, 0.0]),
        rvec(mul(rot(1, sq["EB0Z"] * 1e-6), rot(0, sq["EA0Z"] * 1e-6)), [0.0, 0.0, 1.0]),
    ]
    m = trans([0, 0, 0])
    for k, axis in enumerate(AXES):
        q = pos[k]
        delta = [value(terms, "E" + c + axis, q) * 1e-3 for c in "XYZ"]
        move = [q * dirs[k][i] + delta[i] for i in range(3)]
        a, b, c = (value(terms, "E" + r + axis, q) * 1e-6 for r in "ABC")
        m = mul(m, mul(trans(move), mul(rot(2, c), mul(rot(1, b), rot(0, a)))))
    return [sum(m[i][j] * tool[j] for j in range(3)) + m[i][3] for i in range(3)]


def tilt(d, rng, sigma):
    v = rvec(mul(rot(0, rng.gauss(0, sigma)), mul(rot(1, rng.gauss(0, sigma)),
                                                   rot(2, rng.gauss(0, sigma)))), d)
    n = math.sqrt(sum(x * x for x in v))
    return [x / n for x in v]


def write_line(path, line, start, d, offset, run, rows, sense=None):
    head = [
        "# line: " + line,
        "# start_mm: %.6g,%.6g,%.6g" % tuple(start),
        "# direction: %.15g,%.15g,%.15g" % tuple(d),
        "# tool_offset_mm: %.6g,%.6g,%.6g" % tuple(offset),
        "# structure: XY/Z",
    ]
    if sense is not None:
        head += ["# measures: straightness", "# sense: %.15g,%.15g,%.15g" % tuple(sense)]
    if run:
        head.append("# run: " + run)
    head += ["# source: simulated", "s_mm,pos_x,pos_y,pos_z,disp_um"]
    with open(path, "w") as f:
        f.write("\n".join(head + rows) + "\n")


def measure(terms, sq, start, end, reflector, beam, scale, noise, rng, lost, straight=None):
    """Rows per run. For a straightness line `straight` is the optic's offset
    [um] and `beam` its (tilted) sense: no nominal travel is subtracted."""
    length = math.sqrt(sum((end[k] - start[k]) ** 2 for k in range(3)))
    d = [(end[k] - start[k]) / length for k in range(3)]
    s_list = [length * i / (TARGETS - 1) for i in range(TARGETS)]
    pos = [[start[k] + s * d[k] for k in range(3)] for s in s_list]
    pts = [tool_point(terms, sq, p, reflector) for p in pos]
    beam = beam or d
    out = []
    for run_lost in lost:
        rows = []
        for s, p, pt in zip(s_list, pos, pts):
            along = sum(beam[k] * (pt[k] - pts[0][k]) for k in range(3)) * (1 + scale)
            disp = (along - s) * 1e3 if straight is None else along * 1e3 + straight
            disp += (rng.gauss(0, noise) if noise > 0 else 0.0) - run_lost
            rows.append("%.3f,%.4f,%.4f,%.4f,%.4f" % (s, p[0], p[1], p[2], disp))
        out.append(rows)
    return d, out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--noise-um", type=float, default=0.5)
    ap.add_argument("--scale-ppm", type=float, default=0.5)
    ap.add_argument("--wave", type=int, default=1)
    ap.add_argument("--plan")
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    rng = random.Random(7919 * a.seed + 17)
    terms, sq = random_machine(rng, a.wave != 0)
    os.makedirs(os.path.join(a.out, "heldout"), exist_ok=True)
    if a.plan:
        with open(a.plan) as f:
            plan = [(l["line"], l["start_mm"], l["end_mm"], l["tool_offset_mm"], l.get("sense"))
                    for l in json.load(f)]
    else:
        plan = [(line, [f0[k] * STROKE[k] for k in range(3)], [f1[k] * STROKE[k] for k in range(3)],
                 offset, None) for line, f0, f1, offset in PLAN]
    for line, start, end, offset, sense in plan:
        d0 = [end[k] - start[k] for k in range(3)]
        n0 = math.sqrt(sum(x * x for x in d0))
        u0 = [x / n0 for x in d0]
        straight = None
        if sense is None:
            beam = tilt(u0, rng, 200e-6)
        else:
            slope = rng.gauss(0, 200e-6)
            v = [sense[k] + slope * u0[k] for k in range(3)]
            beam = [x / math.sqrt(sum(y * y for y in v)) for x in v]
            straight = rng.gauss(0, 5.0)
        reflector = [offset[k] + rng.gauss(0, 1.0) for k in range(3)]
        scale = rng.gauss(0, a.scale_ppm * 1e-6) if sense is None else 0.0
        if sense is None:
            lost = sum(LOST_MOTION_UM[k] * abs(d0[k]) / n0 for k in range(3))
        else:  # each moving axis's lost motion, seen along the optic's sense
            lost = sum(LOST_MOTION_UM[k] * math.copysign(1.0, d0[k]) * beam[k]
                       for k in range(3) if abs(d0[k]) > 1e-9)
        d, runs = measure(terms, sq, start, end, reflector, beam, scale, a.noise_um, rng,
                          (0.0, lost), straight)
        for run, rows in zip(("forward", "backward"), runs):
            write_line(os.path.join(a.out, "%s_%s.csv" % (line, run)), line, start, d,
                       offset, run, rows, sense)
    if a.plan:
        rng = random.Random(7919 * a.seed + 29)
    for i in range(HELDOUT):
        while True:
            p0 = [rng.uniform(0, STROKE[k]) for k in range(3)]
            p1 = [rng.uniform(0, STROKE[k]) for k in range(3)]
            if math.dist(p0, p1) > 300:
                break
        tool = [rng.uniform(-150, 150), rng.uniform(-150, 150), rng.uniform(50, 250)]
        d, runs = measure(terms, sq, p0, p1, tool, None, 0.0, 0.0, rng, (0.0,))
        write_line(os.path.join(a.out, "heldout", "H%02d.csv" % (i + 1)), "H%02d" % (i + 1),
                   p0, d, tool, None, runs[0])
    errors = {}
    for name in terms:
        stroke = STROKE[AXES.index(name[2])]
        qs = [stroke * i / 400 for i in range(401)]
        errors[name] = {"positions_mm": qs, "values": [value(terms, name, q) for q in qs],
                        "unit": "urad" if name[1] in "ABC" else "um"}
    truth = {"structure": "XY/Z", "stroke_mm": list(STROKE), "errors": errors,
             "squareness_urad": sq, "class": "degree-5 polynomial + wave, per-line scale"}
    with open(os.path.join(a.out, "truth.json"), "w") as f:
        json.dump(truth, f)


if __name__ == "__main__":
    main()
