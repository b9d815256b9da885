//! Modbus RTU requests as a master builds them, and the application driven
//! through them (`App::request`), for the register-level tests: one copy
//! instead of one per test file.

use crate::mock_flash::{MockFlash, ERASE_SIZE};
use thermocomp::acquisition::channel_map::ChannelMap;
use thermocomp::app::App;
use thermocomp::hal::flash::BackgroundErase;
use thermocomp_protocol::holding::{HR_COMMAND, HR_STAGED_LEN, HR_STAGING, HR_UNLOCK};
use thermocomp_protocol::rtu::{crc16, expected_request_len, MAX_FRAME};

/// One model slot of the mock flash the tests give their boards (two slots).
pub const SLOT: u32 = (8 * ERASE_SIZE) as u32;

/// A reply buffer as `App::request` takes it.
pub type Reply = heapless::Vec<u8, MAX_FRAME>;

/// `body` (unit address first) with its CRC-16 appended.
pub fn frame(body: &[u8]) -> Vec<u8> {
    let mut f = body.to_vec();
    f.extend_from_slice(&crc16(body).to_le_bytes());
    f
}

/// A read request (function `fc`: 3 holding, 4 input registers).
pub fn read(unit: u8, fc: u8, addr: u16, count: u16) -> Vec<u8> {
    let [a, b] = addr.to_be_bytes();
    let [c, d] = count.to_be_bytes();
    frame(&[unit, fc, a, b, c, d])
}

/// FC06: write `v` to holding register `addr`.
pub fn write1(unit: u8, addr: u16, v: u16) -> Vec<u8> {
    let [a, b] = addr.to_be_bytes();
    let [c, d] = v.to_be_bytes();
    frame(&[unit, 6, a, b, c, d])
}

/// FC16: write `vals` from holding register `addr` on.
pub fn write_n(unit: u8, addr: u16, vals: &[u16]) -> Vec<u8> {
    let [a, b] = addr.to_be_bytes();
    let [c, d] = (vals.len() as u16).to_be_bytes();
    let mut body = vec![unit, 0x10, a, b, c, d, (vals.len() * 2) as u8];
    for v in vals {
        body.extend_from_slice(&v.to_be_bytes());
    }
    frame(&body)
}

/// Bytes as the registers that carry them: big-endian words, the last one
/// padded with a zero byte.
pub fn be_words(bytes: &[u8]) -> Vec<u16> {
    bytes
        .chunks(2)
        .map(|c| u16::from_be_bytes([c[0], *c.get(1).unwrap_or(&0)]))
        .collect()
}

/// 32-bit values as register pairs, high word first.
pub fn words(v: &[i32]) -> Vec<u16> {
    v.iter()
        .flat_map(|&x| [((x as u32) >> 16) as u16, x as u16])
        .collect()
}

/// The signed 32-bit value in registers `at`, `at + 1` (high word first).
pub fn s32(w: &[u16], at: usize) -> i32 {
    ((u32::from(w[at]) << 16) | u32::from(w[at + 1])) as i32
}

/// The demo model of `seed` as version `version`, encoded.
pub fn demo_image(seed: u64, version: u32) -> Vec<u8> {
    let mut fm = thermocomp_core::float::demo_model(seed);
    fm.model_version = version;
    let (mut m, _) = fm.quantize().unwrap();
    encode(&mut m)
}

/// `m` encoded as an image (sealed with its CRC, which `m` takes).
pub fn encode(m: &mut thermocomp_core::Model) -> Vec<u8> {
    let mut b = vec![0u8; m.encoded_len()];
    let n = m.encode(&mut b).unwrap();
    b.truncate(n);
    b
}

/// A board at unit 1, 115 200 Bd, on blank mock flash (two [`SLOT`]s),
/// not commissioned.
pub fn blank_app() -> App<MockFlash> {
    App::new(
        MockFlash::new(2 * SLOT as usize),
        SLOT,
        1,
        115_200,
        ChannelMap::new(),
    )
}

/// FC03 of `n` holding registers from `addr` to unit 1 at `now`; the words.
pub fn read_holding<F: BackgroundErase>(app: &mut App<F>, addr: u16, n: u16, now: u64) -> Vec<u16> {
    let mut reply = Reply::new();
    app.request(&read(1, 3, addr, n), now, &mut reply);
    assert_eq!(&reply[..3], &[1, 3, 2 * n as u8], "{reply:02x?}");
    reply[3..3 + 2 * usize::from(n)]
        .chunks(2)
        .map(|c| u16::from_be_bytes([c[0], c[1]]))
        .collect()
}

/// FC04 of `n` input registers from `addr` to unit 1 at `now`; the words.
pub fn read_inputs<F: BackgroundErase>(app: &mut App<F>, addr: u16, n: u16, now: u64) -> Vec<u16> {
    let mut reply = Reply::new();
    app.request(&read(1, 4, addr, n), now, &mut reply);
    assert_eq!(&reply[..3], &[1, 4, 2 * n as u8], "{reply:02x?}");
    reply[3..3 + 2 * usize::from(n)]
        .chunks(2)
        .map(|c| u16::from_be_bytes([c[0], c[1]]))
        .collect()
}

