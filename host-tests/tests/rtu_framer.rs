//! The RTU framer both boards run (src/modbus/rtu_framer.rs): the spec's
//! 3.5-character end, 1.5-character break and 256-byte limit on timed bytes,
//! and the frame-in-frame case of issue 30 end to end through the server.
use heapless::Vec as HVec;
use thermocomp::modbus::rtu_framer::{Outcome, RtuFramer, Timing};
use thermocomp::modbus::{Server, Snapshot};
use thermocomp::state::AppState;
use thermocomp_protocol::holding::*;
use thermocomp_protocol::rtu::{crc16, MAX_FRAME};

/// One character of 11 bits at 115200 baud, µs (rounded up).
const CHAR_115200: u64 = 96;

fn frame(body: &[u8]) -> Vec<u8> {
    let mut f = body.to_vec();
    f.extend_from_slice(&crc16(body).to_le_bytes());
    f
}

/// What came out of the framer: outcomes, with a good frame's bytes.
#[derive(Debug, PartialEq, Eq)]
enum Got {
    Frame(Vec<u8>),
    Broken,
    Oversize,
}

struct Line {
    framer: RtuFramer,
    now: u64,
    char_us: u64,
    got: Vec<Got>,
}

impl Line {
    fn new(baud: u32, char_us: u64) -> Line {
        Line {
            framer: RtuFramer::new(Timing::for_baud(baud)),
            now: 1_000_000,
            char_us,
            got: vec![],
        }
    }
    fn note(&mut self, o: Option<Outcome>) {
        match o {
            Some(Outcome::Frame) => self.got.push(Got::Frame(self.framer.frame().to_vec())),
            Some(Outcome::Broken) => self.got.push(Got::Broken),
            Some(Outcome::Oversize) => self.got.push(Got::Oversize),
            None => {}
        }
    }
    /// Bytes back to back, one character time apart.
    fn send(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.now += self.char_us;
            let o = self.framer.push(b, self.now);
            self.note(o);
        }
    }
    /// Silence for `us`, the framer asked at its deadline and at the end.
    fn silence(&mut self, us: u64) {
        let end = self.now + us;
        if let Some(d) = self.framer.deadline_us().filter(|d| *d <= end) {
            let o = self.framer.idle(d);
            self.note(o);
        }
        let o = self.framer.idle(end);
        self.note(o);
        self.now = end;
    }
}

#[test]
fn the_spec_timing_per_baud_rate() {
    assert_eq!(
        Timing::for_baud(9600),
        Timing {
            t15_us: 1719,
            t35_us: 4011,
            char_us: 1146
        }
    );
    assert_eq!(
        Timing::for_baud(19_200),
        Timing {
            t15_us: 860,
            t35_us: 2006,
            char_us: 573
        }
    );
    for baud in [38_400u32, 57_600, 115_200, 230_400] {
        let t = Timing::for_baud(baud);
        assert_eq!((t.t15_us, t.t35_us), (750, 1750), "{baud}");
        assert_eq!(t.char_us, 11_000_000u64.div_ceil(u64::from(baud)));
    }
}

#[test]
fn a_frame_ends_at_a_silence_of_3_5_characters_not_before() {
    let req = frame(&[1, 4, 0, 0, 0, 2]);
    let mut line = Line::new(115_200, CHAR_115200);
    line.send(&req);
    let last = line.now;
    assert_eq!(line.framer.deadline_us(), Some(last + 1750));
    assert_eq!(
        line.framer.idle(last + 1749),
        None,
        "3.5 chars not yet over"
    );
    assert_eq!(line.framer.idle(last + 1750), Some(Outcome::Frame));
    assert_eq!(line.framer.frame(), &req[..]);
    // Nothing more until the next byte.
    assert_eq!(line.framer.idle(last + 100_000), None);
    assert!(line.framer.frame().is_empty());
    assert_eq!(line.framer.deadline_us(), None);
}

