//! The board's envelope policy (issue 50 item 3) on the QEMU bench board,
//! bit for bit with the desktop. A trace whose sensor T03 (the demo model's
//! input 2, trained over a rise of −2 … +20 K) warms to +23 K and comes
//! back to +14 K: first inside its range, then within the image's margin
//! (0.5 K), then beyond it, then back. Two images of the same model and
//! fallbacks, one with the policy `hold` on every direction, one with
//! `fallback`. Read over Modbus by pymodbus (one snapshot: registers 0–53,
//! 150–157 and 360–371, the sequence read again after them), every
//! compared sample equals `tcomp replay`'s core (corrections, predictions,
//! status, the model serving each direction), and the count registers
//! 360–371 equal the number of replayed rows up to that sample whose
//! direction was beyond the envelope. The status bit `OUT_OF_ENVELOPE` is
//! set on every counted row and on the rows within the margin (rule 4: an
//! input held at its edge), and clear inside. A third image, the same
//! sensors with linear tables only, `extrapolate` on every direction and
//! a 600 s output low-pass on Z (format v5), is compared the same way:
//! beyond the range it serves the linear continuation (not the held edge)
//! and the filter's state runs on the board as in the replay.
use std::collections::BTreeMap;
use std::path::Path;
use std::time::{Duration, Instant};

use host_tests::qemu::{modbus_master, one_board, BenchBoard};
use tcomp_model::replay::ReplayRow;
use thermocomp_core::compensator::status;
use thermocomp_core::float::FloatTable;
use thermocomp_core::float::{demo_model, FloatFallback, FloatTerm};
use thermocomp_core::image::{EnvelopeMode, EnvelopePolicy};

const ROWS: u32 = 1600;
const ROW_S: u32 = 15;
/// Margin of both images' policy, 1/16 °C (0.5 K).
const MARGIN: u16 = 8;
/// Input 2's training range, rise of T03 in K (the demo model's −32 … 320 raw).
const RANGE_HI_K: f64 = 20.0;
/// Stop reading once a sample this far into the trace was compared (after
/// T03 came back inside; the trace goes on, so the board is still serving).
const LAST_ROW: usize = 1000;

/// T03's rise (K) at row `i`: +18 K in 300 rows, +2 K in 200 more up to
/// the range's edge, 250 rows inside the margin (+20.25 K at row 750: the
/// board replays a row per 40 ms, and a loaded machine's Modbus reads are
/// a second or more apart, so each zone must last several seconds), on to
/// +23 K by row 850, back to +14 K by row 1150, then a slow warm-up.
fn t03_rise(i: u32) -> f64 {
    let i = f64::from(i);
    match i {
        i if i < 300.0 => 0.06 * i,
        i if i < 500.0 => 18.0 + 0.01 * (i - 300.0),
        i if i < 750.0 => 20.0 + 0.001 * (i - 500.0),
        i if i < 850.0 => 20.25 + 0.0275 * (i - 750.0),
        i if i < 1150.0 => 23.0 - 0.03 * (i - 850.0),
        i => 14.0 + 0.002 * (i - 1150.0),
    }
}

fn trace(path: &Path) {
    let mut csv = String::from("time_s,spindle_rpm,T01,T02,T03,T04,T05,T06\n");
    for i in 0..ROWS {
        let rpm = if i < 10 { 0 } else { 6000 };
        let x = f64::from(i);
        let temps = [
            20.0 + 0.004 * x,
            20.0 + 0.003 * x,
            20.0 + t03_rise(i),
            20.0 + 0.005 * x,
            20.0 + 0.004 * x,
            20.0 + 0.001 * x,
        ];
        csv += &format!("{},{rpm}", i * ROW_S);
        for t in temps {
            csv += &format!(",{t:.4}");
        }
        csv += "\n";
    }
    std::fs::write(path, csv).unwrap();
}

fn term(coef_um: f64, input: Option<u8>) -> FloatTerm {
    FloatTerm {
        coef_um,
        input,
        input_power: u8::from(input.is_some()),
        position_power: 0,
    }
}

/// The demo model with fallbacks for Z (direction 0) and Y (2) that read
/// no T03, exported with `policy` on every direction.
fn image(path: &Path, fallback: bool) {
    let mut fm = demo_model(1);
    image_fallbacks(&mut fm);
    let policy = EnvelopePolicy {
        mode: if fallback {
            EnvelopeMode::Fallback
        } else {
            EnvelopeMode::Hold
        },
        margin: MARGIN,
    };
    tcomp_model::export::export_enveloped(&fm, (None, None), Some([policy; 6]), path, None)
        .unwrap();
}

