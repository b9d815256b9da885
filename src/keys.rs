//! The board's keys (issue 30): its own unlock key and the public key that
//! model images must be signed with. Both are set at commissioning, stored
//! in the settings store ([`crate::settings::StoredKeys`]), and
//! never shown: the unlock key is in no register and no log; the public
//! key reads back (it is no secret).
//!
//! Signatures are Ed25519 (RFC 8032) checked by `ed25519-compact` (no_std,
//! no heap); the signed bytes are the image's own `total_len` bytes, the
//! signature travels in a trailer after them
//! (`thermocomp_core::image::signed`).

use ed25519_compact::{PublicKey, Signature};
use thermocomp_core::image::signed::SIGNATURE_LEN;
use thermocomp_core::image::SignedImage;
use thermocomp_protocol::holding::{result, FACTORY_UNLOCK_CODE};

/// The key's length in bytes (Ed25519 public key).
pub const PUBLIC_KEY_LEN: usize = 32;
/// What a signature replacing the signing key (command 16) signs: this,
/// then the new key's 32 bytes. The prefix keeps a key-change signature
/// from ever being read as a model signature (an image starts "TCMI").
pub const KEY_CHANGE_CONTEXT: &[u8] = b"thermocomp signing key v1";

/// The keys in force and what a master has written for the next key command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Keys {
    /// The board's own unlock key; `None`: not commissioned (the factory
    /// code opens the commissioning unlock only).
    pub unlock: Option<u16>,
    /// The stored signing key; `None`: unsigned models commit as before.
    pub signing: Option<[u8; PUBLIC_KEY_LEN]>,
    /// HR_SIGNING_KEY as written (for commands 14 and 16).
    pub staged_signing: [u8; PUBLIC_KEY_LEN],
    /// HR_NEW_UNLOCK_KEY as written (for command 15).
    pub new_unlock: u16,
}

impl Keys {
    /// Keys loaded from the slots: the staged signing key shows the stored one.
    pub fn stored(unlock: Option<u16>, signing: Option<[u8; PUBLIC_KEY_LEN]>) -> Keys {
        Keys {
            unlock,
            signing,
            staged_signing: signing.unwrap_or([0; PUBLIC_KEY_LEN]),
            new_unlock: 0,
        }
    }

    /// May a model with this signature (or none) commit? `Err` is the result code.
    pub fn check_model(&self, signed: &SignedImage<'_>) -> Result<(), u16> {
        let Some(key) = &self.signing else {
            // No key stored: signed and unsigned images commit alike (a
            // signature is only checked against a key the board holds).
            return Ok(());
        };
        let Some(signature) = signed.signature else {
            return Err(result::UNSIGNED);
        };
        if verify(key, signed.image, signature) {
            Ok(())
        } else {
            Err(result::BAD_SIGNATURE)
        }
    }

    /// Command 14: store the staged signing key (none stored yet).
    pub fn store_signing(&mut self) -> Result<(), u16> {
        if self.signing.is_some() {
            return Err(result::SIGNING_KEY_SET);
        }
        let key = self.valid_staged_key()?;
        self.signing = Some(key);
        Ok(())
    }

    /// Command 16: replace the stored signing key by the staged one; `proof`
    /// (the staging area) is the stored key's signature over
    /// [`KEY_CHANGE_CONTEXT`] and the new key.
    pub fn replace_signing(&mut self, proof: &[u8]) -> Result<(), u16> {
        let Some(old) = &self.signing else {
            // Nothing to replace: command 14 stores a first key.
            return Err(result::BAD_KEY);
        };
        let new = self.valid_staged_key()?;
        let Ok(proof) = <&[u8; SIGNATURE_LEN]>::try_from(proof) else {
            return Err(result::BAD_SIGNATURE);
        };
        let mut message = [0u8; KEY_CHANGE_CONTEXT.len() + PUBLIC_KEY_LEN];
        for (m, &b) in message
            .iter_mut()
            .zip(KEY_CHANGE_CONTEXT.iter().chain(new.iter()))
        {
            *m = b;
        }
        if !verify(old, &message, proof) {
            return Err(result::BAD_SIGNATURE);
        }
        self.signing = Some(new);
        Ok(())
    }

    /// Command 15: the staged unlock key becomes the board's own (not 0,
    /// not the factory code).
    pub fn set_unlock(&mut self) -> Result<(), u16> {
        let k = self.new_unlock;
        if k == 0 || k == FACTORY_UNLOCK_CODE {
            return Err(result::BAD_KEY);
        }
        self.unlock = Some(k);
        self.new_unlock = 0;
        Ok(())
    }

    fn valid_staged_key(&self) -> Result<[u8; PUBLIC_KEY_LEN], u16> {
        let key = self.staged_signing;
        // A key that is no canonical curve point, or a small-order one,
        // could never verify a signature (or verify too many).
        PublicKey::new(key)
            .validate()
            .map(|()| key)
            .map_err(|_| result::BAD_KEY)
    }
}

/// Is `signature` an Ed25519 signature of `message` by `key`?
pub fn verify(key: &[u8; PUBLIC_KEY_LEN], message: &[u8], signature: &[u8; SIGNATURE_LEN]) -> bool {
    PublicKey::new(*key)
        .verify(message, &Signature::new(*signature))
        .is_ok()
}

#[cfg(test)]
#[allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::cast_possible_truncation
)]
mod tests {
    use super::*;

    /// A signature made by another implementation (Python `cryptography`,
    /// seed 00 01 … 1f, message byte i = (7i + 3) mod 256, 2,048 bytes);
    /// the QEMU bench times the same verification.
    #[test]
    fn verifies_another_implementations_signature_and_nothing_else() {
        fn hex<const N: usize>(s: &str) -> [u8; N] {
            core::array::from_fn(|i| u8::from_str_radix(&s[2 * i..2 * i + 2], 16).unwrap())
        }
        let key: [u8; 32] = hex("03a107bff3ce10be1d70dd18e74bc09967e4d6309ba50d5f1ddc8664125531b8");
        let sig: [u8; 64] = hex("5bd00ad8e1273e224b4f2dd08bb72f89bb14a30c83f5476224cb321f4d350c8ba568aab5b6e5e4f9c416ac58f6f8add6691b04b3e565c2c1ed46d525dcba1101");
        let mut message: [u8; 2048] = core::array::from_fn(|i| ((7 * i + 3) % 256) as u8);
        assert!(verify(&key, &message, &sig));
        message[1000] ^= 1;
        assert!(!verify(&key, &message, &sig));
    }
}
