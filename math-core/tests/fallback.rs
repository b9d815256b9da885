//! Image format v2 (typed sections, fallback models) and degraded-mode
//! compensation: a model sensor lost → the best valid fallback, no jump.
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::cast_possible_truncation,
    reason = "tests: a panic is a failed test"
)]
use thermocomp_core::compensator::status::*;
use thermocomp_core::compensator::ACTIVE_NONE;
use thermocomp_core::float::{demo_model, FloatFallback, FloatModel, FloatTerm};
use thermocomp_core::image::*;
use thermocomp_core::{Compensator, StepInput, StepOutput};

fn term(coef_um: f64, input: Option<u8>) -> FloatTerm {
    FloatTerm {
        coef_um,
        input,
        input_power: u8::from(input.is_some()),
        position_power: 0,
    }
}

/// The demo model (Z: net on inputs 0–4; X: net and table on 0, 1, 4; Y:
/// table on 2, 3) with fallbacks: 1 Z without sensor 0, 2 X without sensor
/// 0, 3 Z without sensors 0 and 1. Their constants sit far from the main
/// model's output so a switch is a large step of the target.
fn with_fallbacks() -> FloatModel {
    let mut f = demo_model(3);
    f.fallbacks = vec![
        FloatFallback {
            direction: 0,
            excluded: vec![0],
            terms: vec![
                term(3.0, Some(1)),
                term(2.0, Some(2)),
                term(1.0, Some(4)),
                term(60.0, None),
            ],
        },
        FloatFallback {
            direction: 1,
            excluded: vec![0],
            terms: vec![term(-4.0, Some(1)), term(-30.0, None)],
        },
        FloatFallback {
            direction: 0,
            excluded: vec![0, 1],
            terms: vec![term(2.0, Some(2)), term(-50.0, None)],
        },
    ];
    f
}

fn encode(m: &mut Model) -> Vec<u8> {
    let mut b = vec![0u8; m.encoded_len()];
    let n = m.encode(&mut b).unwrap();
    assert_eq!(n, b.len());
    b
}

fn reseal(mut b: Vec<u8>) -> Vec<u8> {
    let len = b.len() as u32;
    b[8..12].copy_from_slice(&len.to_le_bytes());
    let n = b.len();
    let crc = crc32(&b[..n - 4]);
    b[n - 4..].copy_from_slice(&crc.to_le_bytes());
    b
}

#[test]
fn a_stored_v1_image_still_parses_and_re_encodes_byte_for_byte() {
    let v1 = include_bytes!("../../fuzz/seeds/model_image/fl-thermal.img");
    assert_eq!(u16::from_le_bytes([v1[4], v1[5]]), 1);
    let mut m = Model::parse(v1).unwrap();
    assert!(m.fallbacks.is_empty());
    assert_eq!(encode(&mut m), v1.to_vec());
    let demo = include_bytes!("../../fuzz/seeds/model_image/demo.img");
    assert!(Model::parse(demo).is_ok());
}

#[test]
fn without_fallbacks_the_encoder_writes_v1_with_them_v2() {
    let (mut plain, _) = demo_model(3).quantize().unwrap();
    let b = encode(&mut plain);
    assert_eq!(u16::from_le_bytes([b[4], b[5]]), 1);
    let (mut m, _) = with_fallbacks().quantize().unwrap();
    let b2 = encode(&mut m);
    assert_eq!(u16::from_le_bytes([b2[4], b2[5]]), SECTIONS_VERSION);
    // Section header 8 B, fallback count 4 B, per fallback 4 B + 8 B per term.
    assert_eq!(b2.len(), b.len() + 8 + 4 + 3 * 4 + 8 * (4 + 2 + 2));
    let back = Model::parse(&b2).unwrap();
    assert_eq!(back, m);
    assert_eq!(back.fallbacks.len(), 3);
    assert_eq!(back.fallbacks[2].excluded, [0, 1]);
    assert_eq!(back.fallbacks[1].excluded, [0, NONE]);
    assert_eq!(back.fallback_terms_of(2).len(), 2);
}

/// The image with fallbacks and the offset of its section list.
fn v2_image() -> (Vec<u8>, usize) {
    let (plain, _) = demo_model(3).quantize().unwrap();
    let base = plain.encoded_len() - 4;
    let (mut m, _) = with_fallbacks().quantize().unwrap();
    (encode(&mut m), base)
}

fn one_line(e: ImageError) -> ImageError {
    let s = e.to_string();
    assert!(!s.is_empty() && !s.contains('\n'), "{s:?}");
    e
}

