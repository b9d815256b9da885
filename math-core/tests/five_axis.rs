//! The five-axis section (image format v2, kind 4): round trip, every
//! refusal typed, the integer evaluation against the same first-order
//! formula in f64 with the same integer coefficients, bit-identity with the
//! kind-3 section when the rotary errors are zero at A = C = 0, and the
//! overflow bound at the extremes (tests run with overflow checks on).
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::cast_possible_truncation,
    reason = "tests: a panic is a failed test"
)]
#![allow(clippy::needless_range_loop)]
use proptest::prelude::*;
use thermocomp_core::five_axis::*;
use thermocomp_core::float::demo_model;
use thermocomp_core::image::*;
use thermocomp_core::volumetric::*;

fn sensor(channel: u8, ref_temp: i32, min: i16, max: i16) -> VolSensor {
    VolSensor {
        sensor: SensorRef {
            rom: [0; 8],
            channel,
            ref_temp,
        },
        min,
        max,
    }
}

fn vol_with(origin: [i32; 3], stroke: [i32; 3], coef: i32) -> Volumetric {
    let sensors = [
        sensor(0, 20 * 16, -10 * 16, 60 * 16),
        sensor(3, 22 * 16, 0, 50 * 16),
    ];
    let terms = [
        VolTerm {
            exps: [0, 0, 0, 0],
            sensor: NONE,
            coef: [coef, -coef, coef / 5],
        },
        VolTerm {
            exps: [1, 0, 1, 1],
            sensor: NONE,
            coef: [coef / 2, coef, -coef],
        },
        VolTerm {
            exps: [0, 1, 0, 0],
            sensor: 1,
            coef: [coef / 7, coef / 3, coef / 9],
        },
    ];
    Volumetric::new(&VolumetricSpec {
        slots: [0, 1, 2],
        origin_um: origin,
        stroke_um: stroke,
        tool_max_um: 500_000,
        max_correction: [100_000; 3],
        sensors: &sensors,
        terms: &terms,
    })
    .unwrap()
}

fn vol() -> Volumetric {
    vol_with([0, 0, -400_000], [800_000, 500_000, 400_000], 3_000_000)
}

/// A section with every kind of error (two temperature columns, order 2).
fn spec() -> FiveAxisSpec {
    let mut s = FiveAxisSpec {
        pivot_a_um: [400_000, 250_000, -150_000],
        offset_c_um: [0, 0, 120_000],
        a_range_mdeg: [-120_000, 120_000],
        c_range_mdeg: [-360_000, 360_000],
        max_correction: [5_000; 3],
        n_sensors: 2,
        order: 2,
        ..FiveAxisSpec::default()
    };
    // XOC 10 µm, YOC −6 µm, AOC 20 µrad, BOC −15 µrad, YOA 4 µm, ZOA −8 µm,
    // BOA 12 µrad, COA −9 µrad; per kelvin 0.3 µm or 1 µrad on sensor 0.
    let loc = [
        10_000_000,
        -6_000_000,
        20_000_000,
        -15_000_000,
        4_000_000,
        -8_000_000,
        12_000_000,
        -9_000_000,
    ];
    for (e, &c) in loc.iter().enumerate() {
        s.location[e][0] = c;
        s.location[e][1] = if e % 4 < 2 { 300_000 } else { 1_000_000 };
        s.location[e][2] = -(e as i32) * 50_000;
    }
    for axis in 0..2 {
        for e in 0..6 {
            let size = if e < 3 { 3_000_000 } else { 8_000_000 };
            s.motion[axis][e][0] = [size / (e as i32 + 1), -size / 2];
            s.motion[axis][e][1] = [size / 5, size / (axis as i32 + 3)];
        }
    }
    s
}

fn model_with(v: Option<Volumetric>, f: Option<FiveAxis>) -> (Model, Vec<u8>) {
    let mut m = demo_model(7).quantize().unwrap().0;
    m.volumetric = v;
    m.five_axis = f;
    let mut buf = vec![0u8; m.encoded_len()];
    let n = m.encode(&mut buf).unwrap();
    assert_eq!(n, buf.len());
    (m, buf)
}

