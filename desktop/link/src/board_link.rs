//! `tcomp record` and `tcomp upload`: a Modbus RTU master for the board,
//! over a serial port (RS-485 adapter) or a TCP socket carrying raw RTU
//! frames (the QEMU bench board's UART).
//!
//! rmodbus builds each request and checks each reply (CRC, unit, function,
//! exception codes); written here is only the transport: send, then read
//! exactly one reply (its length follows from the function code), with a
//! timeout and retries.

use std::io::{Read, Write};
use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};
use rmodbus::client::ModbusRequest;
use rmodbus::{ErrorKind, ModbusProto};

// The register map comes from the board's wire-contract crate
// (docs/register-map.md), so master and server cannot disagree on an address.
use thermocomp_core::limits::MAX_DIRECTIONS;
use thermocomp_protocol::holding::{
    result, CMD_COMMIT_MODEL, CMD_LOCK, CMD_ROLLBACK_MODEL, HR_COMMAND, HR_KEY_STATE,
    HR_PROBE_TEMP_CHANNEL, HR_RESULT, HR_SPINDLE, HR_STAGED_LEN, HR_STAGING, HR_UNLOCK,
    KEY_STATE_SIGNING_KEY, REGISTER_NONE, STAGING_REGS,
};
use thermocomp_protocol::registers::{
    IR_CHANNEL_ROMS, IR_CORRECTIONS, IR_MODEL_CRC, IR_MODEL_VERSION, IR_N_DIRECTIONS,
    IR_PREDICTIONS, IR_PROBE, IR_PROBE_STATE, IR_SAMPLE_TIME, IR_STATES, IR_TEMPERATURES,
    MAP_VERSION, NOT_AVAILABLE, TEST_PATTERN,
};
use thermocomp_protocol::rtu::MAX_WRITE_REGISTERS;
use thermocomp_protocol::states::{ChannelState, ProbeState};
use thermocomp_protocol::MAX_CHANNELS;

/// Input registers 0 up to the predictions: one request, one snapshot.
const SNAPSHOT_LEN: u16 = IR_PREDICTIONS + 2 * MAX_DIRECTIONS as u16;
/// Temperatures and channel states, adjacent: one request.
const CHANNEL_BLOCK: u16 = IR_STATES + MAX_CHANNELS as u16 - IR_TEMPERATURES;
/// Registers per staging write (≤ the FC16 maximum).
const STAGING_CHUNK: usize = 100;
const _: () = assert!(STAGING_CHUNK <= MAX_WRITE_REGISTERS);

enum Transport {
    Tcp(std::net::TcpStream),
    Serial(Box<dyn serialport::SerialPort>),
}

impl Transport {
    fn io(&mut self) -> &mut dyn ReadWrite {
        match self {
            Transport::Tcp(s) => s,
            Transport::Serial(p) => p,
        }
    }
}

trait ReadWrite: Read + Write {}
impl<T: Read + Write + ?Sized> ReadWrite for T {}

pub struct BoardLink {
    transport: Transport,
    unit: u8,
    timeout: Duration,
    retries: u32,
}

/// Name of a Modbus exception code, for error messages.
pub fn exception_name(code: u8) -> &'static str {
    match code {
        1 => "ILLEGAL FUNCTION (unknown function, or locked: unlock first)",
        2 => "ILLEGAL DATA ADDRESS",
        3 => "ILLEGAL DATA VALUE",
        4 => "SERVER DEVICE FAILURE (e.g. the staged model was refused)",
        _ => "exception",
    }
}

impl BoardLink {
    /// RTU frames over TCP (QEMU `-serial tcp:…`).
    pub fn tcp(addr: &str, unit: u8) -> Result<BoardLink> {
        let s =
            std::net::TcpStream::connect(addr).with_context(|| format!("connecting to {addr}"))?;
        s.set_nodelay(true)?;
        Ok(BoardLink {
            transport: Transport::Tcp(s),
            unit,
            timeout: Duration::from_secs(3),
            retries: 3,
        })
    }

