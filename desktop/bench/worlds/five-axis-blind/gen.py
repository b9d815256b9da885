#!/usr/bin/env python3
"""five-axis-blind: a table-tilting XYZ-A-C machine written from the physics,
without reading thermocomp's identifier or simulators.

Writes, per machine: R-test files (docs/formats/rtest.md), displacement-line
files (docs/formats/displacement-lines.md; the 14-line plan and 14 parallel
shifted copies), truth.json and truth_poses.csv.  Stdlib only (Python 3.11).

    python3 gen.py --seed 1 --machines 10 --out /tmp/five-axis-blind

Conventions (also in README.md and in every truth.json):
  machine frame = the frame the linear axes define (X travel defines x, X and
  Y travel the xy plane; every linear error function is zero at its axis's
  zero); positions mm; translational errors um; angles urad; rotations
  right-handed.
  Linear stack, XY/Z chain (ISO 230-1 names, as docs/geometry.md
  "Kinematics"):   p = M_X M_Y M_Z (R_sp tool),
      M_k = Trans(q_k u_k + (EXk,EYk,EZk)) Rz(ECk) Ry(EBk) Rx(EAk),
      u_X = x, u_Y = Rz(EC0Y) y, u_Z = Ry(EB0Z) Rx(EA0Z) z,
      R_sp = Rx(spindle_tilt_x) Ry(spindle_tilt_y)  (spindle axis vs frame).
  Rotary chain (rtest.md / docs/geometry.md "Rotary axes from R-test files"):
      W(a,c) = Trans(pivot_a) M_A(a) Trans(offset_c) M_C(c),
      M_k(t) = E_k(t) L_k R_k(t) L_k^-1,  R_A = Rx(a), R_C = Rz(c),
      L_C = Trans(EXOC, EYOC, 0) Rx(EAOC) Ry(EBOC)   (C axis line: through
            offset_c + (EXOC, EYOC, 0) in the A frame, direction ~ (EBOC, -EAOC, 1)),
      L_A = Trans(0, EYOA, EZOA) Rz(ECOA) Ry(EBOA)   (A axis line: through
            pivot_a + (0, EYOA, EZOA), direction ~ (1, ECOA, -EBOA)),
      E_k(t) = Trans(EXk, EYk, EZk) Rz(ECk) Ry(EBk) Rx(EAk), component errors
            in fixed directions at the nominal axis origin, each
            f(t) = sum_h a_h (cos h t - 1) + b_h sin h t  (zero at 0 deg);
            the first harmonic of the radial and tilt pairs is a pure
            backward whirl (a_1 = -b_2, b_1 = a_2): a forward whirl IS a
            location error, so the truth keeps it there.
  Location errors drift linearly with two sensors:
      L(T) = L_ref + K_ctable (T_ctable - 20) + K_trunnion (T_trunnion - 20).
  R-test reading (workpiece frame, um): W_act^-1 p_act - nest, zeroed at the
  file's first row (noise on every reading, the first included).
  Tool-tip error (truth_poses.csv): W_act^-1 p_act - W_nom^-1 (pos + tool),
  workpiece frame, um.
"""
import argparse
import csv
import json
import math
import os
import random

NOISE_UM = 0.5
STROKE = (800.0, 600.0, 600.0)
PIVOT_A = (400.0, 300.0, 420.0)
OFFSET_C = (0.0, 0.0, 100.0)
NESTS = {"N1": (160.0, 0.0, 50.0), "N2": (-120.0, 110.0, 110.0), "N3": (-80.0, -150.0, 20.0)}
TOOLS = (100.0, 200.0)
SENSORS = ("ctable", "trunnion")
T_REF = 20.0
LINE_TARGETS = 31

LOC_NAMES = ["EXOC", "EYOC", "EAOC", "EBOC", "EYOA", "EZOA", "EBOA", "ECOA"]
# the tool's model-file names (docs/geometry.md "Model file") for the same quantity
TOOL_NAMES = {"EXOC": "xoc_um", "EYOC": "yoc_um", "EAOC": "aoc_urad", "EBOC": "boc_urad",
              "EYOA": "yoa_um", "EZOA": "zoa_um", "EBOA": "boa_urad", "ECOA": "coa_urad"}
