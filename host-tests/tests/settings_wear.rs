//! The settings store on its own sectors (issue 47): settings writes never
//! erase a model slot and erase at most one store page each, and only when
//! a page fills; a power cut at every flash operation of a store — a plain
//! append, the one that opens a fresh page, and the one that wraps around
//! and moves the live records out of the oldest page — leaves the old
//! settings or the new ones, never neither, with the model intact; a board
//! whose settings sit in the old slot layout keeps them on its first boot
//! (also when the store's sectors held something else before).
use host_tests::mock_flash::{MockFlash, ERASE_SIZE};
use host_tests::modbus::{self, demo_image, write_unlocked, SLOT};
use thermocomp::acquisition::channel_map::ChannelMap;
use thermocomp::app::App;
use thermocomp::model_store::ModelStore;
use thermocomp::probe_reference::References;
use thermocomp::settings::{KeptReference, Settings, StoredKeys};
use thermocomp::settings_store::{AREA_BYTES, PAGE};
use thermocomp_protocol::holding::*;

fn boot(flash: MockFlash) -> App<MockFlash> {
    modbus::boot(flash, ChannelMap::new())
}

/// Erases of the model slots' sectors and of the store's pages so far.
fn erases(app: &mut App<MockFlash>) -> (u64, u64) {
    let f = app.flash_mut();
    let at = f.settings_at() as usize / ERASE_SIZE;
    let slots: u64 = f.erase_counts[..2 * SLOT as usize / ERASE_SIZE]
        .iter()
        .sum();
    let store: u64 = f.erase_counts[at..at + AREA_BYTES as usize / ERASE_SIZE]
        .iter()
        .sum();
    (slots, store * ERASE_SIZE as u64 / u64::from(PAGE))
}

/// Write clamp 0 = `v` over Modbus and run the store job to its end: HR_RESULT.
fn write_clamp(app: &mut App<MockFlash>, v: u16) -> u16 {
    write_unlocked(app, HR_CLAMP, v);
    while app.poll_flash() {}
    app.result()
}

/// A board with a model and the store filled by `n` clamp writes (1..=n).
fn board_after(n: u16) -> App<MockFlash> {
    let mut app = boot(MockFlash::new(2 * SLOT as usize));
    app.program(&demo_image(3, 1)).unwrap();
    while app.poll_flash() {}
    for v in 1..=n {
        assert_eq!(write_clamp(&mut app, v), result::OK);
    }
    app
}

#[test]
fn settings_writes_never_erase_a_slot_and_a_power_cut_anywhere_leaves_old_or_new() {
    // Pass 1: which writes erase a store page (the one that opens a fresh
    // page, and the wrap that moves live records out of the oldest).
    let mut app = board_after(0);
    let (slots0, _) = erases(&mut app);
    let mut erasing = Vec::new();
    for v in 1..=1500u16 {
        let (_, before) = erases(&mut app);
        assert_eq!(write_clamp(&mut app, v), result::OK);
        let (slots, after) = erases(&mut app);
        assert_eq!(slots, slots0, "write {v}: no model-slot erase");
        assert!(
            after - before <= 1,
            "write {v} erased {} pages",
            after - before
        );
        if after > before {
            erasing.push(v);
        }
    }
    assert!(
        erasing.len() >= 2,
        "1500 writes fill the 3 pages: {erasing:?}"
    );
    // Pass 2: at a plain append and at each of the first two erasing
    // writes, a power cut at every flash operation.
    let mut wanted = vec![2u16, erasing[0], erasing[1]];
    wanted.sort_unstable();
    for &v in &wanted {
        let image = board_after(v - 1).flash_mut().bytes.clone();
        let per_op = {
            let mut probe = from_bytes(&image);
            let ops = probe.flash_mut().operations;
            assert_eq!(write_clamp(&mut probe, v), result::OK);
            probe.flash_mut().operations - ops
        };
        assert!(per_op >= 3, "write {v}: {per_op} operations");
        let (mut n_old, mut n_new) = (0, 0);
        for cut in 0..=per_op {
            let mut app = from_bytes(&image);
            app.flash_mut().budget = Some(cut);
            let stored = write_clamp(&mut app, v) == result::OK;
            let app = modbus::power_cycle(&mut app, ChannelMap::new());
            assert_eq!(app.model_version(), 1, "write {v}, cut at {cut}: the model");
            let clamp = app.settings().clamp[0];
            match clamp {
                c if c == v => n_new += 1,
                c if c == v - 1 => {
                    assert!(
                        !stored,
                        "write {v}, cut at {cut}: reported stored, old after reboot"
                    );
                    n_old += 1;
                }
                c => panic!("write {v}, cut at {cut}: clamp {c}, neither old nor new"),
            }
        }
        assert!(
            n_old > 0 && n_new > 0,
            "write {v}: {n_old} old, {n_new} new"
        );
    }
}

