#!/usr/bin/env python3
"""A real Modbus RTU master (pymodbus) for the QEMU bench board.

The board's UART0 is a TCP socket carrying RTU frames (QEMU -serial tcp:...),
so pymodbus talks RTU framing over TCP. Each subcommand prints one JSON object.

  read     --port P [--unit U] [--degraded] [--envelope]
                                         snapshot: sequence, sample time, status, corrections;
                                         --degraded adds 150-157, --envelope 360-371 (the
                                         steps beyond the envelope) with the sequence read
                                         again after them ("envelope_same_snapshot")
  upload   --port P --image F [--corrupt] [--length N] [--watch S]
                                         stage, commit; the reply time, the time until the
                                         background write is done, the outcome; with --watch
                                         the largest gap between snapshots before and during it
  badcrc   --port P                      a corrupted frame, then a good one
  raw      --port P --hex H [--hex H ...] [--gap-ms G] [--wait-s S]
                                         raw bytes, piece by piece G ms apart; the bytes back
  rate     --port P [--n N]              requests per second and latency
  command  --port P --code N             unlock, write command N; its exception (None: accepted)
  hold     --port P [--write A=V ...] [--unit U]
                                         unlock, write holding registers (one FC06 each), read 0-31
  inputs   --port P --addr A [--count N] input registers as a list
  fault    --port P                      status and the fault record (input registers 160-168)
  volumetric --port P --at X,Y,Z,L[,A,C] [--at ...]
                                         per point: write the positions (FC16 6-11) and the
                                         tool length (FC16 34-35), all µm, (with A,C in
                                         0.001°: FC16 36-39), then read input registers
                                         180-199 (the volumetric block) and, with A,C,
                                         330-343 (the five-axis block)
  flood    --pipe BASE [--bytes N] [--gap-ms G] [--retry-ms R]
                                         N bytes of garbage into the board's UART (QEMU
                                         -serial pipe:BASE), then one good request; how
                                         long the flood took and the answer after it

No request is ever sent twice: pymodbus runs with retries=0 and every frame
it sends is counted. A request without a valid answer (timeout, garbled
reply) is a dropped frame. Any dropped frame or retry makes the command exit
with status 1 and say how many on stderr, so a test cannot pass on a link
that loses frames. (A Modbus exception is an answer, not a drop.)
"""
import argparse
import json
import socket
import struct
import sys
import time

from pymodbus import FramerType
from pymodbus.client import ModbusTcpClient
from pymodbus.exceptions import ModbusException
from pymodbus.pdu import ExceptionResponse

UNIT = 1
IR_SEQUENCE, IR_SAMPLE_TIME, IR_MODEL_VERSION = 4, 10, 12
IR_CORRECTIONS = 30
IR_ENVELOPE_STEPS = 360
HR_UNLOCK, HR_COMMAND, HR_RESULT, HR_STAGED_LEN, HR_STAGING = 0, 1, 2, 32, 1000
CMD_COMMIT = 1
COMMIT_IN_PROGRESS = 23
# Keys (issue 30): a fresh board takes the factory code for commissioning
# only; this test master gives it TEST_UNLOCK_KEY (host_tests::TEST_UNLOCK_KEY)
# first and unlocks with that.
FACTORY_UNLOCK_CODE, TEST_UNLOCK_KEY = 0xA5C3, 0x7E57
HR_KEY_STATE, HR_NEW_UNLOCK_KEY, CMD_SET_UNLOCK_KEY = 66, 67, 15


def unlock(m):
    """Unlock with the test key, commissioning a fresh board with it first."""
    r = m.call("read_holding_registers", HR_KEY_STATE, count=1)
    if r is not None and not r.isError() and not r.registers[0] & 1:
        m.call("write_register", HR_UNLOCK, FACTORY_UNLOCK_CODE)
        m.call("write_register", HR_NEW_UNLOCK_KEY, TEST_UNLOCK_KEY)
        m.call("write_register", HR_COMMAND, CMD_SET_UNLOCK_KEY)
        t = time.perf_counter()
        while time.perf_counter() - t < 10:
            res = m.call("read_holding_registers", HR_RESULT, count=1)
            if res is not None and not res.isError() and res.registers[0] != COMMIT_IN_PROGRESS:
                break
            time.sleep(0.05)
    return m.call("write_register", HR_UNLOCK, TEST_UNLOCK_KEY)


