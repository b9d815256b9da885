#!/usr/bin/env python3
"""Third truth world for `tcomp diagnose`: a horizontal machining centre with a
travelling column, written from the physics alone (stdlib only).

    python3 gen.py --out DIR --seed S --cases N

writes DIR/case_NNN/{run_a.csv, run_b.csv, machine.toml, truth.json}.
Case i depends only on (seed, i): `--cases 10` writes the first ten cases of
`--cases 60`.  See README.md for the physics and the effects.
"""
import argparse
import json
import math
import os
import random

# ---------------------------------------------------------------------------
# The machine (design values; the truth without an effect is exactly this)
# ---------------------------------------------------------------------------

ALPHA = 11.5e-6
N_MAX = 12000.0
RATED_W = 18000.0
MOTOR_LOSS_FRAC = 0.02
SUPPLY_C = 20.0
TANK_C = 250000.0        # 60 L water x 4186 J/(kg K), less the piping
TANK_G = 6.0             # tank and unit casing to air
DT_SAMPLE = 10           # s
HOURS = 8.0
SUB = 5                  # substeps per sample (2 s)
H_DESIGN = 7.0           # W/(m2 K): free convection + radiation the design uses

# name, C [J/K], g_amb [W/K], area [m2], comment
NODES = [
    ("front_brg", 2200.0, 0.21, 0.03, "front angular-contact pair 7015 + ring of housing, ~4.8 kg steel x 460"),
    ("rear_brg", 1700.0, 0.18, 0.025, "rear pair 7013 + ring of housing, ~3.7 kg"),
    ("shaft_front", 3600.0, 0.32, 0.04, "front half of the shaft, d75 x 225 mm, 7.8 kg x 460; h ~8 rotating"),
    ("shaft_rear", 3600.0, 0.32, 0.04, "rear half of the shaft (rotor side)"),
    ("stator", 9000.0, 0.0, 0.0, "built-in motor stator, ~20 kg Cu/Fe x 450; enclosed, no air path"),
    ("cartridge", 21000.0, 1.75, 0.25, "spindle cartridge ~46 kg; 0.25 m2 x 7 W/(m2 K)"),
    ("head", 190000.0, 11.2, 1.6, "spindle head casting ~410 kg; 1.6 m2 x 7"),
    ("column_upper", 440000.0, 22.4, 3.2, "upper column (Y-guide zone) ~950 kg; 3.2 m2 x 7"),
    ("column_lower", 520000.0, 18.2, 2.6, "column base/saddle ~1.13 t; 2.6 m2 x 7"),
    ("bed", 2000000.0, 85.5, 6.5, "bed ~4.35 t; 6.5 m2 x 7 + 40 W/K to the foundation"),
    ("pallet_table", 300000.0, 14.0, 2.0, "X table + pallet ~650 kg; 2 m2 x 7"),
    ("x_screw", 4100.0, 0.77, 0.11, "X ball screw d40 x 900, 8.9 kg"),
    ("y_screw", 3600.0, 0.7, 0.10, "Y ball screw d40 x 800 (vertical, in the column)"),
    ("z_screw", 7800.0, 1.19, 0.17, "Z ball screw d50 x 1100 (column travel, in the bed)"),
]
NAMES = [n[0] for n in NODES]
IDX = {n: i for i, n in enumerate(NAMES)}

LINKS = [
    ("front_brg", "cartridge", 10.0, "outer rings in the housing bore, contact + 8 mm steel"),
    ("rear_brg", "cartridge", 7.0, "rear outer rings (sliding fit)"),
    ("front_brg", "shaft_front", 6.0, "inner rings on the shaft"),
    ("rear_brg", "shaft_rear", 5.0, "inner rings on the shaft"),
    ("shaft_front", "shaft_rear", 0.9, "shaft conduction 45 x pi 0.0375^2 / 0.225"),
    ("stator", "cartridge", 30.0, "shrink-fitted stator sleeve"),
    ("stator", "shaft_rear", 3.0, "rotor air gap"),
    ("cartridge", "head", 18.0, "bolted front flange + bore contact"),
    ("head", "column_upper", 10.0, "Y linear guides, 4 carriages"),
    ("column_upper", "column_lower", 10.0, "casting conduction 50 x 0.12 / 0.6"),
    ("column_lower", "bed", 14.0, "Z linear guides, 6 carriages"),
    ("bed", "pallet_table", 9.0, "X linear guides + pallet clamping"),
    ("x_screw", "bed", 4.0, "fixed/floating support bearings"),
    ("x_screw", "pallet_table", 2.0, "nut flange"),
    ("y_screw", "column_upper", 3.0, "support bearings at the column top"),
    ("y_screw", "head", 1.5, "nut flange"),
    ("z_screw", "bed", 5.0, "support bearings"),
    ("z_screw", "column_lower", 2.0, "nut flange"),
]

