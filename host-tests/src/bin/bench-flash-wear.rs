//! Flash wear of the board's stores (issue 47), on the mock flash with the
//! F446's layout in miniature: the application exactly as the boards run it
//! (`App` over Modbus requests), one simulated year of a probe reference
//! per minute (command 12, then the reading, then the store job) and a
//! settings write per hour (a clamp register). Counts, per sector, the
//! erases of the settings store's three 16 KiB pages and of the model
//! slots, and the most pages one store erased (each a CPU stall of one
//! 16 KiB sector erase on the NUCLEO).
//!
//!   cargo run --release -p host-tests --bin bench-flash-wear -- [--json] [--minutes N]

use std::time::Instant;

use host_tests::mock_flash::{MockFlash, ERASE_SIZE};
use host_tests::modbus::{self, demo_image, write_unlocked, SLOT};
use host_tests::onewire_emu::{block_on, bus_with_sensors, master, MS};
use thermocomp::acquisition::channel_map::ChannelMap;
use thermocomp::acquisition::temperature::{AcquisitionConfig, TemperatureAcquisition};
use thermocomp::settings_store::{AREA_BYTES, PAGE, PAGES};
use thermocomp_protocol::holding::{HR_CLAMP, HR_COMMAND, HR_PROBE_DIRECTION};

#[derive(clap::Parser)]
#[command(about = "Flash wear of the settings store and the model slots over one simulated year")]
struct Args {
    /// Print the figures as JSON.
    #[arg(long)]
    json: bool,
    /// Simulated minutes (one probe reference each; a settings write every 60).
    #[arg(long, default_value_t = 525_600)]
    minutes: u64,
}

/// Erases of each `size`-byte sector in `[from, to)` of the mock.
fn sector_erases(flash: &MockFlash, from: u32, to: u32, size: u32) -> Vec<u64> {
    (from..to)
        .step_by(size as usize)
        .map(|s| {
            // A sector's erases: those of its first mock sector (the
            // application erases whole sectors).
            flash.erase_counts[s as usize / ERASE_SIZE]
        })
        .collect()
}

fn main() {
    let args: Args = host_tests::cli::parse_or_exit();
    let started = Instant::now();
    // One acquisition cycle on six emulated DS18B20s: the values the
    // application's cycles read (they age; the compensator still steps).
    let bus = bus_with_sensors(6, 0x2EF_0028, 20 * 16);
    let mut acq = TemperatureAcquisition::new(AcquisitionConfig::default(), ChannelMap::new());
    block_on(acq.discover(&mut master(&bus))).expect("six sensors");
    block_on(acq.configure(&mut master(&bus))).expect("configured");
    bus.advance_ns(1_000 * MS);
    let t0 = bus.now_ms();
    block_on(acq.cycle(&mut master(&bus), &mut bus.delay(), t0));

    let mut app = modbus::boot(MockFlash::new(2 * SLOT as usize), *acq.map());
    app.program(&demo_image(7, 1)).expect("demo model stored");
    write_unlocked(&mut app, HR_PROBE_DIRECTION, 0);
    while app.poll_flash() {}
    let settings_at = app.flash_mut().settings_at();
    let slots_before = sector_erases(app.flash_mut(), 0, 2 * SLOT, SLOT);
    let store_before = sector_erases(app.flash_mut(), settings_at, settings_at + AREA_BYTES, PAGE);

    let (mut stores, mut max_pages, mut failed) = (0u64, 0u64, 0u64);
    for minute in 0..args.minutes {
        let now = t0 + minute * 60_000;
        app.cycle(&acq, now, now, Some(3000));
        write_unlocked(&mut app, HR_COMMAND, 12);
        // A reading that wanders a few µm about the model: accepted or
        // refused, the direction's terms change either way.
        let reading = (minute % 97) as i32 * 3 - 140;
        app.take_probe_reference(Some(reading), &acq, now);
        if minute % 60 == 59 {
            write_unlocked(&mut app, HR_CLAMP, 1000 + (minute / 60 % 2) as u16);
        }
        let before: u64 = app.flash_mut().erase_counts.iter().sum();
        while app.poll_flash() {}
        let after: u64 = app.flash_mut().erase_counts.iter().sum();
        let pages = (after - before) * ERASE_SIZE as u64 / u64::from(PAGE);
        max_pages = max_pages.max(pages);
        stores += 1;
        if app.result() == thermocomp_protocol::holding::result::SETTINGS_NOT_STORED {
            failed += 1;
        }
    }

    let flash = app.flash_mut();
    let years = args.minutes as f64 / 525_600.0;
    let store: Vec<u64> = sector_erases(flash, settings_at, settings_at + AREA_BYTES, PAGE)
        .iter()
        .zip(&store_before)
        .map(|(a, b)| a - b)
        .collect();
    let slots: Vec<u64> = sector_erases(flash, 0, 2 * SLOT, SLOT)
        .iter()
        .zip(&slots_before)
        .map(|(a, b)| a - b)
        .collect();
    let per_year_max = store.iter().copied().max().unwrap_or(0) as f64 / years;
    let ten_years = per_year_max * 10.0;
    let met = ten_years <= 10_000.0 && slots.iter().all(|&e| e == 0) && max_pages <= 1;
    if args.json {
        println!(
            "{}",
            serde_json::json!({
                "minutes": args.minutes,
                "references": args.minutes,
                "settings_writes": args.minutes / 60,
                "stores": stores,
                "stores_failed": failed,
                "store_pages": PAGES,
                "store_page_bytes": PAGE,
                "store_erases_per_page": store,
                "store_erases_per_page_per_year_max": per_year_max,
                "store_erases_per_page_10_years_max": ten_years,
                "endurance_cycles": 10_000,
                "model_slot_erases": slots,
                "max_pages_erased_by_one_store": max_pages,
                "goal_met": met,
                "wall_s": started.elapsed().as_secs_f64(),
            })
        );
    } else {
        println!(
            "{} min simulated: {} references, {} settings writes, {} stores ({} failed)",
            args.minutes,
            args.minutes,
            args.minutes / 60,
            stores,
            failed
        );
        println!(
            "settings store ({} × {} KiB pages): erases per page {:?} → {:.0} per year, {:.0} in 10 years (endurance 10,000)",
            PAGES,
            PAGE / 1024,
            store,
            per_year_max,
            ten_years
        );
        println!("model slot erases: {slots:?}; most pages erased by one store: {max_pages}");
        println!(
            "goal (≤ 10,000 in 10 years, 0 slot erases, ≤ 1 page per store): {}",
            if met { "met" } else { "NOT met" }
        );
    }
}
