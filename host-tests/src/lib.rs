//! Test doubles for the board application: they implement the same narrow
//! hardware traits the boards implement, so the real application code runs here.

pub mod mock_flash;
pub mod modbus;
pub mod onewire_emu;
pub mod qemu;

/// The unlock key the tests give their boards at commissioning (a fresh
/// board takes the factory code for commissioning only).
pub const TEST_UNLOCK_KEY: u16 = 0x7E57;

/// Give a fresh board its own unlock key [`TEST_UNLOCK_KEY`] as `tcomp
/// commission` does (factory code, register 67, command 15), and drive the
/// flash write to its end; the board ends locked. A board that has its
/// key already is left as it is.
pub fn commission<F: thermocomp::hal::flash::BackgroundErase>(app: &mut thermocomp::app::App<F>) {
    use thermocomp_protocol::holding::*;
    if app.server.holding.keys.unlock.is_some() {
        return; // commissioned already (a reboot of a commissioned board)
    }
    let unit = app.server.holding.unit;
    let mut reply = heapless::Vec::<u8, { thermocomp_protocol::rtu::MAX_FRAME }>::new();
    for (addr, v) in [
        (HR_UNLOCK, FACTORY_UNLOCK_CODE),
        (HR_NEW_UNLOCK_KEY, TEST_UNLOCK_KEY),
        (HR_COMMAND, CMD_SET_UNLOCK_KEY),
    ] {
        app.request(&modbus::write1(unit, addr, v), 0, &mut reply);
        assert_eq!(
            reply.get(1),
            Some(&6),
            "commissioning write {addr}={v:#x}: {reply:02x?}"
        );
    }
    while app.poll_flash() {}
    assert_eq!(app.server.holding.keys.unlock, Some(TEST_UNLOCK_KEY));
}

/// Upload options of a test: [`TEST_UNLOCK_KEY`]; `allow_missing_sensors`
/// for boards that have no sensors (the mocks).
pub fn upload_opts(
    commit: tcomp_link::board_link::Commit,
    allow_missing_sensors: bool,
) -> tcomp_link::board_link::UploadOptions {
    tcomp_link::board_link::UploadOptions {
        commit,
        unlock_key: TEST_UNLOCK_KEY,
        allow_missing_sensors,
    }
}

/// Give a board behind `link` its unlock key [`TEST_UNLOCK_KEY`] if it has
/// none yet (a fresh QEMU bench board), as `tcomp commission` does.
pub fn commission_link(link: &mut tcomp_link::board_link::BoardLink) {
    use tcomp_link::commission::{commission, key_state, Commission};
    if key_state(link).unwrap().unlock_key_set {
        return;
    }
    let c = Commission {
        unlock_key: None,
        new_unlock_key: Some(TEST_UNLOCK_KEY),
        signing_key: None,
    };
    assert!(commission(link, &c).unwrap().unlock_key_set);
}

/// Stage `file` and commit it over `link` with raw register writes (what a
/// master that skips tcomp's own checks does), after unlocking with
/// [`TEST_UNLOCK_KEY`]; the exception text ("accepted" if none) and HR_RESULT.
pub fn raw_commit(link: &mut tcomp_link::board_link::BoardLink, file: &[u8]) -> (String, u16) {
    use thermocomp_protocol::holding::*;
    tcomp_link::board_link::unlock(link, TEST_UNLOCK_KEY).unwrap();
    for (i, chunk) in modbus::be_words(file).chunks(100).enumerate() {
        link.write_many(HR_STAGING + (i * 100) as u16, chunk)
            .unwrap();
    }
    link.write_one(HR_STAGED_LEN, file.len() as u16).unwrap();
    let e = link
        .write_one(HR_COMMAND, CMD_COMMIT_MODEL)
        .map_or_else(|e| e.to_string(), |()| "accepted".into());
    (e, link.read_holdings(HR_RESULT, 1).unwrap()[0])
}
