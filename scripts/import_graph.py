#!/usr/bin/env python3
"""prtbake's module graph, read from the source alone, checked against LAYERS.

Usage: scripts/import_graph.py [--root DIR] [--dot FILE] [--json]

Modules. Every file under src/ is one: src/lib.rs is the crate root `(crate)`,
src/x.rs and src/x/mod.rs are `x`, src/x/y.rs is `x::y`. bin/prtbake.rs is a
second root, `bin`, above every layer (it may use anything). A room is a
top-level module (bake, trace, mesh, ...).

Test code is left out (tests may reach anywhere): files named *tests*.rs or
test_support.rs, files declared by `#[cfg(test)] mod x;` or starting with
`#![cfg(test)]`, every `mod tests { ... }`, and whatever item or statement
follows a `#[cfg(test)]` (test-only counters and helpers too).

Comments (`//`, nested `/* */`, doc comments) and string, byte and char
literals (raw ones too) are blanked first; lifetimes and labels (`'a`) stay.

References: `use` trees (grouped, nested, multi-line, `self`, `as`, `*`) and
paths anywhere in code that start with `crate::`, `self::`, `super::`
(repeated), `prtbake::` (bin only), a child module's name, or a name that a
`use` bound to a module (`use crate::sh; sh::basis::f` reaches `sh::basis`;
a glob of a module binds its child modules). Inside an inline `mod m { }`,
`self` and `super` are relative to `m`. A reference goes to the longest
module prefix of its absolute path: `crate::bake::transfer::Plan` is
`bake::transfer`, `crate::bake::Scene` is `bake` (a re-export through the
parent). References to one's own module and `mod x;` lines are not edges.
So `pub use child::X` in a mod.rs is an edge parent -> child, a child's
`use super::Y` is child -> parent, and only both together make a cycle.

A room's mod.rs is its front door: it re-exports its files' public items
and holds the few types they all share (the room's error, its settings), so
a file's `super::Error` and the parent's `pub use file::X` go both ways by
design. Cycles through mod.rs are therefore printed (`--strict` fails on
them) but fail only when they remain with mod.rs taken out: two files of a
room that use each other.

Exit 1, listing each problem with the lines behind it, on: a cycle between
rooms (every edge inside the cycle is listed); a cycle between files of one
room that remains when the room's mod.rs is taken out (the component and
one cycle through it); an arrow from a room to a higher one in LAYERS, or a
room missing from LAYERS. Exit 0 when clean.

Not understood: paths made by macros, `#[path]` (only used for test files),
a `use` inside a function (it binds in the whole module here), names a glob
re-imports from the parent's own `use`s, and `#[cfg(test)]` on a struct
field or match arm (it would blank up to the next `;` or block).
"""
import argparse, json, os, re, sys
from collections import defaultdict

# Lowest first: a room may use only rooms before it. `bin` is above them all.
LAYERS = ["disjoint", "files", "colour", "sampling", "sh", "mesh", "atlas", "sky", "trace", "clean", "fixtures", "brdf", "bake",
          "bundle", "shards", "verify", "refine", "panel", "chart", "view", "cli"]

TOK = re.compile(r'//|/\*|(?<!\w)[bc]?r(#*)"|"|\'')
CHAR = re.compile(r"'(?:\\(?:x[0-9a-fA-F]{2}|u\{[0-9a-fA-F]{1,6}\}|.)|[^\\'\n])'")
CFG_TEST = re.compile(r'#\s*\[\s*cfg\s*\(\s*test\s*\)\s*\]')
TESTS_MOD = re.compile(r'\bmod\s+tests\s*\{')
INLINE_MOD = re.compile(r'\bmod\s+(\w+)\s*\{')
DECL_MOD = re.compile(r'\bmod\s+(\w+)\s*;')
USE = re.compile(r'\buse\s+([^;]*);')
PATH = re.compile(r'(?<![\w:$])\$?([A-Za-z_]\w*)((?:\s*::\s*[A-Za-z_]\w*)+)')
TEST_FILE = re.compile(r'.*tests.*\.rs|test_support\.rs')
BIN = ('<bin>',)

def blank(s):  # keeps offsets and line numbers
    return re.sub(r'[^\n]', ' ', s)

