//! The application state both board tasks share: a model committed over
//! Modbus lands in the flash slots and serves; a refused one changes
//! nothing; the probe reading reaches its registers; a reboot finds the model.
use host_tests::mock_flash::MockFlash;
use host_tests::modbus::{blank_app, demo_image, stage_and_send, SLOT};
use thermocomp::acquisition::channel_map::ChannelMap;
use thermocomp::acquisition::probe::ProbeReading;
use thermocomp::app::App;
use thermocomp_protocol::holding::*;
use thermocomp_protocol::registers::*;
use thermocomp_protocol::states::ProbeState;

fn image(version: u32) -> Vec<u8> {
    demo_image(u64::from(version), version)
}

fn upload(app: &mut App<MockFlash>, img: &[u8]) -> Vec<u8> {
    upload_with(app, img, CMD_COMMIT_MODEL)
}

fn upload_with(app: &mut App<MockFlash>, img: &[u8], command: u16) -> Vec<u8> {
    host_tests::commission(app);
    // The flash write runs in the background; the mock erases at once.
    let reply = stage_and_send(app, img, command);
    assert!(!app.flash_busy());
    reply
}

#[test]
fn commit_over_modbus_serves_and_survives_a_reboot() {
    let mut app = blank_app();
    assert_eq!(app.model_version(), 0, "blank flash: no model");
    let v2 = image(2);
    let reply = upload(&mut app, &v2);
    assert_eq!(reply[1], 6, "commit acknowledged: {reply:02x?}");
    assert_eq!(app.model_version(), 2);
    assert_eq!(
        app.model_crc(),
        u32::from_le_bytes(v2[v2.len() - 4..].try_into().unwrap())
    );
    assert_eq!(app.result(), result::OK);
    // A corrupted image: exception 04, v2 keeps serving.
    let mut bad = image(3);
    bad[50] ^= 1;
    let reply = upload(&mut app, &bad);
    assert_eq!((reply[1], reply[2]), (0x86, 0x04), "{reply:02x?}");
    assert_eq!(app.model_version(), 2);
    // Reboot: the flash still holds v2.
    let flash = std::mem::replace(app.flash_mut(), MockFlash::new(0));
    let rebooted = App::new(flash, SLOT, 1, 115_200, ChannelMap::new());
    assert_eq!(rebooted.model_version(), 2);
}

#[test]
fn a_version_not_newer_is_refused_unless_the_rollback_command_commits_it() {
    let mut app = blank_app();
    assert_eq!(upload(&mut app, &image(3))[1], 6);
    assert_eq!(app.model_version(), 3);
    for older_or_same in [2, 3] {
        let reply = upload(&mut app, &image(older_or_same));
        assert_eq!((reply[1], reply[2]), (0x86, 0x04), "{reply:02x?}");
        assert_eq!(app.result(), result::NOT_NEWER);
        assert_eq!(app.model_version(), 3);
    }
    // The rollback command commits the older model (after every other check).
    let mut broken = image(2);
    broken[60] ^= 1;
    let reply = upload_with(&mut app, &broken, CMD_ROLLBACK_MODEL);
    assert_eq!((reply[1], reply[2]), (0x86, 0x04));
    assert_eq!(app.result(), result::BAD_CRC);
    let reply = upload_with(&mut app, &image(2), CMD_ROLLBACK_MODEL);
    assert_eq!(reply[1], 6, "{reply:02x?}");
    assert_eq!(app.result(), result::OK);
    assert_eq!(app.model_version(), 2);
    // After a reboot v2 serves (the newer slot), and v2 again is not newer.
    let flash = std::mem::replace(app.flash_mut(), MockFlash::new(0));
    let mut rebooted = App::new(flash, SLOT, 1, 115_200, ChannelMap::new());
    assert_eq!(rebooted.model_version(), 2);
    let reply = upload(&mut rebooted, &image(2));
    assert_eq!((reply[1], reply[2]), (0x86, 0x04));
    assert_eq!(rebooted.result(), result::NOT_NEWER);
    assert_eq!(upload(&mut rebooted, &image(4))[1], 6);
    assert_eq!(rebooted.model_version(), 4);
}

#[test]
fn a_failing_flash_reports_store_failed_and_keeps_the_old_model() {
    let mut app = blank_app();
    upload(&mut app, &image(2));
    app.flash_mut().budget = Some(3); // power fails during the next commit
    upload(&mut app, &image(4));
    assert_eq!(app.result(), result::STORE_FAILED);
    assert_eq!(app.model_version(), 2);
}

#[test]
fn probe_reading_reaches_its_registers() {
    let mut app = blank_app();
    let r = ProbeReading {
        state: ProbeState::Ok,
        tenth_um: Some(-12_345),
        mean_x16: 0,
        min_code: 0,
        max_code: 0,
    };
    app.set_probe(&r, None);
    let hi = app.snapshot().input_register(IR_PROBE).unwrap();
    let lo = app.snapshot().input_register(IR_PROBE + 1).unwrap();
    assert_eq!(((u32::from(hi) << 16) | u32::from(lo)) as i32, -12_345);
    assert_eq!(
        app.snapshot().input_register(IR_PROBE_STATE),
        Some(ProbeState::Ok.code())
    );
}
