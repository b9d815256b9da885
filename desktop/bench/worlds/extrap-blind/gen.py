#!/usr/bin/env python3
"""extrap-blind world generator (issue 50): thermal models served outside
their training envelope.

Each case is one long run of a machining centre with a motorized spindle,
simulated by a lumped thermal network of its own formulation (see README.md),
16 DS18B20-like sensors (1/16 degC steps), two displacement channels
(dz_um, dx_um) with probe noise. The first 60 % of the rows are the training
part, the rest the served part. Some cases push the served part beyond the
training envelope (ambient +/-0.5..2 K, a spindle speed never seen in
training, or both); the controls keep it inside.

Python 3.11 standard library only.

    python3 gen.py --out DIR --seed N --cases K
"""

import argparse
import json
import math
import os
import random

KINDS = ["ambient_hot", "control", "speed_new", "ambient_cold", "control", "both"]
ALPHA = 11.5  # steel, um per metre per kelvin
SPLIT = 0.6
SUB_DT = 10.0  # integration step, s

# node order of the lumped network
NODES = ["bf", "br", "hs", "mo", "cf", "cb", "bed", "tab", "cool", "floor"]
IDX = {n: i for i, n in enumerate(NODES)}

# base capacities, J/K (each case scales them by 0.7..1.4)
CAP = {
    "bf": 25e3,  # front bearing with its share of shaft and sleeve
    "br": 20e3,  # rear bearing
    "hs": 160e3,  # spindle housing / headstock
    "mo": 40e3,  # built-in motor (stator + rotor)
    "cf": 700e3,  # column, front half (headstock side)
    "cb": 700e3,  # column, back half
    "bed": 2.2e6,  # bed
    "tab": 350e3,  # worktable with fixture and workpiece
    "cool": 400e3,  # coolant tank and circuit
    "floor": 1.0e8,  # foundation slab
}

# base conductances, W/K: (a, b, G, only while the coolant pump runs)
LINKS = [
    ("bf", "hs", 18.0, False),
    ("bf", "air", 2.0, False),
    ("br", "hs", 15.0, False),
    ("br", "air", 2.0, False),
    ("mo", "hs", 12.0, False),
    ("mo", "cool", 35.0, True),  # motor cooling jacket
    ("hs", "cool", 20.0, True),  # housing jacket
    ("hs", "air", 8.0, False),
    ("hs", "cf", 9.0, False),
    ("cf", "cb", 25.0, False),
    ("cf", "air", 14.0, False),
    ("cb", "air", 18.0, False),
    ("cf", "bed", 12.0, False),
    ("cb", "bed", 12.0, False),
    ("bed", "air", 25.0, False),
    ("bed", "floor", 45.0, False),
    ("bed", "tab", 7.0, False),
    ("tab", "air", 22.0, False),
    ("tab", "cool", 10.0, True),  # flood coolant washing the table
    ("cool", "air", 15.0, False),
    ("floor", "air", 1000.0, False),
]

# sensors: name -> list of (source, weight); source "air" is the ambient,
# "air_lag" the ambient through a 20-min first-order lag
SENSORS = [
    ("T_sp_front1", [("bf", 0.85), ("hs", 0.15)]),
    ("T_sp_front2", [("bf", 0.6), ("hs", 0.4)]),
    ("T_sp_rear1", [("br", 0.8), ("hs", 0.2)]),
    ("T_sp_motor", [("mo", 0.5), ("hs", 0.5)]),
    ("T_head1", [("hs", 1.0)]),
    ("T_head2", [("hs", 0.7), ("cf", 0.3)]),
    ("T_col_front", [("cf", 1.0)]),
    ("T_col_back", [("cb", 1.0)]),
    ("T_col_mid", [("cf", 0.5), ("cb", 0.5)]),
    ("T_bed1", [("bed", 1.0)]),
    ("T_bed2", [("bed", 0.7), ("cool", 0.3)]),
    ("T_table1", [("tab", 1.0)]),
    ("T_table2", [("tab", 0.8), ("air", 0.2)]),
    ("T_coolant", [("cool", 1.0)]),
    ("T_ambient", [("air", 1.0)]),
    ("T_air_floor", [("air_lag", 0.7), ("floor", 0.3)]),
]