#[test]
fn round_trip_and_layout() {
    let f = FiveAxis::new(&spec()).unwrap();
    assert_eq!(f.encoded_len(), 56 + 32 * 3 + 96 * 2);
    let (m, buf) = model_with(Some(vol()), Some(f.clone()));
    let back = Model::parse(&buf).unwrap();
    assert_eq!(back.five_axis.as_ref(), Some(&f));
    assert_eq!(back.volumetric, m.volumetric);
    // Without the section the image is the kind-3 image, byte for byte.
    let (_, without) = model_with(Some(vol()), None);
    assert_eq!(buf.len(), without.len() + 4 + f.encoded_len());
}

/// Re-seal an image after editing its body (the CRC and nothing else).
fn reseal(buf: &mut [u8]) {
    let n = buf.len() - 4;
    let crc = crc32(&buf[..n]);
    buf[n..].copy_from_slice(&crc.to_le_bytes());
}

#[test]
fn every_refusal_is_typed() {
    let f = FiveAxis::new(&spec()).unwrap();
    // Kind 4 without kind 3.
    let (_, buf) = model_with(None, Some(f.clone()));
    assert_eq!(
        Model::parse(&buf).unwrap_err(),
        ImageError::FiveAxisWithoutVolumetric
    );
    // More temperature columns than kind 3 has sensors.
    let mut s3 = spec();
    s3.n_sensors = 3;
    let f3 = FiveAxis::new(&s3).unwrap();
    let (_, buf) = model_with(Some(vol()), Some(f3));
    assert_eq!(
        Model::parse(&buf).unwrap_err(),
        ImageError::FiveAxisSensors {
            count: 3,
            available: 2
        }
    );
    // Kind-3 positions beyond ±2^28 µm.
    let far = vol_with([-300_000_000, 0, 0], [800_000, 500_000, 400_000], 1000);
    let (_, buf) = model_with(Some(far), Some(f.clone()));
    assert_eq!(
        Model::parse(&buf).unwrap_err(),
        ImageError::FiveAxisGeometry
    );
    // Spec-level refusals.
    let bad = |edit: &dyn Fn(&mut FiveAxisSpec)| {
        let mut s = spec();
        edit(&mut s);
        FiveAxis::new(&s).unwrap_err()
    };
    assert_eq!(
        bad(&|s| s.order = 5),
        ImageError::FiveAxisOrder { order: 5 }
    );
    assert_eq!(
        bad(&|s| s.pivot_a_um[1] = (1 << 27) + 1),
        ImageError::FiveAxisGeometry
    );
    assert_eq!(
        bad(&|s| s.offset_c_um[2] = i32::MIN),
        ImageError::FiveAxisGeometry
    );
    assert_eq!(
        bad(&|s| s.a_range_mdeg = [10, 10]),
        ImageError::FiveAxisAngleRange { axis: 0 }
    );
    assert_eq!(
        bad(&|s| s.c_range_mdeg = [0, 720_001]),
        ImageError::FiveAxisAngleRange { axis: 1 }
    );
    assert_eq!(
        bad(&|s| s.max_correction[2] = 0),
        ImageError::FiveAxisMaxCorrection {
            direction: 2,
            value: 0
        }
    );
    // 1 mm at 180 K of rise: 10⁹ − 180 · 5,555,556 < 0 → over.
    assert_eq!(
        bad(&|s| s.location[3] = [0, 5_555_556, 0, 0, 0]),
        ImageError::FiveAxisErrorTooLarge { error: 3 }
    );
    // Exactly at the bound is accepted.
    let mut ok = spec();
    ok.location[3] = [1_000_000_000 - 180 * 5_555_555, 5_555_555, 0, 0, 0];
    FiveAxis::new(&ok).unwrap();
    assert_eq!(
        bad(&|s| s.location[0][4] = 1),
        ImageError::FiveAxisErrorTooLarge { error: 0 },
        "an unused temperature column must be zero"
    );
    assert_eq!(
        bad(&|s| s.motion[1][5][0] = [400_000_001, 200_000_000]),
        ImageError::FiveAxisErrorTooLarge { error: 8 + 6 + 5 }
    );
    assert_eq!(
        bad(&|s| s.motion[0][2][3] = [1, 0]),
        ImageError::FiveAxisErrorTooLarge { error: 8 + 2 },
        "a term beyond the order must be zero"
    );
    let msg = ImageError::FiveAxisErrorTooLarge { error: 8 + 6 + 5 }.to_string();
    assert!(msg.contains("ECC"), "{msg}");
    // Byte-level: padding, truncation.
    let (_, good) = model_with(Some(vol()), Some(f.clone()));
    let at = good.len() - 4 - f.encoded_len();
    let mut b = good.clone();
    b[at + 3] = 1; // byte 2 is the flags byte (the_flags_byte)
    reseal(&mut b);
    assert_eq!(
        Model::parse(&b).unwrap_err(),
        ImageError::BadValue {
            what: "five-axis section padding"
        }
    );
    let mut b = good.clone();
    b[at + 1] = 1; // order 1: the payload is longer than it says
    reseal(&mut b);
    assert_eq!(
        Model::parse(&b).unwrap_err(),
        ImageError::SectionLength { kind: 4 }
    );
    let mut b = good.clone();
    b[at + 1] = 9;
    reseal(&mut b);
    assert_eq!(
        Model::parse(&b).unwrap_err(),
        ImageError::FiveAxisOrder { order: 9 }
    );
}

