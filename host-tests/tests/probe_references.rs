//! Probe references in the application (issue 28), on the pin-level 1-Wire
//! emulator, a simulated probe ADC and the mock flash: command 12 updates
//! the served corrections exactly as `thermocomp_core::reference` predicts
//! for the same inputs; a refused reference changes nothing but its count;
//! the state survives a power cycle, command 13 and a new model reset it;
//! command 2 (with a probe direction) re-zeroes. And the probe's own
//! temperature drift: 0.5 µm/K injected, estimated by `tcomp fit`'s
//! estimator from a run where the target does not move, removed by the
//! board before a reading is used, to ≤ 0.05 µm/K.
use host_tests::mock_flash::MockFlash;
use host_tests::modbus::{self, demo_image, read_inputs, write_unlocked, SLOT};
use host_tests::onewire_emu::{block_on, bus_with_sensors, master, Bus, MS};
use thermocomp::acquisition::channel_map::ChannelMap;
use thermocomp::acquisition::probe::{measure, Calibration, ProbeConfig, ProbeReading};
use thermocomp::acquisition::temperature::{AcquisitionConfig, TemperatureAcquisition};
use thermocomp::app::App;
use thermocomp::hal::adc::{AdcError, ProbeAdc};
use thermocomp_core::reference::{ReferenceOutcome, ReferenceParams, ReferenceState};
use thermocomp_core::StepOutput;
use thermocomp_protocol::holding::*;
use thermocomp_protocol::registers::*;
use thermocomp_protocol::states::ProbeState;

/// Unlock, then write `v` to holding register `addr`.
fn write(app: &mut App<MockFlash>, addr: u16, v: u16) -> Vec<u8> {
    write_unlocked(app, addr, v)
}

fn inputs(app: &mut App<MockFlash>, addr: u16, n: u8) -> Vec<u16> {
    read_inputs(app, addr, u16::from(n), 0)
}

/// HR_RESULT after the flash job the last command started (if any).
fn settled_result(app: &mut App<MockFlash>) -> u16 {
    while app.poll_flash() {}
    app.result()
}

struct Rig {
    bus: Bus,
    acq: TemperatureAcquisition,
}

impl Rig {
    fn new() -> Rig {
        let bus = bus_with_sensors(6, 0x2EF_0028, 20 * 16);
        let mut acq = TemperatureAcquisition::new(AcquisitionConfig::default(), ChannelMap::new());
        assert_eq!(block_on(acq.discover(&mut master(&bus))), Ok(6));
        assert_eq!(block_on(acq.configure(&mut master(&bus))), Ok(true));
        Rig { bus, acq }
    }

    /// Sensor k at 20 °C + k·`step` sixteenths, one acquisition cycle 1 s
    /// on, and one application cycle on it: the compensator's own output.
    fn cycle(&mut self, app: &mut App<MockFlash>, step: i16) -> (u64, StepOutput) {
        for k in 0..6 {
            self.bus
                .with_device(k, |d| d.temperature = 20 * 16 + step * (k as i16 + 1));
        }
        self.bus.advance_ns(1_000 * MS);
        let now = self.bus.now_ms();
        block_on(
            self.acq
                .cycle(&mut master(&self.bus), &mut self.bus.delay(), now),
        );
        (now, app.cycle(&self.acq, now, now, Some(3000)))
    }
}

impl Rig {
    /// The emulated device the acquisition reads on channel `c`.
    fn device_on(&self, c: usize) -> usize {
        (0..6)
            .find(|&k| {
                self.bus
                    .with_device(k, |d| d.rom)
                    .and_then(|r| self.acq.map().channel_of(&r))
                    == Some(c)
            })
            .expect("a device on that channel")
    }
}

fn ok_reading(tenth_um: i32) -> ProbeReading {
    ProbeReading {
        state: ProbeState::Ok,
        tenth_um: Some(tenth_um),
        mean_x16: 0,
        min_code: 100,
        max_code: 200,
    }
}

fn boot(rig: &Rig, flash: MockFlash) -> App<MockFlash> {
    modbus::boot(flash, *rig.acq.map())
}

fn power_cycle(rig: &Rig, app: &mut App<MockFlash>) -> App<MockFlash> {
    modbus::power_cycle(app, *rig.acq.map())
}