/// Fallbacks for Z (direction 0) and Y (2) that read no T03.
fn image_fallbacks(fm: &mut thermocomp_core::float::FloatModel) {
    fm.fallbacks = vec![
        FloatFallback {
            direction: 0,
            excluded: vec![2],
            terms: vec![term(8.0, Some(0)), term(4.0, Some(1)), term(2.0, Some(4))],
        },
        FloatFallback {
            direction: 2,
            excluded: vec![2],
            terms: vec![term(-3.0, Some(3)), term(1.5, None)],
        },
    ];
}

/// The demo model's sensors and inputs with linear static tables only
/// (Z and Y read T03, X does not), its fallbacks as in [`image`], policy
/// `mode` on every direction; with `low_pass`, a 600 s output low-pass on Z.
fn linear_image(path: &Path, mode: EnvelopeMode, low_pass: bool) {
    let mut fm = demo_model(1);
    fm.nets.clear();
    let table = |direction: u8, terms: Vec<FloatTerm>| FloatTable {
        direction,
        axis: None,
        terms,
    };
    fm.tables = vec![
        table(
            0,
            vec![
                term(6.0, Some(0)),
                term(-3.0, Some(1)),
                term(9.0, Some(2)),
                term(2.0, Some(4)),
            ],
        ),
        table(1, vec![term(4.0, Some(0)), term(-2.0, Some(3))]),
        table(
            2,
            vec![term(-5.0, Some(2)), term(1.0, Some(3)), term(1.5, None)],
        ),
    ];
    image_fallbacks(&mut fm);
    let policy = EnvelopePolicy {
        mode,
        margin: MARGIN,
    };
    let decay = tcomp_model::export::output_filter::decay_q30(fm.step_ms, 600.0).unwrap();
    let output = low_pass.then_some([decay, 0, 0, 0, 0, 0]);
    tcomp_model::export::export_sections(
        &fm,
        (None, None),
        (Some([policy; 6]), output),
        path,
        None,
    )
    .unwrap();
}

/// Where T03's rise lies at row `i`: 0 inside its range, 1 within the
/// margin, 2 beyond it (from the trace's own values, 1/16 °C as the board
/// reads them).
fn zone(i: usize) -> usize {
    // The value as the trace writes it, rounded to 1/16 °C as the board's parser.
    let q = |k: f64| (format!("{k:.4}").parse::<f64>().unwrap() * 16.0).round();
    let rise = q(20.0 + t03_rise(i as u32)) - q(20.0);
    let hi = RANGE_HI_K * 16.0;
    usize::from(rise > hi) + usize::from(rise > hi + f64::from(MARGIN))
}

/// T03's rise beyond its range at row `i`, 1/16 °C (0 inside).
fn zone_excess(i: usize) -> i64 {
    let rise = t03_rise(i as u32) - RANGE_HI_K;
    (rise.max(0.0) * 16.0).round() as i64
}

/// Serve `img` on the trace, read snapshots until one past [`LAST_ROW`]
/// was compared; every compared sample equals the replay bit for bit.
/// The compared rows' zones (inside, within the margin, beyond).
fn serve_and_compare(t: &Path, img: &Path, rows: &[ReplayRow]) -> [usize; 3] {
    let (board, port) = BenchBoard::serve_tcp(t, img, &["40"]);
    let p = port.to_string();
    // Per row, the replayed rows up to it beyond the envelope, per direction.
    let mut counted = Vec::with_capacity(rows.len());
    let mut sum = [0u64; 6];
    for r in rows {
        for (d, c) in sum.iter_mut().enumerate() {
            *c += u64::from(r.out.envelope >> d & 1);
        }
        counted.push(sum);
    }
    let mut compared: BTreeMap<usize, u16> = BTreeMap::new();
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(240) && compared.keys().last() < Some(&LAST_ROW) {
        let read = modbus_master(&[
            "read",
            "--port",
            &p,
            "--samples",
            "10",
            "--degraded",
            "--envelope",
        ]);
        for s in read.as_array().unwrap() {
            let Some(t_s) = s["sample_time_s"].as_u64() else {
                panic!("{s}\n{}", board.log());
            };
            let i = (t_s / u64::from(ROW_S)) as usize;
            if s["envelope_same_snapshot"] != true || t_s % u64::from(ROW_S) != 0 || i >= rows.len()
            {
                continue;
            }
            let out = &rows[i].out;
            for d in 0..6 {
                let c = &s["corrections"][d];
                assert_eq!(
                    c.as_i64(),
                    Some(i64::from(out.corrections[d])),
                    "row {i} dir {d}: {s}"
                );
                let q = &s["predictions"][d];
                assert_eq!(
                    q.as_i64(),
                    Some(i64::from(out.predicted[d])),
                    "row {i} dir {d}: {s}"
                );
                let n = &s["envelope_steps"][d];
                assert_eq!(n.as_u64(), Some(counted[i][d]), "row {i} dir {d}: {s}");
            }
            for d in 0..3 {
                let a = &s["active"][d];
                assert_eq!(
                    a.as_u64(),
                    Some(u64::from(out.active[d])),
                    "row {i} dir {d}: {s}"
                );
            }
            assert_eq!(
                s["status"].as_u64(),
                Some(u64::from(out.status)),
                "row {i}: {s}"
            );
            compared.insert(i, out.status);
        }
    }
    let mut zones = [0usize; 3];
    for (&i, &st) in &compared {
        let z = zone(i);
        zones[z] += 1;
        let flagged = st & status::OUT_OF_ENVELOPE != 0;
        // Inside: clear; within the margin: set (held at the edge) but not
        // counted; beyond: set and counted in Z and Y, never in X.
        assert_eq!(flagged, z > 0, "row {i} zone {z}: {st:#06x}");
        assert_eq!(
            rows[i].out.envelope,
            if z == 2 { 0b101 } else { 0 },
            "row {i}"
        );
    }
    assert!(
        zones.iter().all(|&n| n >= 3),
        "too few samples per zone (inside, margin, beyond): {zones:?}\n{}",
        board.log()
    );
    zones
}

