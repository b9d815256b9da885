//! The model staging area: an image (and its signature trailer, if any) a
//! master uploads piece by piece, its length, and the check a commit makes
//! before anything is stored.

use thermocomp_core::image::{split_signed, ImageError, MAX_SIGNED_BYTES};
use thermocomp_core::Model;
use thermocomp_protocol::holding::result;

use crate::keys::Keys;

/// Where a commit check parses the candidate image: the model's version,
/// or why it is refused. The application lends its compensator's model
/// storage (and puts the model in force back), so a board keeps no second
/// model on the Modbus task's stack; [`ParseOnStack`] parses into a model
/// of its own (host tools and tests).
pub trait ParseCandidate {
    fn parse_candidate(&mut self, image: &[u8]) -> Result<u32, ImageError>;
}

/// [`ParseCandidate`] into a model on the caller's stack (≈ 17 KB: host
/// only, never on a board).
pub struct ParseOnStack;

impl ParseCandidate for ParseOnStack {
    fn parse_candidate(&mut self, image: &[u8]) -> Result<u32, ImageError> {
        Model::parse(image).map(|m| m.model_version)
    }
}

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
    // Inlined: the 8 KB area is written where it is kept (see AppState::new).
    #[inline(always)]
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
    /// `running_version`. `parser` parses the image (see
    /// [`ParseCandidate`]). `Ok`: the image's length (without its trailer);
    /// `Err`: the result code.
    pub fn check_commit(
        &self,
        keys: &Keys,
        running_version: u32,
        newer_only: bool,
        parser: &mut impl ParseCandidate,
    ) -> Result<usize, u16> {
        let len = usize::from(self.len);
        let Some(staged) = self.bytes.get(..len).filter(|s| !s.is_empty()) else {
            return Err(result::BAD_LENGTH);
        };
        // The image, then its signature trailer if it carries one.
        let (signed, model_version) = split_signed(staged)
            .and_then(|signed| {
                parser
                    .parse_candidate(signed.image)
                    .map(|version| (signed, version))
            })
            .map_err(|e| result::of_image_error(&e))?;
        // With a signing key stored, only a model it signed commits.
        keys.check_model(&signed)?;
        // An older or the same version only on purpose: a stale
        // upload must not replace a newer model by accident.
        if newer_only && model_version <= running_version {
            return Err(result::NOT_NEWER);
        }
        Ok(signed.image.len())
    }
}