def s32(hi, lo):
    return struct.unpack(">i", struct.pack(">HH", hi, lo))[0]


def u32(hi, lo):
    return (hi << 16) | lo


class Master:
    """pymodbus without retries, counting requests, frames sent and drops."""

    def __init__(self, port, unit=UNIT, timeout=3.0):
        self.unit = unit
        self.requests = 0
        self.frames_sent = 0
        self.dropped = []
        self.c = ModbusTcpClient("127.0.0.1", port=port, framer=FramerType.RTU,
                                 timeout=timeout, retries=0, trace_packet=self._trace)
        if not self.c.connect():
            sys.exit(f"cannot connect to 127.0.0.1:{port}")

    def _trace(self, sending, data):
        if sending:
            self.frames_sent += 1
        return data

    def call(self, method, *args, **kwargs):
        """One request; its response, or None when it was dropped."""
        self.requests += 1
        try:
            r = getattr(self.c, method)(*args, device_id=self.unit, **kwargs)
        except ModbusException as e:
            self.dropped.append(f"{method}{args}: {e}")
            return None
        if r.isError() and not isinstance(r, ExceptionResponse):
            self.dropped.append(f"{method}{args}: {r}")
            return None
        return r

    def link(self):
        return {"requests": self.requests, "frames_sent": self.frames_sent,
                "retries": self.frames_sent - self.requests, "dropped": len(self.dropped)}

    def close(self):
        """Closes the link; exits 1 on any retry or dropped frame."""
        self.c.close()
        link = self.link()
        if link["retries"] or link["dropped"]:
            sys.exit(f"link not clean: {json.dumps(link)}; dropped: {self.dropped[:5]}")
        return link


def snapshot(m, degraded=False, envelope=False):
    # One request from the status register to the last prediction: one snapshot.
    r = m.call("read_input_registers", 0, count=54)
    if r is None or r.isError():
        return {"error": str(r)}
    w = r.registers
    extra = {}
    if degraded:
        # Degraded mode (150-157): a second request, so possibly the next snapshot.
        e = m.call("read_input_registers", 150, count=8)
        if e is None or e.isError():
            return {"error": str(e)}
        extra = {"active": e.registers[0:6], "degraded_directions": e.registers[6], "held_directions": e.registers[7]}
    if envelope:
        # Steps beyond the envelope (360-371, u32 per direction), then the
        # sequence again: unchanged, the counts belong to this snapshot.
        e = m.call("read_input_registers", IR_ENVELOPE_STEPS, count=12)
        q = m.call("read_input_registers", IR_SEQUENCE, count=2)
        if e is None or e.isError() or q is None or q.isError():
            return {"error": str(e if e is None or e.isError() else q)}
        extra["envelope_steps"] = [u32(e.registers[2 * d], e.registers[2 * d + 1]) for d in range(6)]
        extra["envelope_same_snapshot"] = u32(*q.registers) == u32(w[IR_SEQUENCE], w[IR_SEQUENCE + 1])
    return {**extra,
        "pattern": u32(w[0], w[1]),
        "status": w[3],
        "sequence": u32(w[IR_SEQUENCE], w[IR_SEQUENCE + 1]),
        "sample_time_s": u32(w[IR_SAMPLE_TIME], w[IR_SAMPLE_TIME + 1]),
        "model_version": u32(w[IR_MODEL_VERSION], w[IR_MODEL_VERSION + 1]),
        "model_crc": u32(w[14], w[15]),
        "n_directions": w[16],
        "corrections": [s32(w[IR_CORRECTIONS + 2 * d], w[IR_CORRECTIONS + 2 * d + 1]) for d in range(6)],
        "predictions": [s32(w[42 + 2 * d], w[43 + 2 * d]) for d in range(6)],
    }