def strip(src):
    """Blank comments and literals, keeping every offset and newline."""
    out, i, n = [], 0, len(src)
    while (m := TOK.search(src, i)):
        s, t = m.start(), m.group()
        out.append(src[i:s])
        if t == '//':
            e = src.find('\n', s) % (n + 1)  # -1 (no newline) becomes n
        elif t == '/*':  # block comments nest
            d, e = 1, s + 2
            while e < n and d:
                two = src[e:e + 2]
                d, e = (d + 1, e + 2) if two == '/*' else (d - 1, e + 2) if two == '*/' else (d, e + 1)
        elif m.group(1) is not None:  # raw string r#"..."#
            e = src.find('"' + m.group(1), m.end())
            e = n if e < 0 else e + 1 + len(m.group(1))
        elif t == '"':
            e = s + 1
            while e < n and src[e] != '"':
                e += 2 if src[e] == '\\' else 1
            e += 1
        elif (c := CHAR.match(src, s)):
            e = c.end()
        else:  # a lifetime or a label
            out.append("'")
            i = s + 1
            continue
        out.append(blank(src[s:e]))
        i = e
    return ''.join(out) + src[i:]

def brace_end(t, i):
    """Index after the `}` matching the `{` at i."""
    d = 0
    for j in range(i, len(t)):
        d += (t[j] == '{') - (t[j] == '}')
        if d == 0:
            return j + 1
    return len(t)

def item_end(t, i):
    """End of the item or statement from i (attributes included): its `;` or its `{ }`."""
    d = 0
    for j in range(i, len(t)):
        d += (t[j] in '([') - (t[j] in ')]')
        if d == 0 and t[j] in ';{':
            return j + 1 if t[j] == ';' else brace_end(t, j)
    return len(t)

def drop_tests(t):
    """Blank test-only code; return the text and the child modules declared for tests."""
    kids = set()
    for pat in (CFG_TEST, TESTS_MOD):
        while (m := pat.search(t)):
            e = item_end(t, m.end()) if pat is CFG_TEST else brace_end(t, m.end() - 1)
            kids.update(DECL_MOD.findall(t[m.start():e]))
            t = t[:m.start()] + blank(t[m.start():e]) + t[e:]
    return t, kids

def use_paths(body):
    """Expand a use tree into [(segments, bound name or '*')]."""
    toks, pos = re.findall(r'::|[{},*]|\w+', body), 0

    def tree(segs):
        nonlocal pos
        segs, out = list(segs), []
        if toks[pos] == '::':
            pos += 1
            segs += [] if segs else ['::']  # ::extern_crate
        while toks[pos] not in '{*':
            segs.append(toks[pos])
            pos += 1
            if pos == len(toks) or toks[pos] != '::':
                segs = segs[:-1] if segs[-1] == 'self' else segs
                name = segs[-1] if segs else None
                if pos < len(toks) and toks[pos] == 'as':
                    name, pos = toks[pos + 1], pos + 2
                return [(segs, name)]
            pos += 1
        pos += 1
        if toks[pos - 1] == '*':
            return [(segs, '*')]
        while toks[pos] != '}':
            out += tree(segs)
            pos += toks[pos] == ','
        pos += 1
        return out
    return tree([])

def load(root):
    files = {}  # module tuple -> path relative to root
    for d, _, names in os.walk(os.path.join(root, 'src')):
        for f in (f for f in names if f.endswith('.rs')):
            rel = os.path.relpath(os.path.join(d, f), root)
            parts = tuple(rel[4:-3].split(os.sep))
            files[parts[:-1] if parts[-1] in ('mod', 'lib') else parts] = rel
    if os.path.exists(os.path.join(root, 'bin', 'prtbake.rs')):
        files[BIN] = os.path.join('bin', 'prtbake.rs')
    texts, tests = {}, set()
    for mod, rel in files.items():
        with open(os.path.join(root, rel), encoding='utf-8') as fh:
            raw = strip(fh.read())
        if TEST_FILE.fullmatch(os.path.basename(rel)) or re.search(r'#!\s*\[\s*cfg\s*\(\s*test\s*\)', raw):
            tests.add(mod)
        texts[mod], kids = drop_tests(raw)
        tests.update(mod + (k,) for k in kids)
    return files, texts, tests