#[test]
fn back_to_back_frames_separated_by_3_5_characters_are_two_frames() {
    let a = frame(&[1, 4, 0, 0, 0, 2]);
    let b = frame(&[1, 3, 0, 0, 0, 1]);
    for baud in [9600u32, 19_200, 115_200] {
        let t = Timing::for_baud(baud);
        let char_us = 11_000_000u64.div_ceil(u64::from(baud));
        // Without idle() between them: the first byte of b ends a.
        let mut line = Line::new(baud, char_us);
        line.send(&a);
        line.now += t.t35_us; // a silence of t3.5 before b's first byte
        line.send(&b);
        line.silence(t.t35_us);
        assert_eq!(
            line.got,
            vec![Got::Frame(a.clone()), Got::Frame(b.clone())],
            "{baud}"
        );
        // With the board asking at the deadline in between.
        let mut line = Line::new(baud, char_us);
        line.send(&a);
        line.silence(t.t35_us);
        line.send(&b);
        line.silence(t.t35_us);
        assert_eq!(
            line.got,
            vec![Got::Frame(a.clone()), Got::Frame(b.clone())],
            "{baud}"
        );
    }
}

/// Issue 30: an FC16 frame to unit 2 whose data carries a unit-1 request
/// (set the unit address to 9) and a broadcast (spindle speed) is one frame
/// to unit 2: neither inner request is a frame.
fn frame_in_frame() -> (Vec<u8>, Vec<u8>, Vec<u8>) {
    let inner = frame(&[1, 6, 0, HR_UNIT as u8, 0, 9]);
    let hidden_broadcast = frame(&[0, 6, 0, HR_SPINDLE as u8, 0x12, 0x34]);
    let mut data = inner.clone();
    data.extend_from_slice(&hidden_broadcast);
    data.extend_from_slice(&[0, 0]); // to whole registers
    let regs = (data.len() / 2) as u8;
    let mut body = vec![2, 0x10, 0x00, 0x05, 0, regs, data.len() as u8];
    body.extend_from_slice(&data);
    (frame(&body), inner, hidden_broadcast)
}

#[test]
fn a_request_inside_another_units_frame_is_not_a_frame() {
    let (outer, inner, bc) = frame_in_frame();
    let mut line = Line::new(115_200, CHAR_115200);
    line.send(&outer);
    line.silence(1750);
    assert_eq!(line.got, vec![Got::Frame(outer.clone())]);
    assert!(!line.got.contains(&Got::Frame(inner)));
    assert!(!line.got.contains(&Got::Frame(bc)));
    // Through the server: unit 2's frame is ignored, nothing changes.
    let mut server = Server::new();
    let mut state = AppState::new(1, 115_200);
    state.keys.unlock = Some(host_tests::TEST_UNLOCK_KEY);
    let snapshot = Snapshot::default();
    let mut reply: HVec<u8, MAX_FRAME> = HVec::new();
    let unlock = host_tests::modbus::write1(1, HR_UNLOCK, host_tests::TEST_UNLOCK_KEY);
    server.handle(&unlock, 0, &snapshot, &mut state, &mut reply);
    assert_eq!(reply.to_vec(), unlock, "unlocked");
    for g in &line.got {
        if let Got::Frame(f) = g {
            server.handle(f, 1, &snapshot, &mut state, &mut reply);
            assert!(reply.is_empty());
        }
    }
    assert_eq!(state.settings.unit, 1);
    assert_eq!(state.plc.spindle_rpm, 0);
}

#[test]
fn garbage_then_a_request_with_no_silence_between_is_one_bad_frame() {
    let req = frame(&[1, 4, 0, 0, 0, 2]);
    let mut bytes = vec![0x55, 0xAA, 0x13, 0x37];
    bytes.extend_from_slice(&req);
    let mut line = Line::new(115_200, CHAR_115200);
    line.send(&bytes);
    line.silence(1750);
    assert_eq!(line.got, vec![Got::Frame(bytes.clone())]);
    // After the silence the same request is a frame of its own.
    line.got.clear();
    line.send(&req);
    line.silence(1750);
    assert_eq!(line.got, vec![Got::Frame(req)]);
}