# Palmgren: M = f1 P dm + 1e-7 f0 (nu n)^(2/3) dm^3 [N mm]; Q = 1.047e-4 n M
BEARINGS = [
    dict(node="front_brg", dm_mm=75.0, f0=0.8, f1=0.0004, load_n=1500.0, nu_cst=8.0),
    dict(node="rear_brg", dm_mm=65.0, f0=0.8, f1=0.0004, load_n=900.0, nu_cst=8.0),
]

JACKET = [("stator", 40.0), ("cartridge", 15.0)]

SENSORS = [  # (name -> column T_<name>, node)
    ("front_brg", "front_brg"),
    ("rear_brg", "rear_brg"),
    ("cartridge", "cartridge"),
    ("head", "head"),
    ("column_top", "column_upper"),
    ("column_base", "column_lower"),
    ("bed", "bed"),
    ("table", "pallet_table"),
    ("xscrew", "x_screw"),
    ("zscrew", "z_screw"),
    ("coolant", "coolant"),
]

# d<name> = sum alpha L (T - T_start); positive = tool away from the work
DIRECTIONS = [
    ("x", [("x_screw", 300.0), ("pallet_table", 100.0), ("head", 40.0), ("column_upper", 30.0)]),
    ("y", [("column_lower", 600.0), ("column_upper", 700.0), ("y_screw", -380.0), ("head", 80.0),
           ("cartridge", 20.0), ("pallet_table", -350.0)]),
    ("z", [("shaft_front", -110.0), ("front_brg", -15.0), ("cartridge", -40.0), ("head", -260.0),
           ("column_upper", -120.0), ("column_lower", -200.0), ("z_screw", -480.0), ("bed", 650.0),
           ("pallet_table", 180.0)]),
]

EFFECT_KINDS = ["ballscrew", "bearing_nonlinear", "convection", "ambient_drift",
                "sensor_lag", "sensor_offset", "chiller"]
ACCEPT = {
    "ballscrew": ["ballscrew"],
    "bearing_nonlinear": ["bearing_nonlinear"],
    "convection": ["convection"],
    "ambient_drift": ["ambient_drift"],
    "sensor_lag": ["sensor_lag"],
    "sensor_offset": ["sensor_offset"],
    "chiller": ["chiller", "periodic"],
}
# parameter findings (a design value released beyond its tolerance) that state the same
# physics: all films stronger = convection; a bearing node's heat stronger than designed
ACCEPT_PARAMETERS = {
    "convection": ["parameter:film"],
    "bearing_nonlinear": ["parameter:heat:front_brg", "parameter:heat:front_brg:f0",
                          "parameter:heat:rear_brg", "parameter:heat:rear_brg:f0"],
}


def bearing_q(b, n):
    if n <= 0:
        return 0.0
    m = b["f1"] * b["load_n"] * b["dm_mm"] + 1e-7 * b["f0"] * (b["nu_cst"] * n) ** (2.0 / 3.0) * b["dm_mm"] ** 3
    return 1.047e-4 * n * m


def motor_q(n):
    return MOTOR_LOSS_FRAC * RATED_W * max(n, 0.0) / N_MAX


# ---------------------------------------------------------------------------
# machine.toml (the design, exactly, without any effect)
# ---------------------------------------------------------------------------

def fnum(v):
    r = repr(float(v))
    return r


