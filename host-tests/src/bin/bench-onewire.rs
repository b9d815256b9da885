//! Bus time of one full acquisition cycle of 20 DS18B20s at 12-bit resolution
//! (Skip ROM + Convert T, conversion wait, 20 × Match ROM + Read Scratchpad),
//! measured on the pin-level emulator's virtual clock with the board's real
//! acquisition code and slot timing. The conversion-time floor is the
//! datasheet maximum t_CONV = 750 ms.
//!
//! `cargo run -p host-tests --bin bench-onewire -- [--json]`

use embedded_hal_02::blocking::delay::DelayMs;
use host_tests::onewire_emu::{block_on, bus_with_sensors, master, Bus, MS};
use thermocomp::acquisition::channel_map::ChannelMap;
use thermocomp::acquisition::temperature::{AcquisitionConfig, TemperatureAcquisition};

/// The command line (clap: `--help` lists every flag).
#[derive(clap::Parser)]
#[command(
    about = "Bus time of one acquisition cycle of 20 DS18B20s at 12 bit on the pin-level emulator, against the 750 ms conversion floor"
)]
struct Args {
    /// Print the figures as JSON.
    #[arg(long)]
    json: bool,
}

const SENSORS: usize = 20;
const FLOOR_MS: f64 = 750.0;
const TARGET_MS: f64 = 1000.0;

struct Run {
    cycle_ms: f64,
    conversion_wait_ms: f64,
    read_ms_per_sensor: f64,
    ok: u8,
    violations: u64,
}

fn board_cycle(conversion_permille: u32) -> Run {
    let bus = bus_with_sensors(SENSORS, 0xBE4C, 21 * 16);
    for i in 0..SENSORS {
        bus.with_device(i, |d| {
            d.conversion_scale_permille = conversion_permille;
            d.temperature += i as i16;
        });
    }
    let mut acq = TemperatureAcquisition::new(AcquisitionConfig::default(), ChannelMap::new());
    let mut m = master(&bus);
    let _ = block_on(acq.discover(&mut m));
    let _ = block_on(acq.configure(&mut m));
    let mut d = bus.delay();
    // Warm-up cycle (first conversion), then the measured one.
    block_on(acq.cycle(&mut m, &mut d, bus.now_ms()));
    bus.advance_ns(1_000 * MS);
    bus.reset_stats();
    let t0 = bus.now_ns();
    let report = block_on(acq.cycle(&mut m, &mut d, bus.now_ms()));
    let total = (bus.now_ns() - t0) as f64 / 1e6;
    // One Match ROM + Read Scratchpad alone, to split the cycle.
    let rom = acq.map().get(0);
    let t1 = bus.now_ns();
    if let Some(rom) = rom {
        let _ = block_on(thermocomp::acquisition::temperature::read_scratchpad(
            &mut m, &rom,
        ));
    }
    let read = (bus.now_ns() - t1) as f64 / 1e6;
    Run {
        cycle_ms: total,
        conversion_wait_ms: total - read * SENSORS as f64,
        read_ms_per_sensor: read,
        ok: report.ok,
        violations: bus.stats().violations.total(),
    }
}

/// The same cycle done with `one-wire-bus` + `ds18b20` 0.1.1 (blocking
/// 750 ms wait, crate slot timing).
fn crate_cycle() -> f64 {
    let bus: Bus = bus_with_sensors(SENSORS, 0xBE4C, 21 * 16);
    let mut ow = match one_wire_bus::OneWire::new(bus.pin()) {
        Ok(ow) => ow,
        Err(_) => return f64::NAN,
    };
    let mut delay = bus.delay();
    let addrs: Vec<_> = ow
        .devices(false, &mut delay)
        .filter_map(Result::ok)
        .collect();
    let t0 = bus.now_ns();
    let _ = ds18b20::start_simultaneous_temp_measurement(&mut ow, &mut delay);
    delay.delay_ms(750u16);
    for a in &addrs {
        let _ = ds18b20::read_scratchpad(a, &mut ow, &mut delay);
    }
    (bus.now_ns() - t0) as f64 / 1e6
}

fn main() {
    let Args { json } = host_tests::cli::parse_or_exit();
    let worst = board_cycle(1000);
    let typical = board_cycle(800);
    let crates = crate_cycle();
    if json {
        println!(
            "{{\"sensors\":{SENSORS},\"resolution_bits\":12,\"cycle_ms\":{:.3},\"convert_phase_ms\":{:.3},\"read_ms_per_sensor\":{:.3},\"floor_ms\":{FLOOR_MS},\"above_floor_ms\":{:.3},\"target_ms\":{TARGET_MS},\"meets_target\":{},\"sensors_ok\":{},\"timing_violations\":{},\"cycle_ms_conversion_600ms\":{:.3},\"crates_cycle_ms\":{:.3}}}",
            worst.cycle_ms,
            worst.conversion_wait_ms,
            worst.read_ms_per_sensor,
            worst.cycle_ms - FLOOR_MS,
            worst.cycle_ms <= TARGET_MS,
            worst.ok,
            worst.violations,
            typical.cycle_ms,
            crates
        );
    } else {
        println!("one acquisition cycle, {SENSORS} x DS18B20 at 12 bit (emulated bus time)");
        println!(
            "  cycle {:.3} ms (target <= {TARGET_MS} ms: {})",
            worst.cycle_ms,
            if worst.cycle_ms <= TARGET_MS {
                "met"
            } else {
                "MISSED"
            }
        );
        println!(
            "  Skip ROM + Convert T + wait until done {:.3} ms (t_CONV 750 ms, polled every 2 ms)",
            worst.conversion_wait_ms
        );
        println!(
            "  reads {:.3} ms = {SENSORS} x {:.3} ms (reset + Match ROM + Read Scratchpad)",
            worst.cycle_ms - worst.conversion_wait_ms,
            worst.read_ms_per_sensor
        );
        println!(
            "  above the 750 ms conversion floor: {:.3} ms",
            worst.cycle_ms - FLOOR_MS
        );
        println!(
            "  sensors ok {}/{SENSORS}, timing violations {}",
            worst.ok, worst.violations
        );
        println!(
            "  parts converting in 600 ms (polled completion): cycle {:.3} ms",
            typical.cycle_ms
        );
        println!("  one-wire-bus + ds18b20 0.1.1, same bus: {crates:.3} ms (executor blocked throughout)");
    }
}