LOC_UNITS = {n: ("um" if n[1] in "XYZ" else "urad") for n in LOC_NAMES}

# ---------------------------------------------------------------- geometry ---
# A transform is (R, t): 3x3 row lists and a 3-vector; x -> R x + t.


def rx(a):
    c, s = math.cos(a), math.sin(a)
    return [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]]


def ry(a):
    c, s = math.cos(a), math.sin(a)
    return [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]]


def rz(a):
    c, s = math.cos(a), math.sin(a)
    return [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]


def mm(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def mv(a, v):
    return [a[i][0] * v[0] + a[i][1] * v[1] + a[i][2] * v[2] for i in range(3)]


def tr(m):
    return [[m[j][i] for j in range(3)] for i in range(3)]


I3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]


def T(R=None, t=(0.0, 0.0, 0.0)):
    return (R if R is not None else I3, list(t))


def compose(*ts):
    R, t = I3, [0.0, 0.0, 0.0]
    for (R2, t2) in ts:
        t = [t[i] + v for i, v in enumerate(mv(R, t2))]
        R = mm(R, R2)
    return (R, t)


def inv(tf):
    R, t = tf
    Rt = tr(R)
    return (Rt, [-v for v in mv(Rt, t)])


def apply(tf, p):
    R, t = tf
    return [v + t[i] for i, v in enumerate(mv(R, p))]


def rot_zyx(ec, eb, ea):
    """Rz(ec) Ry(eb) Rx(ea), angles in rad."""
    return mm(rz(ec), mm(ry(eb), rx(ea)))


# --------------------------------------------------------- linear errors ---
LIN_AXES = "XYZ"
LIN_ERRS = [f"E{d}{k}" for k in LIN_AXES for d in "XYZABC"]


def lin_kind(name):
    d, k = name[1], name[2]
    if d == k:
        return "positioning"
    if d in "XYZ":
        return "straightness"
    if (d, k) in (("A", "X"), ("B", "Y"), ("C", "Z")):
        return "roll"
    return "angular"


def gen_linear(rng):
    errs = {}
    for name in LIN_ERRS:
        kind = lin_kind(name)
        S = STROKE["XYZ".index(name[2])]
        if kind == "straightness":
            # symmetric about mid-stroke, zero value and slope at both ends:
            # the axis direction is the same whichever reference line one uses
            # (slope at 0, end points, least squares) -- no linear part.
            errs[name] = {"form": "straightness", "stroke_mm": S,
                          "bow_um": rng.choice((-1, 1)) * rng.uniform(1.0, 4.0),
                          "wave_um": rng.choice((-1, 1)) * rng.uniform(0.2, 0.8),
                          "wave_cycles": rng.choice((2, 3))}
        else:
            if kind == "positioning":
                p = [rng.uniform(-12, 12), rng.uniform(-4, 4), rng.uniform(-2.5, 2.5)]
                wave, lam = rng.uniform(0.3, 1.0), rng.uniform(90, 250)
            elif kind == "angular":
                p = [rng.uniform(-15, 15), rng.uniform(-6, 6), rng.uniform(-4, 4)]
                wave, lam = rng.uniform(0.5, 2.0), rng.uniform(150, 400)
            else:  # roll
                p = [rng.uniform(-8, 8), rng.uniform(-3, 3), rng.uniform(-2, 2)]
                wave, lam = rng.uniform(0.3, 1.2), rng.uniform(150, 400)
            errs[name] = {"form": "cubic+wave", "stroke_mm": S, "cubic": p,
                          "wave_amp": wave, "wave_length_mm": lam,
                          "wave_phase_rad": rng.uniform(0, 2 * math.pi)}
    sq = {n: rng.choice((-1, 1)) * rng.uniform(5.0, 30.0) for n in ("EC0Y", "EB0Z", "EA0Z")}
    return errs, sq


