//! Eddy-current probe: oversampling, calibration to 0.1 µm, saturation and
//! range detection, against a simulated probe + 12-bit ADC.

use host_tests::onewire_emu::block_on;
use thermocomp::acquisition::probe::{measure, Calibration, ProbeConfig};
use thermocomp::hal::adc::{AdcError, ProbeAdc};
use thermocomp_protocol::states::ProbeState;

/// A probe whose output code is `response(displacement)` plus deterministic
/// uniform noise of ±`noise` codes, clipped at the ADC's rails.
struct SimProbe {
    tenth_um: f64,
    noise: i32,
    seed: u64,
    response: Box<dyn Fn(f64) -> f64>,
    fail_after: Option<u32>,
    taken: u32,
}

impl SimProbe {
    fn linear(tenth_um: f64, noise: i32) -> SimProbe {
        SimProbe {
            tenth_um,
            noise,
            seed: 0x1234_5678,
            // −1000 µm .. +1000 µm over 4096 codes.
            response: Box::new(|y| (y + 10_000.0) * 4096.0 / 20_000.0),
            fail_after: None,
            taken: 0,
        }
    }
}

impl ProbeAdc for SimProbe {
    fn full_scale(&self) -> u16 {
        4095
    }
    async fn sample(&mut self) -> Result<u16, AdcError> {
        if self.fail_after.is_some_and(|n| self.taken >= n) {
            return Err(AdcError::Timeout);
        }
        self.taken += 1;
        self.seed = self
            .seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        // Continuous analog noise, uniform in ±noise codes.
        let u = (self.seed >> 11) as f64 / (1u64 << 53) as f64;
        let r = (2.0 * u - 1.0) * f64::from(self.noise);
        let code = (self.response)(self.tenth_um) + r;
        Ok(code.round().clamp(0.0, 4095.0) as u16)
    }
}

fn config(oversample: u16) -> ProbeConfig {
    ProbeConfig {
        oversample,
        saturation_margin: 4,
        calibration: Calibration::linear(-10_000, 20_000, 4096).unwrap(),
        min_tenth_um: -9_000,
        max_tenth_um: 9_000,
    }
}

#[test]
fn oversampling_resolves_below_one_code() {
    // 123.4 µm; one ADC code is 0.49 µm.
    for truth in [1234.0, -4321.0, 7.0] {
        let mut p = SimProbe::linear(truth, 3);
        let r = block_on(measure(&mut p, &config(256)));
        assert_eq!(r.state, ProbeState::Ok);
        let err = (f64::from(r.tenth_um.unwrap()) - truth).abs();
        assert!(err <= 2.0, "truth {truth}, got {:?}", r.tenth_um);
        assert_eq!(p.taken, 256);
        // A single sample is off by up to the noise (3 codes = 14.6 tenths).
        let mut p = SimProbe::linear(truth, 3);
        let r1 = block_on(measure(&mut p, &config(1)));
        let err1 = (f64::from(r1.tenth_um.unwrap()) - truth).abs();
        assert!(err1 <= 3.0 * 4.883 + 2.5, "{err1}");
    }
}

#[test]
fn saturation_is_detected_not_clamped_into_a_value() {
    // Target beyond +1000 µm: the ADC sits at its rail.
    let mut p = SimProbe::linear(12_000.0, 2);
    let r = block_on(measure(&mut p, &config(64)));
    assert_eq!(r.state, ProbeState::Saturated);
    assert_eq!(r.max_code, 4095);
    let mut p = SimProbe::linear(-11_000.0, 2);
    assert_eq!(
        block_on(measure(&mut p, &config(64))).state,
        ProbeState::Saturated
    );
}

#[test]
fn out_of_measuring_range_is_named_and_the_value_kept() {
    let mut p = SimProbe::linear(9_500.0, 1);
    let r = block_on(measure(&mut p, &config(64)));
    assert_eq!(r.state, ProbeState::OutOfRange);
    assert!((f64::from(r.tenth_um.unwrap()) - 9_500.0).abs() <= 2.0);
}