    /// A serial port (RS-485 adapter), 8N1.
    pub fn serial(path: &str, baud: u32, unit: u8) -> Result<BoardLink> {
        let p = serialport::new(path, baud)
            .timeout(Duration::from_millis(100))
            .open()
            .with_context(|| format!("opening {path}"))?;
        Ok(BoardLink {
            transport: Transport::Serial(p),
            unit,
            timeout: Duration::from_secs(1),
            retries: 3,
        })
    }

    /// Reply timeout per try (default 3 s over TCP, 1 s on a serial port).
    pub fn with_timeout(mut self, timeout: Duration) -> Self {
        self.timeout = timeout;
        self
    }

    /// Send a request, read one reply; retry on silence (a lost or corrupted frame).
    fn transact(
        &mut self,
        mreq: &ModbusRequest,
        request: &[u8],
        data_len: impl Fn(u8) -> usize,
    ) -> Result<Vec<u8>> {
        let mut last = anyhow!("no reply");
        for _ in 0..self.retries {
            match self.once(request, &data_len) {
                Ok(reply) => match mreq.parse_ok(&reply) {
                    Ok(()) => return Ok(reply),
                    Err(e) if e.is_modbus_error() => {
                        let code = reply.get(2).copied().unwrap_or(0);
                        bail!(
                            "the board answered Modbus exception {code:02}: {}",
                            exception_name(code)
                        );
                    }
                    Err(e) => last = anyhow!("bad reply ({e:?}): {reply:02x?}"),
                },
                Err(e) => last = e,
            }
        }
        Err(last.context(format!("no valid reply after {} tries", self.retries)))
    }

    fn once(&mut self, request: &[u8], data_len: &impl Fn(u8) -> usize) -> Result<Vec<u8>> {
        let timeout = self.timeout;
        let io = self.transport.io();
        io.write_all(request)?;
        io.flush()?;
        let start = Instant::now();
        let mut reply = Vec::new();
        let mut byte = [0u8; 1];
        // Total length: exception 5; otherwise 2 + the function's data length + CRC.
        let mut want = 3usize;
        while reply.len() < want {
            if start.elapsed() > timeout {
                bail!("timeout after {} of {want} bytes", reply.len());
            }
            match read_some(
                &mut self.transport,
                &mut byte,
                timeout.saturating_sub(start.elapsed()),
            ) {
                Ok(true) => reply.push(byte[0]),
                Ok(false) => continue,
                Err(e) => return Err(e),
            }
            if reply.len() == 3 {
                want = if reply[1] & 0x80 != 0 {
                    5
                } else {
                    2 + data_len(reply[2]) + 2
                };
            }
        }
        Ok(reply)
    }

    pub fn read_inputs(&mut self, addr: u16, count: u16) -> Result<Vec<u16>> {
        self.read(addr, count, true)
    }

    pub fn read_holdings(&mut self, addr: u16, count: u16) -> Result<Vec<u16>> {
        self.read(addr, count, false)
    }

    fn read(&mut self, addr: u16, count: u16, input: bool) -> Result<Vec<u16>> {
        let mut mreq = ModbusRequest::new(self.unit, ModbusProto::Rtu);
        let mut req = Vec::new();
        if input {
            mreq.generate_get_inputs(addr, count, &mut req)
                .map_err(rm)?;
        } else {
            mreq.generate_get_holdings(addr, count, &mut req)
                .map_err(rm)?;
        }
        // Read replies: byte count, then that many bytes.
        let reply = self.transact(&mreq, &req, |b| 1 + usize::from(b))?;
        let mut out = Vec::new();
        mreq.parse_u16(&reply, &mut out).map_err(rm)?;
        Ok(out)
    }

