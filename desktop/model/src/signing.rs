//! Model signing (issue 30): `tcomp keygen` writes an Ed25519 key pair,
//! `tcomp export --sign` appends the signature trailer
//! (`thermocomp_core::image::signed`) to the image, and a key change
//! (command 16) is signed by the old key. The board checks with the same
//! algorithm (`ed25519-compact`, RFC 8032 Ed25519).
//!
//! Key files are text, one key per file, hex-encoded:
//!
//! ```text
//! # tcomp model-signing private key (Ed25519 seed): keep it secret
//! ed25519-seed: 0f1e…(64 hex digits)
//! ```
//!
//! and `ed25519-public: …` for the public key (what a board stores).

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};
/// A private signing key (the type `read_private` returns).
pub use ed25519_compact::SecretKey;
use ed25519_compact::{KeyPair, PublicKey, Seed};
use thermocomp_core::image::signed::{trailer, SIGNATURE_LEN};
use thermocomp_core::image::split_signed;

const SEED_TAG: &str = "ed25519-seed:";
const PUBLIC_TAG: &str = "ed25519-public:";
/// File names `tcomp keygen DIR` writes.
pub const PRIVATE_FILE: &str = "tcomp-signing.key";
pub const PUBLIC_FILE: &str = "tcomp-signing.pub";
/// What a signature replacing a board's signing key signs (then the new
/// key); the board's `KEY_CHANGE_CONTEXT`.
pub const KEY_CHANGE_CONTEXT: &[u8] = b"thermocomp signing key v1";

/// The two files `keygen` wrote.
#[derive(Debug, serde::Serialize)]
pub struct KeyFiles {
    pub private_key: PathBuf,
    pub public_key: PathBuf,
    /// The public key, hex (what the board's registers 50–65 will hold).
    pub public_hex: String,
}

/// Where `keygen` writes: into a directory (`tcomp-signing.key` and
/// `.pub`), or to a file and the same name with `.pub` added.
pub fn key_paths(target: &Path) -> (PathBuf, PathBuf) {
    if target.is_dir() {
        (target.join(PRIVATE_FILE), target.join(PUBLIC_FILE))
    } else {
        let mut public = target.as_os_str().to_owned();
        public.push(".pub");
        (target.to_path_buf(), PathBuf::from(public))
    }
}

/// Make a new key pair from the system's random source and write it;
/// refuses to overwrite either file.
pub fn keygen(target: &Path) -> Result<KeyFiles> {
    let (private_key, public_key) = key_paths(target);
    for p in [&private_key, &public_key] {
        if p.exists() {
            bail!(
                "{} exists: not overwritten (a signing key is not replaceable by accident)",
                p.display()
            );
        }
    }
    let pair = KeyPair::from_seed(Seed::generate());
    let seed = pair.sk.seed();
    let public_hex = hex(&pair.pk[..]);
    write_new(
        &private_key,
        &format!(
            "# tcomp model-signing private key (Ed25519 seed): keep it secret\n{SEED_TAG} {}\n",
            hex(&seed[..])
        ),
        true,
    )?;
    write_new(
        &public_key,
        &format!("# tcomp model-signing public key (Ed25519): store it on a board with `tcomp commission --signing-key`\n{PUBLIC_TAG} {public_hex}\n"),
        false,
    )?;
    Ok(KeyFiles {
        private_key,
        public_key,
        public_hex,
    })
}

fn write_new(path: &Path, text: &str, secret: bool) -> Result<()> {
    let mut opts = std::fs::OpenOptions::new();
    opts.write(true).create_new(true);
    #[cfg(unix)]
    if secret {
        use std::os::unix::fs::OpenOptionsExt;
        opts.mode(0o600);
    }
    #[cfg(not(unix))]
    let _ = secret;
    let mut f = opts
        .open(path)
        .with_context(|| format!("creating {}", path.display()))?;
    f.write_all(text.as_bytes())
        .with_context(|| format!("writing {}", path.display()))
}

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