/// Unlock with [`crate::keys::TEST_UNLOCK_KEY`], then write `v` to holding
/// register `addr` (unit 1); the reply to the write.
pub fn write_unlocked<F: BackgroundErase>(app: &mut App<F>, addr: u16, v: u16) -> Vec<u8> {
    let mut reply = Reply::new();
    for (a, v) in [(HR_UNLOCK, crate::keys::TEST_UNLOCK_KEY), (addr, v)] {
        app.request(&write1(1, a, v), 0, &mut reply);
    }
    reply.to_vec()
}

/// Unlock with [`crate::keys::TEST_UNLOCK_KEY`], stage `img` 100 registers a
/// frame, write its length and send `command` (unit 1), then give the
/// flash job one poll; the reply to the command.
pub fn stage_and_send<F: BackgroundErase>(app: &mut App<F>, img: &[u8], command: u16) -> Vec<u8> {
    let mut reply = Reply::new();
    app.request(
        &write1(1, HR_UNLOCK, crate::keys::TEST_UNLOCK_KEY),
        0,
        &mut reply,
    );
    for (i, chunk) in be_words(img).chunks(100).enumerate() {
        app.request(
            &write_n(1, HR_STAGING + (i * 100) as u16, chunk),
            0,
            &mut reply,
        );
    }
    app.request(&write1(1, HR_STAGED_LEN, img.len() as u16), 0, &mut reply);
    app.request(&write1(1, HR_COMMAND, command), 0, &mut reply);
    app.poll_flash();
    reply.to_vec()
}

/// A board at unit 1 booting on `flash` with channel map `map`,
/// commissioned (a board that has its key already keeps it).
pub fn boot(flash: MockFlash, map: ChannelMap) -> App<MockFlash> {
    let mut app = App::new(flash, SLOT, 1, 115_200, map);
    commission(&mut app);
    app
}

/// Power off and on: the flash keeps what it holds, and the board boots
/// on it again with channel map `map`.
pub fn power_cycle(app: &mut App<MockFlash>, map: ChannelMap) -> App<MockFlash> {
    let mut flash = std::mem::replace(app.flash_mut(), MockFlash::new(0));
    flash.power_on();
    boot(flash, map)
}

/// A Modbus RTU device on a local TCP socket, as `tcomp`'s link talks to a
/// board: the byte stream is cut into requests by their expected length and
/// `answer` gives each one's reply (empty: silence). One client at a time;
/// the socket's address.
pub fn rtu_socket(mut answer: impl FnMut(&[u8]) -> Vec<u8> + Send + 'static) -> String {
    use std::io::{Read, Write};
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = l.local_addr().unwrap().to_string();
    std::thread::spawn(move || {
        for stream in l.incoming() {
            let Ok(mut s) = stream else { return };
            let mut buf = Vec::new();
            let mut byte = [0u8; 1];
            while s.read_exact(&mut byte).is_ok() {
                buf.push(byte[0]);
                if expected_request_len(&buf).is_some_and(|n| buf.len() >= n) {
                    s.write_all(&answer(&buf)).unwrap();
                    buf.clear();
                }
            }
        }
    });
    addr
}

/// `app` answering each request, then driving its flash job one step as
/// the board's feeder task does; the reply (empty: silence).
pub fn answer<F: BackgroundErase>(app: &mut App<F>, request: &[u8]) -> Vec<u8> {
    let mut reply = Reply::new();
    app.request(request, 0, &mut reply);
    app.poll_flash();
    reply.to_vec()
}

/// The board's application behind [`rtu_socket`], its state shared with
/// the test; the socket's address.
pub fn app_on_socket<F: BackgroundErase + Send + 'static>(
    app: std::sync::Arc<std::sync::Mutex<App<F>>>,
) -> String {
    rtu_socket(move |req| answer(&mut app.lock().unwrap(), req))
}

/// Give a fresh board its own unlock key [`TEST_UNLOCK_KEY`] as `tcomp
/// commission` does (factory code, register 67, command 15), and drive the
/// flash write to its end; the board ends locked. A board that has its
/// key already is left as it is.
pub fn commission<F: thermocomp::hal::flash::BackgroundErase>(app: &mut thermocomp::app::App<F>) {
    use thermocomp_protocol::holding::*;
    if app.keys().unlock.is_some() {
        return; // commissioned already (a reboot of a commissioned board)
    }
    let unit = app.settings().unit;
    let mut reply = heapless::Vec::<u8, { thermocomp_protocol::rtu::MAX_FRAME }>::new();
    for (addr, v) in [
        (HR_UNLOCK, FACTORY_UNLOCK_CODE),
        (HR_NEW_UNLOCK_KEY, crate::keys::TEST_UNLOCK_KEY),
        (HR_COMMAND, CMD_SET_UNLOCK_KEY),
    ] {
        app.request(&write1(unit, addr, v), 0, &mut reply);
        assert_eq!(
            reply.get(1),
            Some(&6),
            "commissioning write {addr}={v:#x}: {reply:02x?}"
        );
    }
    while app.poll_flash() {}
    assert_eq!(app.keys().unlock, Some(crate::keys::TEST_UNLOCK_KEY));
}