/// The served corrections the host predicts: direction 0 with `st`, the others fresh.
fn predicted(out: &StepOutput, now: u64, st: &ReferenceState, max: &[i32]) -> Vec<i32> {
    let p = ReferenceParams::DEFAULT;
    let fresh = ReferenceState::new(&p);
    (0..max.len())
        .map(|d| {
            let s = if d == 0 { st } else { &fresh };
            s.serve(&p, now, out.corrections[d], max[d])
        })
        .collect()
}

#[test]
fn references_serve_what_the_core_predicts_refusals_change_nothing_and_the_state_is_kept() {
    let mut rig = Rig::new();
    let mut app = boot(&rig, MockFlash::new(2 * SLOT as usize));
    app.program(&demo_image(1, 1)).unwrap();
    let max: Vec<i32> = app
        .model()
        .unwrap()
        .directions
        .iter()
        .map(|d| d.max_correction)
        .collect();
    let n = max.len();
    let p = ReferenceParams::DEFAULT;
    // No probe direction (the default): refused with 63, nothing learned.
    write(&mut app, HR_COMMAND, CMD_TAKE_PROBE_REFERENCE);
    assert_eq!(app.result(), result::PROBE_REFERENCE_PENDING);
    let (now, out) = rig.cycle(&mut app, 0);
    app.set_probe(&ok_reading(40), Some((&rig.acq, now)));
    assert_eq!(app.result(), result::NO_PROBE_DIRECTION);
    assert_eq!(&app.snapshot().corrections[..n], &out.corrections[..n]);
    // Direction 0 (stored), and 64 samples per reference.
    let reply = write(&mut app, HR_PROBE_DIRECTION, 0);
    assert_eq!(reply[1], 6, "{reply:02x?}");
    // While that is stored, the setup waits (exception 06, as the limits).
    let reply = write(&mut app, HR_REFERENCE_SAMPLES, 64);
    assert_eq!(reply[1], 0x86, "{reply:02x?}");
    assert_eq!(reply[2], 6, "{reply:02x?}");
    assert_eq!(settled_result(&mut app), result::OK);
    write(&mut app, HR_REFERENCE_SAMPLES, 64);
    assert_eq!(settled_result(&mut app), result::OK);
    assert_eq!(app.probe_reference_samples(), None);
    let mut st = ReferenceState::new(&p);
    let mut step = 0i16;
    for (k, offset) in [(0, 30), (1, 45), (2, 800)] {
        for _ in 0..20 {
            step += 2;
            rig.cycle(&mut app, step);
        }
        write(&mut app, HR_COMMAND, CMD_TAKE_PROBE_REFERENCE);
        assert_eq!(app.probe_reference_samples(), Some(64));
        step += 2;
        let (now, out) = rig.cycle(&mut app, step);
        let reading = out.corrections[0] + offset;
        let before = st;
        let want = st.reference(&p, now, out.corrections[0], reading);
        app.set_probe(&ok_reading(reading), Some((&rig.acq, now)));
        assert_eq!(app.references().state(0), Some(&st), "reference {k}");
        assert_eq!(
            &app.snapshot().corrections[..n],
            &predicted(&out, now, &st, &max)[..],
            "served at once, reference {k}"
        );
        let code = settled_result(&mut app);
        match want {
            ReferenceOutcome::Accepted { .. } => assert_eq!(code, result::OK),
            ReferenceOutcome::Refused { .. } => {
                assert_eq!(code, result::REFERENCE_REFUSED);
                assert_eq!(
                    ReferenceState {
                        refused: 0,
                        last_innovation_nm: 0,
                        last_refused: false,
                        ..st
                    },
                    ReferenceState {
                        last_innovation_nm: 0,
                        ..before
                    },
                    "a refused reference changes nothing but its count and the pending flag"
                );
            }
        }
        // Later cycles follow the same prediction.
        for _ in 0..3 {
            step += 1;
            let (now, out) = rig.cycle(&mut app, step);
            assert_eq!(
                &app.snapshot().corrections[..n],
                &predicted(&out, now, &st, &max)[..]
            );
        }
    }
    assert_eq!((st.accepted, st.refused), (2, 1));
    let w = inputs(&mut app, IR_REF_TIME, 6);
    assert_eq!((w[4], w[5]), (2, 1));
    assert_eq!(
        u32::from(w[0]) << 16 | u32::from(w[1]),
        (st.last_ms.unwrap() / 1000) as u32
    );
    let bias = inputs(&mut app, IR_REF_BIAS, 1)[0] as i16;
    assert!(bias > 30, "bias {bias} (0.1 µm)");

    // A power cycle: the state is back, its last reference at the first cycle.
    let mut app = power_cycle(&rig, &mut app);
    assert_eq!(app.probe_setup().direction, Some(0));
    assert_eq!(app.probe_setup().samples, 64);
    let (now, out) = rig.cycle(&mut app, step);
    let mut rebased = st;
    rebased.last_ms = Some(now);
    assert_eq!(app.references().state(0), Some(&rebased));
    assert_eq!(
        &app.snapshot().corrections[..n],
        &predicted(&out, now, &rebased, &max)[..]
    );

    // Command 2 with a probe direction: re-zero, served 0 now, the model's
    // reference sample kept.
    let reference_before = app.compensator().reference().unwrap().to_vec();
    write(&mut app, HR_COMMAND, CMD_REREFERENCE);
    assert_eq!(&app.snapshot().corrections[..n], &vec![0; n][..]);
    let mut zeroed = rebased;
    zeroed.rezero(&p, now, out.corrections[0]);
    let (now, out) = rig.cycle(&mut app, step + 4);
    assert_eq!(
        app.compensator().reference().unwrap(),
        &reference_before[..]
    );
    assert_eq!(
        app.snapshot().corrections[0],
        predicted(&out, now, &zeroed, &max)[0]
    );
    assert_ne!(
        app.snapshot().corrections[1],
        out.corrections[1],
        "all directions re-zeroed"
    );
    assert_eq!(settled_result(&mut app), result::OK);

    // Command 13: the model alone again (stored).
    write(&mut app, HR_COMMAND, CMD_RESET_REFERENCE_TERMS);
    assert_eq!(settled_result(&mut app), result::OK);
    let (_, out) = rig.cycle(&mut app, step + 5);
    assert_eq!(&app.snapshot().corrections[..n], &out.corrections[..n]);
    let mut app = power_cycle(&rig, &mut app);
    assert_eq!(app.references().state(0), Some(&ReferenceState::new(&p)));

    // A new model resets the terms too.
    write(&mut app, HR_COMMAND, CMD_TAKE_PROBE_REFERENCE);
    let (now, out) = rig.cycle(&mut app, step + 6);
    app.set_probe(&ok_reading(out.corrections[0] + 20), Some((&rig.acq, now)));
    assert_eq!(settled_result(&mut app), result::OK);
    assert_eq!(app.references().state(0).unwrap().accepted, 1);
    app.program(&demo_image(2, 2)).unwrap();
    assert_eq!(app.references().state(0), Some(&ReferenceState::new(&p)));
    let app = power_cycle(&rig, &mut app);
    assert_eq!(app.references().state(0), Some(&ReferenceState::new(&p)));
}