def lin_eval(e, q):
    """Value of one error function at axis position q (mm): um or urad."""
    u = q / e["stroke_mm"]
    if e["form"] == "straightness":
        return (e["bow_um"] * 16.0 * u * u * (1.0 - u) ** 2
                + e["wave_um"] * 0.5 * (1.0 - math.cos(2 * math.pi * e["wave_cycles"] * u)))
    p = e["cubic"]
    ph = e["wave_phase_rad"]
    return (p[0] * u + p[1] * u * u + p[2] * u ** 3
            + e["wave_amp"] * (math.sin(2 * math.pi * q / e["wave_length_mm"] + ph) - math.sin(ph)))


def linear_point(m, pos, tool):
    """Actual tool point (mm) in the machine frame, exact chain."""
    errs, sq = m["linear"], m["squareness_urad"]
    u = {"X": [1.0, 0.0, 0.0],
         "Y": mv(rz(sq["EC0Y"] * 1e-6), [0.0, 1.0, 0.0]),
         "Z": mv(mm(ry(sq["EB0Z"] * 1e-6), rx(sq["EA0Z"] * 1e-6)), [0.0, 0.0, 1.0])}
    chain = []
    for i, k in enumerate(LIN_AXES):
        q = pos[i]
        ev = {d: lin_eval(errs[f"E{d}{k}"], q) for d in "XYZABC"}
        t = [q * u[k][j] + ev["XYZ"[j]] * 1e-3 for j in range(3)]
        chain.append(T(rot_zyx(ev["C"] * 1e-6, ev["B"] * 1e-6, ev["A"] * 1e-6), t))
    st = m["spindle_tilt_urad"]
    rsp = mm(rx(st["about_x"] * 1e-6), ry(st["about_y"] * 1e-6))
    return apply(compose(*chain), mv(rsp, list(tool)))


# --------------------------------------------------------- rotary errors ---
C_COMP = ["EXC", "EYC", "EZC", "EAC", "EBC", "ECC"]
A_COMP = ["EXA", "EYA", "EZA", "EAA", "EBA", "ECA"]


def gen_components(rng, axis):
    """Fourier coefficients (3 harmonics) of the six component errors."""
    if axis == "C":
        pairs = [("EXC", "EYC", 1.0), ("EAC", "EBC", 2.5)]
        single = [("EZC", 0.8), ("ECC", 6.0)]
        h3 = 1.0
    else:
        pairs = [("EYA", "EZA", 1.0), ("EBA", "ECA", 2.5)]
        single = [("EXA", 0.8), ("EAA", 6.0)]
        h3 = 0.5  # A's third harmonic smaller
    out = {}
    for n1, n2, s in pairs:
        r, ph = rng.uniform(0.4, 1.5) * s, rng.uniform(0, 2 * math.pi)
        a1, b1 = r * math.cos(ph), r * math.sin(ph)
        # backward whirl: a_1 = -b_2, b_1 = a_2
        c1 = {"cos": [a1], "sin": [b1]}
        c2 = {"cos": [b1], "sin": [-a1]}
        for comp in (c1, c2):
            for h, amp in ((2, 0.6 * s), (3, 0.3 * s * h3)):
                comp["cos"].append(rng.uniform(-amp, amp))
                comp["sin"].append(rng.uniform(-amp, amp))
        out[n1], out[n2] = c1, c2
    for n, s in single:
        out[n] = {"cos": [rng.uniform(-s, s) * f for f in (1.0, 0.5, 0.25 * h3)],
                  "sin": [rng.uniform(-s, s) * f for f in (1.0, 0.5, 0.25 * h3)]}
    return out


def fourier(c, th):
    return sum(a * (math.cos((h + 1) * th) - 1.0) + b * math.sin((h + 1) * th)
               for h, (a, b) in enumerate(zip(c["cos"], c["sin"])))