#[test]
fn bad_sections_are_named_refusals() {
    let (good, at) = v2_image();
    assert_eq!(good[at], 1, "one section");
    assert_eq!(good[at + 4], SECTION_FALLBACKS);
    let parse = |b: Vec<u8>| Model::parse(&reseal(b)).map_err(one_line);

    let mut b = good.clone();
    b[at + 4] = 7;
    assert_eq!(parse(b), Err(ImageError::UnknownSection { kind: 7 }));

    // Declared payload one byte longer / shorter than its contents.
    for delta in [1i32, -1] {
        let mut b = good.clone();
        let len = u16::from_le_bytes([b[at + 6], b[at + 7]]) as i32 + delta;
        b[at + 6..at + 8].copy_from_slice(&(len as u16).to_le_bytes());
        assert_eq!(
            parse(b),
            Err(ImageError::SectionLength {
                kind: SECTION_FALLBACKS
            }),
            "delta {delta}"
        );
    }

    // The same section twice.
    let mut b = good.clone();
    let end = good.len() - 4;
    let section = good[at + 4..end].to_vec();
    b.truncate(end);
    b.extend_from_slice(&section);
    b.extend_from_slice(&[0; 4]);
    b[at] = 2;
    assert_eq!(
        parse(b),
        Err(ImageError::DuplicateSection {
            kind: SECTION_FALLBACKS
        })
    );

    // Fallback 0 (without sensor 0) rewritten to exclude sensor 1, which input 1 reads.
    let f0 = at + 8 + 4;
    let mut b = good.clone();
    b[f0 + 1] = 1;
    assert_eq!(
        parse(b),
        Err(ImageError::FallbackUsesExcluded {
            fallback: 0,
            sensor: 1
        })
    );

    // Direction and excluded sensor out of range, a position power, no terms.
    let mut b = good.clone();
    b[f0] = 3;
    assert!(matches!(parse(b), Err(ImageError::BadIndex { .. })));
    let mut b = good.clone();
    b[f0 + 1] = 6;
    assert!(matches!(parse(b), Err(ImageError::BadIndex { .. })));
    let mut b = good.clone();
    b[f0 + 4 + 6] = 1;
    assert!(matches!(parse(b), Err(ImageError::BadValue { .. })));
    let mut b = good.clone();
    b[f0 + 4 + 4] = 9; // term input 9 of 5
    assert!(matches!(parse(b), Err(ImageError::BadIndex { .. })));

    // Too many sections.
    let mut b = good.clone();
    b[at] = 200;
    assert!(matches!(parse(b), Err(ImageError::TooMany { .. })));

    // A version-1 image must not carry sections: they are trailing bytes of the tables.
    let mut b = good.clone();
    b[4] = 1;
    assert_eq!(parse(b), Err(ImageError::LengthMismatch));
}

fn step(c: &mut Compensator, now_ms: u64, temps: &[Option<i32>]) -> StepOutput {
    c.step(&StepInput {
        now_ms,
        temps,
        spindle_rpm: 4000,
        positions: &[0],
        stale: false,
    })
}

/// Temperatures warming at sensor-specific rates (1/16 °C).
fn temps_at(t_s: u64) -> Vec<Option<i32>> {
    (0..6)
        .map(|i| Some(320 + (t_s as i32 * (i + 1)) / 60))
        .collect()
}

#[test]
fn a_lost_sensor_switches_to_the_best_valid_fallback_and_back() {
    let (m, _) = with_fallbacks().quantize().unwrap();
    let rates: Vec<i64> = m.directions.iter().map(|d| i64::from(d.max_rate)).collect();
    let mut c = Compensator::new(Some(m));
    let mut prev = [0i32; 6];
    let mut seen_rate_limited_switch = false;
    for t in 0..6000u64 {
        let mut temps = temps_at(t);
        // Sensor 0 lost from 2000 s, sensor 1 too from 3000 to 3500 s; both back at 4000 s.
        if (2000..4000).contains(&t) {
            temps[0] = None;
        }
        if (3000..3500).contains(&t) {
            temps[1] = None;
        }
        let o = step(&mut c, t * 1000, &temps);
        for d in 0..3 {
            assert!(
                (i64::from(o.corrections[d]) - i64::from(prev[d])).abs() <= rates[d],
                "t {t} direction {d}: {} -> {} faster than max rate {}",
                prev[d],
                o.corrections[d],
                rates[d]
            );
        }
        let before = prev;
        prev = o.corrections;
        let active = &o.active[..3];
        match t {
            0..2000 | 4000.. => {
                assert_eq!(active, [0, 0, 0], "t {t}");
                assert_eq!(o.status & (DEGRADED | SENSOR_FAULT), 0, "t {t}");
                assert!(o.status & VALID != 0);
            }
            2000..3000 | 3500..4000 => {
                // Z and X on their fallbacks without sensor 0; Y's main model does not read it.
                assert_eq!(active, [1, 2, 0], "t {t}");
                assert_eq!(
                    o.status & (DEGRADED | SENSOR_FAULT | VALID),
                    DEGRADED | VALID
                );
                if t == 2001 && o.status & RATE_LIMITED != 0 {
                    seen_rate_limited_switch = true;
                }
            }
            _ => {
                // Sensors 0 and 1: Z on the pair fallback; X has none and is held.
                assert_eq!(active, [3, ACTIVE_NONE, 0], "t {t}");
                assert_eq!(
                    o.status & (DEGRADED | SENSOR_FAULT | VALID),
                    DEGRADED | SENSOR_FAULT
                );
                // Held: X does not move while it has no model.
                assert_eq!(o.corrections[1], before[1]);
            }
        }
    }
    assert!(
        seen_rate_limited_switch,
        "the switch to a far fallback rides the rate limit"
    );
}