GROUPS = {
    "spindle": ["T_sp_front1", "T_sp_front2", "T_sp_rear1", "T_sp_motor"],
    "head": ["T_head1", "T_head2"],
    "column": ["T_col_front", "T_col_back", "T_col_mid"],
    "bed": ["T_bed1", "T_bed2"],
    "table": ["T_table1", "T_table2"],
    "coolant": ["T_coolant"],
    "ambient": ["T_ambient", "T_air_floor"],
}


def smoothstep(x):
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    return x * x * (3.0 - 2.0 * x)


def draw_params(rng, kind):
    """Everything random about one machine and one run."""
    p = {"kind": kind}
    if kind in ("ambient_hot", "ambient_cold") and rng.random() < 0.25:
        p["period_s"] = 10.0
        p["hours"] = round(rng.uniform(30.0, 36.0) * 2) / 2
    else:
        p["period_s"] = 60.0
        p["hours"] = round(rng.uniform(42.0, 80.0) * 2) / 2
    p["t0"] = rng.uniform(18.0, 24.0)
    p["day_amp"] = rng.uniform(0.3, 1.5)
    p["day_peak_h"] = rng.uniform(14.0, 17.0)
    p["start_clock_h"] = rng.uniform(0.0, 24.0)
    p["ou_sigma"] = rng.uniform(0.04, 0.12)
    p["ou_tau_s"] = rng.uniform(1200.0, 3600.0)
    p["night_off"] = rng.random() < 0.5
    p["cap"] = {n: CAP[n] * rng.uniform(0.7, 1.4) for n in NODES}
    p["links"] = [[a, b, g * rng.uniform(0.7, 1.4), c] for a, b, g, c in LINKS]
    p["chiller_g"] = rng.uniform(150.0, 350.0)
    p["chiller_offset"] = rng.uniform(-1.0, 1.0)
    p["nmax"] = round(rng.uniform(8000.0, 15000.0), -2)
    p["q_front"] = rng.uniform(120.0, 260.0)
    p["q_rear"] = p["q_front"] * rng.uniform(0.4, 0.7)
    p["bearing_exp"] = rng.uniform(1.3, 1.9)
    p["q_motor"] = rng.uniform(150.0, 350.0)
    p["motor_exp"] = rng.uniform(1.0, 1.4)
    p["q_idle"] = rng.uniform(10.0, 30.0)
    p["q_feed"] = rng.uniform(10.0, 30.0)
    fracs = sorted(rng.sample([0.15, 0.25, 0.35, 0.45, 0.55, 0.65], rng.choice([3, 4])))
    p["train_speeds"] = [round(f * p["nmax"], -2) for f in fracs]
    p["new_speed"] = None
    if kind in ("speed_new", "both"):
        p["new_speed"] = min(p["nmax"], round(rng.uniform(1.2, 1.45) * max(p["train_speeds"]), -2))
    p["amb_step"] = 0.0
    if kind in ("ambient_hot", "both"):
        p["amb_step"] = rng.uniform(0.5, 2.0)
    elif kind == "ambient_cold":
        p["amb_step"] = -rng.uniform(0.5, 2.0)
    p["amb_ramp_h"] = rng.uniform(2.0, 8.0)
    p["amb_start_frac"] = rng.uniform(0.0, 0.25)
    p["geom"] = {
        "col_height_m": rng.uniform(0.5, 0.9),
        "col_depth_m": rng.uniform(0.4, 0.7),
        "sp_front_m": rng.uniform(0.03, 0.08),
        "sp_housing_m": rng.uniform(0.10, 0.25),
        "sp_motor_m": rng.uniform(0.03, 0.10),
        "table_height_m": rng.uniform(0.08, 0.20),
        "head_x_m": rng.uniform(0.02, 0.08) * rng.choice([-1.0, 1.0]),
        "table_x_m": rng.uniform(0.10, 0.30) * rng.choice([-1.0, 1.0]),
        "bend_sign": rng.choice([-1.0, 1.0]),
    }
    p["noise_um"] = rng.uniform(0.15, 0.35)
    p["drift_noise_um"] = rng.uniform(0.05, 0.2)
    p["sensor_offset"] = {name: rng.uniform(-0.3, 0.3) for name, _ in SENSORS}
    p["sensor_noise"] = rng.uniform(0.01, 0.025)
    return p