def gen_location(rng):
    ref, perk = {}, {}
    for n in LOC_NAMES:
        if LOC_UNITS[n] == "um":
            ref[n] = rng.choice((-1, 1)) * rng.uniform(4.0, 25.0)
            perk[n] = {s: rng.uniform(-2.0, 2.0) for s in SENSORS}
        else:
            ref[n] = rng.choice((-1, 1)) * rng.uniform(8.0, 50.0)
            perk[n] = {s: rng.uniform(-4.0, 4.0) for s in SENSORS}
    return ref, perk


def location_at(m, temps):
    return {n: m["location_ref"][n] + sum(m["location_per_kelvin"][n][s] * (temps[s] - T_REF)
                                          for s in SENSORS) for n in LOC_NAMES}


def e_motion(comp, names, th):
    v = {n: fourier(comp[n], th) for n in names}
    X, Y, Z, A, B, C = names
    return T(rot_zyx(v[C] * 1e-6, v[B] * 1e-6, v[A] * 1e-6),
             [v[X] * 1e-3, v[Y] * 1e-3, v[Z] * 1e-3])


def W_actual(m, loc, a_deg, c_deg):
    a, c = math.radians(a_deg), math.radians(c_deg)
    LA = compose(T(t=[0.0, loc["EYOA"] * 1e-3, loc["EZOA"] * 1e-3]),
                 T(mm(rz(loc["ECOA"] * 1e-6), ry(loc["EBOA"] * 1e-6))))
    LC = compose(T(t=[loc["EXOC"] * 1e-3, loc["EYOC"] * 1e-3, 0.0]),
                 T(mm(rx(loc["EAOC"] * 1e-6), ry(loc["EBOC"] * 1e-6))))
    MA = compose(e_motion(m["components"]["A"], A_COMP, a), LA, T(rx(a)), inv(LA))
    MC = compose(e_motion(m["components"]["C"], C_COMP, c), LC, T(rz(c)), inv(LC))
    return compose(T(t=PIVOT_A), MA, T(t=OFFSET_C), MC)


def W_nominal(a_deg, c_deg):
    a, c = math.radians(a_deg), math.radians(c_deg)
    return compose(T(t=PIVOT_A), T(rx(a)), T(t=OFFSET_C), T(rz(c)))


def tooltip_error_um(m, temps, pos, a_deg, c_deg, tool, tilt=True):
    """Actual minus nominal tool point in the workpiece frame (um)."""
    mm_ = m if tilt else dict(m, spindle_tilt_urad={"about_x": 0.0, "about_y": 0.0})
    p_act = linear_point(mm_, pos, tool)
    w_act = apply(inv(W_actual(m, location_at(m, temps), a_deg, c_deg)), p_act)
    w_nom = apply(inv(W_nominal(a_deg, c_deg)), [pos[i] + tool[i] for i in range(3)])
    return [(w_act[i] - w_nom[i]) * 1e3 for i in range(3)]


# ------------------------------------------------------------------ plans ---
def rtest_poses():
    poses = [(0.0, 0.0)]
    poses += [(0.0, float(c)) for c in range(20, 360, 20)]
    for c in (0, 90, 180, 270):
        poses += [(float(a), float(c)) for a in range(-100, 101, 10)]
    for a in (50, -50):
        poses += [(float(a), float(c)) for c in range(0, 360, 45)]
    poses.append((0.0, 0.0))
    return poses