    pub fn write_one(&mut self, addr: u16, value: u16) -> Result<()> {
        let mut mreq = ModbusRequest::new(self.unit, ModbusProto::Rtu);
        let mut req = Vec::new();
        mreq.generate_set_holding(addr, value, &mut req)
            .map_err(rm)?;
        self.transact(&mreq, &req, |_| 4).map(|_| ())
    }

    pub fn write_many(&mut self, addr: u16, values: &[u16]) -> Result<()> {
        let mut mreq = ModbusRequest::new(self.unit, ModbusProto::Rtu);
        let mut req = Vec::new();
        mreq.generate_set_holdings_bulk(addr, values, &mut req)
            .map_err(rm)?;
        self.transact(&mreq, &req, |_| 4).map(|_| ())
    }
}

fn rm(e: ErrorKind) -> anyhow::Error {
    anyhow!("Modbus: {e:?}")
}

/// Read one byte within `wait`; Ok(false) on a short read timeout.
fn read_some(t: &mut Transport, byte: &mut [u8; 1], wait: Duration) -> Result<bool> {
    let wait = wait.max(Duration::from_millis(1));
    let r = match t {
        Transport::Tcp(s) => {
            s.set_read_timeout(Some(wait))?;
            s.read(byte)
        }
        Transport::Serial(p) => p.read(byte),
    };
    match r {
        Ok(1) => Ok(true),
        Ok(_) => bail!("connection closed"),
        Err(e)
            if matches!(
                e.kind(),
                std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
            ) =>
        {
            Ok(false)
        }
        Err(e) => Err(e.into()),
    }
}

/// A 32-bit register pair (high word first) at register address `at` of a
/// block read from address 0.
fn u32_of(w: &[u16], at: u16) -> u32 {
    let at = usize::from(at);
    (u32::from(w[at]) << 16) | u32::from(w[at + 1])
}

/// What an upload did.
#[derive(Debug, serde::Serialize)]
pub struct UploadSummary {
    pub bytes: usize,
    pub model_version: u32,
    pub model_crc: String,
    pub result: u16,
    /// The file carried a signature trailer (`tcomp export --sign`).
    pub signed: bool,
    /// Model sensors the image names by a ROM code that is on none of the
    /// board's channels (input registers 200–279): the board serves without
    /// them (fallback or held) until that sensor is on the bus. Empty when
    /// the board does not serve ROM codes.
    pub sensors_not_on_board: Vec<usize>,
}

/// How `upload` commits.
#[derive(Debug, Clone, Copy)]
pub struct UploadOptions {
    pub commit: Commit,
    /// The board's own unlock key (set at commissioning).
    pub unlock_key: u16,
    /// Send a model whose sensors the board does not have now (it then
    /// serves without them: fallback or held); refused otherwise.
    pub allow_missing_sensors: bool,
}

/// The model sensors the board has no sensor for now, one line each naming
/// the sensor and its channel: by ROM code, a code on none of its channels
/// (input registers 200–279); by channel, a channel with no sensor on it
/// (state unused or no presence, 130–149). Read from the board's identity
/// registers before anything is sent.
pub fn missing_sensors(
    link: &mut BoardLink,
    model: &thermocomp_core::Model,
) -> Result<Vec<String>> {
    let by_rom = model.sensors.iter().any(|s| s.rom != [0; 8]);
    let by_channel = model.sensors.iter().any(|s| s.rom == [0; 8]);
    let roms = if by_rom {
        Some(channel_roms(link)?)
    } else {
        None
    };
    let states = if by_channel {
        Some(link.read_inputs(IR_STATES, MAX_CHANNELS as u16)?)
    } else {
        None
    };
    let absent = [ChannelState::Unused.code(), ChannelState::NoPresence.code()];
    let mut out = vec![];
    for (i, s) in model.sensors.iter().enumerate() {
        let line = if s.rom != [0; 8] {
            let on_board = roms.as_ref().is_some_and(|r| r.contains(&s.rom));
            (!on_board).then(|| {
                format!(
                    "model sensor {i} (ROM {}, trained on channel {}) is on none of the board's channels",
                    tcomp_data::runcsv::format_rom(&s.rom),
                    s.channel
                )
            })
        } else {
            let state = states
                .as_ref()
                .and_then(|st| st.get(usize::from(s.channel)).copied());
            state.is_none_or(|st| absent.contains(&st)).then(|| {
                format!(
                    "model sensor {i} reads channel {} (T{:02})",
                    s.channel,
                    s.channel + 1
                )
            })
        };
        out.extend(line);
    }
    Ok(out)
}

