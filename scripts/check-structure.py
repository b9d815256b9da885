#!/usr/bin/env python3
"""Structure rules of the house, checked on every crate of the workspace:
no import circle between the files of a crate, no file over 800 lines and no
function over 150 lines outside tests. Cargo itself forbids circles between
crates.

Import graph. Every file of a crate target is read with a small Rust lexer
(comments, strings, raw strings, char literals and lifetimes skipped), and
every module-relative path in code that is not test-only becomes an edge from
its file to the file that defines the module the path names:
  * every `use` form: `use crate::a::X`, `use super::X`, `use self::a::X`,
    a bare first segment (`use gate::f` inside the module that declares
    `mod gate;`: Rust 2018 uniform paths), nested groups
    `use a::{b, c::{d, e}}`, `{self, …}`, `as` renames, globs, `pub use`;
  * paths written in code: `super::gate::f()`, `crate::x::y`, `self::a::B`,
    `gate::f()` for a module `gate` in scope (declared in the current module,
    or brought in by a `use`, or by a glob `use super::*`).
A bare first segment that names no module in scope (an external crate, std,
a type, an enum) is no edge. A path resolves to the deepest *module* it
walks through: `super::Finding` (an item of the parent, even one the parent
only re-exports) is an edge to the parent's file; `super::gate::f` an edge to
gate's file. Test code (items under `#[cfg(test)]`, `mod tests;` files
declared so) makes no edge, so `#[cfg(test)] mod tests { use super::*; }` is
none; neither do `mod x;` declarations themselves.

Reported: every circle between files (each strongly connected set of files,
with one cycle per edge inside it, hop by hop, each hop with the line of the
reference: `a.rs:12 -> b.rs:40 -> a.rs` reads "a.rs line 12 refers to b.rs,
b.rs line 40 refers to a.rs"); and, separately, every file that imports items
from its parent hub (a/b.rs or a/b/mod.rs taking names that live in a/mod.rs
or a.rs; any ancestor module's file counts, the crate root too): an error in
the desktop crates (desktop/), elsewhere a warning (an error with
--strict-hub).

Usage: scripts/check-structure.py [--verbose] [--strict-hub]
       scripts/check-structure.py --self-test
Exit 1 on a violation (an import circle, a file or function too long, with
--strict-hub a hub import). Hand-written: no Rust crate checks file-level
import graphs or lengths."""
import json, os, re, subprocess, sys, tempfile
from collections import deque

MAX_FILE, MAX_FN = 800, 150
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
verbose = '--verbose' in sys.argv
strict_hub = '--strict-hub' in sys.argv


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


# ---------------------------------------------------------------- lexer

RAW_STR = re.compile(r'(?:b|c)?r(#*)"')
STR = re.compile(r'(?:b|c)?"')
CHAR = re.compile(r"b?'(?:\\(?:x[0-9a-fA-F]{2}|u\{[0-9a-fA-F_]*\}|.)|[^\\'\n])'")
LIFETIME = re.compile(r"'(?:r#)?\w+")
IDENT = re.compile(r'r#\w+|[^\W\d]\w*')
NUMBER = re.compile(r'\d\w*(?:\.\d\w*)?')


