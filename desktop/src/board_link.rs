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

/// Register addresses (README.md, "Modbus register map").
pub mod map {
    pub const IR_SNAPSHOT: u16 = 0;
    pub const IR_SNAPSHOT_LEN: u16 = 54;
    pub const IR_TEMPERATURES: u16 = 110;
    pub const CHANNELS: u16 = 20;
    pub const HR_UNLOCK: u16 = 0;
    pub const HR_COMMAND: u16 = 1;
    pub const HR_RESULT: u16 = 2;
    pub const HR_SPINDLE: u16 = 5;
    pub const HR_STAGED_LEN: u16 = 32;
    pub const HR_STAGING: u16 = 1000;
    pub const UNLOCK_CODE: u16 = 0xA5C3;
    pub const CMD_COMMIT: u16 = 1;
    pub const NOT_AVAILABLE: u16 = 0x8000;
}

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

fn u32_of(w: &[u16], at: usize) -> u32 {
    (u32::from(w[at]) << 16) | u32::from(w[at + 1])
}

/// What an upload did.
#[derive(Debug, serde::Serialize)]
pub struct UploadSummary {
    pub bytes: usize,
    pub model_version: u32,
    pub model_crc: String,
    pub result: u16,
}

/// Validate locally, stage, commit, and check that the board now serves it.
pub fn upload(link: &mut BoardLink, image: &[u8]) -> Result<UploadSummary> {
    let model = thermocomp_core::Model::parse(image)
        .map_err(|e| anyhow!("the image is not valid, not sent: {e}"))?;
    link.write_one(map::HR_UNLOCK, map::UNLOCK_CODE)
        .context("unlocking")?;
    let mut padded = image.to_vec();
    padded.resize(image.len().div_ceil(2) * 2, 0);
    let words: Vec<u16> = padded
        .chunks(2)
        .map(|c| u16::from_be_bytes([c[0], c[1]]))
        .collect();
    for (i, chunk) in words.chunks(100).enumerate() {
        let addr = map::HR_STAGING + (i * 100) as u16;
        link.write_many(addr, chunk)
            .with_context(|| format!("staging registers {addr}…"))?;
    }
    link.write_one(map::HR_STAGED_LEN, image.len() as u16)
        .context("writing the staged length")?;
    let commit = link.write_one(map::HR_COMMAND, map::CMD_COMMIT);
    let result = link
        .read_holdings(map::HR_RESULT, 1)?
        .first()
        .copied()
        .unwrap_or(u16::MAX);
    commit.with_context(|| format!("commit refused, result register {result}"))?;
    let snap = link.read_inputs(map::IR_SNAPSHOT, 16)?;
    let (version, crc) = (u32_of(&snap, 12), u32_of(&snap, 14));
    if version != model.model_version || crc != model.crc {
        bail!(
            "the board serves version {version} crc {crc:#010x}, not the uploaded {} {:#010x}",
            model.model_version,
            model.crc
        );
    }
    Ok(UploadSummary {
        bytes: image.len(),
        model_version: version,
        model_crc: format!("{crc:#010x}"),
        result,
    })
}

/// Poll the board and append rows to a run CSV. Columns: `time_s` (host
/// time since the recording started, continued on --append), `board_time_s`
/// (the board's sample time), `spindle_rpm` (the PLC's register), `T01…`
/// (°C, empty when the channel has no valid value), `comp_d<k>_um` (the
/// served correction per direction, µm), `dprobe_um` (probe, when valid),
/// `state_T01…` (channel state codes). Each row is flushed at once.
pub fn record(
    link: &mut BoardLink,
    out: &Path,
    interval: Duration,
    samples: usize,
    append: bool,
) -> Result<usize> {
    let snap = link.read_inputs(map::IR_SNAPSHOT, map::IR_SNAPSHOT_LEN)?;
    let temps = link.read_inputs(map::IR_TEMPERATURES, 2 * map::CHANNELS)?;
    let n_dir = usize::from(snap[16]).min(6);
    // Channels in use: any state but "unused" (0).
    let channels: Vec<usize> = (0..map::CHANNELS as usize)
        .filter(|&c| temps[20 + c] != 0)
        .collect();
    let mut header = vec![
        "time_s".to_string(),
        "board_time_s".into(),
        "spindle_rpm".into(),
    ];
    header.extend(channels.iter().map(|c| format!("T{:02}", c + 1)));
    header.extend((0..n_dir).map(|d| format!("comp_d{d}_um")));
    header.push("dprobe_um".into());
    header.extend(channels.iter().map(|c| format!("state_T{:02}", c + 1)));
    let header_line = header.join(",");
    let mut t0 = 0.0;
    let mut file = if append && out.exists() {
        let text = std::fs::read_to_string(out)?;
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
        writeln!(f, "# board_model_version: {}", u32_of(&snap, 12))?;
        writeln!(f, "# board_model_crc: {:#010x}", u32_of(&snap, 14))?;
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
        let snap = link.read_inputs(map::IR_SNAPSHOT, map::IR_SNAPSHOT_LEN)?;
        let temps = link.read_inputs(map::IR_TEMPERATURES, 2 * map::CHANNELS)?;
        let rpm = link.read_holdings(map::HR_SPINDLE, 1)?[0];
        let mut row = vec![
            format!("{t:.3}"),
            u32_of(&snap, 10).to_string(),
            rpm.to_string(),
        ];
        for &c in &channels {
            let v = temps[c];
            row.push(if v == map::NOT_AVAILABLE {
                String::new()
            } else {
                format!("{:.2}", f64::from(v as i16) / 100.0)
            });
        }
        for d in 0..n_dir {
            row.push(format!(
                "{:.1}",
                f64::from(u32_of(&snap, 30 + 2 * d) as i32) / 10.0
            ));
        }
        row.push(if snap[22] == 2 {
            format!("{:.1}", f64::from(u32_of(&snap, 20) as i32) / 10.0)
        } else {
            String::new()
        });
        row.extend(channels.iter().map(|&c| temps[20 + c].to_string()));
        writeln!(file, "{}", row.join(","))?;
        file.flush()?;
    }
    Ok(samples)
}
