//! Settings that persist: stored with the model in the A/B slots, applied at
//! boot, restored to defaults by command 7, and a power cut at every flash
//! operation of a settings commit (or of a model commit) leaves the old
//! settings or the new ones, with the model intact.
use embedded_storage::nor_flash::NorFlash as _;
use host_tests::mock_flash::{MockFlash, ERASE_SIZE};
use host_tests::modbus::{self, frame, write1, Reply, SLOT};
use thermocomp::acquisition::channel_map::ChannelMap;
use thermocomp::app::App;
use thermocomp::model_store::ModelStore;
use thermocomp::settings::Settings;
use thermocomp_core::limits::MAX_IMAGE_BYTES;
use thermocomp_core::Model;
use thermocomp_protocol::holding::*;

fn image(version: u32) -> (Model, Vec<u8>) {
    let mut fm = thermocomp_core::float::demo_model(u64::from(version));
    fm.model_version = version;
    let (mut m, _) = fm.quantize().unwrap();
    let mut b = vec![0u8; m.encoded_len()];
    m.encode(&mut b).unwrap();
    (Model::parse(&b).unwrap(), b)
}

fn settings(k: u16) -> Settings {
    Settings {
        unit: 10 + k as u8,
        baud: 19_200,
        clamp: [100 + k, 200, 300, u16::MAX, u16::MAX, 50],
        rate: [7 + k; 6],
    }
}

fn reboot(store: &mut ModelStore<MockFlash>) -> ModelStore<MockFlash> {
    let mut flash = std::mem::replace(store.flash(), MockFlash::new(0));
    flash.power_on();
    ModelStore::new(flash, SLOT)
}

fn stored(store: &ModelStore<MockFlash>) -> Option<Settings> {
    store.settings().and_then(Settings::decode)
}

#[test]
fn settings_and_model_survive_reboots_each_keeping_the_other() {
    let mut buf = [0u8; MAX_IMAGE_BYTES];
    let mut store = ModelStore::new(MockFlash::new(2 * SLOT as usize), SLOT);
    assert_eq!(store.load(&mut buf), None);
    assert_eq!(store.settings(), None, "blank flash: defaults");
    // Settings before any model: a settings-only slot.
    store.commit_settings(&settings(1).encode()).unwrap();
    let mut store = reboot(&mut store);
    assert_eq!(store.load(&mut buf), None);
    assert_eq!(stored(&store), Some(settings(1)));
    // A model commit keeps the settings.
    let (m1, b1) = image(1);
    store.commit(&b1).unwrap();
    let mut store = reboot(&mut store);
    assert_eq!(store.load(&mut buf), Some(m1.clone()));
    assert_eq!(stored(&store), Some(settings(1)));
    // A settings commit keeps the model.
    store.commit_settings(&settings(2).encode()).unwrap();
    let mut store = reboot(&mut store);
    assert_eq!(store.load(&mut buf), Some(m1));
    assert_eq!(stored(&store), Some(settings(2)));
}

/// Cut the power at every flash operation of `op` (starting from a store
/// holding model v1 and settings(1)); after the reboot `check` gets what
/// loaded. Returns how many cuts left the old and the new state.
fn cut_everywhere(
    op: impl Fn(&mut ModelStore<MockFlash>) -> bool,
    check: impl Fn(u64, Option<Model>, Option<Settings>) -> bool,
) -> (u32, u32) {
    let (_, b1) = image(1);
    let fresh = || {
        let mut s = ModelStore::new(MockFlash::new(2 * SLOT as usize), SLOT);
        s.commit(&b1).unwrap();
        s.commit_settings(&settings(1).encode()).unwrap();
        s.commit(&b1).unwrap(); // both slots written once: stale data in the inactive one
        s
    };
    let mut probe = fresh();
    let before = probe.flash().operations;
    assert!(op(&mut probe));
    let per_op = probe.flash().operations - before;
    assert!(per_op > 3, "{per_op}");
    let (mut old, mut new) = (0, 0);
    let mut buf = [0u8; MAX_IMAGE_BYTES];
    for cut in 0..=per_op {
        let mut s = fresh();
        s.flash().budget = Some(cut);
        let ok = op(&mut s);
        assert_eq!(ok, cut >= per_op, "cut at {cut}");
        let mut r = reboot(&mut s);
        let m = r.load(&mut buf);
        let st = stored(&r);
        if check(cut, m, st) {
            new += 1;
        } else {
            old += 1;
        }
    }
    (old, new)
}