def lex(text):
    """Tokens (kind, value, line): kind 'id' (identifier or keyword; a raw
    identifier keeps its `r#`), 'p' (punctuation, `::` as one token), 'lit'."""
    toks, i, n, line = [], 0, len(text), 1
    while i < n:
        c = text[i]
        if c == '\n':
            line += 1; i += 1; continue
        if c.isspace():
            i += 1; continue
        if text.startswith('//', i):
            j = text.find('\n', i)
            i = n if j < 0 else j
            continue
        if text.startswith('/*', i):
            depth = 0
            while i < n:
                if text.startswith('/*', i):
                    depth += 1; i += 2
                elif text.startswith('*/', i):
                    depth -= 1; i += 2
                    if depth == 0:
                        break
                else:
                    line += text[i] == '\n'; i += 1
            continue
        m = RAW_STR.match(text, i)
        if m:
            end = '"' + m.group(1)
            j = text.find(end, m.end())
            j = n if j < 0 else j + len(end)
            toks.append(('lit', '', line)); line += text.count('\n', i, j); i = j
            continue
        m = STR.match(text, i)
        if m:
            j = m.end()
            while j < n and text[j] != '"':
                j += 2 if text[j] == '\\' else 1
            j += 1
            toks.append(('lit', text[m.end():j - 1], line)); line += text.count('\n', i, j); i = j
            continue
        if c == "'" or text.startswith("b'", i):
            m = CHAR.match(text, i)
            if m:
                toks.append(('lit', '', line)); i = m.end(); continue
            m = LIFETIME.match(text, i)
            if m:
                toks.append(('lt', m.group(0), line)); i = m.end(); continue
        m = IDENT.match(text, i)
        if m:
            toks.append(('id', m.group(0), line)); i = m.end(); continue
        m = NUMBER.match(text, i)
        if m:
            toks.append(('lit', '', line)); i = m.end(); continue
        if text.startswith('::', i):
            toks.append(('p', '::', line)); i += 2; continue
        toks.append(('p', c, line)); i += 1
    return toks


# ---------------------------------------------------------------- parser

OPEN, CLOSE = {'{': '}', '(': ')', '[': ']'}, {'}', ')', ']'}


def cfg_is_test(attr):
    """`#[cfg(test)]`, `#[cfg(all(test, …))]`: test-only (not `not(test)`, `any(…)`)."""
    vals = [v for k, v, _ in attr if k == 'id']
    return bool(vals) and vals[0] == 'cfg' and 'test' in vals and 'not' not in vals and 'any' not in vals


def parse_use_tree(toks, i, prefix, out):
    """One use tree from toks[i]; appends (segments, alias | None for a glob, line)."""
    segs = list(prefix)
    if i < len(toks) and toks[i][1] == '::':
        segs.append('::'); i += 1          # `use ::ext::x`: an external crate
    while i < len(toks):
        k, v, line = toks[i]
        if v == '{' and k == 'p':
            i += 1
            while i < len(toks) and toks[i][1] != '}':
                if toks[i][1] == ',':
                    i += 1; continue
                i = parse_use_tree(toks, i, segs, out)
            return i + 1
        if v == '*' and k == 'p':
            out.append((tuple(segs), None, line))
            return i + 1
        if k != 'id':
            return i + 1
        segs.append(v); i += 1
        if i < len(toks) and toks[i][1] == '::':
            i += 1; continue
        alias = v
        if i + 1 < len(toks) and toks[i][1] == 'as':
            alias = toks[i + 1][1]; i += 2
        if segs[-1] == 'self' and len(segs) > 1:
            segs.pop()
            if alias == 'self':
                alias = segs[-1]
        out.append((tuple(segs), alias, line))
        return i
    return i