def cmd_read(a):
    m = Master(a.port, unit=a.unit, timeout=a.timeout)
    out = [snapshot(m, a.degraded, a.envelope) for _ in range(a.samples)]
    m.close()
    print(json.dumps(out))


def watch_sequence(m, seconds, until=None):
    """Polls the snapshot sequence for `seconds` (or until `until()` is
    true and `seconds` passed); the largest host-time gap between two
    sequence changes, in ms."""
    t0 = time.perf_counter()
    last_seq, last_t, gap = None, None, 0.0
    while True:
        r = m.call("read_input_registers", IR_SEQUENCE, count=2)
        now = time.perf_counter()
        if r is not None and not r.isError():
            seq = u32(r.registers[0], r.registers[1])
            if seq != last_seq:
                if last_t is not None:
                    gap = max(gap, now - last_t)
                last_seq, last_t = seq, now
        finished = until is None or until()
        if now - t0 >= seconds and finished:
            return round(1000 * gap, 1)
        time.sleep(0.01)


def cmd_upload(a):
    image = open(a.image, "rb").read()
    if a.corrupt:
        image = bytearray(image)
        image[len(image) // 2] ^= 0xFF
        image = bytes(image)
    m = Master(a.port)
    out = {"bytes": len(image)}
    if a.watch:
        out["baseline_max_sample_gap_ms"] = watch_sequence(m, a.watch)
    unlock(m)
    padded = image + b"\0" * (len(image) % 2)
    words = [int.from_bytes(padded[i:i + 2], "big") for i in range(0, len(padded), 2)]
    for i in range(0, len(words), 100):
        r = m.call("write_registers", HR_STAGING + i, words[i:i + 100])
        if r is not None and r.isError():
            out["staging_error"] = str(r)
    length = len(image) if a.length is None else a.length
    r = m.call("write_register", HR_STAGED_LEN, length)
    out["length_exception"] = getattr(r, "exception_code", None) if r is not None and r.isError() else None
    t = time.perf_counter()
    r = m.call("write_register", HR_COMMAND, CMD_COMMIT)
    out["commit_reply_ms"] = round(1000 * (time.perf_counter() - t), 1)
    out["commit_exception"] = getattr(r, "exception_code", None) if r is not None and r.isError() else None
    # The flash is written in the background: poll the result while it says
    # "in progress" (23).
    state = {"result": None}

    def done():
        res = m.call("read_holding_registers", HR_RESULT, count=1)
        state["result"] = None if res is None or res.isError() else res.registers[0]
        if state["result"] != COMMIT_IN_PROGRESS and "commit_done_ms" not in out:
            out["commit_done_ms"] = round(1000 * (time.perf_counter() - t), 1)
        return state["result"] != COMMIT_IN_PROGRESS or time.perf_counter() - t > 10
    if a.watch:
        out["commit_max_sample_gap_ms"] = watch_sequence(m, a.watch, done)
    else:
        while not done():
            time.sleep(0.02)
    out["result"] = state["result"]
    # The lock after the commit: HR_UNLOCK reads 1 while unlocked, and a
    # protected write (the staged length again, harmless) is refused with
    # exception 01 while locked.
    r = m.call("read_holding_registers", HR_UNLOCK, count=1)
    out["unlocked_after"] = None if r is None or r.isError() else r.registers[0]
    r = m.call("write_register", HR_STAGED_LEN, length & 0xFFFF)
    out["protected_write_exception_after"] = getattr(r, "exception_code", None) if r is not None and r.isError() else None
    time.sleep(0.3)
    out["after"] = snapshot(m)
    out["link"] = m.close()
    print(json.dumps(out))


def crc16(data):
    crc = 0xFFFF
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return crc


def cmd_badcrc(a):
    # Raw bytes on the socket: pymodbus would not send a frame with a wrong CRC.
    s = socket.create_connection(("127.0.0.1", a.port), timeout=2)
    req = bytes([UNIT, 4, 0, 0, 0, 2])
    good = req + struct.pack("<H", crc16(req))
    bad = req + struct.pack("<H", crc16(req) ^ 0x5555)

    def answer(frame, expect, wait_s):
        # Collect until `expect` bytes or `wait_s`: the reply may arrive byte
        # by byte, and a loaded host slows QEMU down.
        s.sendall(frame)
        s.settimeout(wait_s)
        got = b""
        try:
            while len(got) < expect:
                chunk = s.recv(256)
                if not chunk:
                    break
                got += chunk
        except socket.timeout:
            pass
        return got

    out = {"bad": answer(bad, 1, 2.0).hex()}
    out["good"] = answer(good, 9, 10.0).hex()
    s.close()
    print(json.dumps(out))


def cmd_rate(a):
    m = Master(a.port)
    lat = []
    t0 = time.perf_counter()
    for _ in range(a.n):
        t = time.perf_counter()
        r = m.call("read_input_registers", 0, count=54)
        lat.append(time.perf_counter() - t)
        if r is None or r.isError():
            m.close()
            sys.exit(f"read failed: {r}")
    total = time.perf_counter() - t0
    link = m.close()
    lat.sort()
    print(json.dumps({
        "requests": a.n,
        "retries": link["retries"],
        "dropped": link["dropped"],
        "registers_per_request": 54,
        "requests_per_s": round(a.n / total, 1),
        "latency_ms_median": round(1000 * lat[len(lat) // 2], 3),
        "latency_ms_p99": round(1000 * lat[int(len(lat) * 0.99) - 1], 3),
    }))


def cmd_raw(a):
    # Raw bytes on the socket, in pieces with silences between them: what
    # no master library sends (a frame split by a pause, a frame inside
    # another). Prints every byte that came back within --wait-s.
    s = socket.create_connection(("127.0.0.1", a.port), timeout=2)
    s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    pieces = [bytes.fromhex(p) for p in a.hex]
    for i, piece in enumerate(pieces):
        if i:
            time.sleep(a.gap_ms / 1000)
        s.sendall(piece)
    s.settimeout(0.05)
    got = b""
    t = time.perf_counter()
    while time.perf_counter() - t < a.wait_s:
        try:
            chunk = s.recv(256)
            if not chunk:
                break
            got += chunk
        except socket.timeout:
            pass
    s.close()
    print(json.dumps({"sent": [p.hex() for p in pieces], "reply": got.hex()}))


def cmd_flood(a):
    # The pipe holds at most one page: the writes below block until the board
    # has taken all but the last 4 kB, as a real line (which holds a few bytes
    # in flight) would, so "the flood has stopped" means the same to both ends.
    # A TCP socket would queue hundreds of kB that QEMU then feeds the guest
    # one byte per main-loop turn.
    import fcntl
    import os
    import random
    import threading
    tx = os.open(a.pipe + ".in", os.O_WRONLY)
    fcntl.fcntl(tx, fcntl.F_SETPIPE_SZ, 4096)
    rx = os.open(a.pipe + ".out", os.O_RDONLY)
    replies = bytearray()
    lock = threading.Lock()

    def reader():
        while True:
            chunk = os.read(rx, 4096)
            if not chunk:
                return
            with lock:
                replies.extend(chunk)
    threading.Thread(target=reader, daemon=True).start()
    rng = random.Random(13)
    # Garbage never addresses this board (no unit 0 or 1 byte), and ends in
    # the header of a long FC16 request for unit 2: a reader that only
    # restarts at a silent gap is then in the middle of a 255-byte "frame".
    garbage = bytes(rng.randrange(2, 256) for _ in range(a.bytes - 7))
    garbage += bytes([2, 0x10, 0, 0, 0, 0x7B, 0xF6])
    t0 = time.perf_counter()
    for i in range(0, len(garbage), 4096):
        view = memoryview(garbage)[i:i + 4096]
        while view:
            view = view[os.write(tx, view):]
    flood_s = time.perf_counter() - t0
    time.sleep(a.gap_ms / 1000)
    with lock:
        replies_to_garbage = len(replies)
        replies.clear()
    req = bytes([UNIT, 4, 0, 0, 0, 2])
    req += struct.pack("<H", crc16(req))
    want = bytes([UNIT, 4, 4, 0x12, 0x34, 0x56, 0x78])
    t1 = time.perf_counter()
    os.write(tx, req)
    sent = 1
    answer_s = None
    while time.perf_counter() - t1 < a.wait_s:
        with lock:
            if want in replies:
                answer_s = time.perf_counter() - t1
                break
        # A master's retry after its response timeout: the request that
        # followed the garbage with no silence was part of the garbage's frame.
        if a.retry_ms and time.perf_counter() - t1 >= sent * a.retry_ms / 1000:
            os.write(tx, req)
            sent += 1
        time.sleep(0.001)
    print(json.dumps({"flood_bytes": len(garbage), "flood_s": round(flood_s, 2),
                      "flood_bytes_per_s": round(len(garbage) / flood_s),
                      "replies_to_garbage_bytes": replies_to_garbage, "requests_sent": sent,
                      "answer_s": None if answer_s is None else round(answer_s, 3)}))


def cmd_command(a):
    m = Master(a.port, unit=a.unit)
    unlock(m)
    t = time.perf_counter()
    r = m.call("write_register", HR_COMMAND, a.code)
    out = {"exception": getattr(r, "exception_code", None) if r is not None and r.isError() else None,
           "reply_ms": round(1000 * (time.perf_counter() - t), 1)}
    out["link"] = m.close()
    print(json.dumps(out))


def cmd_hold(a):
    m = Master(a.port, unit=a.unit)
    out = {"exceptions": {}}
    if a.write:
        unlock(m)
    for w in a.write:
        addr, val = (int(x, 0) for x in w.split("="))
        t = time.perf_counter()
        while True:
            r = m.call("write_register", addr, val)
            # 06: a settings write is still going to flash; ask again.
            if r is None or not r.isError() or r.exception_code != 6 or time.perf_counter() - t > 10:
                break
            time.sleep(0.05)
        if r is not None and r.isError():
            out["exceptions"][addr] = r.exception_code
    if a.write and not a.no_read:
        # Until the settings are in flash (HR_RESULT leaves 23).
        t = time.perf_counter()
        while time.perf_counter() - t < 10:
            res = m.call("read_holding_registers", HR_RESULT, count=1)
            if res is None or res.isError() or res.registers[0] != COMMIT_IN_PROGRESS:
                break
            time.sleep(0.05)
    if not a.no_read:
        r = m.call("read_holding_registers", 0, count=32)
        out["registers"] = None if r is None or r.isError() else r.registers
    m.close()
    print(json.dumps(out))


def cmd_inputs(a):
    m = Master(a.port)
    r = m.call("read_input_registers", a.addr, count=a.count)
    m.close()
    print(json.dumps(r.registers))


def cmd_fault(a):
    m = Master(a.port, timeout=a.timeout)
    st = m.call("read_input_registers", 3, count=1)
    r = m.call("read_input_registers", 160, count=20)
    m.close()
    w = r.registers
    print(json.dumps({"status": st.registers[0], "kind": w[0], "pc": u32(w[1], w[2]),
                      "uptime_s": u32(w[3], w[4]), "count": u32(w[5], w[6]),
                      "detail": u32(w[7], w[8]), "reserved": w[9:]}))


def cmd_volumetric(a):
    m = Master(a.port)
    out = []
    for at in a.at:
        vals = [int(v) for v in at.split(",")]
        x, y, z, tool = vals[:4]
        angles = vals[4:6]
        regs = []
        for v in (x, y, z):
            regs += list(struct.unpack(">HH", struct.pack(">i", v)))
        w1 = m.call("write_registers", 6, regs)
        w2 = m.call("write_registers", 34, list(struct.unpack(">HH", struct.pack(">i", tool))))
        calls = [w1, w2]
        if angles:
            ang = []
            for v in angles:
                ang += list(struct.unpack(">HH", struct.pack(">i", v)))
            calls.append(m.call("write_registers", 36, ang))
        r = m.call("read_input_registers", 180, count=20)
        calls.append(r)
        f = None
        if angles:
            f = m.call("read_input_registers", 330, count=14)
            calls.append(f)
        if None in calls or any(c.isError() for c in calls):
            out.append({"error": str(calls)})
            continue
        w = r.registers
        five = {}
        if f is not None:
            g = f.registers
            five = {"angles": [s32(g[0], g[1]), s32(g[2], g[3])], "five_status": g[4],
                    "order": g[5], "rotary": [s32(g[6 + 2 * d], g[7 + 2 * d]) for d in range(3)],
                    "five_sequence": u32(g[12], g[13])}
        out.append({**five, "at": vals,
                    "correction": [s32(w[2 * d], w[2 * d + 1]) for d in range(3)],
                    "status": w[6], "terms": w[7], "tool_um": s32(w[8], w[9]),
                    "temps_16": [struct.unpack(">h", struct.pack(">H", t))[0] for t in w[10:14]],
                    "sequence": u32(w[14], w[15])})
    m.close()
    print(json.dumps(out))


def main():
    p = argparse.ArgumentParser()
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("read"); r.add_argument("--port", type=int, required=True); r.add_argument("--samples", type=int, default=1)
    r.add_argument("--unit", type=int, default=UNIT); r.add_argument("--timeout", type=float, default=3.0)
    r.add_argument("--degraded", action="store_true")
    r.add_argument("--envelope", action="store_true")
    u = sub.add_parser("upload"); u.add_argument("--port", type=int, required=True); u.add_argument("--image", required=True); u.add_argument("--corrupt", action="store_true")
    u.add_argument("--length", type=int, default=None, help="stage this length instead of the image's")
    u.add_argument("--watch", type=float, default=0.0, help="seconds of sequence polling before and after the commit")
    b = sub.add_parser("badcrc"); b.add_argument("--port", type=int, required=True)
    q = sub.add_parser("rate"); q.add_argument("--port", type=int, required=True); q.add_argument("--n", type=int, default=200)
    w = sub.add_parser("raw"); w.add_argument("--port", type=int, required=True)
    w.add_argument("--hex", action="append", required=True, help="one piece of bytes (hex); pieces are sent --gap-ms apart")
    w.add_argument("--gap-ms", type=float, default=20.0); w.add_argument("--wait-s", type=float, default=0.5)
    f = sub.add_parser("flood"); f.add_argument("--pipe", required=True); f.add_argument("--bytes", type=int, default=300_000)
    f.add_argument("--gap-ms", type=float, default=0.0); f.add_argument("--wait-s", type=float, default=5.0)
    f.add_argument("--retry-ms", type=float, default=0.0, help="send the request again every this many ms until answered")
    c = sub.add_parser("command"); c.add_argument("--port", type=int, required=True); c.add_argument("--code", type=int, required=True)
    c.add_argument("--unit", type=int, default=UNIT)
    h = sub.add_parser("hold"); h.add_argument("--port", type=int, required=True); h.add_argument("--write", action="append", default=[])
    h.add_argument("--unit", type=int, default=UNIT); h.add_argument("--no-read", action="store_true")
    i = sub.add_parser("inputs"); i.add_argument("--port", type=int, required=True)
    i.add_argument("--addr", type=int, required=True); i.add_argument("--count", type=int, default=1)
    g = sub.add_parser("fault"); g.add_argument("--port", type=int, required=True); g.add_argument("--timeout", type=float, default=3.0)
    v = sub.add_parser("volumetric"); v.add_argument("--port", type=int, required=True)
    v.add_argument("--at", action="append", required=True, help="x,y,z,tool in µm")
    a = p.parse_args()
    {"read": cmd_read, "upload": cmd_upload, "badcrc": cmd_badcrc, "rate": cmd_rate,
     "flood": cmd_flood, "command": cmd_command, "fault": cmd_fault, "hold": cmd_hold, "inputs": cmd_inputs,
     "volumetric": cmd_volumetric, "raw": cmd_raw}[a.cmd](a)


if __name__ == "__main__":
    main()