/// Which commit command an upload ends with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Commit {
    /// The board refuses a version not newer than the one it runs.
    NewerOnly,
    /// Go back to an older (or the same) version on purpose.
    Rollback,
}

/// Whether input registers 0–2 (test pattern, map version) come from a
/// thermocomp board whose map has every block this tool reads: an older map
/// would answer the newer addresses with exceptions or zeros. A newer map
/// keeps every address of this one, so it is accepted.
pub fn check_register_map(first: &[u16]) -> Result<()> {
    let [hi, lo, version, ..] = first else {
        bail!(
            "the board answered {} of the 3 identification registers",
            first.len()
        );
    };
    let pattern = u32::from(*hi) << 16 | u32::from(*lo);
    if pattern != TEST_PATTERN {
        bail!(
            "input registers 0-1 read {pattern:#010x}, not the test pattern {TEST_PATTERN:#010x}: not a thermocomp board, or the word order is swapped"
        );
    }
    if *version < MAP_VERSION {
        bail!(
            "the board serves register map version {version}; this tcomp needs version {MAP_VERSION} or later (update the board's firmware)"
        );
    }
    Ok(())
}

/// Validate locally, check the size, stage, commit, and check that the board
/// now serves it. `file` is an image, or an image and its signature trailer
/// (`tcomp export --sign`); `unlock_key` is the board's own key (the factory
/// code only opens commissioning). Any failure after the unlock relocks the
/// board, so a failed upload never leaves it open to configuration writes.
pub fn upload(link: &mut BoardLink, file: &[u8], opts: &UploadOptions) -> Result<UploadSummary> {
    let UploadOptions {
        commit,
        unlock_key,
        allow_missing_sensors,
    } = *opts;
    let staging_bytes = usize::from(STAGING_REGS) * 2;
    if file.len() > staging_bytes {
        bail!(
            "the image is {} bytes; the board's staging area holds {staging_bytes}: not sent",
            file.len()
        );
    }
    let signed = thermocomp_core::image::split_signed(file)
        .map_err(|e| anyhow!("the image is not valid, not sent: {e}"))?;
    let model = thermocomp_core::Model::parse(signed.image)
        .map_err(|e| anyhow!("the image is not valid, not sent: {e}"))?;
    check_register_map(&link.read_inputs(0, 3)?).context("not sent")?;
    // A board with a signing key takes signed models only (a board
    // without the key registers answers an exception: it has no key).
    let key_state = link.read_holdings(HR_KEY_STATE, 1).ok();
    let board_wants_signature = key_state
        .and_then(|k| k.first().copied())
        .is_some_and(|k| k & KEY_STATE_SIGNING_KEY != 0);
    if board_wants_signature && signed.signature.is_none() {
        bail!(
            "the board stores a signing key and commits signed models only: export with --sign <private key file>; not sent"
        );
    }
    let missing = missing_sensors(link, &model)?;
    if let (false, Some(first)) = (allow_missing_sensors, missing.first()) {
        bail!(
            "{first}{}: the board has no sensor there now; not sent (--allow-missing-sensors sends it anyway: the board then serves without them, fallback or held)",
            if missing.len() > 1 {
                format!(" (and {} more: {})", missing.len() - 1, missing[1..].join("; "))
            } else {
                String::new()
            }
        );
    }
    let is_signed = signed.signature.is_some();
    match stage_and_commit(link, file, commit, unlock_key) {
        Ok(result) => verify(link, file, &model, result, is_signed),
        Err(e) => {
            // A commit locks the board itself; everything else needs a lock.
            // (A board already locked answers exception 01: nothing to do.)
            match link.write_one(HR_COMMAND, CMD_LOCK) {
                Ok(()) => Err(e.context("upload failed; the board is locked again")),
                Err(lock) if lock.to_string().contains("exception 01") => {
                    Err(e.context("upload failed; the board is locked"))
                }
                Err(lock) => Err(e.context(format!(
                    "upload failed, and relocking failed too ({lock}); the board relocks itself 60 s after the unlock"
                ))),
            }
        }
    }
}