def parse_file(toks, file_mod, file_test):
    """Walk one file's tokens. Returns (mod_decls, inline_mods, uses, paths):
    mod_decls (scope, name, path_attr, test), inline_mods (module path, test),
    uses (scope, segments, alias|None, line, test), paths (scope, segments, line, test)."""
    mod_decls, inline_mods, uses, paths = [], [], [], []
    frames = [(file_mod, file_test)]      # one per open `{`: (module, test)
    nest = []                              # every open bracket: (char, frames depth)
    pending_test, pending_path, pending_level, pending_inline = False, None, None, None
    item_test_level = None                 # nest level of the test-only item being walked
    i, n = 0, len(toks)
    while i < n:
        k, v, line = toks[i]
        level = len(nest)
        test = frames[-1][1] or item_test_level is not None
        scope = frames[-1][0]
        if k == 'p' and v == '#':
            j, inner = i + 1, False
            if j < n and toks[j][1] == '!':
                inner, j = True, j + 1
            if j < n and toks[j][1] == '[':
                depth, a = 0, j
                while a < n:
                    if toks[a][1] == '[' and toks[a][0] == 'p': depth += 1
                    elif toks[a][1] == ']' and toks[a][0] == 'p':
                        depth -= 1
                        if depth == 0: break
                    a += 1
                attr = toks[j + 1:a]
                if cfg_is_test(attr):
                    if inner:
                        frames[-1] = (frames[-1][0], True)
                    else:
                        pending_test, pending_level = True, level
                if attr and attr[0][1] == 'path' and len(attr) >= 3 and attr[2][0] == 'lit':
                    pending_path, pending_level = attr[2][1], level
                i = a + 1
                continue
        if pending_test and level == pending_level and item_test_level is None:
            item_test_level = level
            test = True
        pending_test = False
        if k == 'p' and v in OPEN:
            nest.append((v, len(frames)))
            if v == '{':
                frames.append((scope + (pending_inline,) if pending_inline else scope, test))
                if pending_inline:
                    inline_mods.append((frames[-1][0], test))
                pending_inline = None
                if level == pending_level:
                    pending_path = None
            i += 1
            continue
        if k == 'p' and v in CLOSE:
            if nest:
                _, depth = nest.pop()
                del frames[depth:]
            # a test item ends with its body's `}` or when its enclosing bracket closes
            if item_test_level is not None and (len(nest) < item_test_level
                                                or (v == '}' and len(nest) == item_test_level)):
                item_test_level = None
            i += 1
            continue
        if k == 'p' and v in (';', ','):
            if item_test_level is not None and level == item_test_level:
                item_test_level = None
            if level == pending_level:
                pending_path = None
            i += 1
            continue
        if k == 'id' and v == 'mod' and i + 2 < n and toks[i + 1][0] == 'id':
            name, nxt = toks[i + 1][1], toks[i + 2][1]
            if nxt == ';':
                mod_decls.append((scope, name, pending_path, test))
                pending_path = None
                i += 2          # the `;` is walked next (ends a test item)
                continue
            if nxt == '{':
                pending_inline = name
                i += 2
                continue
        if k == 'id' and v == 'use' and (i == 0 or toks[i - 1][1] != '::'):
            out = []
            j = parse_use_tree(toks, i + 1, (), out)
            while j < n and toks[j][1] != ';':
                j += 1
            for segs, alias, _ in out:
                uses.append((scope, segs, alias, line, test))
            i = j           # the `;` is walked next
            continue
        if k == 'id' and i + 2 < n and toks[i + 1][1] == '::' and toks[i + 2][0] == 'id' \
                and (i == 0 or toks[i - 1][1] not in ('::', '.')):
            segs, j = [v], i + 1
            while j + 1 < n and toks[j][1] == '::' and toks[j + 1][0] == 'id':
                segs.append(toks[j + 1][1]); j += 2
            if i > 0 and toks[i - 1][1] == '$' and v == 'crate':
                segs[0] = 'crate'
            paths.append((scope, tuple(segs), line, test))
            i = j
            continue
        i += 1
    return mod_decls, inline_mods, uses, paths


# ---------------------------------------------------------------- one crate

def rel(f):
    return os.path.relpath(f, ROOT)


