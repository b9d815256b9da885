//! `tcomp commission`: give a board its own unlock key and the public key
//! its models must be signed with (holding registers 50–67, commands 14–16,
//! docs/register-map.md "Keys and commissioning").
//!
//! A fresh board has no unlock key: the factory code unlocks it for
//! commissioning only (setting its key, command 15). Once it has its key,
//! only that key unlocks it; the board never shows it.

use anyhow::{bail, Context, Result};
use thermocomp_protocol::holding::{
    result, CMD_LOCK, CMD_REPLACE_SIGNING_KEY, CMD_SET_UNLOCK_KEY, CMD_STORE_SIGNING_KEY,
    FACTORY_UNLOCK_CODE, HR_COMMAND, HR_KEY_STATE, HR_NEW_UNLOCK_KEY, HR_SIGNING_KEY,
    HR_STAGED_LEN, HR_STAGING, KEY_STATE_SIGNING_KEY, KEY_STATE_UNLOCK_KEY,
};

use crate::board_link::{await_result, unlock, BoardLink};

/// A signing key to store on the board.
#[derive(Debug, Clone, Copy)]
pub enum SigningKey {
    /// The first key (command 14; refused when one is stored).
    First([u8; 32]),
    /// Replace the stored key (command 16): the new key and the old key's
    /// signature over "thermocomp signing key v1" ‖ the new key.
    Replace { key: [u8; 32], proof: [u8; 64] },
}

/// What to commission.
#[derive(Debug, Clone, Copy)]
pub struct Commission {
    /// The board's unlock key now; `None`: a fresh board (factory code).
    pub unlock_key: Option<u16>,
    /// Set the board's unlock key to this.
    pub new_unlock_key: Option<u16>,
    pub signing_key: Option<SigningKey>,
}

/// The board's key state after commissioning (HR_KEY_STATE).
#[derive(Debug, serde::Serialize)]
pub struct KeyState {
    pub unlock_key_set: bool,
    pub signing_key_stored: bool,
    /// Holding registers 50–65 in hex when a key is stored (empty: none):
    /// the key last written there, which the board does not guarantee to be
    /// the stored one (it never reads its stored key back).
    pub signing_key: String,
}

/// Read HR_KEY_STATE and the signing key registers.
pub fn key_state(link: &mut BoardLink) -> Result<KeyState> {
    let state = link
        .read_holdings(HR_KEY_STATE, 1)
        .context("reading the key state (holding register 66): does this firmware have keys?")?;
    let bits = state.first().copied().unwrap_or(0);
    let key = link.read_holdings(HR_SIGNING_KEY, 16)?;
    let stored = bits & KEY_STATE_SIGNING_KEY != 0;
    Ok(KeyState {
        unlock_key_set: bits & KEY_STATE_UNLOCK_KEY != 0,
        signing_key_stored: stored,
        signing_key: if stored {
            key.iter().map(|w| format!("{w:04x}")).collect()
        } else {
            String::new()
        },
    })
}

/// Run the commissioning steps; the board ends locked whatever happens.
pub fn commission(link: &mut BoardLink, c: &Commission) -> Result<KeyState> {
    let outcome = steps(link, c);
    // Every step ends with the board locked (command 15 locks by itself,
    // a refusal locks); lock once more for the paths that do not.
    let _ = link.write_one(HR_COMMAND, CMD_LOCK);
    outcome?;
    key_state(link)
}

fn steps(link: &mut BoardLink, c: &Commission) -> Result<()> {
    let mut key = c.unlock_key.unwrap_or(FACTORY_UNLOCK_CODE);
    if let Some(new) = c.new_unlock_key {
        if new == 0 || new == FACTORY_UNLOCK_CODE {
            bail!("the new unlock key may be neither 0 nor the factory code");
        }
        unlock(link, key)?;
        link.write_one(HR_NEW_UNLOCK_KEY, new)
            .context("writing the new unlock key")?;
        run(link, CMD_SET_UNLOCK_KEY, "setting the unlock key")?;
        key = new;
    }
    if let Some(signing) = c.signing_key {
        unlock(link, key)?;
        let (public, command) = match signing {
            SigningKey::First(k) => (k, CMD_STORE_SIGNING_KEY),
            SigningKey::Replace { key, proof } => {
                let words: Vec<u16> = proof
                    .chunks(2)
                    .map(|c| u16::from_be_bytes([c[0], c[1]]))
                    .collect();
                link.write_many(HR_STAGING, &words)
                    .context("staging the key-change signature")?;
                link.write_one(HR_STAGED_LEN, 64)?;
                (key, CMD_REPLACE_SIGNING_KEY)
            }
        };
        let words: Vec<u16> = public
            .chunks(2)
            .map(|c| u16::from_be_bytes([c[0], c[1]]))
            .collect();
        link.write_many(HR_SIGNING_KEY, &words)
            .context("writing the signing key (holding registers 50-65)")?;
        run(link, command, "storing the signing key")?;
    }
    Ok(())
}

/// Write a key command and wait until it is stored.
fn run(link: &mut BoardLink, command: u16, what: &str) -> Result<()> {
    let sent = link.write_one(HR_COMMAND, command);
    let code = await_result(link);
    match (sent, code) {
        (Ok(()), Some(result::OK)) => Ok(()),
        (Ok(()), Some(code)) => bail!(
            "{what}: in force but not stored: result {code} {}",
            result::name(code)
        ),
        (Ok(()), None) => bail!("{what}: the result register could not be read"),
        (Err(e), Some(code @ result::SIGNING_KEY_SET)) => Err(e.context(format!(
            "{what}: refused, result {code} SIGNING_KEY_SET: the board stores a signing key; replace it with --replace-signed-by <old private key file>"
        ))),
        (Err(e), Some(code)) => Err(e.context(format!(
            "{what}: refused, result {code} {}",
            result::name(code)
        ))),
        (Err(e), None) => Err(e.context(format!("{what}: refused"))),
    }
}