def machine_toml():
    L = []
    L.append("# Horizontal machining centre, travelling column (Z on the bed), spindle head")
    L.append("# on the column (Y), X table + pallet on the bed; built-in motor spindle with")
    L.append("# a chiller-fed jacket on stator and cartridge. Third truth world of")
    L.append("# tcomp diagnose (desktop/bench/worlds/third), written from the design:")
    L.append("# capacities = mass x cp (steel/cast iron 460 J/(kg K)), losses to air = area x")
    L.append("# 7 W/(m2 K) (free convection + radiation), joints from contact areas, bearing")
    L.append("# heat from the SKF/Palmgren model, motor loss 2 % of rated at n_max.")
    L.append("# The design budgets no heat on the ball screws (nuts and support bearings run")
    L.append("# cool at these feeds): there is no [[source]] with driver = \"feed\".")
    L.append("# No [tolerance] table: every design value +-25 % (the default).")
    L.append('name = "hmc-500-travelling-column"')
    L.append('description = "HMC, travelling column, motor spindle with chiller jacket; 11 sensors + T_ambient; dx dy dz"')
    L.append("ambient_c = 20.0               # nominal shop air (expansion reference)")
    L.append(f"n_max_rpm = {fnum(N_MAX)}")
    L.append(f"rated_power_w = {fnum(RATED_W)}        # built-in motor, 18 kW")
    L.append(f"motor_loss_frac = {MOTOR_LOSS_FRAC}         # loss at n_max, proportional to speed")
    L.append('motor_node = "stator"')
    L.append(f"alpha_per_k = {ALPHA}")
    L.append("")
    L.append("[noise]")
    L.append("temp_c = 0.02")
    L.append("quant_c = 0.0625")
    L.append("disp_um = 0.2")
    for name, c, g, a, com in NODES:
        L.append("")
        L.append("[[node]]")
        L.append(f'name = "{name}"            # {com}')
        L.append(f"c_j_per_k = {fnum(c)}")
        L.append(f"g_amb_w_per_k = {fnum(g)}")
        L.append(f"area_m2 = {fnum(a)}")
    for a, b, g, com in LINKS:
        L.append("")
        L.append(f"[[link]]                      # {com}")
        L.append(f'a = "{a}"')
        L.append(f'b = "{b}"')
        L.append(f"g_w_per_k = {fnum(g)}")
    for b in BEARINGS:
        L.append("")
        L.append("[[bearing]]                   # oil-air lubrication, spring preload")
        L.append(f'node = "{b["node"]}"')
        for k in ("dm_mm", "f0", "f1", "load_n", "nu_cst"):
            L.append(f"{k} = {fnum(b[k])}")
    L.append("")
    L.append("[coolant]                     # spindle cooling unit; jacket valve follows coolant_on")
    L.append(f"supply_c = {fnum(SUPPLY_C)}")
    L.append('flows = "coolant_on"')
    L.append("jacket = [ " + ", ".join(f'{{ node = "{n}", g_w_per_k = {fnum(g)} }}' for n, g in JACKET) + " ]")
    L.append(f"tank_c_j_per_k = {fnum(TANK_C)}     # 60 L water")
    L.append(f"tank_g_amb_w_per_k = {fnum(TANK_G)}")
    for s, n in SENSORS:
        L.append("")
        L.append("[[sensor]]")
        L.append(f'name = "{s}"')
        L.append(f'node = "{n}"')
    L.append("")
    L.append("[[sensor]]")
    L.append('name = "ambient"')
    L.append('node = "ambient"')
    for d, terms in DIRECTIONS:
        L.append("")
        L.append("[[direction]]")
        L.append(f'name = "{d}"')
        L.append("terms = [")
        for n, l in terms:
            L.append(f'  {{ node = "{n}", length_mm = {fnum(l)} }},')
        L.append("]")
    L.append("")
    L.append("[effects]")
    L.append('bearing_nodes = ["front_brg", "rear_brg"]')
    L.append('ballscrew_nodes = ["x_screw", "y_screw", "z_screw"]')
    L.append('coolant_nodes = ["stator", "cartridge"]')
    L.append('bending = { a = "column_upper", b = "column_lower", direction = "z" }')
    return "\n".join(L) + "\n"


