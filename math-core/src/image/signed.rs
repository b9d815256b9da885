//! A signed model file: the image, then a signature trailer.
//!
//! ```text
//! image     total_len bytes, exactly as the format defines it (CRC-32 last)
//! trailer   72 B  "TSIG", algorithm u8 (1: Ed25519), 3 × 0,
//!                 signature [64] over the image's total_len bytes
//! ```
//!
//! The trailer is outside the image, so the image, its CRC-32, its
//! `total_len` and everything the board stores and serves are the same
//! signed or not, and a file without a trailer (every image written before
//! signing existed) is read exactly as before. Only this split knows the
//! trailer; [`Model::parse`](super::Model::parse) still refuses any byte
//! after the CRC. The signature is checked by the board (`src/`), which
//! holds the public key; the core knows no cryptography.

use super::error::ImageError;
use crate::limits::MAX_IMAGE_BYTES;

/// First bytes of the signature trailer.
pub const SIGNATURE_MAGIC: [u8; 4] = *b"TSIG";
/// Algorithm byte of an Ed25519 signature (RFC 8032, pure Ed25519).
pub const SIG_ED25519: u8 = 1;
/// Bytes of an Ed25519 signature.
pub const SIGNATURE_LEN: usize = 64;
/// Bytes of the whole trailer: magic, algorithm, 3 × 0, signature.
pub const TRAILER_LEN: usize = 8 + SIGNATURE_LEN;
/// Largest signed file: the largest image and its trailer (the board's
/// staging area holds this much).
pub const MAX_SIGNED_BYTES: usize = MAX_IMAGE_BYTES + TRAILER_LEN;

/// A file split into the image and its signature, if it carries one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SignedImage<'a> {
    /// The image bytes (for [`Model::parse`](super::Model::parse)).
    pub image: &'a [u8],
    /// The Ed25519 signature over `image`, `None` for an unsigned file.
    pub signature: Option<&'a [u8; SIGNATURE_LEN]>,
}

/// Split `bytes` into the image and its signature trailer. The image's own
/// `total_len` (header bytes 8–11) says where the trailer starts; bytes
/// after the image that are exactly one trailer are the signature, anything
/// else after it stays with the image (so [`Model::parse`] refuses them as
/// trailing bytes, as before). A trailer with the magic but another
/// algorithm or non-zero padding is [`ImageError::BadSignatureTrailer`].
///
/// [`Model::parse`]: super::Model::parse
pub fn split_signed(bytes: &[u8]) -> Result<SignedImage<'_>, ImageError> {
    let unsigned = SignedImage {
        image: bytes,
        signature: None,
    };
    let Some(&[a, b, c, d]) = bytes.get(8..12) else {
        return Ok(unsigned);
    };
    let Ok(total) = usize::try_from(u32::from_le_bytes([a, b, c, d])) else {
        return Ok(unsigned);
    };
    let (Some(image), Some(trailer)) = (bytes.get(..total), bytes.get(total..)) else {
        return Ok(unsigned);
    };
    let Some((head, signature)) = trailer
        .split_first_chunk::<8>()
        .filter(|(h, _)| h.starts_with(&SIGNATURE_MAGIC))
    else {
        return Ok(unsigned);
    };
    let Ok(signature) = <&[u8; SIGNATURE_LEN]>::try_from(signature) else {
        return Err(ImageError::BadSignatureTrailer);
    };
    if head[4..] != [SIG_ED25519, 0, 0, 0] {
        return Err(ImageError::BadSignatureTrailer);
    }
    Ok(SignedImage {
        image,
        signature: Some(signature),
    })
}

/// The trailer that carries `signature` (what `tcomp export --sign` appends).
pub fn trailer(signature: &[u8; SIGNATURE_LEN]) -> [u8; TRAILER_LEN] {
    let mut t = [0u8; TRAILER_LEN];
    let head = [
        SIGNATURE_MAGIC[0],
        SIGNATURE_MAGIC[1],
        SIGNATURE_MAGIC[2],
        SIGNATURE_MAGIC[3],
        SIG_ED25519,
        0,
        0,
        0,
    ];
    for (byte, v) in t.iter_mut().zip(head.into_iter().chain(*signature)) {
        *byte = v;
    }
    t
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    fn image(len: u32) -> [u8; 40] {
        let mut b = [0u8; 40];
        b[..4].copy_from_slice(b"TCMI");
        b[8..12].copy_from_slice(&len.to_le_bytes());
        b
    }

    #[test]
    fn unsigned_files_split_into_themselves() {
        let b = image(40);
        assert_eq!(split_signed(&b).unwrap().image, &b[..]);
        assert_eq!(split_signed(&b).unwrap().signature, None);
        // Too short for a header, or trailing garbage: left to the parser.
        assert_eq!(split_signed(&b[..5]).unwrap().image.len(), 5);
        let mut long = [0u8; 50];
        long[..40].copy_from_slice(&image(40));
        assert_eq!(split_signed(&long).unwrap().image.len(), 50);
    }

    #[test]
    fn a_trailer_splits_off_and_a_bad_one_is_refused() {
        let sig = [7u8; SIGNATURE_LEN];
        let mut f = image(40).to_vec();
        f.extend_from_slice(&trailer(&sig));
        let s = split_signed(&f).unwrap();
        assert_eq!(s.image.len(), 40);
        assert_eq!(s.signature, Some(&sig));
        let mut other_alg = f.clone();
        other_alg[44] = 2;
        assert_eq!(
            split_signed(&other_alg),
            Err(ImageError::BadSignatureTrailer)
        );
        assert_eq!(
            split_signed(&f[..f.len() - 1]),
            Err(ImageError::BadSignatureTrailer)
        );
    }
}