#[test]
fn a_frame_with_a_silence_over_1_5_characters_inside_is_discarded() {
    let req = frame(&[1, 4, 0, 0, 0, 2]);
    for baud in [9600u32, 115_200] {
        let t = Timing::for_baud(baud);
        let char_us = 11_000_000u64.div_ceil(u64::from(baud));
        // Inner silences (from the end of one byte to the next byte's
        // arrival, on top of the byte's own time): just over t1.5, and just
        // under t3.5.
        for inner in [t.t15_us + 1, t.t35_us - 1] {
            let mut line = Line::new(baud, char_us);
            line.send(&req[..3]);
            line.now += inner;
            line.send(&req[3..]);
            line.silence(t.t35_us);
            assert_eq!(line.got, vec![Got::Broken], "{baud} baud, gap {inner} µs");
            // The next whole request is answered.
            line.got.clear();
            line.send(&req);
            line.silence(t.t35_us);
            assert_eq!(line.got, vec![Got::Frame(req.clone())]);
        }
        // Exactly t1.5 is still one frame.
        let mut line = Line::new(baud, char_us);
        line.send(&req[..3]);
        line.now += t.t15_us;
        line.send(&req[3..]);
        line.silence(t.t35_us);
        assert_eq!(line.got, vec![Got::Frame(req.clone())], "{baud}");
    }
}

#[test]
fn a_frame_split_by_3_5_characters_is_two_fragments() {
    let req = frame(&[1, 4, 0, 0, 0, 2]);
    let mut line = Line::new(115_200, CHAR_115200);
    line.send(&req[..4]);
    line.silence(5_000);
    line.send(&req[4..]);
    line.silence(1750);
    assert_eq!(
        line.got,
        vec![Got::Frame(req[..4].to_vec()), Got::Frame(req[4..].to_vec())]
    );
    // Neither fragment gets an answer.
    let mut server = Server::new();
    let mut state = AppState::new(1, 115_200);
    let mut reply: HVec<u8, MAX_FRAME> = HVec::new();
    for g in &line.got {
        if let Got::Frame(f) = g {
            server.handle(f, 1, &Snapshot::default(), &mut state, &mut reply);
            assert!(reply.is_empty());
        }
    }
}

#[test]
fn frames_above_256_bytes_are_discarded_whole() {
    let mut line = Line::new(115_200, CHAR_115200);
    let max: Vec<u8> = (0..=255u8).collect();
    line.send(&max);
    line.silence(1750);
    assert_eq!(line.got, vec![Got::Frame(max.clone())]);
    line.got.clear();
    let mut long = max.clone();
    long.extend_from_slice(&frame(&[1, 4, 0, 0, 0, 2]));
    line.send(&long);
    line.silence(1750);
    assert_eq!(line.got, vec![Got::Oversize]);
    assert!(line.framer.frame().is_empty());
}

#[test]
fn a_new_timing_drops_the_frame_in_progress() {
    let mut line = Line::new(115_200, CHAR_115200);
    line.send(&[1, 4, 0]);
    line.framer.set_timing(Timing::for_baud(9600));
    assert_eq!(line.framer.deadline_us(), None);
    assert_eq!(line.framer.idle(u64::MAX), None);
    assert_eq!(line.framer.timing().t35_us, 4011);
}

#[test]
fn a_clock_that_stands_still_never_ends_a_frame_early() {
    // Several bytes with the same time stamp (a coarse clock): one frame.
    let req = frame(&[1, 4, 0, 0, 0, 2]);
    let mut f = RtuFramer::new(Timing::for_baud(115_200));
    for &b in &req {
        assert_eq!(f.push(b, 10), None);
    }
    assert_eq!(f.idle(10 + 1749), None);
    assert_eq!(f.idle(10 + 1750), Some(Outcome::Frame));
    assert_eq!(f.frame(), &req[..]);
}
