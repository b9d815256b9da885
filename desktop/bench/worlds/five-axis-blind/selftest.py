#!/usr/bin/env python3
"""Checks of gen.py's physics against hand-derived first-order forms (run: python3 selftest.py)."""
import copy
import math
import random

import gen


def zero_machine():
    m, _ = gen.gen_machine(7, 0, 1)
    for e in m["linear"].values():
        if e["form"] == "straightness":
            e["bow_um"] = e["wave_um"] = 0.0
        else:
            e["cubic"] = [0.0, 0.0, 0.0]
            e["wave_amp"] = 0.0
    m["squareness_urad"] = {k: 0.0 for k in m["squareness_urad"]}
    for ax in m["components"].values():
        for c in ax.values():
            c["cos"] = [0.0] * 3
            c["sin"] = [0.0] * 3
    m["location_ref"] = {n: 0.0 for n in gen.LOC_NAMES}
    m["location_per_kelvin"] = {n: {s: 0.0 for s in gen.SENSORS} for n in gen.LOC_NAMES}
    m["spindle_tilt_urad"] = {"about_x": 0.0, "about_y": 0.0}
    return m


def reading(m, a, c, nest=(160.0, 0.0, 50.0), tool=(0.0, 0.0, 100.0)):
    temps = {s: gen.T_REF for s in gen.SENSORS}
    def raw(a, c):
        sphere = gen.apply(gen.W_nominal(a, c), list(nest))
        pos = [sphere[i] - tool[i] for i in range(3)]
        p = gen.linear_point(m, pos, tool)
        w = gen.apply(gen.inv(gen.W_actual(m, gen.location_at(m, temps), a, c)), p)
        return [(w[i] - nest[i]) * 1e3 for i in range(3)]
    r0 = raw(0.0, 0.0)
    return [x - y for x, y in zip(raw(a, c), r0)]


def close(u, v, tol):
    return max(abs(x - y) for x, y in zip(u, v)) < tol


poses = [(a, c) for a in (-90, -40, 0, 30, 100) for c in (0, 45, 130, 270)]
m0 = zero_machine()
assert all(close(reading(m0, a, c), [0, 0, 0], 1e-9) for a, c in poses)

# C offset o: reading (I - R_c^T) o at A = 0
m = copy.deepcopy(m0); m["location_ref"]["EXOC"] = 10.0; m["location_ref"]["EYOC"] = -6.0
for c in (30, 90, 200):
    cr = math.radians(c); o = [10.0, -6.0, 0.0]
    Rt = gen.tr(gen.rz(cr)); exp = [o[i] - v for i, v in enumerate(gen.mv(Rt, o))]
    assert close(reading(m, 0.0, c), exp, 1e-4), (reading(m, 0.0, c), exp)

# forward whirl of (EXC, EYC) == C offset (first order); of (EAC, EBC) == C tilt
for (n1, n2, l1, l2, amp) in (("EXC", "EYC", "EXOC", "EYOC", 8.0), ("EAC", "EBC", "EAOC", "EBOC", 30.0)):
    ma = copy.deepcopy(m0); mb = copy.deepcopy(m0)
    ma["location_ref"][l1] = amp; ma["location_ref"][l2] = -0.5 * amp
    # location (X, Y) gives a_X = -X, b_X = Y, a_Y = -Y, b_Y = -X
    X, Y = amp, -0.5 * amp
    mb["components"]["C"][n1] = {"cos": [-X, 0, 0], "sin": [Y, 0, 0]}
    mb["components"]["C"][n2] = {"cos": [-Y, 0, 0], "sin": [-X, 0, 0]}
    for a, c in poses:
        assert close(reading(ma, a, c), reading(mb, a, c), 2e-3), (n1, a, c, reading(ma, a, c), reading(mb, a, c))
# same for A: (EYA, EZA) == (YOA, ZOA), (EBA, ECA) == (BOA, COA)
for (n1, n2, l1, l2, amp) in (("EYA", "EZA", "EYOA", "EZOA", 8.0), ("EBA", "ECA", "EBOA", "ECOA", 30.0)):
    ma = copy.deepcopy(m0); mb = copy.deepcopy(m0)
    ma["location_ref"][l1] = amp; ma["location_ref"][l2] = -0.5 * amp
    Y, Z = amp, -0.5 * amp
    mb["components"]["A"][n1] = {"cos": [-Y, 0, 0], "sin": [Z, 0, 0]}
    mb["components"]["A"][n2] = {"cos": [-Z, 0, 0], "sin": [-Y, 0, 0]}
    for a, c in poses:
        assert close(reading(ma, a, c), reading(mb, a, c), 2e-3), (n1, a, c, reading(ma, a, c), reading(mb, a, c))

# axis tilt directions: C axis ~ (BOC, -AOC, 1), A axis ~ (1, COA, -BOA)
m = copy.deepcopy(m0); m["location_ref"]["EAOC"] = 40.0; m["location_ref"]["EBOC"] = 25.0
LC = gen.compose(gen.T(gen.mm(gen.rx(40e-6), gen.ry(25e-6))))
d = gen.mv(LC[0], [0, 0, 1]); assert abs(d[0] - 25e-6) < 1e-9 and abs(d[1] + 40e-6) < 1e-9
LA = gen.mm(gen.rz(30e-6), gen.ry(20e-6)); d = gen.mv(LA, [1, 0, 0])
assert abs(d[1] - 30e-6) < 1e-9 and abs(d[2] + 20e-6) < 1e-9

# spindle tilt == apparent location errors (README derivation)
for L in (100.0, 200.0):
    ma = copy.deepcopy(m0); ma["spindle_tilt_urad"] = {"about_x": 25.0, "about_y": -18.0}
    mb = copy.deepcopy(m0)
    dx, dy = -18.0 * 1e-6 * L * 1e3, -25.0 * 1e-6 * L * 1e3
    mb["location_ref"].update(EXOC=-dx, EYOC=-dy, EYOA=-dy, EZOA=0.0)
    for a, c in poses:
        for nest in gen.NESTS.values():
            ra, rb = reading(ma, a, c, nest, (0, 0, L)), reading(mb, a, c, nest, (0, 0, L))
            assert close(ra, rb, 2e-3), (L, a, c, ra, rb)

# squareness: EC0Y moves a pure-Y move along +x by -EC0Y*y (u_Y = Rz(EC0Y) y)
m = copy.deepcopy(m0); m["squareness_urad"]["EC0Y"] = 20.0
p = gen.linear_point(m, [0.0, 500.0, 0.0], (0.0, 0.0, 0.0))
assert abs(p[0] * 1e3 - (-20e-6 * 500 * 1e3)) < 1e-3

# straightness shape: zero value and slope at both ends, no least-squares slope
e = {"form": "straightness", "stroke_mm": 600.0, "bow_um": 3.0, "wave_um": 0.5, "wave_cycles": 3}
n = 2001; qs = [600.0 * i / (n - 1) for i in range(n)]; fs = [gen.lin_eval(e, q) for q in qs]
mq = sum(qs) / n; slope = sum((q - mq) * f for q, f in zip(qs, fs)) / sum((q - mq) ** 2 for q in qs)
assert abs(slope) < 1e-9 and abs(fs[0]) < 1e-12 and abs(fs[-1]) < 1e-9
print("selftest ok")