def analyse(root):
    files, texts, tests = load(root)
    mods, doubts, refs = set(files) - {BIN}, [], defaultdict(list)  # (from, to) -> ["path:line: text"]
    known = mods | tests
    for src in sorted(m for m in texts if m not in tests):
        t, rel, is_bin = texts[src], files[src], src == BIN
        regions = [(m.start(), brace_end(t, m.end() - 1), m.group(1)) for m in INLINE_MOD.finditer(t)]
        here_at = lambda p: (() if is_bin else src) + tuple(n for s, e, n in regions if s <= p < e)
        line_of = lambda p: t.count('\n', 0, p) + 1

        def resolve(segs, here, scope):
            h = segs[0]
            if (h == 'crate' and not is_bin) or (h == 'prtbake' and is_bin):
                return tuple(segs[1:])
            if h in ('self', 'super') and not is_bin:
                k = next((k for k, x in enumerate(segs) if x != 'super'), len(segs))
                return here[:len(here) - k] + tuple(segs[max(k, h == 'self'):])
            return scope[h] + tuple(segs[1:]) if h in scope else None

        def target(path):
            return max((path[:k] for k in range(len(path) + 1) if path[:k] in known), key=len, default=()) if path else None

        def add(path, pos, what):
            if (tgt := target(path)) is None:
                return
            where = f"{rel}:{line_of(pos)}: {' '.join(what.split())[:110]}"
            if tgt in tests:
                doubts.append(f"{where} (non-test code names the test module {'::'.join(tgt)})")
            elif tgt != src and (tgt or () in mods):
                refs[(src, tgt)].append(where)

        def expand(m):
            try:
                return use_paths(m.group(1))
            except IndexError:
                doubts.append(f"{rel}:{line_of(m.start())}: could not parse `use {m.group(1)[:60]}`")
                return []
        uses = [(m, here_at(m.start()), expand(m)) for m in USE.finditer(t)]
        scopes = {}
        for here in {h for _, h, _ in uses} | {here_at(0)} | {here_at(s) for s, _, _ in regions}:
            scope = {} if is_bin else {m[-1]: m for m in known if m[:-1] == here and len(m) == len(here) + 1}
            for _ in range(2):  # twice: a use may start from a module another use bound
                for segs, name in (x for _, h, paths in uses if h == here for x in paths if x[0]):
                    p = resolve(segs, here, scope)
                    if p in known and name == '*':
                        scope.update({c[-1]: c for c in mods if c[:-1] == p and len(c) == len(p) + 1})
                    elif p in known and name:
                        scope[name] = p
            scopes[here] = scope
        for m, here, paths in uses:  # evidence: the paths of this use that reach the same module
            hits = defaultdict(list)
            for segs, _ in (x for x in paths if x[0]):
                p = resolve(segs, here, scopes[here])
                hits[target(p)].append((p, '::'.join(segs)))
            for p, _ in (x for group in hits.values() for x in group):
                add(p, m.start(), 'use ' + ', '.join(x for _, x in hits[target(p)]))
            t = t[:m.start()] + blank(m.group()) + t[m.end():]
        for m in PATH.finditer(t):
            here = here_at(m.start())
            add(resolve([m.group(1)] + re.findall(r'\w+', m.group(2)), here, scopes.get(here, {})), m.start(), m.group())
    return mods, tests, refs, doubts

def name(m):
    return 'bin' if m == BIN else '::'.join(m) or '(crate)'

def sccs(nodes, edges):
    """Tarjan: the strongly connected components of more than one node."""
    index, low, stack, out = {}, {}, [], []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = stack[stack.index(v):]
            del stack[stack.index(v):]
            out.extend([sorted(comp)] if len(comp) > 1 else [])
    for v in sorted(nodes):
        if v not in index:
            visit(v)
    return out

def cycle_through(comp, edges):
    """A shortest cycle from comp[0] back to itself inside comp."""
    prev, queue = {}, [comp[0]]
    for v in queue:
        for w in sorted(edges.get(v, ())):
            if w == comp[0]:
                path = [v]
                while path[-1] != comp[0]:
                    path.append(prev[path[-1]])
                return path[::-1] + [comp[0]]
            if w in comp and w not in prev:
                prev[w] = v
                queue.append(w)

def evidence(lines, keep, indent='\n        '):
    lines = list(dict.fromkeys(lines))
    return ''.join(indent + x for x in lines[:keep]) + (f"{indent}... {len(lines) - keep} more" if len(lines) > keep else '')