class Crate:
    """The files and module-relative references of one crate target."""

    def __init__(self, root_file):
        root_file = os.path.normpath(root_file)
        self.mods = {(): dict(file=root_file, test=False, inline=False, by_path=False)}
        self.aliases, self.globs, self.refs = {}, {}, []
        todo = [()]
        while todo:
            fm = todo.pop()
            info = self.mods[fm]
            f = info['file']
            decls, inline, uses, paths = parse_file(lex(open(f, encoding='utf-8').read()), fm, info['test'])
            for mp, t in inline:
                self.mods.setdefault(mp, dict(file=f, test=t, inline=True, by_path=False))
            base = os.path.basename(f)
            d = os.path.dirname(f)
            own_dir = d if fm == () or info['by_path'] or base in ('mod.rs', 'lib.rs', 'main.rs') \
                else os.path.join(d, base[:-3])
            for scope, name, path_attr, t in decls:
                inner = scope[len(fm):]
                if path_attr:
                    cand = [os.path.join(os.path.join(own_dir, *inner) if inner else d, path_attr)]
                else:
                    b = os.path.join(own_dir, *inner)
                    cand = [os.path.join(b, name + '.rs'), os.path.join(b, name, 'mod.rs')]
                for c in cand:
                    if os.path.isfile(c):
                        self.mods[scope + (name,)] = dict(file=os.path.normpath(c), test=t, inline=False,
                                                          by_path=bool(path_attr))
                        todo.append(scope + (name,))
                        break
            for scope, segs, alias, line, t in uses:
                if alias is None:
                    self.globs.setdefault(scope, []).append(segs)
                elif alias != '_':
                    self.aliases.setdefault(scope, {})[alias] = segs
                self.refs.append((scope, segs, line, t, 'use'))
            for scope, segs, line, t in paths:
                self.refs.append((scope, segs, line, t, 'path'))

    def file_module(self, m):
        while self.mods[m]['inline']:
            m = m[:-1]
        return m

    def lookup(self, scope, name, seen):
        """A bare first segment in `scope` (Rust 2018): (module, names a module) or None."""
        if scope + (name,) in self.mods:
            return scope + (name,), True
        if (scope, name) in seen:
            return None
        seen = seen | {(scope, name)}
        segs = self.aliases.get(scope, {}).get(name)
        if segs is not None:
            return self.walk(scope, segs, seen)
        for g in self.globs.get(scope, ()):
            r = self.walk(scope, g, seen)
            if r is not None and r[1]:
                found = self.lookup(r[0], name, seen)
                if found is not None:
                    return found
        return None

    def walk(self, scope, segs, seen=frozenset()):
        """The deepest module a path walks through, and whether every segment
        was a module; None for an external crate, std, or a name not in scope."""
        s0 = segs[0]
        if s0 == 'crate':
            m, rest = (), segs[1:]
        elif s0 in ('self', 'super'):
            m, rest = scope, segs
            while rest and rest[0] in ('self', 'super'):
                if rest[0] == 'super':
                    if not m:
                        return None
                    m = m[:-1]
                rest = rest[1:]
        else:
            r = self.lookup(scope, s0, seen)
            if r is None or not r[1]:
                return r
            m, rest = r[0], segs[1:]
        for s in rest:
            if m + (s,) not in self.mods:
                return m, False
            m = m + (s,)
        return m, True

    def edges(self):
        """{(from file, to file): [(line, path as written)]} and the hub imports
        [(file, hub file, line, path)], test code left out."""
        edges, hubs = {}, []
        for scope, segs, line, test, kind in self.refs:
            if test or self.mods[scope]['test']:
                continue
            r = self.walk(scope, segs)
            if r is None:
                continue
            src, dst = self.mods[scope]['file'], self.mods[r[0]]['file']
            if src == dst:
                continue
            written = '::'.join(segs) + ('::*' if kind == 'use' and segs in self.globs.get(scope, ()) else '')
            edges.setdefault((src, dst), []).append((line, written))
            fm, tm = self.file_module(scope), self.file_module(r[0])
            if len(tm) < len(fm) and fm[:len(tm)] == tm:
                hubs.append((src, dst, line, written))
        return edges, hubs


def sccs(graph):
    index, low, stack, on, out, n = {}, {}, [], set(), [], [0]
    sys.setrecursionlimit(10000)
    def strong(v):
        index[v] = low[v] = n[0]; n[0] += 1; stack.append(v); on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                strong(w); low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop(); on.discard(w); comp.append(w)
                if w == v: break
            if len(comp) > 1: out.append(sorted(comp))
    for v in sorted(graph):
        if v not in index: strong(v)
    return out