/// The first-order formula of the module docs in f64 with the same integer
/// coefficients, 0.1 µm, before the clamp: the rotary part and the total.
fn f64_eval(
    v: &Volumetric,
    f: &FiveAxis,
    pos: [i32; 3],
    tool: i32,
    ang: [i32; 2],
    temps: &[i32],
) -> ([f64; 3], [f64; 3]) {
    let rises: Vec<f64> = v
        .sensors
        .iter()
        .zip(temps)
        .map(|(s, &t)| {
            f64::from(t.clamp(i32::from(s.min), i32::from(s.max)) - s.sensor.ref_temp) / 16.0
        })
        .collect();
    let a = f64::from(ang[0].clamp(f.a_range_mdeg[0], f.a_range_mdeg[1])) / 1000.0;
    let c = f64::from(ang[1].clamp(f.c_range_mdeg[0], f.c_range_mdeg[1])) / 1000.0;
    let (sa, ca) = a.to_radians().sin_cos();
    let (sc, cc) = c.to_radians().sin_cos();
    let rx = [[1.0, 0.0, 0.0], [0.0, ca, -sa], [0.0, sa, ca]];
    let rz = [[cc, -sc, 0.0], [sc, cc, 0.0], [0.0, 0.0, 1.0]];
    let mul = |a: &[[f64; 3]; 3], b: &[f64; 3]| -> [f64; 3] {
        [0, 1, 2].map(|i| (0..3).map(|j| a[i][j] * b[j]).sum())
    };
    let mut rxz = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            rxz[i][j] = (0..3).map(|k| rx[i][k] * rz[k][j]).sum();
        }
    }
    let id = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    // Location values in µm / rad.
    let loc: Vec<f64> = (0..8)
        .map(|e| {
            let row = f.location[e];
            let v = f64::from(row[0])
                + (0..usize::from(f.n_sensors))
                    .map(|i| f64::from(row[1 + i]) * rises[i])
                    .sum::<f64>();
            if [2, 3, 6, 7].contains(&e) {
                v * 1e-12
            } else {
                v * 1e-6
            }
        })
        .collect();
    let motion = |axis: usize, deg: f64| -> ([f64; 3], [f64; 3]) {
        let mut out = [0.0; 6];
        for e in 0..6 {
            for k in 0..usize::from(f.order) {
                let t = (k as f64 + 1.0) * deg.to_radians();
                let [ak, bk] = f.motion[axis][e][k];
                out[e] += f64::from(ak) * (t.cos() - 1.0) + f64::from(bk) * t.sin();
            }
            out[e] *= if e < 3 { 1e-6 } else { 1e-12 };
        }
        ([out[0], out[1], out[2]], [out[3], out[4], out[5]])
    };
    let pivot = f.pivot_a_um.map(f64::from);
    let off = mul(&rx, &f.offset_c_um.map(f64::from));
    let oc = [0, 1, 2].map(|k| pivot[k] + off[k]);
    let p: [f64; 3] = {
        let mut p = [0.0; 3];
        for k in 0..3 {
            let lo = f64::from(v.origin_um[k]);
            p[k] = f64::from(pos[k]).clamp(lo, lo + f64::from(v.stroke_um[k]));
        }
        p[2] += f64::from(tool.clamp(0, v.tool_max_um));
        p
    };
    let (da, ea) = motion(0, a);
    let (dc, ec) = motion(1, c);
    let (mut la, mut lc) = (
        ([0.0, loc[4], loc[5]], [0.0, loc[6], loc[7]]),
        ([loc[0], loc[1], 0.0], [loc[2], loc[3], 0.0]),
    );
    if f.flags & FIVE_AXIS_RTEST_LOCATION != 0 {
        // (I − R(θ))·ξ in the axis's base frame.
        let i_minus = |r: &[[f64; 3]; 3], v: [f64; 3]| {
            let rv = mul(r, &v);
            [0, 1, 2].map(|k| v[k] - rv[k])
        };
        la = (i_minus(&rx, la.0), i_minus(&rx, la.1));
        lc = (i_minus(&rz, lc.0), i_minus(&rz, lc.1));
    }
    let tr = [
        (id, pivot, la.0, la.1),
        (rx, pivot, da, ea),
        (rx, oc, lc.0, lc.1),
        (rxz, oc, dc, ec),
    ];
    let mut rot = [0.0; 3];
    for (r, o, d, e) in tr {
        let rd = mul(&r, &d);
        let re = mul(&r, &e);
        let arm = [0, 1, 2].map(|k| p[k] - o[k]);
        let x = [
            re[1] * arm[2] - re[2] * arm[1],
            re[2] * arm[0] - re[0] * arm[2],
            re[0] * arm[1] - re[1] * arm[0],
        ];
        for k in 0..3 {
            rot[k] -= (rd[k] + x[k]) * 10.0; // µm → 0.1 µm
        }
    }
    let positions = [pos[0], pos[1], pos[2], 0, 0, 0];
    let t: Vec<Option<i32>> = temps.iter().map(|&t| Some(t)).collect();
    let lin = v.evaluate(&positions, tool, &t);
    let total = [0, 1, 2].map(|d| lin.acc[d] as f64 / ACC_PER_TENTH_UM as f64 + rot[d]);
    (rot, total)
}