/// Unlock, stage, commit; the result register's value on success.
fn stage_and_commit(
    link: &mut BoardLink,
    image: &[u8],
    commit: Commit,
    unlock_key: u16,
) -> Result<u16> {
    unlock(link, unlock_key)?;
    let mut padded = image.to_vec();
    padded.resize(image.len().div_ceil(2) * 2, 0);
    let words: Vec<u16> = padded
        .chunks(2)
        .map(|c| u16::from_be_bytes([c[0], c[1]]))
        .collect();
    for (i, chunk) in words.chunks(STAGING_CHUNK).enumerate() {
        let addr = HR_STAGING + (i * STAGING_CHUNK) as u16;
        link.write_many(addr, chunk)
            .with_context(|| format!("staging registers {addr}…"))?;
    }
    // image.len() ≤ the staging area (8192), so it fits the u16 register.
    link.write_one(HR_STAGED_LEN, image.len() as u16)
        .context("writing the staged length")?;
    let command = match commit {
        Commit::NewerOnly => CMD_COMMIT_MODEL,
        Commit::Rollback => CMD_ROLLBACK_MODEL,
    };
    let committed = link.write_one(HR_COMMAND, command);
    let code = await_result(link);
    match (committed, code) {
        (Ok(()), Some(result::OK)) => Ok(result::OK),
        (Ok(()), Some(code)) => bail!("commit accepted, but storing it failed: result {code} {}", result::name(code)),
        (Ok(()), None) => bail!("committed, but the result register could not be read"),
        (Err(e), Some(result::NOT_NEWER)) => Err(e.context(format!(
            "commit refused: result {} NOT_NEWER, the board runs this or a newer model version; pass --rollback to go back on purpose",
            result::NOT_NEWER
        ))),
        (Err(e), Some(code @ (result::UNSIGNED | result::BAD_SIGNATURE))) => Err(e.context(format!(
            "commit refused: result {code} {}: the board commits only models signed with the private key of the public key it stores (registers 50-65)",
            result::name(code)
        ))),
        (Err(e), Some(code)) => Err(e.context(format!(
            "commit refused: result {code} {}",
            result::name(code)
        ))),
        (Err(e), None) => Err(e.context("commit refused")),
    }
}

/// Unlock with `key`; a refusal says what the key is.
pub fn unlock(link: &mut BoardLink, key: u16) -> Result<()> {
    link.write_one(HR_UNLOCK, key).map_err(|e| {
        if e.to_string().contains("exception 03") {
            e.context("unlocking: the board refused the key (give the board's own unlock key: --unlock-key or TCOMP_UNLOCK_KEY; the factory code opens only commissioning)")
        } else {
            e.context("unlocking")
        }
    })
}

/// HR_RESULT once the board has finished a commit: it answers a commit
/// (model, settings, keys) at once and writes the flash in the background
/// (result 23 until done: ~1-2 s for a sector erase). `None`: unreadable.
pub fn await_result(link: &mut BoardLink) -> Option<u16> {
    let read = |link: &mut BoardLink| {
        link.read_holdings(HR_RESULT, 1)
            .ok()
            .and_then(|r| r.first().copied())
    };
    let mut code = read(link);
    let start = std::time::Instant::now();
    while code == Some(result::COMMIT_IN_PROGRESS) && start.elapsed() < Duration::from_secs(15) {
        std::thread::sleep(Duration::from_millis(50));
        code = read(link);
    }
    code
}