def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--root', default=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    ap.add_argument('--dot', metavar='FILE', help='write the room graph as Graphviz')
    ap.add_argument('--json', action='store_true', help='print edges and problems as JSON')
    ap.add_argument('--strict', action='store_true', help='fail on cycles through a room\'s mod.rs too')
    args = ap.parse_args()
    mods, tests, refs, doubts = analyse(args.root)
    room = lambda m: name(m).split('::')[0]
    rooms = sorted({room(m) for m in mods - tests - {()}} | {room(m) for e in refs for m in e})
    room_refs, room_pairs, fedges, frefs = defaultdict(list), defaultdict(set), defaultdict(dict), {}
    for (a, b), lines in refs.items():
        if room(a) != room(b):
            room_refs[(room(a), room(b))] += lines
            room_pairs[(room(a), room(b))].add((a, b))
        else:
            fedges[room(a)].setdefault(name(a), set()).add(name(b))
            frefs[(name(a), name(b))] = lines
    redges, order = defaultdict(set), {r: i for i, r in enumerate(LAYERS)}
    for a, b in room_refs:
        redges[a].add(b)
    up = {(a, b) for a, b in room_refs if a != 'bin' and a in order and b in order and order[a] < order[b]}
    problems, bad, notes = [], set(), []
    for comp in sccs(rooms, redges):
        inside = sorted((a, b) for a, b in room_refs if a in comp and b in comp)
        bad.update(inside)
        problems.append(f"room cycle {' -> '.join(cycle_through(comp, redges))}; edges inside {{{', '.join(comp)}}}:" + ''.join(
            f"\n    {a} -> {b} ({len(room_refs[(a, b)])} refs{', upward' if (a, b) in up else ''}):"
            + evidence(room_refs[(a, b)], 3) for a, b in inside))
    for r in sorted(fedges):
        nodes = set(fedges[r]) | {x for v in fedges[r].values() for x in v}
        for comp in sccs(nodes, fedges[r]):
            inner = {a: (v & set(comp)) - {r} for a, v in fedges[r].items() if a in comp and a != r}
            subs = sccs(set(inner), inner) if r in comp else []
            if r in comp and not subs and not args.strict:
                notes.append(f"through mod.rs only: {r} {{{', '.join(comp)}}}")
                continue
            text = f"file cycle in {r} {{{', '.join(comp)}}}"
            for c in [comp] + subs:
                cyc = cycle_through(c, fedges[r])
                text += f"\n  {'cycle' if c is comp else 'without ' + r + ' (mod.rs), still'}: {' -> '.join(cyc)}" + ''.join(
                    f"\n    {a} -> {b}:" + evidence(frefs[(a, b)], 2) for a, b in zip(cyc, cyc[1:]))
            problems.append(text)
    problems += [f"room {r} is not in LAYERS" for r in rooms if r not in order and r != 'bin']
    for a, b in sorted(up):
        problems.append(f"upward arrow {a} -> {b} ({a} is below {b} in LAYERS):" + evidence(room_refs[(a, b)], 6))
    if args.dot:
        with open(args.dot, 'w', encoding='utf-8') as fh:
            fh.write('digraph rooms {\n  rankdir=BT;\n  node [shape=box];\n' + ''.join(f'  "{r}";\n' for r in rooms))
            for (a, b), lines in sorted(room_refs.items()):
                red = ', color=red, fontcolor=red' if (a, b) in bad | up else ''
                fh.write(f'  "{a}" -> "{b}" [label="{len(lines)}"{red}];\n')
            fh.write('}\n')
    if args.json:
        json.dump({'layers': LAYERS,
                   'rooms': [{'from': a, 'to': b, 'refs': len(v), 'file_edges': len(room_pairs[(a, b)])}
                             for (a, b), v in sorted(room_refs.items())],
                   'files': [{'from': name(a), 'to': name(b), 'refs': len(v), 'at': v} for (a, b), v in sorted(refs.items())],
                   'problems': problems, 'doubts': doubts}, sys.stdout, indent=1)
        print()
        return 1 if problems else 0
    print(f"LAYERS (lowest first): {' < '.join(LAYERS)}\n\nRooms -> rooms they use (references/file edges):")
    for r in rooms:
        outs = sorted((b, len(v), len(room_pairs[(a, b)])) for (a, b), v in room_refs.items() if a == r)
        print(f"  {r:9} -> " + (', '.join(f"{b} {n}/{f}" for b, n, f in outs) or '-'))
    print("\nFiles within rooms (file -> files it uses, references):")
    for r in sorted(fedges):
        print(f"  [{r}]" + ''.join(f"\n    {a} -> {', '.join(f'{b} {len(frefs[(a, b)])}' for b in sorted(fedges[r][a]))}" for a in sorted(fedges[r])))
    print(''.join(f"doubt: {d}\n" for d in doubts) + ''.join(f"\n{n}" for n in notes) + f"\n\n{len(problems)} problem(s)" + ''.join(f"\n- {p}" for p in problems))
    return 1 if problems else 0

if __name__ == '__main__':
    sys.exit(main())