fn unhex<const N: usize>(s: &str) -> Option<[u8; N]> {
    let s = s.trim();
    if s.len() != 2 * N || !s.is_ascii() {
        return None;
    }
    let mut out = [0u8; N];
    for (i, o) in out.iter_mut().enumerate() {
        *o = u8::from_str_radix(&s[2 * i..2 * i + 2], 16).ok()?;
    }
    Some(out)
}

/// The value after `tag` in a key file.
fn tagged<const N: usize>(path: &Path, tag: &str, what: &str) -> Result<[u8; N]> {
    let text =
        std::fs::read_to_string(path).map_err(|e| anyhow!("reading {}: {e}", path.display()))?;
    let value = text
        .lines()
        .find_map(|l| l.trim().strip_prefix(tag))
        .ok_or_else(|| anyhow!("{}: not a {what} file (no `{tag}` line)", path.display()))?;
    unhex::<N>(value)
        .ok_or_else(|| anyhow!("{}: `{tag}` is not {} hex digits", path.display(), 2 * N))
}

/// The private key of a `keygen` private key file.
pub fn read_private(path: &Path) -> Result<SecretKey> {
    let seed = tagged::<32>(path, SEED_TAG, "tcomp private key")?;
    Ok(KeyPair::from_seed(Seed::new(seed)).sk)
}

/// The public key (32 bytes) of a `keygen` public key file, checked to be
/// a key a board accepts (a canonical point of large order).
pub fn read_public(path: &Path) -> Result<[u8; 32]> {
    let key = tagged::<32>(path, PUBLIC_TAG, "tcomp public key")?;
    PublicKey::new(key)
        .validate()
        .map_err(|_| anyhow!("{}: not a valid Ed25519 public key", path.display()))?;
    Ok(key)
}

/// The public half of a private key.
pub fn public_of(sk: &SecretKey) -> [u8; 32] {
    *sk.public_key()
}

/// Ed25519 signature of `message` (deterministic, RFC 8032).
pub fn sign(sk: &SecretKey, message: &[u8]) -> [u8; SIGNATURE_LEN] {
    *sk.sign(message, None)
}

/// The image with its signature trailer appended. Refuses a file that is
/// already signed (sign the unsigned image).
pub fn sign_image(image: &[u8], sk: &SecretKey) -> Result<Vec<u8>> {
    let split = split_signed(image).map_err(|e| anyhow!("{e}"))?;
    if split.signature.is_some() {
        bail!("the image is signed already");
    }
    let mut out = image.to_vec();
    out.extend_from_slice(&trailer(&sign(sk, image)));
    Ok(out)
}

/// Does `signature` sign `message` under `key`?
pub fn verify(key: &[u8; 32], message: &[u8], signature: &[u8; SIGNATURE_LEN]) -> bool {
    PublicKey::new(*key)
        .verify(message, &ed25519_compact::Signature::new(*signature))
        .is_ok()
}

/// The proof command 16 wants: the old key's signature over
/// [`KEY_CHANGE_CONTEXT`] and the new public key.
pub fn key_change_proof(old: &SecretKey, new_public: &[u8; 32]) -> [u8; SIGNATURE_LEN] {
    let mut message = KEY_CHANGE_CONTEXT.to_vec();
    message.extend_from_slice(new_public);
    sign(old, &message)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keygen_writes_a_pair_that_signs_and_refuses_to_overwrite() {
        let dir = tempfile::tempdir().unwrap();
        let files = keygen(dir.path()).unwrap();
        let sk = read_private(&files.private_key).unwrap();
        let pk = read_public(&files.public_key).unwrap();
        assert_eq!(public_of(&sk), pk);
        let sig = sign(&sk, b"TCMI image");
        assert!(verify(&pk, b"TCMI image", &sig));
        assert!(!verify(&pk, b"TCMI imagf", &sig));
        let again = keygen(dir.path()).unwrap_err().to_string();
        assert!(again.contains("not overwritten"), "{again}");
        // A file target gets `.pub` beside it.
        let f = dir.path().join("line3");
        let files = keygen(&f).unwrap();
        assert_eq!(files.public_key, dir.path().join("line3.pub"));
        assert!(read_public(&files.private_key).is_err());
    }
}