#[test]
fn a_power_cut_at_every_step_of_a_settings_commit_leaves_old_or_new() {
    let (m1, _) = image(1);
    let (old, new) = cut_everywhere(
        |s| s.commit_settings(&settings(2).encode()).is_ok(),
        |cut, m, st| {
            assert_eq!(m.as_ref(), Some(&m1), "cut at {cut}: the model stays");
            match st {
                Some(s) if s == settings(1) => false,
                Some(s) if s == settings(2) => true,
                other => panic!("cut at {cut}: settings {other:?}"),
            }
        },
    );
    assert!(old > 0 && new > 0, "old {old} new {new}");
}

#[test]
fn a_power_cut_at_every_step_of_a_model_commit_keeps_the_settings() {
    let (m1, _) = image(1);
    let (m2, b2) = image(2);
    let (old, new) = cut_everywhere(
        |s| s.commit(&b2).is_ok(),
        |cut, m, st| {
            assert_eq!(st, Some(settings(1)), "cut at {cut}: settings stay");
            match m {
                Some(m) if m == m1 => false,
                Some(m) if m == m2 => true,
                other => panic!("cut at {cut}: {other:?}"),
            }
        },
    );
    assert!(old > 0 && new > 0, "old {old} new {new}");
}

#[test]
fn settings_decode_refuses_out_of_range_values() {
    let good = settings(3).encode();
    assert_eq!(Settings::decode(&good), Some(settings(3)));
    let mut bad = good;
    bad[1] = 0; // unit 0 is broadcast
    assert_eq!(Settings::decode(&bad), None);
    let mut bad = good;
    bad[2..4].copy_from_slice(&77u16.to_le_bytes()); // 7700 baud
    assert_eq!(Settings::decode(&bad), None);
    let mut bad = good;
    bad[0] = 9; // another version
    assert_eq!(Settings::decode(&bad), None);
    assert_eq!(Settings::decode(&good[..good.len() - 1]), None);
}

fn app_on(flash: MockFlash) -> App<MockFlash> {
    modbus::boot(flash, ChannelMap::new())
}

fn power_cycle(app: &mut App<MockFlash>) -> App<MockFlash> {
    modbus::power_cycle(app, ChannelMap::new())
}