#[test]
fn served_value_converges_to_the_fallback_prediction() {
    let (m, _) = with_fallbacks().quantize().unwrap();
    let mut c = Compensator::new(Some(m));
    let mut last = None;
    for t in 0..4000u64 {
        let mut temps = temps_at(t);
        if t >= 1000 {
            temps[0] = None;
        }
        last = Some(step(&mut c, t * 1000, &temps));
    }
    let o = last.unwrap();
    assert_eq!(o.active[0], 1);
    // Rate limit settled: the served value is the fallback's prediction (within the clamp).
    assert_eq!(o.corrections[0], o.predicted[0]);
    assert!(o.predicted[0] > 500, "fallback constant of 60 µm dominates");
}

#[test]
fn a_direction_without_fallbacks_is_held_as_before() {
    let (m, _) = with_fallbacks().quantize().unwrap();
    let mut c = Compensator::new(Some(m));
    let mut y_before = 0;
    for t in 0..3000u64 {
        let mut temps = temps_at(t);
        if t >= 2000 {
            temps[3] = None; // Y's main model reads sensor 3; no fallback for Y
        }
        let o = step(&mut c, t * 1000, &temps);
        if t == 1999 {
            y_before = o.corrections[2];
        }
        if t >= 2000 {
            // Z's network reads sensor 3 too: its fallback "without sensor 0"
            // does not, so it serves (any fallback whose inputs are valid).
            assert_eq!(o.active[..3], [1, 0, ACTIVE_NONE]);
            assert_eq!(o.corrections[2], y_before);
            assert_eq!(
                o.status & (SENSOR_FAULT | VALID | DEGRADED),
                SENSOR_FAULT | DEGRADED
            );
        }
    }
}

#[test]
fn images_without_fallbacks_keep_the_old_fault_rule() {
    let (m, _) = demo_model(3).quantize().unwrap();
    let mut c = Compensator::new(Some(m));
    for t in 0..100u64 {
        let mut temps = temps_at(t);
        if t >= 50 {
            temps[0] = None;
        }
        let o = step(&mut c, t * 1000, &temps);
        if t >= 50 {
            assert_eq!(o.status & (SENSOR_FAULT | VALID | DEGRADED), SENSOR_FAULT);
            assert_eq!(o.active, [ACTIVE_NONE; 6]);
        } else {
            assert_eq!(o.active[..3], [0, 0, 0]);
        }
    }
}

#[test]
fn a_sensor_dead_at_power_up_is_served_by_fallbacks_until_a_new_reference() {
    let (m, _) = with_fallbacks().quantize().unwrap();
    let mut c = Compensator::new(Some(m));
    for t in 0..200u64 {
        let mut temps = temps_at(t);
        if t < 100 {
            temps[0] = None;
        }
        let o = step(&mut c, t * 1000, &temps);
        // Sensor 0 has no reference sample: its rise stays invalid even once it reads again.
        assert_eq!(o.active[..3], [1, 2, 0], "t {t}");
        assert_eq!(
            o.status & (DEGRADED | VALID | SENSOR_FAULT),
            DEGRADED | VALID
        );
    }
    assert_eq!(c.reference().unwrap()[1], temps_at(0)[1].unwrap());
    c.rereference();
    let o = step(&mut c, 200_000, &temps_at(200));
    assert_eq!(o.active[..3], [0, 0, 0]);
    assert_eq!(o.status & DEGRADED, 0);
}
