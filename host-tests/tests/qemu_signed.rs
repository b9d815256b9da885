//! Signed models on the QEMU bench board (issue 30), with `tcomp`'s own
//! masters: the firmware is commissioned (its unlock key and a signing
//! public key), an unsigned image staged by a master that skips tcomp's
//! checks is refused (exception 04, result 70) and the old model keeps
//! serving, a wrongly signed one is refused (71), and the image signed
//! with the right key commits and serves.

use host_tests::qemu::{export_demo, one_board, warming_trace, BenchBoard};
use host_tests::raw_commit;
use host_tests::TEST_UNLOCK_KEY;
use tcomp_link::board_link::{upload, BoardLink, Commit};
use tcomp_link::commission::{commission, Commission, SigningKey};
use tcomp_model::signing;
use thermocomp_protocol::holding::*;
use thermocomp_protocol::registers::IR_MODEL_VERSION;

fn image(version: u32, path: &std::path::Path) -> Vec<u8> {
    export_demo(u64::from(version), version, path)
}

fn version(link: &mut BoardLink) -> u32 {
    let w = link.read_inputs(IR_MODEL_VERSION, 2).unwrap();
    u32::from(w[0]) << 16 | u32::from(w[1])
}

#[test]
#[ignore = "needs the QEMU firmware and qemu-system-arm: scripts/test.sh"]
fn the_bench_board_commits_signed_models_only_once_it_holds_a_key() {
    let _one = one_board();
    let dir = tempfile::tempdir().unwrap();
    let trace = dir.path().join("trace.csv");
    warming_trace(&trace, 3000, 0.001);
    let v1 = dir.path().join("v1.img");
    image(1, &v1);
    let v2 = image(2, &dir.path().join("v2.img"));
    let keys = signing::keygen(dir.path()).unwrap();
    let private = signing::read_private(&keys.private_key).unwrap();
    let public = signing::read_public(&keys.public_key).unwrap();
    let (board, port) = BenchBoard::serve_tcp(&trace, &v1, &["50"]);
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