# ---------------------------------------------------------------------------
# linear algebra (stdlib): symmetric Jacobi eigen-decomposition, exact ZOH
# ---------------------------------------------------------------------------

def jacobi_eig(S):
    n = len(S)
    A = [row[:] for row in S]
    V = [[1.0 if i == j else 0.0 for j in range(n)] for i in range(n)]
    for _sweep in range(100):
        off = sum(A[i][j] ** 2 for i in range(n) for j in range(n) if i != j)
        if off < 1e-22 * max(1.0, sum(A[i][i] ** 2 for i in range(n))):
            break
        for p in range(n - 1):
            for q in range(p + 1, n):
                if abs(A[p][q]) < 1e-300:
                    continue
                theta = (A[q][q] - A[p][p]) / (2.0 * A[p][q])
                t = (1.0 if theta >= 0 else -1.0) / (abs(theta) + math.sqrt(theta * theta + 1.0))
                c = 1.0 / math.sqrt(t * t + 1.0)
                s = t * c
                for k in range(n):
                    akp, akq = A[k][p], A[k][q]
                    A[k][p] = c * akp - s * akq
                    A[k][q] = s * akp + c * akq
                for k in range(n):
                    apk, aqk = A[p][k], A[q][k]
                    A[p][k] = c * apk - s * aqk
                    A[q][k] = s * apk + c * aqk
                for k in range(n):
                    vkp, vkq = V[k][p], V[k][q]
                    V[k][p] = c * vkp - s * vkq
                    V[k][q] = s * vkp + c * vkq
    return [A[i][i] for i in range(n)], V


class Network:
    """C dx/dt = -(L + diag g) x + F; g includes air, jacket and extra films."""

    def __init__(self):
        n = len(NODES)
        self.n = n
        self.C = [c for _, c, _, _, _ in NODES]
        self.g_air = [g for _, _, g, _, _ in NODES]
        self.area = [a for _, _, _, a, _ in NODES]
        self.Lap = [[0.0] * n for _ in range(n)]
        for a, b, g, _ in LINKS:
            i, j = IDX[a], IDX[b]
            self.Lap[i][i] += g
            self.Lap[j][j] += g
            self.Lap[i][j] -= g
            self.Lap[j][i] -= g
        self.cache = {}

    def step_ops(self, gdiag, dt):
        key = (tuple(round(x, 9) for x in gdiag), dt)
        op = self.cache.get(key)
        if op is not None:
            return op
        n = self.n
        cs = [math.sqrt(c) for c in self.C]
        S = [[(self.Lap[i][j] + (gdiag[i] if i == j else 0.0)) / (cs[i] * cs[j]) for j in range(n)] for i in range(n)]
        lam, U = jacobi_eig(S)
        e = [math.exp(-l * dt) for l in lam]
        w = [(1.0 - e[k]) / lam[k] if lam[k] > 1e-15 else dt for k in range(n)]
        # Phi = C^-1/2 U diag(e) U^T C^1/2 ; Psi = C^-1/2 U diag(w) U^T C^-1/2
        Phi = [[sum(U[i][k] * e[k] * U[j][k] for k in range(n)) * cs[j] / cs[i] for j in range(n)] for i in range(n)]
        Psi = [[sum(U[i][k] * w[k] * U[j][k] for k in range(n)) / (cs[i] * cs[j]) for j in range(n)] for i in range(n)]
        op = [Phi[i] + Psi[i] for i in range(n)]
        if len(self.cache) > 4000:
            self.cache.clear()
        self.cache[key] = op
        return op


# ---------------------------------------------------------------------------
# duties and shop air
# ---------------------------------------------------------------------------

STYLES = {
    "high": [6000, 7000, 8000, 9000, 10000, 11000],
    "mixed": [1500, 2500, 4000, 5500, 7000, 8500, 10000],
    "low": [800, 1200, 2000, 3000, 4000, 5000],
}


