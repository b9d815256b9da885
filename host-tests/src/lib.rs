//! Test doubles for the board application: they implement the same narrow
//! hardware traits the boards implement, so the real application code runs here.

pub mod cli;
pub mod keys;
pub mod mock_flash;
pub mod modbus;
pub mod onewire_emu;
pub mod qemu;
pub mod rotary_drift;

pub use keys::TEST_UNLOCK_KEY;
pub use modbus::commission;

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