#[test]
fn a_probe_that_is_not_ok_or_without_its_temperature_takes_no_reference() {
    let mut rig = Rig::new();
    let mut app = boot(&rig, MockFlash::new(2 * SLOT as usize));
    app.program(&demo_image(1, 1)).unwrap();
    write(&mut app, HR_PROBE_DIRECTION, 0);
    settled_result(&mut app);
    // The probe's DS18B20 on channel 5.
    write(&mut app, HR_PROBE_TEMP_CHANNEL, 5);
    settled_result(&mut app);
    write(&mut app, HR_COMMAND, CMD_TAKE_PROBE_REFERENCE);
    let (now, _) = rig.cycle(&mut app, 1);
    let mut bad = ok_reading(10);
    bad.state = ProbeState::OutOfRange;
    app.set_probe(&bad, Some((&rig.acq, now)));
    assert_eq!(app.result(), result::PROBE_NOT_READY);
    // The probe's sensor gone: no drift correction possible, no reference.
    rig.bus.unplug(rig.device_on(5));
    write(&mut app, HR_COMMAND, CMD_TAKE_PROBE_REFERENCE);
    let (now, _) = rig.cycle(&mut app, 1);
    app.set_probe(&ok_reading(10), Some((&rig.acq, now)));
    assert_eq!(app.result(), result::PROBE_TEMPERATURE_MISSING);
    assert_eq!(app.references().state(0).unwrap().accepted, 0);
    assert_eq!(app.references().state(0).unwrap().refused, 0);
    // Out-of-range settings are refused with exception 03.
    let reply = write(&mut app, HR_REFERENCE_SAMPLES, 0);
    assert_eq!(reply[1], 0x86, "{reply:02x?}");
    let reply = write(&mut app, HR_PROBE_DIRECTION, 6);
    assert_eq!(reply[1], 0x86, "{reply:02x?}");
}