def circles(edges):
    """[(files of one strongly connected set, [cycles as file lists])]: one
    shortest cycle through every edge inside the set, without repeats."""
    graph = {}
    for a, b in edges:
        graph.setdefault(a, set()).add(b)
    out = []
    for comp in sccs(graph):
        inside = set(comp)
        cycles = []
        for a in comp:
            for b in sorted(graph[a] & inside):
                prev, q = {b: None}, deque([b])   # shortest path b -> a inside the set
                while q and a not in prev:
                    u = q.popleft()
                    for w in sorted(graph.get(u, ()) & inside):
                        if w not in prev:
                            prev[w] = u; q.append(w)
                path, u = [], a
                while u is not None:
                    path.append(u); u = prev[u]
                cyc = ([a] + path[::-1])[:-1]      # a, b, …, (back to a)
                k = cyc.index(min(cyc))
                cyc = cyc[k:] + cyc[:k]
                if cyc not in cycles:
                    cycles.append(cyc)
        out.append((comp, sorted(cycles, key=lambda c: (len(c), c))))
    return out


def show_cycle(cyc, edges, short):
    hops = []
    for i, a in enumerate(cyc):
        b = cyc[(i + 1) % len(cyc)]
        hops.append(f'{short(a)}:{edges[(a, b)][0][0]}')
    return ' -> '.join(hops + [short(cyc[0])])


# ---------------------------------------------------------------- lengths

def non_test(text):
    lines = text.split('\n')
    for i, l in enumerate(lines):
        if l.strip().startswith('#[cfg(test)]'):
            return lines[:i]
    return lines


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
                bad.append(f'{rel(f)}:{i + 1}: function `{m.group(7)}` has {j - i + 1} lines (max {MAX_FN})')
        i += 1
    return bad


# ---------------------------------------------------------------- the check

def check_crate(name, root_file, short=rel):
    """(circle reports, hub reports) of one crate target, as text lines."""
    crate = Crate(root_file)
    edges, hubs = crate.edges()
    circle_lines = []
    for comp, cycles in circles(edges):
        circle_lines.append(f'{name}: import circle between {len(comp)} files: '
                            + ', '.join(short(f) for f in comp)
                            + ''.join('\n    ' + show_cycle(c, edges, short) for c in cycles))
    per_file = {}
    for src, dst, line, written in hubs:
        per_file.setdefault((src, dst), []).append((line, written))
    hub_lines = [f'{short(src)}:{refs[0][0]}: imports from its hub {short(dst)}: '
                 + ', '.join(sorted({w for _, w in refs}))
                 for (src, dst), refs in sorted(per_file.items())]
    return crate, circle_lines, hub_lines


def main():
    problems, hub_warnings, seen_files = [], [], set()
    for name, root_file in crates():
        crate, circle_lines, hub_lines = check_crate(name, root_file)
        for info in crate.mods.values():
            f = info['file']
            if f in seen_files:
                continue
            seen_files.add(f)
            lines = non_test(open(f, encoding='utf-8').read())
            if len(lines) > MAX_FILE:
                problems.append(f'{rel(f)}: {len(lines)} lines outside tests (max {MAX_FILE})')
            problems += long_functions(f, lines)
        problems += [c for c in circle_lines if c not in problems]
        hub_warnings += [h for h in hub_lines if h not in hub_warnings]
        if verbose:
            n = len({i['file'] for i in crate.mods.values()})
            print(f'{name}: {n} files, {len(crate.refs)} module-relative references')
    # In the desktop crates a hub import is an error always (issue 48: rooms
    # by role, no module importing its parent hub); elsewhere a warning.
    hub_errors = [h for h in hub_warnings if strict_hub or h.startswith('desktop/')]
    for h in hub_warnings:
        print(('error: ' if h in hub_errors else 'warning: ') + h)
    print(f'structure: {len(hub_warnings)} file(s) importing from their parent hub'
          + (' (errors: --strict-hub)' if strict_hub
             else f' ({len(hub_errors)} of them in desktop/: errors; elsewhere warnings, --strict-hub makes them errors)'))
    for p in problems:
        print(p)
    print(f'structure: {len(problems)} violation(s) (import circles, files > {MAX_FILE} lines, functions > {MAX_FN} lines)')
    return 1 if problems or hub_errors else 0