#[test]
#[ignore = "needs the QEMU firmware, qemu-system-arm and pymodbus: scripts/test.sh"]
fn the_envelope_policy_and_its_counts_over_modbus_equal_the_desktop_replay() {
    let _one = one_board();
    let dir = std::env::temp_dir().join(format!("thermocomp-envelope-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (t, hold, fallback) = (
        dir.join("trace.csv"),
        dir.join("hold.img"),
        dir.join("fallback.img"),
    );
    trace(&t);
    image(&hold, false);
    image(&fallback, true);
    let held = tcomp_model::replay::replay_files(&t, &hold).unwrap();
    let fell = tcomp_model::replay::replay_files(&t, &fallback).unwrap();
    // The two policies serve differently beyond the envelope, alike elsewhere.
    let beyond: Vec<usize> = (0..held.len()).filter(|&i| zone(i) == 2).collect();
    assert!(beyond.len() > 100, "{}", beyond.len());
    for &i in &beyond {
        assert_eq!(held[i].out.active[..3], [0, 0, 0], "row {i}");
        assert_eq!(fell[i].out.active[..3], [1, 0, 2], "row {i}");
        assert_ne!(fell[i].out.status & status::DEGRADED, 0, "row {i}");
    }
    let differ = |d: usize| {
        beyond
            .iter()
            .filter(|&&i| held[i].out.corrections[d] != fell[i].out.corrections[d])
            .count()
    };
    assert!(differ(0) > beyond.len() / 2 && differ(2) > beyond.len() / 2);
    assert_eq!(differ(1), 0);
    for i in 0..beyond[0] {
        assert_eq!(held[i].out, fell[i].out, "row {i}");
    }

    // The linear image: continued beyond the range (Z and Y read T03; X
    // does not), low-passed on Z; against the same tables held at the edge.
    let (lin, lin_hold) = (dir.join("extrapolate.img"), dir.join("linear-hold.img"));
    linear_image(&lin, EnvelopeMode::Extrapolate, true);
    linear_image(&lin_hold, EnvelopeMode::Hold, true);
    let ext = tcomp_model::replay::replay_files(&t, &lin).unwrap();
    let lh = tcomp_model::replay::replay_files(&t, &lin_hold).unwrap();
    for &i in &beyond {
        assert_ne!(ext[i].out.status & status::OUT_OF_ENVELOPE, 0, "row {i}");
        assert_eq!(ext[i].out.predicted[1], lh[i].out.predicted[1], "row {i}");
    }
    // Y (−5 µm per normalised unit of T03, no filter) moves on past the
    // edge: further from the held value the further T03 is beyond.
    let peak = *beyond.iter().max_by_key(|&&i| zone_excess(i)).unwrap();
    assert!(
        ext[peak].out.predicted[2] < lh[peak].out.predicted[2] - 5,
        "row {peak}"
    );
    let zones_hold = serve_and_compare(&t, &hold, &held);
    let zones_fallback = serve_and_compare(&t, &fallback, &fell);
    let zones_ext = serve_and_compare(&t, &lin, &ext);
    eprintln!("compared samples (inside, margin, beyond): hold {zones_hold:?}, fallback {zones_fallback:?}, extrapolate + low-pass {zones_ext:?}");
    assert!(zones_ext[2] > 0, "{zones_ext:?}");
}