#[test]
fn polynomial_linearisation() {
    // A probe with a quadratic characteristic y(x) = −10000 + 0.2·x + 1e-6·x²
    // (x in 1/16 code), calibrated with the matching Q32 coefficients.
    fn y_of_x(x: f64) -> f64 {
        -10_000.0 + 0.2 * x + 1e-6 * x * x
    }
    let cal = Calibration {
        coeffs: [
            -10_000i64 << 32,
            (0.2 * 4294967296.0f64).round() as i64,
            (1e-6 * 4294967296.0f64).round() as i64,
            0,
        ],
    };
    // The probe's response: the code whose calibrated value is y (bisection).
    let invert = |y: f64| {
        let (mut lo, mut hi) = (0.0f64, 4095.0f64);
        for _ in 0..60 {
            let mid = (lo + hi) / 2.0;
            if y_of_x(mid * 16.0) < y {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        lo
    };
    for truth in [-9_000.0, -2_000.0, 3_000.0, 7_000.0] {
        let mut p = SimProbe {
            response: Box::new(invert),
            ..SimProbe::linear(truth, 2)
        };
        let cfg = ProbeConfig {
            calibration: cal,
            min_tenth_um: -20_000,
            max_tenth_um: 20_000,
            ..config(256)
        };
        let r = block_on(measure(&mut p, &cfg));
        assert_eq!(r.state, ProbeState::Ok);
        let got = f64::from(r.tenth_um.unwrap());
        // One code is 3.2..13 tenths along this curve; averaging gets within 4.
        assert!((got - truth).abs() <= 4.0, "{truth}: {r:?}");
        // The linear part alone would be off by the quadratic term.
        let x = f64::from(r.mean_x16);
        let linear_only = -10_000.0 + 0.2 * x;
        if truth > 0.0 {
            assert!((linear_only - truth).abs() > 50.0, "{truth}");
        }
    }
}

#[test]
fn calibration_overflow_and_adc_failure_are_named() {
    let mut p = SimProbe::linear(0.0, 0);
    let cfg = ProbeConfig {
        calibration: Calibration {
            coeffs: [0, 0, 0, i64::MAX / 4],
        },
        ..config(4)
    };
    let r = block_on(measure(&mut p, &cfg));
    assert_eq!(r.state, ProbeState::CalibrationOverflow);
    assert_eq!(r.tenth_um, None);
    let mut p = SimProbe {
        fail_after: Some(10),
        ..SimProbe::linear(0.0, 0)
    };
    assert_eq!(
        block_on(measure(&mut p, &config(64))).state,
        ProbeState::AdcError
    );
    let mut p = SimProbe::linear(0.0, 0);
    assert_eq!(
        block_on(measure(&mut p, &config(0))).state,
        ProbeState::BadConfig
    );
    assert_eq!(
        block_on(measure(&mut p, &config(5000))).state,
        ProbeState::BadConfig
    );
}

#[test]
fn measured_drift_run_through_the_probe_chain() {
    // The five eddy-current channels of the measured FL_THERMAL run (the
    // first 8.2 h of the licensed excerpt in `demo/trace.csv`, µm), through a simulated probe
    // (±1000 µm over 12 bits, ±2 codes of analog noise), 256× oversampling
    // and the linear calibration. Compiled in: no skip when a file is absent.
    let text = include_str!("../../demo/trace.csv");
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let cols: Vec<usize> = (0..header.len())
        .filter(|&i| header[i].starts_with('d') && header[i].ends_with("_um"))
        .collect();
    assert_eq!(cols.len(), 5);
    let mut worst = 0.0f64;
    let mut n = 0;
    let mut span = (f64::MAX, f64::MIN);
    for line in lines.take(1_968).step_by(2) {
        let fields: Vec<&str> = line.split(',').collect();
        for &c in &cols {
            let um: f64 = fields[c].parse().unwrap();
            span = (span.0.min(um), span.1.max(um));
            let mut p = SimProbe::linear(um * 10.0, 2);
            let r = block_on(measure(&mut p, &config(256)));
            assert_eq!(r.state, ProbeState::Ok);
            let err = (f64::from(r.tenth_um.unwrap()) - um * 10.0).abs();
            worst = worst.max(err);
            n += 1;
        }
    }
    assert_eq!(n, 984 * 5);
    // The excerpt drifts by more than 20 µm: many codes, not one value.
    assert!(span.1 - span.0 > 20.0, "{span:?}");
    // Better than 0.2 µm everywhere (one ADC code is 0.49 µm).
    assert!(worst <= 2.0, "worst error {worst} tenths of a µm");
    println!("{n} probe readings, worst error {:.2} µm", worst / 10.0);
}
