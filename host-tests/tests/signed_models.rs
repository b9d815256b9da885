//! Signed models and the board's keys (issue 30), end to end on the host:
//! `tcomp`'s link (commission, upload) against the board's application
//! (server, keys, model store on a mock flash) behind a socket. Unsigned
//! and wrongly signed images are refused with their own result codes and
//! the old model keeps serving; the right signature commits; the keys
//! survive a reboot; a stored signing key is replaced only with the old
//! key's signature.
use std::sync::{Arc, Mutex};

use host_tests::mock_flash::{MockFlash, ERASE_SIZE};
use host_tests::modbus::app_on_socket;
use host_tests::raw_commit;
use tcomp_link::board_link::{upload, BoardLink, Commit};
use tcomp_link::commission::{commission, Commission, SigningKey};
use tcomp_model::signing;
use thermocomp::acquisition::channel_map::ChannelMap;
use thermocomp::app::App;
use thermocomp_protocol::holding::*;

const SLOT: u32 = (8 * ERASE_SIZE) as u32;
/// The unlock key these tests give their boards.
const KEY: u16 = host_tests::TEST_UNLOCK_KEY;

/// The board's application behind a socket (one client at a time), its
/// state shared with the test.
fn board_on_socket(app: App<MockFlash>) -> (String, Arc<Mutex<App<MockFlash>>>) {
    let board = Arc::new(Mutex::new(app));
    (app_on_socket(board.clone()), board)
}

fn fresh_app(flash: MockFlash) -> App<MockFlash> {
    App::new(flash, SLOT, 1, 115_200, ChannelMap::new())
}

fn image(version: u32) -> Vec<u8> {
    let mut fm = thermocomp_core::float::demo_model(u64::from(version));
    fm.model_version = version;
    let (mut m, _) = fm.quantize().unwrap();
    let mut b = vec![0u8; m.encoded_len()];
    m.encode(&mut b).unwrap();
    b
}

struct Keys {
    _dir: tempfile::TempDir,
    private: signing::SecretKey,
    public: [u8; 32],
}

fn new_keys() -> Keys {
    let dir = tempfile::tempdir().unwrap();
    let files = signing::keygen(dir.path()).unwrap();
    Keys {
        private: signing::read_private(&files.private_key).unwrap(),
        public: signing::read_public(&files.public_key).unwrap(),
        _dir: dir,
    }
}

/// A fresh board given its unlock key and `keys`' public key, running version 2.
fn commissioned(keys: &Keys) -> (BoardLink, Arc<Mutex<App<MockFlash>>>) {
    let mut app = fresh_app(MockFlash::new(2 * SLOT as usize));
    app.program(&image(2)).unwrap();
    let (addr, board) = board_on_socket(app);
    let mut link = BoardLink::tcp(&addr, 1).unwrap();
    let state = commission(
        &mut link,
        &Commission {
            unlock_key: None,
            new_unlock_key: Some(KEY),
            signing_key: Some(SigningKey::First(keys.public)),
        },
    )
    .unwrap();
    assert!(state.unlock_key_set && state.signing_key_stored);
    (link, board)
}

fn serving(board: &Arc<Mutex<App<MockFlash>>>) -> u32 {
    board.lock().unwrap().model_version()
}

#[test]
fn unsigned_and_wrongly_signed_images_are_refused_and_the_old_model_kept() {
    let keys = new_keys();
    let (mut link, board) = commissioned(&keys);
    // tcomp refuses to send an unsigned image to a board with a key.
    let e = format!(
        "{:#}",
        upload(
            &mut link,
            &image(3),
            &host_tests::upload_opts(Commit::NewerOnly, true)
        )
        .unwrap_err()
    );
    assert!(e.contains("--sign"), "{e}");
    // A master that sends it anyway: exception 04, result 70, locked.
    let (e, code) = raw_commit(&mut link, &image(3));
    assert!(e.contains("exception 04"), "{e}");
    assert_eq!(code, result::UNSIGNED);
    assert!(!board.lock().unwrap().unlocked(0));
    assert_eq!(serving(&board), 2);
    // Signed with another key: result 71, through tcomp and raw.
    let other = new_keys();
    let wrong = signing::sign_image(&image(3), &other.private).unwrap();
    let e = format!(
        "{:#}",
        upload(
            &mut link,
            &wrong,
            &host_tests::upload_opts(Commit::NewerOnly, true)
        )
        .unwrap_err()
    );
    assert!(e.contains("BAD_SIGNATURE"), "{e}");
    assert_eq!(raw_commit(&mut link, &wrong).1, result::BAD_SIGNATURE);
    // The right key's signature on another image (a tampered image).
    let mut tampered = signing::sign_image(&image(3), &keys.private).unwrap();
    tampered[40] ^= 1;
    // (The CRC catches a flip inside the image; re-seal it so only the
    // signature can tell.)
    let n = image(3).len();
    let crc = thermocomp_core::image::crc32(&tampered[..n - 4]);
    tampered[n - 4..n].copy_from_slice(&crc.to_le_bytes());
    assert_eq!(raw_commit(&mut link, &tampered).1, result::BAD_SIGNATURE);
    // A malformed trailer (another algorithm byte).
    let mut odd = signing::sign_image(&image(3), &keys.private).unwrap();
    odd[n + 4] = 2;
    assert_eq!(raw_commit(&mut link, &odd).1, result::BAD_SIGNATURE);
    assert_eq!(serving(&board), 2, "the old model serves throughout");
    assert!(!board.lock().unwrap().unlocked(0));
}

