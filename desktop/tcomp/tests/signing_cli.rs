//! `tcomp keygen` and `tcomp export --sign` (issue 30): the pair is written
//! once (never overwritten), the signed file is the image plus a trailer
//! whose signature verifies under the public key, and bad input is a
//! one-line error.
use std::process::Command;

fn tcomp(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_tcomp"))
        .args(args)
        .env_remove("TCOMP_UNLOCK_KEY")
        .output()
        .unwrap()
}

fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn keygen_then_export_sign_writes_a_verifiable_signed_image() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path().to_str().unwrap();
    let o = tcomp(&["keygen", d, "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let again = tcomp(&["keygen", d]);
    assert!(!again.status.success());
    let e = stderr(&again);
    assert!(
        e.contains("not overwritten") && e.lines().count() == 1,
        "{e}"
    );
    let key = dir.path().join("tcomp-signing.key");
    let (plain, signed) = (dir.path().join("p.img"), dir.path().join("s.img"));
    let p = plain.to_str().unwrap();
    assert!(tcomp(&["export", "--demo", "-o", p]).status.success());
    let o = tcomp(&[
        "export",
        "--demo",
        "--sign",
        key.to_str().unwrap(),
        "-o",
        signed.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let public = tcomp_model::signing::read_public(&dir.path().join("tcomp-signing.pub")).unwrap();
    let hex: String = public.iter().map(|b| format!("{b:02x}")).collect();
    assert_eq!(summary["signed_by"], hex.as_str());
    let (plain, signed) = (
        std::fs::read(&plain).unwrap(),
        std::fs::read(&signed).unwrap(),
    );
    assert_eq!(signed.len(), plain.len() + 72);
    let split = thermocomp_core::image::split_signed(&signed).unwrap();
    assert_eq!(
        split.image,
        &plain[..],
        "the image is the same signed or not"
    );
    assert!(tcomp_model::signing::verify(
        &public,
        split.image,
        split.signature.unwrap()
    ));
    // A public key file is no private key: one line.
    let o = tcomp(&[
        "export",
        "--demo",
        "--sign",
        dir.path().join("tcomp-signing.pub").to_str().unwrap(),
        "-o",
        dir.path().join("x.img").to_str().unwrap(),
    ]);
    let e = stderr(&o);
    assert!(
        !o.status.success() && e.contains("not a tcomp private key file"),
        "{e}"
    );
    // upload names the missing unlock key before touching any board.
    let o = tcomp(&["upload", p, "--tcp", "127.0.0.1:1"]);
    let e = stderr(&o);
    assert!(!o.status.success() && e.contains("TCOMP_UNLOCK_KEY"), "{e}");
}
