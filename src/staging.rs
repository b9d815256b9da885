//! The model staging area: an image (and its signature trailer, if any) a
//! master uploads piece by piece, its length, and the check a commit makes
//! before anything is stored.

use thermocomp_core::image::{split_signed, MAX_SIGNED_BYTES};
use thermocomp_core::Model;
use thermocomp_protocol::holding::result;

use crate::keys::Keys;

pub struct Staging {
    /// The image and its signature trailer, if any.
    bytes: [u8; MAX_SIGNED_BYTES],
    /// The length a master declared (HR_STAGED_LEN), ≤ [`MAX_SIGNED_BYTES`].
    len: u16,
}

impl Default for Staging {
    fn default() -> Self {
        Self::new()
    }
}

impl Staging {
    pub fn new() -> Self {
        Staging {
            bytes: [0; MAX_SIGNED_BYTES],
            len: 0,
        }
    }

    /// The declared length.
    pub fn len(&self) -> u16 {
        self.len
    }

    /// Nothing declared.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Declare the length (checked ≤ [`MAX_SIGNED_BYTES`] by the caller).
    pub fn set_len(&mut self, len: u16) {
        self.len = len;
    }

    /// The staged image bytes.
    pub fn staged(&self) -> &[u8] {
        // A length past the buffer (refused when written) stages all of it.
        self.bytes
            .get(..usize::from(self.len))
            .unwrap_or(&self.bytes)
    }

    /// The whole area, whatever the declared length.
    pub fn area(&self) -> &[u8] {
        &self.bytes
    }

    /// Scratch buffer (the staging area) for reading a stored image at
    /// boot, and where uploaded bytes are written.
    pub fn scratch(&mut self) -> &mut [u8] {
        &mut self.bytes
    }

    /// Clear the area and its length (command 5).
    pub fn clear(&mut self) {
        self.bytes.fill(0);
        self.len = 0;
    }

    /// The staged bytes as a proof (command 16: the old key's signature);
    /// empty when the declared length is past the area.
    pub fn proof(&self) -> &[u8] {
        self.bytes.get(..usize::from(self.len)).unwrap_or(&[])
    }

    /// May the staged image commit (command 3, or 17 with `newer_only`
    /// false)? It must parse, carry a signature by the stored signing key
    /// when there is one, and, with `newer_only`, be newer than
    /// `running_version`. `Ok`: the image's length (without its trailer);
    /// `Err`: the result code.
    pub fn check_commit(
        &self,
        keys: &Keys,
        running_version: u32,
        newer_only: bool,
    ) -> Result<usize, u16> {
        let len = usize::from(self.len);
        let Some(staged) = self.bytes.get(..len).filter(|s| !s.is_empty()) else {
            return Err(result::BAD_LENGTH);
        };
        // The image, then its signature trailer if it carries one.
        // Parsed in place: one model on the stack, not a second one
        // on the way out of the parser.
        let mut model = Model::empty(0, 0);
        let signed = split_signed(staged)
            .and_then(|signed| model.parse_into(signed.image).map(|()| signed))
            .map_err(|e| result::of_image_error(&e))?;
        // With a signing key stored, only a model it signed commits.
        keys.check_model(&signed)?;
        // An older or the same version only on purpose: a stale
        // upload must not replace a newer model by accident.
        if newer_only && model.model_version <= running_version {
            return Err(result::NOT_NEWER);
        }
        Ok(signed.image.len())
    }
}