def make_duty(rng, style):
    n = int(HOURS * 3600 / DT_SAMPLE) + 1
    rpm = [0.0] * n
    feed = [0.0] * n
    cool = [0] * n
    door = [0] * n            # door open (only the convection effect reads it)
    speeds = STYLES[style]
    feed_mean_base = rng.uniform(0.25, 0.75)
    k = int(rng.uniform(0, 20) * 60 / DT_SAMPLE)      # idle start
    while k < n:
        block = int(rng.uniform(20, 90) * 60 / DT_SAMPLE)
        end = min(n, k + block)
        while k < end:
            op = int(rng.uniform(2, 15) * 60 / DT_SAMPLE)
            if rng.random() < 0.75:          # programmed speeds: a few round values
                s = float(rng.choice(speeds))
            else:                            # an odd one (a special tool)
                s = round(rng.uniform(min(speeds), max(speeds)) / 50.0) * 50.0
            s = min(N_MAX, s)
            fm = min(0.95, max(0.05, feed_mean_base + rng.uniform(-0.25, 0.25)))
            for j in range(k, min(end, k + op)):
                rpm[j] = s
                feed[j] = round(min(1.0, max(0.0, fm + rng.gauss(0, 0.15))), 2)
                cool[j] = 1
            k = min(end, k + op)
            tc = rng.randint(1, 2)                     # tool change: spindle stops
            for j in range(k, min(end, k + tc)):
                rpm[j] = 0.0
                feed[j] = round(rng.uniform(0.3, 1.0), 2)
                cool[j] = 1
            k = min(end, k + tc)
        idle = int(rng.uniform(5, 60) * 60 / DT_SAMPLE)
        if rng.random() < 0.6:
            d = int(rng.uniform(2, 10) * 60 / DT_SAMPLE)
            for j in range(k, min(n, k + min(d, idle))):
                door[j] = 1
        k += idle
    return rpm, feed, cool, door


def make_ambient(rng, n):
    """True shop air at the sample times: base + ramp + part of a day + slow wander."""
    base = rng.uniform(19.0, 22.0)
    rate = rng.uniform(-0.12, 0.2) / 3600.0
    a24 = rng.uniform(0.2, 0.9)
    ph = rng.uniform(0, 2 * math.pi)
    ou = 0.0
    out = []
    tau = 1800.0
    sig = 0.08
    a = math.exp(-DT_SAMPLE / tau)
    for k in range(n):
        t = k * DT_SAMPLE
        out.append(base + rate * t + a24 * (math.sin(2 * math.pi * t / 86400.0 + ph) - math.sin(ph)) + ou)
        ou = a * ou + sig * math.sqrt(1 - a * a) * rng.gauss(0, 1)
    return out


# ---------------------------------------------------------------------------
# effects (own formulations) and their random draws
# ---------------------------------------------------------------------------

HEIGHT_W = {  # share of the air-layer drift each body sees (stratification by height)
    "front_brg": 1.0, "rear_brg": 1.0, "shaft_front": 1.0, "shaft_rear": 1.0, "stator": 1.0,
    "cartridge": 1.0, "head": 1.0, "column_upper": 1.0, "y_screw": 1.0, "column_lower": 0.7,
    "pallet_table": 0.5, "x_screw": 0.4, "z_screw": 0.3, "bed": 0.3,
}
CARRIER = {"x_screw": "pallet_table", "y_screw": "head", "z_screw": "column_lower"}