# the 14 lines as `tcomp geometry plan --stroke 800,600,600` prints them
# (start, end, reflector offset): the format page does not list a plan
PLAN14 = [
    ("L01", (0, 0, 0), (800, 600, 600), (100, 0, 100)),
    ("L02", (800, 0, 0), (0, 600, 600), (100, 100, 100)),
    ("L03", (0, 600, 0), (800, 0, 600), (100, 100, 100)),
    ("L04", (800, 600, 0), (0, 0, 600), (0, 0, 250)),
    ("L05", (800, 0, 0), (400, 600, 600), (0, 0, 250)),
    ("L06", (0, 0, 0), (800, 600, 0), (0, 100, 100)),
    ("L07", (800, 0, 600), (0, 600, 600), (-100, 0, 100)),
    ("L08", (0, 600, 0), (800, 600, 600), (0, 0, 250)),
    ("L09", (800, 0, 0), (0, 0, 600), (-100, 0, 100)),
    ("L10", (800, 0, 0), (800, 600, 600), (-100, 0, 100)),
    ("L11", (800, 600, 0), (800, 0, 600), (-100, 0, 100)),
    ("L12", (0, 0, 0), (0, 600, 0), (100, 0, 100)),
    ("L13", (800, 0, 600), (800, 600, 600), (0, 0, 250)),
    ("L14", (0, 0, 0), (0, 0, 600), (100, 100, 100)),
]
# 14 more: each line shifted parallel within its plane (shortened to stay in
# the stroke), same reflector offset
PLAN_EXTRA = [
    ("L15", (0, 0, 150), (600, 450, 600), (100, 0, 100)),
    ("L16", (800, 0, 150), (200, 450, 600), (100, 100, 100)),
    ("L17", (0, 600, 150), (600, 150, 600), (100, 100, 100)),
    ("L18", (800, 600, 150), (200, 150, 600), (0, 0, 250)),
    ("L19", (500, 0, 0), (100, 600, 600), (0, 0, 250)),
    ("L20", (200, 0, 0), (800, 450, 0), (0, 100, 100)),
    ("L21", (800, 150, 600), (200, 600, 600), (-100, 0, 100)),
    ("L22", (200, 600, 0), (800, 600, 450), (0, 0, 250)),
    ("L23", (800, 0, 150), (200, 0, 600), (-100, 0, 100)),
    ("L24", (800, 150, 0), (800, 600, 450), (-100, 0, 100)),
    ("L25", (800, 450, 0), (800, 0, 450), (-100, 0, 100)),
    ("L26", (400, 0, 0), (400, 600, 0), (100, 0, 100)),
    ("L27", (400, 0, 600), (400, 600, 600), (0, 0, 250)),
    ("L28", (400, 0, 0), (400, 0, 600), (100, 100, 100)),
]


# ---------------------------------------------------------------- writers ---
def fmt(v, nd=6):
    s = f"{v:.{nd}f}"
    return "0" if float(s) == 0 else s.rstrip("0").rstrip(".")


def csv_vec(v):
    return ",".join(fmt(x) for x in v)


def write_line(path, lid, start, end, tool, run, m, rng):
    d = [end[i] - start[i] for i in range(3)]
    L = math.sqrt(sum(x * x for x in d))
    d = [x / L for x in d]
    rows = []
    for i in range(LINE_TARGETS):
        s = L * i / (LINE_TARGETS - 1)
        pos = [start[j] + s * d[j] for j in range(3)]
        p = linear_point(m, pos, tool)
        e = sum((p[j] - pos[j] - tool[j]) * d[j] for j in range(3)) * 1e3
        rows.append([s, pos, e + rng.gauss(0.0, NOISE_UM)])
    if run == "backward":
        rows.reverse()
    z0 = rows[0][2]
    with open(path, "w", newline="") as f:
        f.write(f"# line: {lid}\n# run: {run}\n# start_mm: {csv_vec(start)}\n"
                f"# direction: {','.join(repr(x) for x in d)}\n# tool_offset_mm: {csv_vec(tool)}\n"
                f"# structure: XY/Z\n# temperature_state: S1\n# source: simulated\n")
        f.write("s_mm,pos_x,pos_y,pos_z,disp_um\n")
        for k, (s, pos, e) in enumerate(rows):
            f.write(f"{fmt(s)},{csv_vec(pos)},{fmt(0.0 if k == 0 else e - z0, 4)}\n")