fn from_bytes(bytes: &[u8]) -> App<MockFlash> {
    let mut f = MockFlash::new(0);
    f.bytes = bytes.to_vec();
    boot(f)
}

/// The settings block of the old slot layout: settings, channel map, kept
/// reference ('R'), probe references ('Q'), keys ('K').
fn old_blob(settings: &Settings, kept: &KeptReference, keys: &StoredKeys) -> Vec<u8> {
    let setup = thermocomp::probe_reference::ProbeSetup {
        direction: Some(2),
        samples: 64,
        temp_channel: Some(5),
        drift_nm_per_k: -120,
        gauge_zero: 4321,
    };
    let mut v = settings.encode().to_vec();
    v.extend_from_slice(&ChannelMap::new().to_bytes());
    v.extend_from_slice(&kept.encode());
    v.extend_from_slice(&References::new().encode(&setup));
    v.extend_from_slice(&keys.encode());
    v
}

#[test]
fn a_board_with_settings_in_the_old_slot_layout_keeps_them_on_first_boot() {
    let settings = Settings {
        unit: 17,
        baud: 19_200,
        clamp: [150, 200, 300, u16::MAX, u16::MAX, 50],
        rate: [9; 6],
    };
    let mut temps = [None; thermocomp_protocol::MAX_CHANNELS];
    temps[0] = Some(21 * 16);
    temps[3] = Some(-5 * 16);
    let kept = KeptReference { temps };
    let keys = StoredKeys {
        unlock: Some(0x5A17),
        signing: Some([7; 32]),
    };
    let blob = old_blob(&settings, &kept, &keys);
    for garbage in [false, true] {
        // The old firmware's layout: model and settings in slot A; the
        // store's sectors erased, or (an update over old program code)
        // holding anything.
        let mut flash = MockFlash::new(2 * SLOT as usize);
        if garbage {
            let at = flash.settings_at() as usize;
            for (i, b) in flash.bytes[at..].iter_mut().enumerate() {
                *b = (i as u32).wrapping_mul(2_654_435_761).to_le_bytes()[3];
            }
        }
        let mut store = ModelStore::new(flash, SLOT);
        store.commit_with(&demo_image(4, 1), &blob).unwrap();
        let mut flash = std::mem::replace(store.flash(), MockFlash::new(0));
        let slot_erases: u64 = flash.erase_counts[..2 * SLOT as usize / ERASE_SIZE]
            .iter()
            .sum();
        flash.power_on();
        let mut app = App::new(flash, SLOT, 1, 115_200, ChannelMap::new());
        let check = |app: &App<MockFlash>, when: &str| {
            assert_eq!(app.settings(), settings, "{when} (garbage {garbage})");
            assert_eq!(app.kept_reference(), Some(kept), "{when}");
            assert_eq!(app.keys().unlock, keys.unlock, "{when}");
            assert_eq!(app.keys().signing, keys.signing, "{when}");
            assert_eq!(app.probe_setup().direction, Some(2), "{when}");
            assert_eq!(app.probe_setup().gauge_zero, 4321, "{when}");
            assert_eq!(app.model_version(), 1, "{when}");
        };
        check(&app, "first boot");
        let now: u64 = app.flash_mut().erase_counts[..2 * SLOT as usize / ERASE_SIZE]
            .iter()
            .sum();
        assert_eq!(now, slot_erases, "migration erases no model slot");
        // A new model (its slot has no settings block) and a reboot: the
        // settings now come from the store.
        app.program(&demo_image(5, 2)).unwrap();
        let mut flash = std::mem::replace(app.flash_mut(), MockFlash::new(0));
        flash.power_on();
        let app = App::new(flash, SLOT, 1, 115_200, ChannelMap::new());
        assert_eq!(
            app.settings(),
            settings,
            "after a new model (garbage {garbage})"
        );
        assert_eq!(app.kept_reference(), Some(kept));
        assert_eq!(app.keys().unlock, keys.unlock);
        assert_eq!(app.probe_setup().gauge_zero, 4321);
        assert_eq!(app.model_version(), 2);
    }
}