def draw_effect(rng, kind):
    p = {}
    if kind == "ballscrew":
        p["k_total_w"] = rng.uniform(12.0, 45.0)
        w = {s: rng.uniform(0.5, 1.5) for s in ("x_screw", "y_screw", "z_screw")}
        tot = sum(w.values())
        p["share"] = {s: v / tot for s, v in w.items()}
        p["carrier_frac"] = rng.uniform(0.15, 0.4)
        p["viscous_v"] = rng.uniform(0.0, 0.6)
    elif kind == "bearing_nonlinear":
        p["form"] = rng.choice(["preload", "steep"])
        if p["form"] == "preload":
            p["kp_front_n_per_k"] = rng.uniform(60.0, 220.0)
            p["kp_rear_n_per_k"] = p["kp_front_n_per_k"] * rng.uniform(0.3, 0.8)
        else:
            p["a"] = rng.uniform(2.3, 3.5)
            p["share_front_at_10000"] = rng.uniform(0.15, 0.6)
            p["rear_rel"] = rng.uniform(0.0, 0.6)
    elif kind == "convection":
        p["h_fan"] = rng.uniform(2.5, 9.0)
        p["h_door"] = rng.uniform(0.0, 12.0)
        p["h_wind"] = rng.uniform(0.0, 12.0)
    elif kind == "ambient_drift":
        for r in ("a", "b"):
            p[r] = dict(rate_c_per_h=rng.choice([-1, 1]) * rng.uniform(0.08, 0.3),
                        amp_c=rng.uniform(0.0, 0.5), period_h=rng.uniform(3.0, 12.0),
                        phase=rng.uniform(0, 2 * math.pi))
    elif kind == "sensor_lag":
        p["sensor"] = rng.choice(["front_brg", "rear_brg", "cartridge"])
        p["tau_s"] = rng.uniform(120.0, 900.0)
    elif kind == "sensor_offset":
        p["sensor"] = rng.choice([s for s, _ in SENSORS])
        p["run"] = rng.choice(["a", "b"])
        p["at_s"] = 0.0 if rng.random() < 0.25 else float(round(rng.uniform(1.5, 6.5) * 3600 / DT_SAMPLE) * DT_SAMPLE)
        p["offset_c"] = rng.choice([-1, 1]) * rng.uniform(0.25, 1.0)
    elif kind == "chiller":
        q0 = rng.uniform(150.0, 350.0)          # pump + unit heat into the tank, always
        r = rng.uniform(2.0, 4.0)                # compressor power / base load
        per = rng.uniform(12.0, 38.0) * 60.0     # period at base load
        band = per * q0 * (r - 1.0) / (TANK_C * r)
        band = min(2.0, max(0.3, band))
        p.update(q_base_w=q0, power_w=q0 * r, band_c=band,
                 period_at_base_s=band * TANK_C * (1.0 / q0 + 1.0 / (q0 * (r - 1.0))),
                 ramp_on_s=45.0, ramp_off_s=20.0, min_off_s=180.0)
    return p


# ---------------------------------------------------------------------------
# simulation of one run
# ---------------------------------------------------------------------------

def quant(rng, t):
    return round((t + rng.gauss(0, 0.02)) / 0.0625) * 0.0625