def write_rtest(path, m, state, nest, tool, rng):
    temps = state["temps"]
    loc = location_at(m, temps)
    with open(path, "w", newline="") as f:
        f.write("# structure: XYZ-A(x)-C(z) table\n"
                f"# pivot_a_mm: {csv_vec(PIVOT_A)}\n# offset_c_mm: {csv_vec(OFFSET_C)}\n"
                f"# nest_mm: {csv_vec(nest)}\n# tool_mm: {csv_vec(tool)}\n# source: simulated\n")
        f.write("pos_x,pos_y,pos_z,a_deg,c_deg,dx_um,dy_um,dz_um,"
                + ",".join(f"T_{s}" for s in SENSORS) + "\n")
        first = None
        for a, c in rtest_poses():
            sphere = apply(W_nominal(a, c), list(nest))
            pos = [sphere[i] - tool[i] for i in range(3)]
            for i in range(3):
                assert -1e-9 <= pos[i] <= STROKE[i] + 1e-9, (pos, a, c)
            p_act = linear_point(m, pos, tool)
            w = apply(inv(W_actual(m, loc, a, c)), p_act)
            r = [(w[i] - nest[i]) * 1e3 + rng.gauss(0.0, NOISE_UM) for i in range(3)]
            if first is None:
                first = r
            r = [r[i] - first[i] for i in range(3)]
            f.write(f"{csv_vec(pos)},{fmt(a)},{fmt(c)},"
                    + ",".join(fmt(x, 4) for x in r) + ","
                    + ",".join(fmt(temps[s], 3) for s in SENSORS) + "\n")


# ----------------------------------------------------------------- machine ---
def gen_machine(seed, index, n_states):
    rng = random.Random(f"five-axis-blind/{seed}/{index}")
    lin, sq = gen_linear(rng)
    ref, perk = gen_location(rng)
    comps = {"C": gen_components(rng, "C"), "A": gen_components(rng, "A")}
    tilt, psi = rng.uniform(10.0, 40.0), rng.uniform(0, 2 * math.pi)
    base = {s: T_REF + rng.uniform(-0.3, 0.3) for s in SENSORS}
    steps = [{"ctable": 0.0, "trunnion": 0.0},
             {"ctable": rng.uniform(2.5, 4.0), "trunnion": rng.uniform(0.8, 1.8)},
             {"ctable": rng.uniform(5.0, 7.0), "trunnion": rng.uniform(3.5, 5.0)}]
    states = [{"name": f"S{i + 1}", "temps": {s: round(base[s] + steps[i][s], 3) for s in SENSORS}}
              for i in range(n_states)]
    m = {"linear": lin, "squareness_urad": sq, "location_ref": ref,
         "location_per_kelvin": perk, "components": comps,
         "spindle_tilt_urad": {"about_x": tilt * math.cos(psi), "about_y": tilt * math.sin(psi)},
         "states": states}
    for st in states:
        st["location"] = location_at(m, st["temps"])
    return m, rng