#[test]
fn the_right_signature_commits_and_the_keys_survive_a_reboot() {
    let keys = new_keys();
    let (mut link, board) = commissioned(&keys);
    let signed = signing::sign_image(&image(3), &keys.private).unwrap();
    let s = upload(
        &mut link,
        &signed,
        &host_tests::upload_opts(Commit::NewerOnly, true),
    )
    .unwrap();
    assert!(s.signed);
    assert_eq!((s.model_version, s.result), (3, result::OK));
    assert_eq!(serving(&board), 3);
    // The slot holds the image, not the trailer: a reboot serves it and
    // still holds both keys.
    let flash = std::mem::replace(board.lock().unwrap().flash_mut(), MockFlash::new(0));
    let rebooted = fresh_app(flash);
    assert_eq!(rebooted.model_version(), 3);
    assert_eq!(rebooted.keys().signing, Some(keys.public));
    assert_eq!(rebooted.keys().unlock, Some(KEY));
    let (addr, board) = board_on_socket(rebooted);
    let mut link = BoardLink::tcp(&addr, 1).unwrap();
    assert_eq!(
        link.read_holdings(HR_KEY_STATE, 1).unwrap()[0],
        KEY_STATE_UNLOCK_KEY | KEY_STATE_SIGNING_KEY
    );
    let signed4 = signing::sign_image(&image(4), &keys.private).unwrap();
    upload(
        &mut link,
        &signed4,
        &host_tests::upload_opts(Commit::NewerOnly, true),
    )
    .unwrap();
    assert_eq!(serving(&board), 4);
    // A board without a signing key takes unsigned and signed images alike.
    let mut app = fresh_app(MockFlash::new(2 * SLOT as usize));
    app.program(&image(2)).unwrap();
    let (addr, board) = board_on_socket(app);
    let mut link = BoardLink::tcp(&addr, 1).unwrap();
    let c = Commission {
        unlock_key: None,
        new_unlock_key: Some(KEY),
        signing_key: None,
    };
    commission(&mut link, &c).unwrap();
    assert!(
        !upload(
            &mut link,
            &image(3),
            &host_tests::upload_opts(Commit::NewerOnly, true)
        )
        .unwrap()
        .signed
    );
    upload(
        &mut link,
        &signed4,
        &host_tests::upload_opts(Commit::NewerOnly, true),
    )
    .unwrap();
    assert_eq!(serving(&board), 4);
}

#[test]
fn a_stored_signing_key_is_replaced_only_with_the_old_keys_signature() {
    let (old, new) = (new_keys(), new_keys());
    let (mut link, board) = commissioned(&old);
    let c = |signing_key| Commission {
        unlock_key: Some(KEY),
        new_unlock_key: None,
        signing_key: Some(signing_key),
    };
    // Command 14 again: refused (72), the old key stays.
    let e = format!(
        "{:#}",
        commission(&mut link, &c(SigningKey::First(new.public))).unwrap_err()
    );
    assert!(e.contains("SIGNING_KEY_SET"), "{e}");
    // Command 16 proven by the new key itself (not the stored one): 71.
    let forged = signing::key_change_proof(&new.private, &new.public);
    let e = format!(
        "{:#}",
        commission(
            &mut link,
            &c(SigningKey::Replace {
                key: new.public,
                proof: forged
            })
        )
        .unwrap_err()
    );
    assert!(e.contains("BAD_SIGNATURE"), "{e}");
    assert_eq!(board.lock().unwrap().keys().signing, Some(old.public));
    // Proven by the old key: replaced; models signed by the old key are refused.
    let proof = signing::key_change_proof(&old.private, &new.public);
    let state = commission(
        &mut link,
        &c(SigningKey::Replace {
            key: new.public,
            proof,
        }),
    )
    .unwrap();
    assert!(state.signing_key_stored);
    let by_old = signing::sign_image(&image(3), &old.private).unwrap();
    assert_eq!(raw_commit(&mut link, &by_old).1, result::BAD_SIGNATURE);
    let by_new = signing::sign_image(&image(3), &new.private).unwrap();
    upload(
        &mut link,
        &by_new,
        &host_tests::upload_opts(Commit::NewerOnly, true),
    )
    .unwrap();
    assert_eq!(serving(&board), 3);
    // Not a curve point: BAD_KEY.
    let fresh = fresh_app(MockFlash::new(2 * SLOT as usize));
    let (addr, _board) = board_on_socket(fresh);
    let mut link = BoardLink::tcp(&addr, 1).unwrap();
    let e = format!(
        "{:#}",
        commission(
            &mut link,
            &Commission {
                unlock_key: None,
                new_unlock_key: Some(KEY),
                signing_key: Some(SigningKey::First([0xFF; 32])),
            }
        )
        .unwrap_err()
    );
    assert!(e.contains("BAD_KEY"), "{e}");
}
