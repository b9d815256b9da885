//! `tcomp keygen` and `tcomp commission` (issue 30: signed models and the
//! per-board unlock key), and the unlock key every board-writing command
//! takes (`--unlock-key`, else the `TCOMP_UNLOCK_KEY` environment variable,
//! so the key need not be on the command line).

use anyhow::{anyhow, Result};
use tcomp_link::board_link::BoardLink;
use tcomp_link::commission::{commission, key_state, Commission, SigningKey};

/// Where the unlock key of a board-writing command comes from.
#[derive(clap::Args)]
pub struct UnlockArgs {
    /// The board's own unlock key (0x… or decimal; default: the
    /// TCOMP_UNLOCK_KEY environment variable). A board that has none yet
    /// takes the factory code, for commissioning only.
    #[arg(long)]
    pub unlock_key: Option<String>,
}

impl UnlockArgs {
    /// The key given (flag, else environment); `None`: none given.
    pub fn key(&self) -> Result<Option<u16>> {
        let text = match &self.unlock_key {
            Some(k) => Some(k.clone()),
            None => std::env::var("TCOMP_UNLOCK_KEY").ok(),
        };
        text.map(|t| parse_key(&t)).transpose()
    }
}

/// A 16-bit key: `0x1234` or `4660`.
pub fn parse_key(text: &str) -> Result<u16> {
    let t = text.trim();
    let v = match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
        Some(hex) => u16::from_str_radix(hex, 16),
        None => t.parse::<u16>(),
    };
    v.map_err(|_| anyhow!("unlock key {t:?}: expected a 16-bit number (0x1234 or 4660)"))
}

#[derive(clap::Args)]
pub struct KeygenArgs {
    /// A directory (writes tcomp-signing.key and tcomp-signing.pub) or a
    /// file (writes it and FILE.pub). Existing files are not overwritten.
    pub target: std::path::PathBuf,
    /// Print the written files as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn keygen(args: KeygenArgs) -> Result<()> {
    let files = tcomp_model::signing::keygen(&args.target)?;
    if args.json {
        println!("{}", serde_json::to_string(&files)?);
    } else {
        println!(
            "wrote private key {} (keep it secret: whoever has it can sign models) and public key {}\n  public key {}",
            files.private_key.display(),
            files.public_key.display(),
            files.public_hex
        );
    }
    Ok(())
}

#[derive(clap::Args)]
pub struct CommissionArgs {
    #[command(flatten)]
    pub unlock: UnlockArgs,
    /// Give the board this unlock key (0x… or decimal; not 0 nor the factory code).
    #[arg(long)]
    pub new_unlock_key: Option<String>,
    /// Store this public key file (`tcomp keygen`): from then on the board
    /// commits only models signed with its private key.
    #[arg(long)]
    pub signing_key: Option<std::path::PathBuf>,
    /// Replace the board's stored signing key by --signing-key, proven by
    /// the old private key file.
    #[arg(long, requires = "signing_key")]
    pub replace_signed_by: Option<std::path::PathBuf>,
    /// Print the board's key state as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn commission_board(mut link: BoardLink, args: CommissionArgs) -> Result<()> {
    let signing_key = match (&args.signing_key, &args.replace_signed_by) {
        (Some(public), None) => Some(SigningKey::First(tcomp_model::signing::read_public(
            public,
        )?)),
        (Some(public), Some(old)) => {
            let key = tcomp_model::signing::read_public(public)?;
            let old = tcomp_model::signing::read_private(old)?;
            Some(SigningKey::Replace {
                key,
                proof: tcomp_model::signing::key_change_proof(&old, &key),
            })
        }
        (None, _) => None,
    };
    let c = Commission {
        unlock_key: args.unlock.key()?,
        new_unlock_key: args.new_unlock_key.as_deref().map(parse_key).transpose()?,
        signing_key,
    };
    let state = if c.new_unlock_key.is_none() && c.signing_key.is_none() {
        key_state(&mut link)?
    } else {
        commission(&mut link, &c)?
    };
    if args.json {
        println!("{}", serde_json::to_string(&state)?);
    } else {
        println!(
            "unlock key: {}; signing key: {}",
            if state.unlock_key_set {
                "set (the board's own)"
            } else {
                "none (factory code: commissioning only)"
            },
            if state.signing_key_stored {
                // The board never reads its stored key back: registers 50-65
                // hold whatever any master wrote there last.
                format!(
                    "stored (registers 50-65 show the key last written, which need not be the stored one: {}; a signed upload is the proof)",
                    state.signing_key
                )
            } else {
                "none (unsigned models commit)".to_string()
            }
        );
    }
    Ok(())
}