/// The board must now serve the uploaded model.
fn verify(
    link: &mut BoardLink,
    image: &[u8],
    model: &thermocomp_core::Model,
    result: u16,
    signed: bool,
) -> Result<UploadSummary> {
    let snap = link.read_inputs(0, IR_MODEL_CRC + 2)?;
    let (version, crc) = (u32_of(&snap, IR_MODEL_VERSION), u32_of(&snap, IR_MODEL_CRC));
    if version != model.model_version || crc != model.crc {
        bail!(
            "the board serves version {version} crc {crc:#010x}, not the uploaded {} {:#010x}",
            model.model_version,
            model.crc
        );
    }
    // Sensors named by ROM that the board has on no channel.
    let sensors_not_on_board = match channel_roms(link) {
        Ok(roms) => model
            .sensors
            .iter()
            .enumerate()
            .filter(|(_, s)| s.rom != [0; 8] && !roms.contains(&s.rom))
            .map(|(i, _)| i)
            .collect(),
        Err(_) => vec![],
    };
    Ok(UploadSummary {
        bytes: image.len(),
        model_version: version,
        model_crc: format!("{crc:#010x}"),
        result,
        signed,
        sensors_not_on_board,
    })
}

/// The ROM code of each channel's sensor (all zero: unmapped), from input
/// registers 200–279 (4 per channel, bytes in bus order).
pub fn channel_roms(link: &mut BoardLink) -> Result<[[u8; 8]; MAX_CHANNELS]> {
    let words = link.read_inputs(IR_CHANNEL_ROMS, 4 * MAX_CHANNELS as u16)?;
    let mut roms = [[0u8; 8]; MAX_CHANNELS];
    for (rom, w) in roms.iter_mut().zip(words.chunks(4)) {
        for (k, v) in w.iter().enumerate() {
            rom[2 * k..2 * k + 2].copy_from_slice(&v.to_be_bytes());
        }
    }
    Ok(roms)
}

/// The probe's own temperature drift for `record`: the bus channel of the
/// DS18B20 beside it and k (nm/K), as the board's holding registers 42–43.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ProbeDriftSetup {
    pub channel: usize,
    pub nm_per_k: i16,
}

/// [`record`] with the board's probe-drift setup (holding registers 42–43).
pub fn record(
    link: &mut BoardLink,
    out: &Path,
    interval: Duration,
    samples: usize,
    append: bool,
) -> Result<usize> {
    record_with(link, out, interval, samples, append, None)
}

/// The probe's reading in µm with its drift removed, as the board removes it
/// (`thermocomp_core::reference::remove_probe_drift`): `raw` 0.1 µm, the
/// channel's temperature register (0.01 °C) back to the board's 1/16 °C.
pub fn probe_without_drift(raw: i32, temp_centi: i16, nm_per_k: i16) -> f64 {
    let t16 = (f64::from(temp_centi) * 16.0 / 100.0).round() as i32;
    f64::from(thermocomp_core::reference::remove_probe_drift(
        raw,
        t16,
        i32::from(nm_per_k),
    )) / 10.0
}