def simulate(net, rng, duty, amb, kind, p, run):
    rpm, feed, cool, door = duty
    n = net.n
    ns = len(rpm)
    dt = DT_SAMPLE / SUB
    # start: equilibrium at rest with the air (and its layer) at t = 0
    x = [amb[0]] * n
    tank = SUPPLY_C
    comp = 0.0          # compressor capacity 0..1
    comp_on = False
    off_since = 0.0
    lag = None
    if kind == "sensor_lag":
        lag = x[IDX[dict(SENSORS)[p["sensor"]]]]
    fi, ri = IDX["front_brg"], IDX["rear_brg"]
    sfi, sri, ci = IDX["shaft_front"], IDX["shaft_rear"], IDX["cartridge"]
    stat = IDX["stator"]
    extra_share_max = 0.0
    rows_T = []
    rows_cool = []
    rows_lag = []
    for k in range(ns):
        rows_T.append(x[:])
        rows_cool.append(tank)
        if lag is not None:
            rows_lag.append(lag)
        if k == ns - 1:
            break
        nrpm, f, flow = rpm[k], feed[k], cool[k]
        a0, a1 = amb[k], amb[k + 1]
        # conductances to sinks
        gdiag = list(net.g_air)
        if flow:
            for nm, g in JACKET:
                gdiag[IDX[nm]] += g
        extra_g = [0.0] * n
        if kind == "convection":
            h = p["h_fan"] + (p["h_door"] if door[k] else 0.0)
            for i in range(n):
                extra_g[i] = h * net.area[i]
            wind = p["h_wind"] * (nrpm / N_MAX) ** 0.8
            for nm in ("cartridge", "head", "shaft_front", "shaft_rear"):
                extra_g[IDX[nm]] += wind * net.area[IDX[nm]]
        gtot = [gdiag[i] + extra_g[i] for i in range(n)]
        op = net.step_ops(gtot, dt)
        # heat (design)
        q = [0.0] * n
        qb = [bearing_q(BEARINGS[0], nrpm), bearing_q(BEARINGS[1], nrpm)]
        q[fi] += qb[0]
        q[ri] += qb[1]
        q[stat] += motor_q(nrpm)
        if kind == "ballscrew" and f > 0:
            v = p["viscous_v"]
            qt = p["k_total_w"] * f * (1.0 + v * f) / (1.0 + v)
            for s, sh in p["share"].items():
                qs = qt * sh
                q[IDX[s]] += qs * (1.0 - p["carrier_frac"])
                q[IDX[CARRIER[s]]] += qs * p["carrier_frac"]
        steep_extra = None
        if kind == "bearing_nonlinear" and p["form"] == "steep" and nrpm > 0:
            k10 = p["share_front_at_10000"] * bearing_q(BEARINGS[0], 10000.0) / (10000.0 / N_MAX) ** p["a"]
            ef = k10 * (nrpm / N_MAX) ** p["a"]
            er = p["rear_rel"] * ef * bearing_q(BEARINGS[1], 10000.0) / bearing_q(BEARINGS[0], 10000.0)
            steep_extra = (ef, er)
            q[fi] += ef
            q[ri] += er
            if qb[0] > 0:
                extra_share_max = max(extra_share_max, ef / qb[0])
        for sub in range(SUB):
            frac = (sub + 0.5) / SUB
            ta = a0 + (a1 - a0) * frac
            t_s = (k + frac) * DT_SAMPLE
            sink = [ta] * n
            if kind == "ambient_drift":
                d = p[run]
                th = t_s / 3600.0
                delta = d["rate_c_per_h"] * th + d["amp_c"] * (
                    math.sin(2 * math.pi * th / d["period_h"] + d["phase"]) - math.sin(d["phase"]))
                sink = [ta + HEIGHT_W[NAMES[i]] * delta for i in range(n)]
            coolant_t = tank if kind == "chiller" else SUPPLY_C
            qq = q
            if kind == "bearing_nonlinear" and p["form"] == "preload" and nrpm > 0:
                qq = q[:]
                dtf = max(0.0, x[sfi] - x[ci])
                dtr = max(0.0, x[sri] - x[ci])
                bf, br = BEARINGS
                ef = 1.047e-4 * nrpm * bf["f1"] * p["kp_front_n_per_k"] * dtf * bf["dm_mm"]
                er = 1.047e-4 * nrpm * br["f1"] * p["kp_rear_n_per_k"] * dtr * br["dm_mm"]
                qq[fi] += ef
                qq[ri] += er
                if qb[0] > 0:
                    extra_share_max = max(extra_share_max, ef / qb[0])
            F = [qq[i] + net.g_air[i] * sink[i] + extra_g[i] * sink[i] for i in range(n)]
            if flow:
                for nm, g in JACKET:
                    F[IDX[nm]] += g * coolant_t
            v = x + F
            xn = [sum(a * b for a, b in zip(row, v)) for row in op]
            if kind == "chiller":
                qj = 0.0
                if flow:
                    for nm, g in JACKET:
                        qj += g * (x[IDX[nm]] - tank)
                if comp_on and tank < SUPPLY_C - p["band_c"] / 2:
                    comp_on = False
                    off_since = t_s
                elif (not comp_on) and tank > SUPPLY_C + p["band_c"] / 2 and t_s - off_since >= p["min_off_s"]:
                    comp_on = True
                tgt = 1.0 if comp_on else 0.0
                tau = p["ramp_on_s"] if comp_on else p["ramp_off_s"]
                comp += (tgt - comp) * (1.0 - math.exp(-dt / tau))
                dq = p["q_base_w"] + qj + TANK_G * (ta - tank) - p["power_w"] * comp
                tank += dt * dq / TANK_C
            if lag is not None:
                node_t = x[IDX[dict(SENSORS)[p["sensor"]]]]
                lag += (node_t - lag) * (1.0 - math.exp(-dt / p["tau_s"]))
            x = xn
    return rows_T, rows_cool, rows_lag, extra_share_max