#[test]
fn settings_written_over_modbus_apply_at_boot_and_command_7_restores_defaults() {
    let mut app = app_on(MockFlash::new(2 * SLOT as usize));
    let mut reply = Reply::new();
    assert_eq!(app.settings(), Settings::default());
    app.request(
        &write1(1, HR_UNLOCK, host_tests::TEST_UNLOCK_KEY),
        0,
        &mut reply,
    );
    app.request(&write1(1, HR_CLAMP + 2, 150), 0, &mut reply);
    assert_eq!(reply[1], 6, "{reply:02x?}");
    app.poll_flash();
    app.request(&write1(1, HR_RATE, 40), 0, &mut reply);
    app.poll_flash();
    app.request(&write1(1, HR_BAUD, 192), 0, &mut reply);
    app.poll_flash();
    app.request(&write1(1, HR_UNIT, 9), 0, &mut reply);
    assert_eq!(reply[0], 1, "the reply still comes from unit 1");
    app.poll_flash();
    let mut expect = Settings::default();
    expect.clamp[2] = 150;
    expect.rate[0] = 40;
    expect.baud = 19_200;
    expect.unit = 9;
    assert_eq!(app.settings(), expect);
    let (_, b1) = image(1);
    app.program(&b1).unwrap();
    // Power cycle: the clamp the integrator tightened is still tight.
    let mut app = power_cycle(&mut app);
    assert_eq!(app.settings(), expect);
    assert_eq!(app.model_version(), 1);
    app.request(&frame(&[9, 3, 0, HR_CLAMP as u8, 0, 6]), 0, &mut reply);
    assert_eq!(&reply[..3], &[9, 3, 12], "unit 9 answers: {reply:02x?}");
    assert_eq!(u16::from_be_bytes([reply[7], reply[8]]), 150);
    // Command 7: defaults, applied and stored.
    app.request(
        &write1(9, HR_UNLOCK, host_tests::TEST_UNLOCK_KEY),
        0,
        &mut reply,
    );
    let change = app.request(&write1(9, HR_COMMAND, CMD_RESTORE_DEFAULTS), 0, &mut reply);
    assert_eq!(reply[0], 9, "answered at the old address");
    app.poll_flash();
    assert_eq!(
        change,
        thermocomp::app::LinkChange::Reconfigure { baud: 115_200 }
    );
    assert_eq!(app.settings(), Settings::default());
    let mut app = power_cycle(&mut app);
    assert_eq!(app.settings(), Settings::default());
    assert_eq!(app.model_version(), 1, "the model stays");
    // A flash that fails: the change is in force, HR_RESULT says it is not stored.
    app.flash_mut().budget = Some(0);
    app.request(
        &write1(1, HR_UNLOCK, host_tests::TEST_UNLOCK_KEY),
        0,
        &mut reply,
    );
    app.request(&write1(1, HR_CLAMP, 10), 0, &mut reply);
    assert_eq!(app.settings().clamp[0], 10);
    assert!(!app.poll_flash(), "the failed write ends the job");
    app.request(&frame(&[1, 3, 0, HR_RESULT as u8, 0, 1]), 0, &mut reply);
    assert_eq!(
        u16::from_be_bytes([reply[3], reply[4]]),
        result::SETTINGS_NOT_STORED
    );
}

/// A flash whose erase runs in the background for `steps` polls, as the
/// QEMU board's flash model does in real time.
struct SlowErase {
    inner: MockFlash,
    left: u32,
    steps: u32,
}

impl embedded_storage::nor_flash::ErrorType for SlowErase {
    type Error = host_tests::mock_flash::MockError;
}
impl embedded_storage::nor_flash::ReadNorFlash for SlowErase {
    const READ_SIZE: usize = 1;
    fn read(&mut self, o: u32, b: &mut [u8]) -> Result<(), Self::Error> {
        self.inner.read(o, b)
    }
    fn capacity(&self) -> usize {
        self.inner.capacity()
    }
}
impl embedded_storage::nor_flash::NorFlash for SlowErase {
    const WRITE_SIZE: usize = 4;
    const ERASE_SIZE: usize = ERASE_SIZE;
    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        self.inner.erase(from, to)
    }
    fn write(&mut self, o: u32, b: &[u8]) -> Result<(), Self::Error> {
        assert_eq!(self.left, 0, "programmed while the erase runs");
        self.inner.write(o, b)
    }
}
impl thermocomp::hal::flash::BackgroundErase for SlowErase {
    fn settings_area(&self) -> std::ops::Range<u32> {
        thermocomp::hal::flash::BackgroundErase::settings_area(&self.inner)
    }
    fn mapped(&self, from: u32, len: u32) -> Option<&[u8]> {
        thermocomp::hal::flash::BackgroundErase::mapped(&self.inner, from, len)
    }
    fn start_erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        self.left = self.steps;
        self.inner.erase(from, to)
    }
    fn erase_done(&mut self) -> bool {
        self.left = self.left.saturating_sub(1);
        self.left == 0
    }
}