/// Poll the board and append rows to a run CSV. Columns: `time_s` (host
/// time since the recording started, continued on --append), `board_time_s`
/// (the board's sample time), `spindle_rpm` (the PLC's register), `T01…`
/// (°C, empty when the channel has no valid value), `comp_d<k>_um` (the
/// served correction per direction, µm), `dprobe_um` (probe when valid,
/// its own drift removed: `drift`, else the board's registers 42–43; empty
/// when the probe's temperature is not available), `probe_raw_um` (the
/// probe as read), `state_T01…` (channel state codes). Each row is flushed
/// at once. The metadata names each column's sensor by ROM code (`# rom.T01:
/// 28…`) when the board serves them, and the drift removed
/// (`# probe_channel`, `# probe_drift_um_per_k`); appending to a file whose
/// sensors changed is refused.
pub fn record_with(
    link: &mut BoardLink,
    out: &Path,
    interval: Duration,
    samples: usize,
    append: bool,
    drift: Option<ProbeDriftSetup>,
) -> Result<usize> {
    let snap = link.read_inputs(0, SNAPSHOT_LEN)?;
    check_register_map(&snap)?;
    let drift = drift_setup(link, drift)?;
    let block = link.read_inputs(IR_TEMPERATURES, CHANNEL_BLOCK)?;
    let state_of = |block: &[u16], c: usize| block[usize::from(IR_STATES - IR_TEMPERATURES) + c];
    let n_dir = usize::from(snap[usize::from(IR_N_DIRECTIONS)]).min(MAX_DIRECTIONS);
    // Channels in use: any state but "unused".
    let channels: Vec<usize> = (0..MAX_CHANNELS)
        .filter(|&c| state_of(&block, c) != ChannelState::Unused.code())
        .collect();
    let mut header = vec![
        "time_s".to_string(),
        "board_time_s".into(),
        "spindle_rpm".into(),
    ];
    header.extend(channels.iter().map(|c| format!("T{:02}", c + 1)));
    header.extend((0..n_dir).map(|d| format!("comp_d{d}_um")));
    header.push("dprobe_um".into());
    header.push("probe_raw_um".into());
    header.extend(channels.iter().map(|c| format!("state_T{:02}", c + 1)));
    let header_line = header.join(",");
    // The sensor on each channel, by ROM code (input registers 200–279).
    let roms = channel_roms(link);
    let rom_lines: Vec<(String, String)> = match &roms {
        Ok(roms) => channels
            .iter()
            .filter(|&&c| roms[c] != [0; 8])
            .map(|&c| {
                (
                    format!("{}T{:02}", tcomp_data::runcsv::ROM_KEY_PREFIX, c + 1),
                    tcomp_data::runcsv::format_rom(&roms[c]),
                )
            })
            .collect(),
        Err(e) => {
            eprintln!("note: the board does not serve ROM codes (input registers 200-279: {e}); the run names no sensor by ROM code");
            vec![]
        }
    };
    let mut t0 = 0.0;
    let mut file = if append && out.exists() {
        let text = std::fs::read_to_string(out)?;
        // A column must stay one physical sensor: a swapped sensor starts a new file.
        for line in text.lines().filter_map(|l| l.strip_prefix("# ")) {
            let Some((k, v)) = line.split_once(':') else {
                continue;
            };
            if !k.starts_with(tcomp_data::runcsv::ROM_KEY_PREFIX) {
                continue;
            }
            let now = rom_lines.iter().find(|(key, _)| key == k.trim());
            if now.map(|(_, r)| r.as_str()) != Some(v.trim()) {
                bail!(
                    "{}: the sensor of {} was {} when the file was started and is {} now; record to a new file",
                    out.display(),
                    k.trim().trim_start_matches(tcomp_data::runcsv::ROM_KEY_PREFIX),
                    v.trim(),
                    now.map_or("missing", |(_, r)| r.as_str())
                );
            }
        }
        let mut lines = text.lines().filter(|l| !l.starts_with('#'));
        if lines.next() != Some(header_line.as_str()) {
            bail!(
                "{} has other columns than this board gives; record to a new file",
                out.display()
            );
        }
        if let Some(last) = lines.next_back() {
            t0 = last
                .split(',')
                .next()
                .and_then(|v| v.parse::<f64>().ok())
                .unwrap_or(0.0)
                + interval.as_secs_f64();
        }
        std::fs::OpenOptions::new().append(true).open(out)?
    } else {
        let mut f =
            std::fs::File::create(out).with_context(|| format!("creating {}", out.display()))?;
        writeln!(f, "# source: recorded")?;
        writeln!(
            f,
            "# board_model_version: {}",
            u32_of(&snap, IR_MODEL_VERSION)
        )?;
        writeln!(
            f,
            "# board_model_crc: {:#010x}",
            u32_of(&snap, IR_MODEL_CRC)
        )?;
        for (k, v) in &rom_lines {
            writeln!(f, "# {k}: {v}")?;
        }
        if let Some(d) = drift {
            writeln!(f, "# probe_channel: T{:02}", d.channel + 1)?;
            writeln!(
                f,
                "# probe_drift_um_per_k: {}",
                f64::from(d.nm_per_k) / 1000.0
            )?;
        }
        writeln!(f, "{header_line}")?;
        f
    };
    let start = Instant::now();
    for k in 0..samples {
        let due = start + interval * k as u32;
        if let Some(wait) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
        let t = t0 + start.elapsed().as_secs_f64();
        let snap = link.read_inputs(0, SNAPSHOT_LEN)?;
        let block = link.read_inputs(IR_TEMPERATURES, CHANNEL_BLOCK)?;
        let rpm = link.read_holdings(HR_SPINDLE, 1)?[0];
        let mut row = vec![
            format!("{t:.3}"),
            u32_of(&snap, IR_SAMPLE_TIME).to_string(),
            rpm.to_string(),
        ];
        for &c in &channels {
            let v = block[c];
            row.push(if v == NOT_AVAILABLE {
                String::new()
            } else {
                format!("{:.2}", f64::from(v as i16) / 100.0)
            });
        }
        for d in 0..n_dir {
            row.push(format!(
                "{:.1}",
                f64::from(u32_of(&snap, IR_CORRECTIONS + 2 * d as u16) as i32) / 10.0
            ));
        }
        row.extend(probe_cells(&snap, &block, drift));
        row.extend(channels.iter().map(|&c| state_of(&block, c).to_string()));
        writeln!(file, "{}", row.join(","))?;
        file.flush()?;
    }
    Ok(samples)
}