#[test]
fn integer_evaluation_follows_the_f64_formula() {
    let v = vol();
    let f = FiveAxis::new(&spec()).unwrap();
    let mut worst = 0.0f64;
    let mut n = 0;
    for ia in 0..9i32 {
        for ic in 0..8 {
            let ang = [-120_000 + ia * 30_000 - 17 * ia.signum(), ic * 45_000 - 1];
            let pos = [100_000 * ic, 60_000 * ia, -350_000 + 20_000 * ic];
            let tool = 50_000 + 10_000 * ia;
            let temps = [20 * 16 + 3 * ia, 22 * 16 + 5 * ic];
            let (rot, total) = f64_eval(&v, &f, pos, tool, ang, &temps);
            let got = evaluate(
                &v,
                &f,
                &[pos[0], pos[1], pos[2]],
                tool,
                ang,
                &temps.map(Some),
            );
            assert_eq!(got.status, vstatus::VALID, "{ang:?}");
            assert_eq!(got.five_status, fstatus::INCLUDED);
            for d in 0..3 {
                // Half an LSB of the register, plus nrad × arm (≤ 1 m here) and trig.
                let e = (f64::from(got.corrections[d]) - total[d]).abs();
                assert!(
                    e <= 0.5 + 0.05,
                    "{ang:?} {pos:?} d{d}: {} vs {}",
                    got.corrections[d],
                    total[d]
                );
                assert!((f64::from(got.rotary[d]) - rot[d]).abs() <= 0.55);
                worst = worst.max(e);
            }
            assert!(
                rot.iter().any(|r| r.abs() > 50.0),
                "rotary part visible: {rot:?}"
            );
            n += 1;
        }
    }
    assert_eq!(n, 72);
    println!("worst |served − f64| {worst:.3} (0.1 µm)");
}