#[test]
fn a_commit_is_answered_at_once_and_written_in_the_background() {
    let flash = SlowErase {
        inner: MockFlash::new(2 * SLOT as usize),
        left: 0,
        steps: 5,
    };
    let mut app = App::new(flash, SLOT, 1, 115_200, ChannelMap::new());
    host_tests::commission(&mut app);
    let mut reply = Reply::new();
    let (_, img) = image(3);
    app.request(
        &write1(1, HR_UNLOCK, host_tests::TEST_UNLOCK_KEY),
        0,
        &mut reply,
    );
    for (i, pair) in img.chunks(2).enumerate() {
        let v = u16::from_be_bytes([pair[0], *pair.get(1).unwrap_or(&0)]);
        app.request(&write1(1, HR_STAGING + i as u16, v), 0, &mut reply);
    }
    app.request(&write1(1, HR_STAGED_LEN, img.len() as u16), 0, &mut reply);
    app.request(&write1(1, HR_COMMAND, CMD_COMMIT_MODEL), 0, &mut reply);
    assert_eq!(reply[1], 6, "the commit is acknowledged: {reply:02x?}");
    assert_eq!(app.result(), result::COMMIT_IN_PROGRESS);
    assert_eq!(app.model_version(), 0, "not swapped in yet");
    // While it is written: reads answer, staging and settings are busy (06),
    // the PLC's registers are written as usual. (The commit locked the board.)
    app.request(
        &write1(1, HR_UNLOCK, host_tests::TEST_UNLOCK_KEY),
        0,
        &mut reply,
    );
    app.request(&write1(1, HR_STAGING, 0), 0, &mut reply);
    assert_eq!((reply[1], reply[2]), (0x86, 6));
    app.request(&write1(1, HR_CLAMP, 5), 0, &mut reply);
    assert_eq!((reply[1], reply[2]), (0x86, 6));
    app.request(&write1(1, HR_SPINDLE, 1200), 0, &mut reply);
    assert_eq!(reply[1], 6);
    let mut polls = 0;
    while app.poll_flash() {
        polls += 1;
        assert!(polls < 100);
    }
    assert_eq!(polls, 4, "the erase took its time");
    assert_eq!(app.result(), result::OK);
    assert_eq!(app.model_version(), 3);
    app.request(&write1(1, HR_CLAMP, 5), 0, &mut reply);
    assert_eq!(reply[1], 6, "not busy any more");
}

fn rom(n: u8) -> thermocomp::acquisition::rom::RomCode {
    thermocomp::acquisition::rom::RomCode::from_serial(0x28, [n, 0, 0, 0, 0, 1])
}

#[test]
fn the_channel_map_persists_and_a_swapped_sensor_goes_to_a_free_channel() {
    let mut app = app_on(MockFlash::new(2 * SLOT as usize));
    // First boot: the search found a and b (channels 0 and 1).
    let mut m1 = ChannelMap::new();
    m1.assign_new(&[rom(1), rom(2)]).unwrap();
    app.update_channel_map(m1);
    assert!(app.flash_busy(), "stored in the background");
    app.poll_flash();
    let read = |app: &mut App<MockFlash>| {
        let mut reply = Reply::new();
        app.request(&frame(&[1, 4, 0, 170, 0, 4]), 0, &mut reply);
        let w: Vec<u16> = reply[3..11]
            .chunks(2)
            .map(|c| u16::from_be_bytes([c[0], c[1]]))
            .collect();
        (
            u32::from(w[0]) << 16 | u32::from(w[1]),
            u32::from(w[2]) << 16 | u32::from(w[3]),
        )
    };
    assert_eq!(read(&mut app).1, 0b11, "channels 0 and 1 added since boot");
    // Reboot: the map comes from flash, not from the (empty) search order.
    let mut app = power_cycle(&mut app);
    assert_eq!(app.channel_map(), m1);
    assert_eq!(read(&mut app), (0, 0), "nothing added since this boot");
    // Sensor b is swapped for c: the board starts the search from the stored
    // map, so c takes the free channel 2 and b keeps channel 1 (missing).
    let mut m2 = app.channel_map();
    m2.assign_new(&[rom(1), rom(3)]).unwrap();
    assert_eq!(m2.channel_of(&rom(2)), Some(1));
    assert_eq!(m2.channel_of(&rom(3)), Some(2));
    app.update_channel_map(m2);
    app.poll_flash();
    assert_eq!(read(&mut app).1, 0b100, "c reported as new on channel 2");
    let app = power_cycle(&mut app);
    assert_eq!(app.channel_map(), m2);
    assert_eq!(app.settings(), Settings::default(), "settings untouched");
}