/// The drift `record` removes: given, else the board's holding registers 42–43.
fn drift_setup(
    link: &mut BoardLink,
    given: Option<ProbeDriftSetup>,
) -> Result<Option<ProbeDriftSetup>> {
    let drift = match given {
        Some(d) => Some(d),
        None => {
            let w = link.read_holdings(HR_PROBE_TEMP_CHANNEL, 2)?;
            (w[0] != REGISTER_NONE).then(|| ProbeDriftSetup {
                channel: usize::from(w[0]),
                nm_per_k: w[1] as i16,
            })
        }
    };
    if let Some(d) = drift {
        if d.channel >= MAX_CHANNELS {
            bail!(
                "probe temperature channel {}: the board has channels 1-{MAX_CHANNELS}",
                d.channel + 1
            );
        }
    }
    Ok(drift)
}

/// `dprobe_um` (drift removed; empty without the probe's temperature) and
/// `probe_raw_um` of one row, both empty when the probe is not OK.
fn probe_cells(snap: &[u16], block: &[u16], drift: Option<ProbeDriftSetup>) -> [String; 2] {
    let raw = (snap[usize::from(IR_PROBE_STATE)] == ProbeState::Ok.code())
        .then(|| u32_of(snap, IR_PROBE) as i32);
    let without = match (raw, drift) {
        (Some(r), None) => Some(f64::from(r) / 10.0),
        (Some(r), Some(d)) => Some(block[d.channel])
            .filter(|&t| t != NOT_AVAILABLE)
            .map(|t| probe_without_drift(r, t as i16, d.nm_per_k)),
        (None, _) => None,
    };
    [
        without.map_or(String::new(), |v| format!("{v:.1}")),
        raw.map_or(String::new(), |r| format!("{:.1}", f64::from(r) / 10.0)),
    ]
}