# ---------------------------------------------------------------- self-test

FIXTURES = {
    # each: files, expected circles (sets of files), expected hub importers (src, hub)
    'crate_path': ({
        'lib.rs': 'mod a;\nmod b;\npub fn root() {}\n',
        'a.rs': 'use crate::b::B;\npub struct A;\n',
        'b.rs': 'pub struct B;\nfn f() { let _ = crate::a::A; }\n',
    }, [{'a.rs', 'b.rs'}], []),
    'super_and_self': ({
        'lib.rs': 'mod m;\n',
        'm/mod.rs': 'mod x;\nmod y;\npub struct Hub;\nuse self::x::X;\n',
        'm/x.rs': 'pub struct X;\nuse super::Hub;\n',
        'm/y.rs': 'fn g() -> super::x::X { super::x::X }\n',
    }, [{'m/mod.rs', 'm/x.rs'}], [('m/x.rs', 'm/mod.rs')]),
    'bare_sibling': ({
        'lib.rs': 'mod d;\n',
        'd/mod.rs': 'mod release;\nmod gate;\nuse release::merge;\npub struct Finding;\n',
        'd/release.rs': 'use super::{gate, Finding};\npub fn merge() { gate::f(); }\n',
        'd/gate.rs': 'pub fn f() {}\n',
    }, [{'d/mod.rs', 'd/release.rs'}], [('d/release.rs', 'd/mod.rs')]),
    'nested_groups_and_pub_use': ({
        'lib.rs': 'mod a;\nmod b;\n',
        'a/mod.rs': 'mod c;\npub mod e;\npub use c::C;\n',
        'a/c.rs': 'pub struct C;\n',
        'a/e.rs': 'pub struct E;\n',
        'b.rs': 'pub use crate::{a::{c::C as Cee, e::{self, E}}, a};\n',
    }, [], []),
    'nested_group_circle': ({
        'lib.rs': 'mod a;\nmod b;\n',
        'a/mod.rs': 'pub mod e;\n',
        'a/e.rs': 'pub struct E;\npub fn f() { crate::b::g() }\n',
        'b.rs': 'pub use crate::{a::{e::{self, E}}};\npub fn g() {}\n',
    }, [{'a/e.rs', 'b.rs'}], []),
    'inline_paths_via_alias_and_glob': ({
        'lib.rs': 'mod p;\n',
        'p/mod.rs': 'mod k;\nmod q;\npub fn timing() -> bool { k::on() }\n',
        'p/k.rs': 'pub fn on() -> bool { super::timing() }\n',
        'p/q.rs': 'use super::*;\nfn z() { k::on(); }\n',
    }, [{'p/mod.rs', 'p/k.rs'}], [('p/k.rs', 'p/mod.rs'), ('p/q.rs', 'p/mod.rs')]),
    'tests_are_no_edge': ({
        'lib.rs': 'mod a;\nmod b;\npub struct R;\n',
        'a.rs': 'pub fn f() { crate::b::g() }\n#[cfg(test)]\nmod tests {\n    use super::*;\n    use crate::R;\n    #[test]\n    fn t() { crate::b::g(); let _ = crate::a::f; }\n}\n',
        'b.rs': 'pub fn g() {}\n#[cfg(test)]\nuse crate::a::f;\n#[cfg(test)]\nmod tests;\n#[cfg(test)]\nfn h() { crate::a::f() }\nfn after() { let _ = 1; }\n',
        'b/tests.rs': 'use super::*;\nuse crate::a::f;\n',
    }, [], []),
    'external_std_comments_strings': ({
        'lib.rs': 'mod a;\nmod b;\n',
        'a.rs': 'use std::fmt;\nuse ::serde::x;\nuse nalgebra::DMatrix;\n// crate::b::g\n/* crate::b::g /* nested */ crate::b::g */\nfn s() -> &\'static str { "crate::b::g" }\nfn r() -> &\'static str { r#"crate::b::g "quoted" "# }\nfn c() -> char { \'"\' }\nfn l<\'a>(x: &\'a str) -> &\'a str { x }\nstruct Kind; impl Kind { fn t() {} }\nfn k() { Kind::t(); Vec::<u8>::new(); }\n',
        'b.rs': 'pub fn g() { crate::a::l("x"); }\n',
    }, [], []),
    'path_attribute_and_inline_mod': ({
        'lib.rs': 'mod a;\nmod outer {\n    pub mod inner;\n    pub fn o() { crate::a::f() }\n}\n#[path = "elsewhere/bb.rs"]\nmod b;\n',
        'a.rs': 'pub fn f() {}\npub fn g() { crate::outer::inner::h(); crate::b::z(); crate::outer::o(); }\n',
        'outer/inner.rs': 'pub fn h() {}\n',
        'elsewhere/bb.rs': 'pub fn z() { crate::a::f() }\n',
    }, [{'lib.rs', 'a.rs', 'elsewhere/bb.rs'}], [('a.rs', 'lib.rs')]),
    'code_after_test_items': ({
        'lib.rs': 'mod a;\nmod b;\n',
        'a.rs': 'pub struct A;\nimpl A {\n    #[cfg(test)]\n    fn t() { crate::b::g() }\n    #[cfg(not(test))]\n    fn n() {}\n    fn u() { crate::b::g() }\n}\n',
        'b.rs': '#![allow(dead_code)]\n#[cfg(test)]\nconst N: [u8; 2] = [0; 2];\npub fn g() { let _ = crate::a::A; }\n',
    }, [{'a.rs', 'b.rs'}], []),
    'test_only_file': ({
        'lib.rs': 'mod a;\nmod b;\n',
        'a.rs': '#![cfg(test)]\nuse crate::b::g;\n',
        'b.rs': 'pub fn g() { crate::a::f() }\n',
    }, [], []),
}