def write_run(path, rng, machine_name, run_id, duty, amb, sim, kind, p, run):
    rows_T, rows_cool, rows_lag, _ = sim
    rpm, feed, cool, _door = duty
    ns = len(rpm)
    cols = ["time_s", "spindle_rpm", "feed_activity", "coolant_on"]
    cols += ["T_" + s for s, _ in SENSORS] + ["T_ambient"] + ["d%s_um" % d for d, _ in DIRECTIONS]
    T0 = rows_T[0]
    e0 = None
    lines = ["# machine: %s" % machine_name, "# run: %s" % run_id,
             "# ambient: shop air, measured by T_ambient", "# source: simulated",
             "# sample_period_s: %d" % DT_SAMPLE, ",".join(cols)]
    for k in range(ns):
        T = rows_T[k]
        vals = ["%d" % (k * DT_SAMPLE), "%g" % rpm[k], "%.2f" % feed[k], "%d" % cool[k]]
        for s, node in SENSORS:
            if node == "coolant":
                t = rows_cool[k]
            else:
                t = T[IDX[node]]
            if kind == "sensor_lag" and s == p["sensor"]:
                t = rows_lag[k]
            if kind == "sensor_offset" and s == p["sensor"] and run == p["run"] and k * DT_SAMPLE >= p["at_s"]:
                t += p["offset_c"]
            vals.append("%.4f" % quant(rng, t))
        vals.append("%.4f" % quant(rng, amb[k]))
        e = [rng.gauss(0, 0.2) for _ in DIRECTIONS]
        if e0 is None:
            e0 = e
        for di, (d, terms) in enumerate(DIRECTIONS):
            dv = sum(ALPHA * l * 1000.0 * (T[IDX[nm]] - T0[IDX[nm]]) for nm, l in terms)
            vals.append("%.2f" % (dv + e[di] - e0[di]))
        lines.append(",".join(vals))
    with open(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")


def make_case(out, seed, i, net):
    rng = random.Random(seed * 1000003 + i * 7919 + 17)
    clean = rng.random() < 1.0 / 6.0
    kind = None if clean else rng.choice(EFFECT_KINDS)
    p = draw_effect(rng, kind) if kind else {}
    styles = ["high", "mixed", "low"]
    sa = rng.choice(styles)
    sb = rng.choice([s for s in styles if s != sa])
    d = os.path.join(out, "case_%03d" % i)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, "machine.toml"), "w") as fh:
        fh.write(machine_toml())
    info = {}
    for run, style in (("a", sa), ("b", sb)):
        duty = make_duty(rng, style)
        amb = make_ambient(rng, len(duty[0]))
        sim = simulate(net, rng, duty, amb, kind, p, run)
        write_run(os.path.join(d, "run_%s.csv" % run), rng, "hmc-500-travelling-column",
                  "case%03d-%s-%s" % (i, run, style), duty, amb, sim, kind, p, run)
        rpm = duty[0]
        info[run] = dict(style=style, max_rpm=max(rpm), mean_rpm=sum(rpm) / len(rpm),
                         mean_feed=sum(duty[1]) / len(rpm))
        if kind == "bearing_nonlinear":
            info[run]["extra_heat_share_front_max"] = sim[3]
        if kind == "chiller":
            ct = sim[1]
            info[run]["coolant_min_c"] = min(ct)
            info[run]["coolant_max_c"] = max(ct)
    truth = {
        "effect": kind if kind else "none",
        "accept": ACCEPT[kind] if kind else [],
        "accept_parameters": ACCEPT_PARAMETERS.get(kind, []) if kind else [],
        "sensor": ("T_" + p["sensor"]) if kind in ("sensor_lag", "sensor_offset") else None,
        "params": p,
        "clean": clean,
        "runs": info,
    }
    with open(os.path.join(d, "truth.json"), "w") as fh:
        json.dump(truth, fh, indent=1, sort_keys=True)
    return truth


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--cases", type=int, default=60)
    ap.add_argument("--first", type=int, default=0, help="first case index (default 0)")
    a = ap.parse_args()
    net = Network()
    os.makedirs(a.out, exist_ok=True)
    for i in range(a.first, a.first + a.cases):
        t = make_case(a.out, a.seed, i, net)
        print("case_%03d %s" % (i, t["effect"]), flush=True)


if __name__ == "__main__":
    main()