/// A flash whose board says "not now" (its RS-485 port is transmitting or
/// receiving) for the first `busy_looks` looks: the NUCLEO's erase stalls
/// the CPU, so it must never start under a reply (issue 30).
struct BusyLine {
    inner: MockFlash,
    busy_looks: u32,
}

impl embedded_storage::nor_flash::ErrorType for BusyLine {
    type Error = host_tests::mock_flash::MockError;
}
impl embedded_storage::nor_flash::ReadNorFlash for BusyLine {
    const READ_SIZE: usize = 1;
    fn read(&mut self, o: u32, b: &mut [u8]) -> Result<(), Self::Error> {
        self.inner.read(o, b)
    }
    fn capacity(&self) -> usize {
        self.inner.capacity()
    }
}
impl embedded_storage::nor_flash::NorFlash for BusyLine {
    const WRITE_SIZE: usize = 4;
    const ERASE_SIZE: usize = ERASE_SIZE;
    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        assert_eq!(self.busy_looks, 0, "erased while the line was busy");
        self.inner.erase(from, to)
    }
    fn write(&mut self, o: u32, b: &[u8]) -> Result<(), Self::Error> {
        self.inner.write(o, b)
    }
}
impl thermocomp::hal::flash::BackgroundErase for BusyLine {
    fn settings_area(&self) -> std::ops::Range<u32> {
        thermocomp::hal::flash::BackgroundErase::settings_area(&self.inner)
    }
    fn mapped(&self, from: u32, len: u32) -> Option<&[u8]> {
        thermocomp::hal::flash::BackgroundErase::mapped(&self.inner, from, len)
    }
    fn ready_to_erase(&mut self) -> bool {
        if self.busy_looks == 0 {
            return true;
        }
        self.busy_looks -= 1;
        false
    }
}

#[test]
fn the_erase_waits_until_the_board_says_the_line_is_quiet() {
    let flash = BusyLine {
        inner: MockFlash::new(2 * SLOT as usize),
        busy_looks: 0,
    };
    let mut app = App::new(flash, SLOT, 1, 115_200, ChannelMap::new());
    host_tests::commission(&mut app);
    // The line is busy for the model's commit (commissioning stored the key).
    app.flash_mut().busy_looks = 3;
    let mut reply = Reply::new();
    let (_, img) = image(3);
    app.request(
        &write1(1, HR_UNLOCK, host_tests::TEST_UNLOCK_KEY),
        0,
        &mut reply,
    );
    for (i, pair) in img.chunks(2).enumerate() {
        let v = u16::from_be_bytes([pair[0], *pair.get(1).unwrap_or(&0)]);
        app.request(&write1(1, HR_STAGING + i as u16, v), 0, &mut reply);
    }
    app.request(&write1(1, HR_STAGED_LEN, img.len() as u16), 0, &mut reply);
    app.request(&write1(1, HR_COMMAND, CMD_COMMIT_MODEL), 0, &mut reply);
    assert_eq!(reply[1], 6, "answered first: {reply:02x?}");
    for look in 0..3 {
        assert!(app.poll_flash(), "look {look}: still in progress");
        assert_eq!(app.result(), result::COMMIT_IN_PROGRESS);
    }
    assert!(
        !app.poll_flash(),
        "erased and written at the first quiet look"
    );
    assert_eq!(app.result(), result::OK);
    assert_eq!(app.model_version(), 3);
}
