#!/usr/bin/env python3
"""Static worst-case stack of a firmware ELF, from its disassembly.

Usage: scripts/stack-estimate.py <elf> [--paths N]

Each function's frame is what its prologue reserves (push, vpush, sub sp);
its depth is the frame plus the deepest callee reached by a direct call or
tail call (bl, b.w). Thread mode: the deepest of `main` and the embassy
tasks' poll functions (the executor polls one task at a time on the main
stack); interrupts: the deepest handler (upper-case names, HardFault),
added once on top (no nesting counted). Indirect calls (function pointers,
dyn) are not followed, so the figure is a lower bound of the true worst
case; a recursion is cut at its first repeat. Prints one JSON line.
"""
import json
import re
import subprocess
import sys

PUSH = re.compile(r"\t(?:push|stmdb)(?:\.w)?\s+(?:sp!, )?\{([^}]*)\}")
VPUSH = re.compile(r"\tvpush\s+\{([^}]*)\}")
SUB_SP = re.compile(r"\tsub(?:\.w|w)?\s+sp, (?:sp, )?#(\d+)")
CALL = re.compile(r"\t(?:bl|b\.w)\s+[0-9a-f]+ <([^>+]+)>")
HEAD = re.compile(r"^[0-9a-f]+ <(.+)>:$")


def regs(text):
    """Registers in a push list ("r4-r7, lr" -> 5; "d8-d9" -> 2 doubles)."""
    n = 0
    for r in text.split(","):
        r = r.strip()
        if "-" in r:
            a, b = r.split("-")
            n += int(b[1:]) - int(a[1:]) + 1
        else:
            n += 1
    return n


def parse(elf):
    dis = subprocess.run(
        ["arm-none-eabi-objdump", "-d", "--no-show-raw-insn", elf],
        capture_output=True, text=True, check=True).stdout
    frames, calls, cur = {}, {}, None
    for line in dis.splitlines():
        m = HEAD.match(line)
        if m:
            cur = m.group(1)
            frames[cur], calls[cur] = 0, set()
            continue
        if cur is None:
            continue
        if m := PUSH.search(line):
            frames[cur] += 4 * regs(m.group(1))
        elif m := VPUSH.search(line):
            width = 8 if m.group(1).strip().startswith("d") else 4
            frames[cur] += width * regs(m.group(1))
        elif m := SUB_SP.search(line):
            frames[cur] += int(m.group(1))
        elif (m := CALL.search(line)) and m.group(1) != cur:
            calls[cur].add(m.group(1))
    return frames, calls


def deepest(frames, calls):
    memo = {}

    def depth(f, seen):
        if f in memo:
            return memo[f]
        best = (0, [])
        for c in calls.get(f, ()):
            if c not in seen:
                d = depth(c, seen | {f})
                if d[0] > best[0]:
                    best = d
        res = (frames.get(f, 0) + best[0], [f] + best[1])
        memo[f] = res
        return res

    return depth


def demangle(names):
    out = subprocess.run(["arm-none-eabi-c++filt"], input="\n".join(names),
                         capture_output=True, text=True).stdout.splitlines()
    return [re.sub(r"::h[0-9a-f]{16}$", "", n) for n in out]


def main():
    sys.setrecursionlimit(20000)
    elf = sys.argv[1]
    frames, calls = parse(elf)
    depth = deepest(frames, calls)
    names = list(frames)
    pretty = dict(zip(names, demangle(names)))
    thread = [f for f in names if f == "main" or "TaskStorage" in pretty[f] and "poll" in pretty[f]]
    irq = [f for f in names if re.fullmatch(r"[A-Z][A-Z0-9_]+|HardFault", f)]
    t = max((depth(f, frozenset()) for f in thread), default=(0, []))
    i = max((depth(f, frozenset()) for f in irq), default=(0, []))
    path = [f"{pretty[f]} ({frames[f]} B)" for f in t[1]]
    print(json.dumps({
        "stack_estimate_bytes": t[0] + i[0],
        "thread_bytes": t[0],
        "interrupt_bytes": i[0],
        "deepest_path": path,
    }))


if __name__ == "__main__":
    main()