def segments(rng, speeds, t_from, t_to, p, new_share=0.0):
    """Spindle programme: steps of 20 min .. 4 h; None marks the new speed."""
    out = []
    t = t_from
    bag = []
    while t < t_to:
        if not bag:
            bag = list(speeds) + [0.0]
            rng.shuffle(bag)
        if p["new_speed"] is not None and rng.random() < new_share:
            n = p["new_speed"]
        else:
            n = bag.pop()
        dur = round(rng.uniform(20.0, 240.0)) * 60.0
        end = min(t + dur, t_to)
        out.append((t, end, n, rng.uniform(0.3, 0.8)))
        t = end
    return out


def programme(rng, p, t_split, t_end):
    train = segments(rng, p["train_speeds"], 0.0, t_split, p)
    share = 0.45 if p["new_speed"] is not None else 0.0
    served = segments(rng, p["train_speeds"], t_split, t_end, p, share)
    if p["new_speed"] is not None and all(s[2] != p["new_speed"] for s in served):
        a, b, _, f = served[0]
        served[0] = (a, b, p["new_speed"], f)
    return train + served


def speed_at(prog, t, p):
    """Commanded speed and feed activity at time t (night shutdown applied)."""
    if p["night_off"]:
        clock = (p["start_clock_h"] + t / 3600.0) % 24.0
        if clock >= 22.0 or clock < 6.0:
            return 0.0, 0.0
    for a, b, n, f in prog:
        if a <= t < b:
            return n, (f if n > 0 else 0.0)
    return 0.0, 0.0


def ambient_base(p, t):
    clock = p["start_clock_h"] + t / 3600.0
    return p["t0"] + p["day_amp"] * math.cos(2.0 * math.pi * (clock - p["day_peak_h"]) / 24.0)


def ambient_extra(p, t, t_split, t_end):
    if p["amb_step"] == 0.0:
        return 0.0
    start = t_split + p["amb_start_frac"] * (t_end - t_split)
    return p["amb_step"] * smoothstep((t - start) / (p["amb_ramp_h"] * 3600.0))


def heat(p, n, feed):
    x = n / p["nmax"]
    q = [0.0] * len(NODES)
    q[IDX["bf"]] = p["q_front"] * x ** p["bearing_exp"]
    q[IDX["br"]] = p["q_rear"] * x ** p["bearing_exp"]
    q[IDX["mo"]] = p["q_motor"] * x ** p["motor_exp"] + (p["q_idle"] if n > 0 else 0.0)
    q[IDX["tab"]] = p["q_feed"] * feed
    return q


def step(p, T, air, n, feed, coolant, dt):
    """One explicit Euler step of the network (dt far below every time constant)."""
    flow = heat(p, n, feed)
    for a, b, g, needs_pump in p["links"]:
        if needs_pump and not coolant:
            continue
        ta = T[IDX[a]]
        tb = air if b == "air" else T[IDX[b]]
        w = g * (tb - ta)
        flow[IDX[a]] += w
        if b != "air":
            flow[IDX[b]] -= w
    if coolant:
        flow[IDX["cool"]] += p["chiller_g"] * (air + p["chiller_offset"] - T[IDX["cool"]])
    return [T[i] + dt * flow[i] / p["cap"][NODES[i]] for i in range(len(NODES))]