def self_test():
    failures = 0
    with tempfile.TemporaryDirectory() as tmp:
        for name, (files, want_circles, want_hubs) in FIXTURES.items():
            root = os.path.join(tmp, name)
            for path, text in files.items():
                os.makedirs(os.path.dirname(os.path.join(root, path)), exist_ok=True)
                open(os.path.join(root, path), 'w', encoding='utf-8').write(text)
            short = lambda f: os.path.relpath(f, root)
            crate = Crate(os.path.join(root, 'lib.rs'))
            edges, hubs = crate.edges()
            got_circles = sorted(sorted(short(f) for f in comp) for comp, _ in circles(edges))
            want = sorted(sorted(c) for c in want_circles)
            got_hubs = sorted({(short(s), short(d)) for s, d, _, _ in hubs})
            ok = got_circles == want and got_hubs == sorted(want_hubs)
            failures += not ok
            print(f'self-test {name}: {"ok" if ok else "FAILED"}')
            if not ok:
                print(f'    circles {got_circles}, want {want}\n    hubs {got_hubs}, want {sorted(want_hubs)}')
                for (a, b), ev in sorted(edges.items()):
                    print(f'    edge {short(a)} -> {short(b)}: {ev}')
    print(f'self-test: {len(FIXTURES) - failures} of {len(FIXTURES)} fixtures pass')
    return 1 if failures else 0


if __name__ == '__main__':
    sys.exit(self_test() if '--self-test' in sys.argv else main())
