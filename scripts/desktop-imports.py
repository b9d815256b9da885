#!/usr/bin/env python3
"""Usage: scripts/desktop-imports.py [DESKTOP_DIR]. Import circles between the files of each desktop crate, and arrows between
crates against the layer order. Edges: `crate::a::b`, `super::a`, and a
module's own child paths (`child::x` after `mod child;`), in code outside
`#[cfg(test)]` modules."""
import re, sys, pathlib, itertools
ROOT = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else pathlib.Path(__file__).resolve().parent.parent / "desktop")
LAYER = {'tcomp_data': 0, 'tcomp_geometry': 1, 'tcomp_model': 2, 'tcomp_thermal': 2,
         'tcomp_link': 2, 'tcomp_bench': 3, 'tcomp': 3}
DIR = {'data': 'tcomp_data', 'geometry': 'tcomp_geometry', 'model': 'tcomp_model',
       'thermal': 'tcomp_thermal', 'link': 'tcomp_link', 'bench': 'tcomp_bench', 'tcomp': 'tcomp'}
bad = 0
for d, crate in DIR.items():
    src = ROOT / d / 'src'
    files = {}
    for f in src.rglob('*.rs'):
        rel = f.relative_to(src)
        if rel.parts[0] == 'bin':
            continue
        parts = list(rel.with_suffix('').parts)
        if parts[-1] in ('mod', 'lib', 'main'):
            parts = parts[:-1]
        files[tuple(parts)] = f
    def resolve(path):
        for k in range(len(path), -1, -1):
            if tuple(path[:k]) in files:
                return tuple(path[:k])
        return None
    edges = {m: set() for m in files}
    for mod, f in files.items():
        text = f.read_text()
        cut = text.find('#[cfg(test)]')
        code = text if cut < 0 else text[:cut]
        code = re.sub(r'//.*', '', code)
        is_dir_mod = f.name in ('mod.rs', 'lib.rs', 'main.rs')
        base = list(mod) if is_dir_mod else list(mod[:-1])  # module that `super` of a child refers to
        children = set(re.findall(r'^\s*(?:pub(?:\([a-z]+\))?\s+)?mod\s+([a-z_0-9]+)\s*;', code, re.M))
        for m in re.finditer(r'\b((?:crate|super|[a-z_0-9]+)(?:::[a-z_][a-z_0-9]*)+)', code):
            segs = m.group(1).split('::')
            if segs[0] == 'crate':
                path = segs[1:]
            elif segs[0] == 'super':
                cur = list(mod)
                while segs and segs[0] == 'super':
                    cur = cur[:-1]; segs = segs[1:]
                path = cur + segs
            elif segs[0] in children:
                path = list(mod) + segs
            elif segs[0] in DIR.values() and segs[0] != crate:
                if LAYER[segs[0]] >= LAYER[crate]:
                    print(f'{crate}: arrow to a same or higher layer: {segs[0]} in {f}'); bad += 1
                continue
            else:
                continue
            t = resolve(path)
            if t is not None and t != mod:
                edges[mod].add(t)
    # strongly connected components (Tarjan)
    index, low, stack, on, comps, i = {}, {}, [], set(), [], [0]
    def strong(v):
        index[v] = low[v] = i[0]; i[0] += 1; stack.append(v); on.add(v)
        for w in edges[v]:
            if w not in index:
                strong(w); low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            c = []
            while True:
                w = stack.pop(); on.discard(w); c.append(w)
                if w == v: break
            comps.append(c)
    sys.setrecursionlimit(10000)
    for v in edges:
        if v not in index: strong(v)
    for c in comps:
        # a parent module using its child and the child using the parent's items is a circle too
        if len(c) > 1:
            bad += 1
            print(f'{crate}: circle: ' + ' ↔ '.join('/'.join(x) or '(root)' for x in c))
print('circles/arrows found:', bad)
sys.exit(1 if bad else 0)