/// The R-test location mode (flag bit 0): the same f64 formula with the
/// location rows turned into (I − R(θ))·ξ_L(T), over poses and temperatures.
#[test]
fn rtest_location_mode_follows_the_f64_formula() {
    let v = vol();
    let mut s = spec();
    s.flags = FIVE_AXIS_RTEST_LOCATION;
    let f = FiveAxis::new(&s).unwrap();
    let (mut worst, mut n) = (0.0f64, 0);
    for ia in 0..9i32 {
        for ic in 0..8 {
            let ang = [-120_000 + ia * 30_000 - 17 * ia.signum(), ic * 45_000 - 1];
            let pos = [100_000 * ic, 60_000 * ia, -350_000 + 20_000 * ic];
            let tool = 50_000 + 10_000 * ia;
            for temps in [[320, 352], [320 + 9 * ia, 352 - 7 * ic], [640, 160]] {
                let (rot, total) = f64_eval(&v, &f, pos, tool, ang, &temps);
                let got = evaluate(&v, &f, &pos, tool, ang, &temps.map(Some));
                assert_eq!(got.status, vstatus::VALID, "{ang:?}");
                for d in 0..3 {
                    // ½ LSB, plus 4 nrad × arm (≤ 1 m) and the trig.
                    let e = (f64::from(got.corrections[d]) - total[d]).abs();
                    assert!(e <= 0.5 + 0.08, "{ang:?} {temps:?} d{d}: {e}");
                    assert!((f64::from(got.rotary[d]) - rot[d]).abs() <= 0.58);
                    worst = worst.max(e);
                }
                n += 1;
            }
        }
    }
    assert_eq!(n, 216);
    println!("R-test mode: worst |served − f64| {worst:.3} (0.1 µm)");
}

/// In the R-test mode a location error, drifting or not, is zero at
/// A = C = 0: with no component errors the total there is the kind-3
/// correction bit for bit, at any temperature; away from zero it is not.
#[test]
fn rtest_locations_vanish_at_the_zero_pose() {
    let v = vol();
    let mut s = spec();
    s.flags = FIVE_AXIS_RTEST_LOCATION;
    s.order = 0;
    s.motion = Default::default();
    let f = FiveAxis::new(&s).unwrap();
    let mut board = s;
    board.flags = 0;
    let fb = FiveAxis::new(&board).unwrap();
    for temps in [[320, 352], [500, 100], [-100, 700]] {
        let t = temps.map(Some);
        let pos = [300_000, 200_000, -100_000];
        let lin = v.evaluate(&pos, 80_000, &t);
        let at0 = evaluate(&v, &f, &pos, 80_000, [0, 0], &t);
        assert_eq!(at0.corrections, lin.corrections, "{temps:?}");
        assert_eq!(at0.rotary, [0; 3]);
        // The board's own convention serves the slots at A = C = 0.
        let b0 = evaluate(&v, &fb, &pos, 80_000, [0, 0], &t);
        assert_ne!(b0.rotary, [0; 3]);
        let away = evaluate(&v, &f, &pos, 80_000, [30_000, 45_000], &t);
        assert!(away.rotary.iter().any(|r| r.abs() > 10), "{away:?}");
    }
}