def displacement(p, T):
    """Tool relative to workpiece, um, absolute (the run makes it relative)."""
    g = p["geom"]
    col = 0.5 * (T[IDX["cf"]] + T[IDX["cb"]])
    spindle = g["sp_front_m"] * T[IDX["bf"]] + g["sp_housing_m"] * T[IDX["hs"]]
    spindle += g["sp_motor_m"] * T[IDX["mo"]]
    dz = ALPHA * (g["col_height_m"] * col - spindle - g["table_height_m"] * T[IDX["tab"]])
    bend = ALPHA * g["col_height_m"] ** 2 / (2.0 * g["col_depth_m"]) * g["bend_sign"]
    dx = bend * (T[IDX["cf"]] - T[IDX["cb"]])
    dx += ALPHA * (g["head_x_m"] * T[IDX["hs"]] + g["table_x_m"] * T[IDX["tab"]])
    return dz, dx


def sensor_values(p, T, air, air_lag, rng):
    out = []
    for name, mix in SENSORS:
        v = p["sensor_offset"][name] + rng.gauss(0.0, p["sensor_noise"])
        for src, w in mix:
            if src == "air":
                v += w * air
            elif src == "air_lag":
                v += w * air_lag
            else:
                v += w * T[IDX[src]]
        out.append(round(v * 16.0) / 16.0)
    return out


def simulate(p, rng):
    """Rows of (time, rpm, feed, coolant, temps, dz, dx) and the split row."""
    period = p["period_s"]
    rows_n = int(round(p["hours"] * 3600.0 / period)) + 1
    t_end = (rows_n - 1) * period
    split_row = int(math.floor(SPLIT * rows_n))
    t_split = split_row * period
    prog = programme(rng, p, t_split, t_end + period)
    T = [p["t0"]] * len(NODES)
    T[IDX["floor"]] = p["t0"] - 0.5
    ou = 0.0
    a_ou = math.exp(-SUB_DT / p["ou_tau_s"])
    s_ou = p["ou_sigma"] * math.sqrt(1.0 - a_ou * a_ou)
    a_lag = math.exp(-SUB_DT / 1200.0)
    air_lag = p["t0"]
    t = -24.0 * 3600.0  # a cold, idle day before the run
    while t < 0.0:
        ou = a_ou * ou + s_ou * rng.gauss(0.0, 1.0)
        air = ambient_base(p, t) + ou
        air_lag = a_lag * air_lag + (1.0 - a_lag) * air
        T = step(p, T, air, 0.0, 0.0, False, SUB_DT)
        t += SUB_DT
    sub = max(1, int(round(period / SUB_DT)))
    dt = period / sub
    a_dn = math.exp(-period / 900.0)
    drift = 0.0
    rows = []
    last_on = -1e9
    ref = None
    for i in range(rows_n):
        t = i * period
        n, feed = speed_at(prog, t, p)
        if n > 0:
            last_on = t
        coolant = n > 0 or t - last_on < 600.0
        air = ambient_base(p, t) + ou + ambient_extra(p, t, t_split, t_end)
        temps = sensor_values(p, T, air, air_lag, rng)
        dz, dx = displacement(p, T)
        if ref is None:
            ref = (dz, dx)
        drift = a_dn * drift + p["drift_noise_um"] * math.sqrt(1 - a_dn * a_dn) * rng.gauss(0, 1)
        mz = dz - ref[0] + rng.gauss(0.0, p["noise_um"]) + drift
        mx = dx - ref[1] + rng.gauss(0.0, p["noise_um"]) - drift
        rows.append((t, n, feed, 1 if coolant else 0, temps, mz, mx))
        for _ in range(sub):
            ou = a_ou * ou + s_ou * rng.gauss(0.0, 1.0)
            tt = t + _ * dt
            air = ambient_base(p, tt) + ou + ambient_extra(p, tt, t_split, t_end)
            air_lag = a_lag * air_lag + (1.0 - a_lag) * air
            T = step(p, T, air, n, feed, coolant, dt)
    return rows, split_row


def envelope(rows, split_row):
    """Per sensor: how far the served part goes beyond the training range, K."""
    out = {}
    for j, (name, _) in enumerate(SENSORS):
        tr = [r[4][j] for r in rows[:split_row]]
        sv = [r[4][j] for r in rows[split_row:]]
        hi = max(sv) - max(tr)
        lo = min(tr) - min(sv)
        out[name] = {
            "train_min": min(tr),
            "train_max": max(tr),
            "served_min": min(sv),
            "served_max": max(sv),
            "beyond_k": round(max(hi, lo, 0.0), 4),
        }
    return out