/// A 16-bit probe ADC (±1000 µm) at a fixed target whose reading drifts
/// 0.5 µm/K with its own temperature, with ±3 codes of noise.
struct DriftingProbe {
    gap_tenth_um: f64,
    temp_c: f64,
    seed: u64,
}

const DRIFT_UM_PER_K: f64 = 0.5;

impl ProbeAdc for DriftingProbe {
    fn full_scale(&self) -> u16 {
        u16::MAX
    }
    async fn sample(&mut self) -> Result<u16, AdcError> {
        self.seed = self
            .seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let u = (self.seed >> 11) as f64 / (1u64 << 53) as f64;
        let y = self.gap_tenth_um + 10.0 * DRIFT_UM_PER_K * (self.temp_c - 20.0);
        let code = (y + 10_000.0) * 65_536.0 / 20_000.0 + (2.0 * u - 1.0) * 3.0;
        Ok(code.round().clamp(0.0, 65_535.0) as u16)
    }
}

fn probe_config() -> ProbeConfig {
    ProbeConfig {
        oversample: 256,
        saturation_margin: 8,
        calibration: Calibration::linear(-10_000, 20_000, 65_536).unwrap(),
        min_tenth_um: -9_000,
        max_tenth_um: 9_000,
    }
}

/// Least-squares slope of y on x.
fn slope(pts: &[(f64, f64)]) -> f64 {
    let n = pts.len() as f64;
    let (mx, my) = (
        pts.iter().map(|p| p.0).sum::<f64>() / n,
        pts.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    sxy / sxx
}

#[test]
fn the_probes_own_drift_is_estimated_and_removed_to_a_tenth() {
    let mut rig = Rig::new();
    let mut adc = DriftingProbe {
        gap_tenth_um: 1_234.0,
        temp_c: 20.0,
        seed: 7,
    };
    // The probe's DS18B20 is channel 5 (T06); the target does not move while
    // the probe warms from 15 to 35 °C: record what the board reads.
    let temps: Vec<f64> = (0..41).map(|i| 15.0 + 0.5 * f64::from(i)).collect();
    let mut csv = String::from("time_s,T06,probe_raw_um\n");
    let mut raw_pts = vec![];
    let dev = rig.device_on(5);
    for (i, &t) in temps.iter().enumerate() {
        rig.bus
            .with_device(dev, |d| d.temperature = (t * 16.0) as i16);
        rig.bus.advance_ns(1_000 * MS);
        let now = rig.bus.now_ms();
        block_on(
            rig.acq
                .cycle(&mut master(&rig.bus), &mut rig.bus.delay(), now),
        );
        let t16 = rig.acq.value(5, now).usable().unwrap();
        adc.temp_c = f64::from(t16) / 16.0;
        let r = block_on(measure(&mut adc, &probe_config()));
        assert_eq!(r.state, ProbeState::Ok);
        let um = f64::from(r.tenth_um.unwrap()) / 10.0;
        raw_pts.push((adc.temp_c, um));
        csv += &format!("{i},{},{um:.1}\n", f64::from(t16) / 16.0);
    }
    assert!(
        (slope(&raw_pts) - DRIFT_UM_PER_K).abs() < 0.02,
        "{}",
        slope(&raw_pts)
    );
    let run = tcomp_data::runcsv::Run::from_reader(csv.as_bytes()).unwrap();
    let est = tcomp_model::probe_drift::estimate(&run, "T06").unwrap();
    assert!((est.um_per_k - DRIFT_UM_PER_K).abs() < 0.03, "{est:?}");

    // The board with the estimate (holding registers 42–43) and the gauge
    // zero at the true gap: what a reference uses has the drift removed.
    let mut app = boot(&rig, MockFlash::new(2 * SLOT as usize));
    app.program(&demo_image(1, 1)).unwrap();
    for (a, v) in [
        (HR_PROBE_DIRECTION, 0),
        (HR_PROBE_TEMP_CHANNEL, 5),
        (HR_PROBE_DRIFT, est.register_nm_per_k as u16),
        (HR_GAUGE_ZERO + 1, 1_234),
    ] {
        write(&mut app, a, v);
        assert_eq!(settled_result(&mut app), result::OK);
    }
    let mut used = vec![];
    for &t in temps.iter().rev() {
        rig.bus
            .with_device(dev, |d| d.temperature = (t * 16.0) as i16);
        // Fresh terms for each: the innovation is then reading − model.
        write(&mut app, HR_COMMAND, CMD_RESET_REFERENCE_TERMS);
        settled_result(&mut app);
        write(&mut app, HR_COMMAND, CMD_TAKE_PROBE_REFERENCE);
        rig.bus.advance_ns(1_000 * MS);
        let now = rig.bus.now_ms();
        block_on(
            rig.acq
                .cycle(&mut master(&rig.bus), &mut rig.bus.delay(), now),
        );
        let out = app.cycle(&rig.acq, now, now, Some(0));
        adc.temp_c = f64::from(rig.acq.value(5, now).usable().unwrap()) / 16.0;
        let mut cfg = probe_config();
        cfg.oversample = app.probe_reference_samples().unwrap();
        let r = block_on(measure(&mut adc, &cfg));
        app.set_probe(&r, Some((&rig.acq, now)));
        settled_result(&mut app);
        let st = app.references().state(0).unwrap();
        assert_eq!(st.accepted + st.refused, 1);
        let y_nm = f64::from(st.last_innovation_nm) + 100.0 * f64::from(out.corrections[0]);
        used.push((adc.temp_c, y_nm / 1000.0));
    }
    let left = slope(&used);
    println!(
        "probe drift: injected {DRIFT_UM_PER_K} µm/K, estimated {:.4} µm/K, left after removal {left:+.4} µm/K",
        est.um_per_k
    );
    assert!(left.abs() <= 0.05, "left {left} µm/K");
    // Without the removal the board would have used the full drift.
    assert!(slope(&raw_pts).abs() > 0.4);
}

/// Hostile run of issue 30: a PLC that sets the probe direction and gives
/// command 12 straight after (the settings are still being stored) reads
/// 62 (not taken) in holding register 2, then 0 once the settings store
/// ends — and 0 is "accepted" for command 12 (docs/register-map.md). The
/// reference was not taken; the register must not say it was.
#[test]
fn a_settings_store_ending_after_a_refused_probe_reference_does_not_report_ok() {
    let mut rig = Rig::new();
    let mut app = boot(&rig, MockFlash::new(2 * SLOT as usize));
    app.program(&demo_image(1, 1)).unwrap();
    // Register 40 changes: a settings store starts (result 23); not settled.
    write(&mut app, HR_PROBE_DIRECTION, 0);
    assert!(app.flash_busy());
    write(&mut app, HR_COMMAND, CMD_TAKE_PROBE_REFERENCE);
    let (now, _) = rig.cycle(&mut app, 1);
    let mut bad = ok_reading(10);
    bad.state = ProbeState::OutOfRange;
    app.set_probe(&bad, Some((&rig.acq, now)));
    assert_eq!(app.result(), result::PROBE_NOT_READY);
    assert_eq!(app.references().state(0).unwrap().accepted, 0);
    // The settings store ends: what the PLC reads now.
    let settled = settled_result(&mut app);
    assert_eq!(app.references().state(0).unwrap().accepted, 0);
    assert_ne!(
        settled,
        result::OK,
        "holding register 2 says 0 (accepted) for a probe reference that was not taken"
    );
}