/// Old images (flags byte 0) parse as before; the flag round-trips; an
/// unknown flag bit is refused with its own error (result code 87).
#[test]
fn the_flags_byte() {
    let f = FiveAxis::new(&spec()).unwrap();
    assert_eq!(f.flags, 0);
    let (_, old) = model_with(Some(vol()), Some(f.clone()));
    let at = old.len() - 4 - f.encoded_len();
    assert_eq!(old[at + 2], 0, "the old padding byte");
    let mut s = spec();
    s.flags = FIVE_AXIS_RTEST_LOCATION;
    let fr = FiveAxis::new(&s).unwrap();
    let (_, buf) = model_with(Some(vol()), Some(fr.clone()));
    assert_eq!(buf.len(), old.len(), "same layout");
    assert_eq!(buf[at + 2], FIVE_AXIS_RTEST_LOCATION);
    assert_eq!(Model::parse(&buf).unwrap().five_axis, Some(fr));
    for bad in [2u8, 0x81, 0xFF] {
        let mut b = old.clone();
        b[at + 2] = bad;
        reseal(&mut b);
        assert_eq!(
            Model::parse(&b).unwrap_err(),
            ImageError::FiveAxisFlags { flags: bad }
        );
        s.flags = bad;
        assert_eq!(
            FiveAxis::new(&s).unwrap_err(),
            ImageError::FiveAxisFlags { flags: bad }
        );
    }
    let msg = ImageError::FiveAxisFlags { flags: 2 }.to_string();
    assert!(msg.contains("0x02") && !msg.contains('\n'), "{msg}");
}

#[test]
fn angle_clamps_and_status() {
    let v = vol();
    let f = FiveAxis::new(&spec()).unwrap();
    let t = [Some(320), Some(352)];
    let inside = evaluate(&v, &f, &[1, 2, -3], 0, [120_000, 0], &t);
    let outside = evaluate(&v, &f, &[1, 2, -3], 0, [130_000, 0], &t);
    assert_eq!(inside.corrections, outside.corrections);
    assert_eq!(outside.angles_mdeg, [120_000, 0]);
    assert_eq!(outside.five_status, fstatus::INCLUDED | fstatus::A_CLAMPED);
    assert_ne!(outside.status & vstatus::ANGLE_CLAMPED, 0);
    assert_eq!(inside.status & vstatus::ANGLE_CLAMPED, 0);
    let c_out = evaluate(&v, &f, &[1, 2, -3], 0, [0, -400_000], &t);
    assert_eq!(c_out.five_status, fstatus::INCLUDED | fstatus::C_CLAMPED);
    // A sensor fault: nothing included.
    let fault = evaluate(&v, &f, &[1, 2, -3], 0, [0, 0], &[Some(320), None]);
    assert_eq!(fault.status & vstatus::VALID, 0);
    assert_ne!(fault.status & vstatus::SENSOR_FAULT, 0);
    assert_eq!(fault.five_status & fstatus::INCLUDED, 0);
    // The max correction of the section clamps the total.
    let mut s = spec();
    s.max_correction = [3; 3];
    let small = FiveAxis::new(&s).unwrap();
    let o = evaluate(
        &v,
        &small,
        &[400_000, 250_000, -200_000],
        100_000,
        [45_000, 30_000],
        &t,
    );
    assert!(o.corrections.iter().all(|c| c.abs() <= 3));
    assert_ne!(o.status & vstatus::CLAMPED, 0);
}