def group_beyond(env):
    return {g: max(env[s]["beyond_k"] for s in names) for g, names in GROUPS.items()}


def write_run(path, case_id, p, rows):
    names = [s for s, _ in SENSORS]
    with open(path, "w", encoding="utf-8") as f:
        f.write("# machine: extrap-blind-%s\n" % case_id)
        f.write("# run: %s\n" % case_id)
        f.write("# source: simulated\n")
        f.write("# sample_period_s: %g\n" % p["period_s"])
        cols = ["time_s", "spindle_rpm", "feed_activity", "coolant_on"] + names
        f.write(",".join(cols + ["dz_um", "dx_um"]) + "\n")
        for t, n, feed, cool, temps, mz, mx in rows:
            vals = ["%g" % t, "%d" % n, "%.2f" % feed, "%d" % cool]
            vals += ["%.4f" % v for v in temps]
            vals += ["%.2f" % mz, "%.2f" % mx]
            f.write(",".join(vals) + "\n")


def control_inside(env):
    return all(e["beyond_k"] <= 0.15 for e in env.values())


def make_case(seed, i):
    kind = KINDS[i % len(KINDS)]
    tries = 0
    while True:
        rng = random.Random((seed * 1000003 + i) * 101 + tries)
        p = draw_params(rng, kind)
        rows, split_row = simulate(p, rng)
        env = envelope(rows, split_row)
        tries += 1
        if kind != "control" or control_inside(env) or tries >= 30:
            return p, rows, split_row, env, tries


def truth(case_id, seed, p, rows, split_row, env, tries):
    served_speeds = sorted({r[1] for r in rows[split_row:] if r[1] > 0})
    train_speeds = sorted({r[1] for r in rows[:split_row] if r[1] > 0})
    gb = group_beyond(env)
    beyond = p["kind"] != "control"
    return {
        "case": case_id,
        "seed": seed,
        "kind": p["kind"],
        "beyond_by_design": beyond,
        "control_inside_checked": (p["kind"] == "control" and control_inside(env)),
        "draws": tries,
        "rows": len(rows),
        "period_s": p["period_s"],
        "train_rows": [0, split_row],
        "served_rows": [split_row, len(rows)],
        "split_time_s": rows[split_row][0],
        "train_speeds_rpm": train_speeds,
        "served_speeds_rpm": served_speeds,
        "new_speed_rpm": p["new_speed"],
        "ambient_step_k": round(p["amb_step"], 3),
        "group_beyond_k": gb,
        "sensor_envelope": env,
        "channels": ["dz_um", "dx_um"],
        "params": p,
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--cases", type=int, default=10)
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    index = []
    for i in range(a.cases):
        case_id = "case_%03d" % i
        d = os.path.join(a.out, case_id)
        os.makedirs(d, exist_ok=True)
        p, rows, split_row, env, tries = make_case(a.seed, i)
        write_run(os.path.join(d, "run.csv"), case_id, p, rows)
        t = truth(case_id, a.seed, p, rows, split_row, env, tries)
        with open(os.path.join(d, "truth.json"), "w", encoding="utf-8") as f:
            json.dump(t, f, indent=1, sort_keys=True)
        gb = t["group_beyond_k"]
        print(
            "%s %-12s %5.1f h %3.0f s rows %5d split %5d  beyond K: ambient %.2f table %.2f spindle %.2f"
            % (case_id, p["kind"], p["hours"], p["period_s"], len(rows), split_row,
               gb["ambient"], gb["table"], gb["spindle"])
        )
        index.append({"case": case_id, "kind": p["kind"], "beyond_by_design": t["beyond_by_design"]})
    with open(os.path.join(a.out, "cases.json"), "w", encoding="utf-8") as f:
        json.dump({"seed": a.seed, "cases": index}, f, indent=1)


if __name__ == "__main__":
    main()