def truth_json(m, seed, index):
    st = m["spindle_tilt_urad"]
    apparent = {}
    for L in TOOLS:
        # a constant machine-frame sphere offset d = (R_sp - I) tool is, in the
        # R-test readings, exactly the location errors XOC -= d_x, YOC -= d_y,
        # YOA -= d_y, ZOA -= d_z (derivation in README.md)
        d = [st["about_y"] * 1e-6 * L * 1e3, -st["about_x"] * 1e-6 * L * 1e3, 0.0]  # um
        apparent[f"tool_{int(L)}mm"] = [
            dict(s["location"], EXOC=s["location"]["EXOC"] - d[0],
                 EYOC=s["location"]["EYOC"] - d[1], EYOA=s["location"]["EYOA"] - d[1],
                 EZOA=s["location"]["EZOA"] - d[2]) for s in m["states"]]
    tab = {}
    for n, e in m["linear"].items():
        S = e["stroke_mm"]
        tab[n] = [round(lin_eval(e, S * i / 10), 4) for i in range(11)]
    return {
        "world": "five-axis-blind", "seed": seed, "machine": index,
        "units": "positions mm; translations um; angles urad; per_kelvin per K",
        "conventions": __doc__,
        "geometry": {"pivot_a_mm": PIVOT_A, "offset_c_mm": OFFSET_C, "stroke_mm": STROKE,
                     "nests_mm": NESTS, "tools_mm": TOOLS, "line_structure": "XY/Z"},
        "noise_um": NOISE_UM,
        "sensors": list(SENSORS), "temperature_reference_c": T_REF,
        "location_ref": m["location_ref"],
        "location_per_kelvin": m["location_per_kelvin"],
        "states": m["states"],
        "tool_names": TOOL_NAMES,
        "location_apparent_with_spindle_tilt": apparent,
        "spindle_tilt_urad": st,
        "components": m["components"],
        "component_form": "f(t) = sum_h cos[h-1] (cos h t - 1) + sin[h-1] sin h t; um (EX*,EY*,EZ*) or urad (EA*,EB*,EC*)",
        "squareness_urad": m["squareness_urad"],
        "linear": m["linear"],
        "linear_forms": {
            "straightness": "bow_um*16u^2(1-u)^2 + wave_um*(1-cos(2 pi wave_cycles u))/2, u = q/stroke",
            "cubic+wave": "c0 u + c1 u^2 + c2 u^3 + wave_amp (sin(2 pi q/wave_length + phase) - sin(phase)), u = q/stroke"},
        "linear_tabulated_0_to_stroke_11pts": tab,
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--machines", type=int, default=10, help="machines 0..N-1")
    ap.add_argument("--machine", type=int, help="only this machine index")
    ap.add_argument("--states", type=int, default=3, choices=(1, 2, 3))
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    idx = [args.machine] if args.machine is not None else range(args.machines)
    for i in idx:
        m, rng = gen_machine(args.seed, i, args.states)
        d = os.path.join(args.out, f"m{i:02d}")
        for sub in ("rtest", "lines", "lines_extra"):
            os.makedirs(os.path.join(d, sub), exist_ok=True)
        for plan, sub in ((PLAN14, "lines"), (PLAN_EXTRA, "lines_extra")):
            for lid, s, e, tool in plan:
                for run in ("forward", "backward"):
                    write_line(os.path.join(d, sub, f"{lid}_{run}.csv"), lid,
                               [float(x) for x in s], [float(x) for x in e],
                               [float(x) for x in tool], run, m, rng)
        for st in m["states"]:
            for nn, nest in NESTS.items():
                for L in TOOLS:
                    write_rtest(os.path.join(d, "rtest", f"{st['name']}_{nn}_T{int(L)}.csv"),
                                m, st, nest, (0.0, 0.0, L), rng)
        with open(os.path.join(d, "truth.json"), "w") as f:
            json.dump(truth_json(m, args.seed, i), f, indent=1)
        prng = random.Random(f"five-axis-blind/poses/{args.seed}/{i}")
        poses = [([round(prng.uniform(100, 700), 3), round(prng.uniform(80, 520), 3),
                   round(prng.uniform(80, 520), 3)],
                  round(prng.uniform(-90, 90), 3), round(prng.uniform(0, 360), 3),
                  prng.choice((100.0, 150.0, 200.0)))
                 for _ in range(20)]
        with open(os.path.join(d, "truth_poses.csv"), "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["state"] + [f"T_{s}" for s in SENSORS]
                       + ["x_mm", "y_mm", "z_mm", "a_deg", "c_deg", "tool_mm",
                          "dx_um", "dy_um", "dz_um", "tilt_dx_um", "tilt_dy_um", "tilt_dz_um"])
            for st in m["states"]:
                for pos, a, c, L in poses:
                    tool = (0.0, 0.0, L)
                    e = tooltip_error_um(m, st["temps"], pos, a, c, tool)
                    e0 = tooltip_error_um(m, st["temps"], pos, a, c, tool, tilt=False)
                    w.writerow([st["name"]] + [st["temps"][s] for s in SENSORS]
                               + pos + [a, c, L]
                               + [round(v, 4) for v in e] + [round(e[k] - e0[k], 4) for k in range(3)])
        print(f"wrote {d}")


if __name__ == "__main__":
    main()