#[test]
fn the_extreme_section_does_not_overflow() {
    let lim = 1i32 << 28;
    let st = MAX_VOL_STROKE_UM;
    let v = vol_with([-lim, lim - st, -lim], [st; 3], i32::MAX);
    let mut s = FiveAxisSpec {
        pivot_a_um: [1 << 27, -(1 << 27), 1 << 27],
        offset_c_um: [-(1 << 27), 1 << 27, -(1 << 27)],
        a_range_mdeg: [-720_000, 720_000],
        c_range_mdeg: [-720_000, 720_000],
        max_correction: [100_000; 3],
        n_sensors: 2,
        order: 4,
        ..FiveAxisSpec::default()
    };
    for (e, row) in s.location.iter_mut().enumerate() {
        let sign = if e % 2 == 0 { 1 } else { -1 };
        // |c0| + 180·(|c1| + |c2|) = 10⁹ exactly.
        *row = [
            sign * 100_000_000,
            sign * 2_500_000,
            -sign * 2_500_000,
            0,
            0,
        ];
    }
    for axis in &mut s.motion {
        for e in axis.iter_mut() {
            for k in e.iter_mut() {
                *k = [100_000_000, -50_000_000]; // Σ 4 · (2·10⁸ + 5·10⁷) = 10⁹
            }
        }
    }
    let board = FiveAxis::new(&s).unwrap();
    s.flags = FIVE_AXIS_RTEST_LOCATION;
    let rtest = FiveAxis::new(&s).unwrap();
    for f in [board, rtest] {
        extreme_poses(&v, &f);
    }
}

fn extreme_poses(v: &Volumetric, f: &FiveAxis) {
    let lim = 1i32 << 28;
    let (_, buf) = model_with(Some(v.clone()), Some(f.clone()));
    Model::parse(&buf).unwrap();
    let temps_edges = [[-160, 0], [960, 800], [-880, 2000]];
    for a in [
        -720_000,
        -540_000,
        -90_000,
        -1,
        0,
        45_000,
        720_000,
        i32::MIN,
        i32::MAX,
    ] {
        for c in [-720_000, -135_000, 0, 89_999, 720_000, i32::MAX] {
            for p in [-lim, lim, 0, i32::MIN, i32::MAX] {
                for t in temps_edges {
                    let o = evaluate(
                        v,
                        f,
                        &[p, p.saturating_neg(), p],
                        i32::MAX,
                        [a, c],
                        &t.map(Some),
                    );
                    assert_ne!(o.status & vstatus::VALID, 0);
                    assert!(o.corrections.iter().all(|c| c.abs() <= 100_000));
                }
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]
    /// With no rotary errors at A = C = 0 the five-axis total is the kind-3
    /// correction, bit for bit; with errors it is total for any input.
    #[test]
    fn zero_rotary_errors_at_zero_is_the_three_axis_correction(
        x in -100_000i32..900_000, y in -50_000i32..550_000, z in -450_000i32..50_000,
        tool in -10_000i32..600_000, t0 in -200i32..1000, t1 in -20i32..900,
        a in any::<i32>(), c in any::<i32>(),
    ) {
        let v = vol();
        let zero = FiveAxis::new(&FiveAxisSpec {
            a_range_mdeg: [-120_000, 120_000],
            c_range_mdeg: [-360_000, 360_000],
            max_correction: [100_000; 3],
            ..FiveAxisSpec::default()
        }).unwrap();
        let temps = [Some(t0), Some(t1)];
        let lin = v.evaluate(&[x, y, z], tool, &temps);
        let five = evaluate(&v, &zero, &[x, y, z], tool, [0, 0], &temps);
        prop_assert_eq!(five.corrections, lin.corrections);
        prop_assert_eq!(five.status, lin.status);
        prop_assert_eq!(five.rotary, [0, 0, 0]);
        // Any pose with errors: total, within the max correction.
        let f = FiveAxis::new(&spec()).unwrap();
        let o = evaluate(&v, &f, &[x, y, z], tool, [a, c], &temps);
        prop_assert!(o.corrections.iter().all(|c| c.abs() <= 5_000));
    }
}
