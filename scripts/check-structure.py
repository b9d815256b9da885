#!/usr/bin/env python3
"""Structure rules of the house, checked on every crate of the workspace:
no import circle between the files of a crate (`use crate::…`, `super::…`,
`self::…` and inline paths), no file over 800 lines and no function over
150 lines outside tests. Cargo itself forbids circles between crates.
Usage: scripts/check-structure.py [--verbose]   (exit 1 on a violation)
Hand-written: no Rust crate checks file-level import graphs or lengths."""
import json, os, re, subprocess, sys

MAX_FILE, MAX_FN = 800, 150
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
verbose = '--verbose' in sys.argv


def crates():
    meta = json.loads(subprocess.check_output(
        ['cargo', 'metadata', '--no-deps', '--format-version', '1'], cwd=ROOT))
    for p in meta['packages']:
        for t in p['targets']:
            if t['kind'][0] in ('lib', 'bin') and 'src' in t['src_path']:
                yield p['name'], t['src_path']
    fuzz = os.path.join(ROOT, 'fuzz', 'fuzz_targets')
    for f in sorted(os.listdir(fuzz)) if os.path.isdir(fuzz) else []:
        yield 'fuzz:' + f, os.path.join(fuzz, f)


def module_files(root_file):
    """Files of one crate target: module path -> file, following `mod x;`."""
    mods = {(): root_file}
    todo = [((), root_file)]
    while todo:
        path, f = todo.pop()
        d = os.path.dirname(f)
        base = os.path.basename(f)
        own_dir = d if base in ('lib.rs', 'main.rs', 'mod.rs') or path == () else os.path.join(d, base[:-3])
        text = open(f, encoding='utf-8').read()
        for m in re.finditer(r'^\s*(?:#\[path\s*=\s*"([^"]+)"\]\s*)?(?:pub(?:\([^)]*\))?\s+)?mod\s+(\w+)\s*;', text, re.M):
            name = m.group(2)
            if m.group(1):
                cand = [os.path.join(d, m.group(1))]
            else:
                cand = [os.path.join(own_dir, name + '.rs'), os.path.join(own_dir, name, 'mod.rs')]
            for c in cand:
                if os.path.isfile(c):
                    mods[path + (name,)] = c
                    todo.append((path + (name,), c))
                    break
    return mods


def non_test(text):
    lines = text.split('\n')
    for i, l in enumerate(lines):
        if l.strip().startswith('#[cfg(test)]'):
            return lines[:i]
    return lines


def expand(prefix, body):
    """`a::{b, c::{d}}` -> [a::b, a::c::d] (one level of braces is enough here)."""
    out = []
    m = re.match(r'([\w:]*?)(?:::)?\{(.*)\}$', body, re.S)
    if not m:
        return [body]
    head, inner = m.group(1), m.group(2)
    depth, cur, parts = 0, '', []
    for ch in inner:
        if ch == '{': depth += 1
        if ch == '}': depth -= 1
        if ch == ',' and depth == 0:
            parts.append(cur); cur = ''
        else:
            cur += ch
    parts.append(cur)
    for p in parts:
        p = p.strip()
        if p:
            out += [((head + '::') if head else '') + q for q in expand('', p)]
    return out


def refs(lines):
    text = '\n'.join(re.sub(r'//.*', '', l) for l in lines)
    found = []
    for m in re.finditer(r'\buse\s+((?:crate|super|self)(?:::\w+)*(?:::\{[^;]*\})?)\s*;', text):
        found += expand('', re.sub(r'\s+', '', m.group(1)))
    for m in re.finditer(r'\b((?:crate|super|self)(?:::(?:super|\w+))+)', text):
        found.append(m.group(1))
    return found


def resolve(cur, is_dir_mod, ref, mods):
    parts = ref.split('::')
    if parts[0] == 'crate':
        path, rest = (), parts[1:]
    else:
        path = cur
        rest = parts
        while rest and rest[0] in ('super', 'self'):
            if rest[0] == 'super':
                path = path[:-1]
            rest = rest[1:]
    best = None
    for k in range(len(rest) + 1):
        cand = path + tuple(rest[:k])
        if cand in mods:
            best = cand
    return best


def sccs(graph):
    index, low, stack, on, out, n = {}, {}, [], set(), [], [0]
    sys.setrecursionlimit(10000)
    def strong(v):
        index[v] = low[v] = n[0]; n[0] += 1; stack.append(v); on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                strong(w); low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop(); on.discard(w); comp.append(w)
                if w == v: break
            if len(comp) > 1: out.append(comp)
    for v in list(graph):
        if v not in index: strong(v)
    return out


FN = re.compile(r'^\s*(pub(\([^)]*\))?\s+)?(const\s+)?(async\s+)?(unsafe\s+)?(extern\s+"C"\s+)?fn\s+(\w+)')


def long_functions(f, lines):
    bad = []
    i = 0
    while i < len(lines):
        m = FN.match(lines[i])
        if m:
            depth, started, j = 0, False, i
            while j < len(lines):
                s = re.sub(r'//.*', '', lines[j])
                s = re.sub(r'"(\\.|[^"\\])*"', '""', s)
                s = re.sub(r"'(\\.|[^'\\])'", "''", s)
                if not started and ';' in s and '{' not in s:
                    break
                depth += s.count('{') - s.count('}')
                started = started or '{' in s
                if started and depth <= 0:
                    break
                j += 1
            if started and j - i + 1 > MAX_FN:
                bad.append(f'{os.path.relpath(f, ROOT)}:{i + 1}: function `{m.group(7)}` has {j - i + 1} lines (max {MAX_FN})')
        i += 1
    return bad


problems, seen_files = [], set()
for crate, root_file in crates():
    mods = module_files(root_file)
    graph = {}
    for path, f in mods.items():
        text = open(f, encoding='utf-8').read()
        lines = non_test(text)
        if f not in seen_files:
            seen_files.add(f)
            if len(lines) > MAX_FILE:
                problems.append(f'{os.path.relpath(f, ROOT)}: {len(lines)} lines outside tests (max {MAX_FILE})')
            problems += long_functions(f, lines)
        is_dir = os.path.basename(f) in ('mod.rs', 'lib.rs', 'main.rs')
        for r in refs(lines):
            t = resolve(path, is_dir, r, mods)
            if t is not None and t != path:
                graph.setdefault(path, set()).add(t)
    for comp in sccs(graph):
        names = sorted(os.path.relpath(mods[p], ROOT) for p in comp)
        problems.append(f'{crate}: import circle between ' + ', '.join(names))
    if verbose:
        print(f'{crate}: {len(mods)} files')

for p in problems:
    print(p)
print(f'structure: {len(problems)} violation(s) (import circles, files > {MAX_FILE} lines, functions > {MAX_FN} lines)')
sys.exit(1 if problems else 0)
