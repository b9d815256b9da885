//! Signed models on the QEMU bench board (issue 30), with `tcomp`'s own
//! masters: the firmware is commissioned (its unlock key and a signing
//! public key), an unsigned image staged by a master that skips tcomp's
//! checks is refused (exception 04, result 70) and the old model keeps
//! serving, a wrongly signed one is refused (71), and the image signed
//! with the right key commits and serves.
use std::time::Duration;

use host_tests::qemu::{free_tcp_port, BenchBoard};
use host_tests::TEST_UNLOCK_KEY;
use tcomp_link::board_link::{unlock, upload, BoardLink, Commit};
use tcomp_link::commission::{commission, Commission, SigningKey};
use tcomp_model::signing;
use thermocomp_protocol::holding::*;
use thermocomp_protocol::registers::IR_MODEL_VERSION;

const BOOT: Duration = Duration::from_secs(60);

/// One bench board at a time (see qemu_modbus.rs).
static ONE_BOARD: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn image(version: u32, path: &std::path::Path) -> Vec<u8> {
    let mut fm = thermocomp_core::float::demo_model(u64::from(version));
    fm.model_version = version;
    tcomp_model::export::export(&fm, path).unwrap();
    std::fs::read(path).unwrap()
}

/// Stage and commit with raw register writes; the exception text and HR_RESULT.
fn raw_commit(link: &mut BoardLink, file: &[u8]) -> (String, u16) {
    unlock(link, TEST_UNLOCK_KEY).unwrap();
    let mut padded = file.to_vec();
    padded.resize(file.len().div_ceil(2) * 2, 0);
    let words: Vec<u16> = padded
        .chunks(2)
        .map(|c| u16::from_be_bytes([c[0], c[1]]))
        .collect();
    for (i, chunk) in words.chunks(100).enumerate() {
        link.write_many(HR_STAGING + (i * 100) as u16, chunk)
            .unwrap();
    }
    link.write_one(HR_STAGED_LEN, file.len() as u16).unwrap();
    let e = link
        .write_one(HR_COMMAND, CMD_COMMIT_MODEL)
        .map_or_else(|e| e.to_string(), |()| "accepted".into());
    (e, link.read_holdings(HR_RESULT, 1).unwrap()[0])
}

fn version(link: &mut BoardLink) -> u32 {
    let w = link.read_inputs(IR_MODEL_VERSION, 2).unwrap();
    u32::from(w[0]) << 16 | u32::from(w[1])
}

#[test]
#[ignore = "needs the QEMU firmware and qemu-system-arm: scripts/test.sh"]
fn the_bench_board_commits_signed_models_only_once_it_holds_a_key() {
    let _one = ONE_BOARD.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    let trace = dir.path().join("trace.csv");
    let mut csv = String::from("time_s,spindle_rpm,T01,T02,T03,T04,T05,T06\n");
    for i in 0..3000u32 {
        csv += &format!("{},3000", i * 15);
        for c in 0..6 {
            csv += &format!(",{:.4}", 20.0 + f64::from(i * (c + 1)) * 0.001);
        }
        csv += "\n";
    }
    std::fs::write(&trace, csv).unwrap();
    let v1 = dir.path().join("v1.img");
    image(1, &v1);
    let v2 = image(2, &dir.path().join("v2.img"));
    let keys = signing::keygen(dir.path()).unwrap();
    let private = signing::read_private(&keys.private_key).unwrap();
    let public = signing::read_public(&keys.public_key).unwrap();
    let port = free_tcp_port();
    let serial = format!("tcp:127.0.0.1:{port},server=on,wait=off,nodelay=on");
    let board = BenchBoard::start(
        &serial,
        &["serve", trace.to_str().unwrap(), v1.to_str().unwrap(), "50"],
    );
    assert!(
        board.wait_for("serving Modbus RTU", BOOT),
        "{}",
        board.log()
    );
    let mut link = BoardLink::tcp(&format!("127.0.0.1:{port}"), 1).unwrap();
    // A fresh board: the factory code opens commissioning only.
    link.write_one(HR_UNLOCK, FACTORY_UNLOCK_CODE).unwrap();
    let e = link.write_one(HR_STAGED_LEN, 10).unwrap_err().to_string();
    assert!(e.contains("exception 01"), "{e}");
    let state = commission(
        &mut link,
        &Commission {
            unlock_key: None,
            new_unlock_key: Some(TEST_UNLOCK_KEY),
            signing_key: Some(SigningKey::First(public)),
        },
    )
    .unwrap();
    assert!(state.unlock_key_set && state.signing_key_stored);
    assert_eq!(version(&mut link), 1);
    // Unsigned: refused, locked, version 1 serves.
    let (e, code) = raw_commit(&mut link, &v2);
    assert!(e.contains("exception 04"), "{e}");
    assert_eq!(code, result::UNSIGNED);
    assert_eq!(link.read_holdings(HR_UNLOCK, 1).unwrap(), vec![0]);
    assert_eq!(version(&mut link), 1);
    // Signed by another key: refused.
    let other = signing::keygen(&dir.path().join("other")).unwrap();
    let other = signing::read_private(&other.private_key).unwrap();
    let wrong = signing::sign_image(&v2, &other).unwrap();
    assert_eq!(raw_commit(&mut link, &wrong).1, result::BAD_SIGNATURE);
    assert_eq!(version(&mut link), 1);
    // Signed with the key: committed through tcomp's upload, and served.
    let signed = signing::sign_image(&v2, &private).unwrap();
    let opts = host_tests::upload_opts(Commit::NewerOnly, false);
    let s = upload(&mut link, &signed, &opts).unwrap();
    assert!(s.signed);
    assert_eq!((s.model_version, s.result), (2, result::OK));
    assert_eq!(version(&mut link), 2, "{}", board.log());
    // The firmware prints no key (the boot log says nothing of it).
    assert!(!board.log().contains("7e57") && !board.log().contains("7E57"));
}
