#!/usr/bin/env python3
"""prtbake's module graph, read from the source alone, checked against LAYERS.

Usage: scripts/import_graph.py [--root DIR] [--dot FILE] [--json]

Modules. Every file under src/ is one: src/lib.rs is the crate root `(crate)`,
src/x.rs and src/x/mod.rs are `x`, src/x/y.rs is `x::y`. bin/prtbake.rs is a
second root, `bin`, above every layer (it may use anything). A room is a
top-level module (bake, trace, mesh, ...).

Test code is left out (tests may reach anywhere): files named *tests*.rs or
test_support.rs, files declared by `#[cfg(test)] mod x;`, files with
`#![cfg(test)]`, any `mod tests { ... }`, and whatever item or statement
follows a `#[cfg(test)]` (test-only counters and helpers too).

Before reading paths, comments (`//`, nested `/* */`, doc comments) and
string, byte and char literals (raw ones too) are blanked; lifetimes and
labels (`'a`) are not char literals and stay.

References: `use` trees (grouped, nested, multi-line, `self`, `as`, `*`) and
paths anywhere in code that start with `crate::`, `self::`, `super::`
(repeated), `prtbake::` (bin only), the name of a child module, or a name a
`use` bound to a module (`use crate::sh; sh::basis::x` reaches `sh::basis`;
a glob of a module binds its child modules). Inside an inline `mod m { }`,
`self` and `super` are relative to `m`. A reference goes to the longest
module prefix of its absolute path: `crate::bake::transfer::Plan` is
`bake::transfer`, `crate::bake::Scene` is `bake` (a re-export through the
parent). References to one's own module and `mod x;` declarations are not
edges. So `pub use child::X` in a mod.rs is an edge parent -> child, a
child's `use super::Y` is child -> parent, and only both make a cycle.

Exit 1, listing each problem with the lines behind it, on: a cycle between
rooms; a cycle between files of one room (each strongly connected component
with one cycle through it); an arrow from a room to a higher room in LAYERS
(or a room missing from LAYERS). Exit 0 when clean.

Not understood: paths built by macros, `#[path]` (only used for test files),
function-local `use` scoping (a `use` binds in its whole module), and
`#[cfg(test)]` on a struct field or match arm (it would blank to the next `;`).
"""
import argparse, json, os, re, sys
from collections import defaultdict

# Lowest first: a room may use only rooms before it. `bin` sits above all.
LAYERS = ["files", "sh", "sampling", "mesh", "sky", "brdf", "fixtures", "clean", "trace", "bake",
          "shards", "bundle", "budget", "refine", "verify", "panel", "chart", "view", "cli"]

TOK = re.compile(r'//|/\*|(?<!\w)[bc]?r(#*)"|"|\'')
CHAR = re.compile(r"'(?:\\(?:x[0-9a-fA-F]{2}|u\{[0-9a-fA-F]{1,6}\}|.)|[^\\'\n])'")
CFG_TEST = re.compile(r'#\s*\[\s*cfg\s*\(\s*test\s*\)\s*\]')
INLINE_MOD = re.compile(r'\bmod\s+(\w+)\s*\{')
DECL_MOD = re.compile(r'\bmod\s+(\w+)\s*;')
USE = re.compile(r'\buse\s+([^;]*);')
PATH = re.compile(r'(?<![\w:])([A-Za-z_]\w*)((?:\s*::\s*[A-Za-z_]\w*)+)')
TEST_FILE = re.compile(r'.*tests.*\.rs|test_support\.rs')


def blank(s):
    return re.sub(r'[^\n]', ' ', s)


def strip(src):
    """Blank comments and literals, keeping every offset and newline."""
    out, i, n = [], 0, len(src)
    while (m := TOK.search(src, i)):
        out.append(src[i:m.start()])
        s, t = m.start(), m.group()
        if t == '//':
            e = src.find('\n', s)
            e = n if e < 0 else e
        elif t == '/*':
            d, e = 1, s + 2
            while e < n and d:
                step = src[e:e + 2]
                d, e = (d + 1, e + 2) if step == '/*' else (d - 1, e + 2) if step == '*/' else (d, e + 1)
        elif m.group(1) is not None:  # raw string r#"..."#
            e = src.find('"' + m.group(1), m.end())
            e = n if e < 0 else e + 1 + len(m.group(1))
        elif t == '"':
            e = s + 1
            while e < n and src[e] != '"':
                e += 2 if src[e] == '\\' else 1
            e += 1
        else:
            c = CHAR.match(src, s)
            if not c:  # a lifetime or a label
                out.append("'")
                i = s + 1
                continue
            e = c.end()
        out.append(blank(src[s:e]))
        i = e
    out.append(src[i:])
    return ''.join(out)


def brace_end(t, i):
    """Index after the `}` matching the `{` at i."""
    d = 0
    for j in range(i, len(t)):
        d += (t[j] == '{') - (t[j] == '}')
        if d == 0:
            return j + 1
    return len(t)


def item_end(t, i):
    """End of the item or statement starting at i: its `;` or its `{ }` block."""
    d = 0
    for j in range(i, len(t)):
        c = t[j]
        if c in '([':
            d += 1
        elif c in ')]':
            d -= 1
        elif d == 0 and c == ';':
            return j + 1
        elif d == 0 and c == '{':
            return brace_end(t, j)
    return len(t)


def drop_tests(t):
    """Blank test-only items; return the text and child modules declared for tests."""
    test_children = set()
    for pat, whole in ((CFG_TEST, True), (re.compile(r'\bmod\s+tests\s*\{'), False)):
        while (m := pat.search(t)):
            e = item_end(t, m.end()) if whole else brace_end(t, m.end() - 1)
            test_children.update(DECL_MOD.findall(t[m.start():e]))
            t = t[:m.start()] + blank(t[m.start():e]) + t[e:]
    return t, test_children


def use_paths(body):
    """Expand a use tree into (segments, bound name; '*' for a glob)."""
    toks, pos = re.findall(r'::|[{},*]|\w+', body), 0

    def tree(prefix):
        nonlocal pos
        segs, out = list(prefix), []
        if toks[pos] == '::':
            pos += 1
            if not prefix:
                segs.append('::')  # ::extern_crate
        while True:
            t = toks[pos]
            if t == '{':
                pos += 1
                while toks[pos] != '}':
                    out += tree(segs)
                    pos += toks[pos] == ','
                pos += 1
                return out
            if t == '*':
                pos += 1
                return out + [(segs, '*')]
            segs.append(t)
            pos += 1
            if pos < len(toks) and toks[pos] == '::':
                pos += 1
                continue
            break
        if segs[-1] == 'self':
            segs = segs[:-1]
        name = segs[-1] if segs else None
        if pos < len(toks) and toks[pos] == 'as':
            name, pos = toks[pos + 1], pos + 2
        return out + [(segs, name)]
    return tree([])


def load(root):
    files = {}  # module tuple (or ('<bin>',)) -> (relative path, stripped text)
    for d, _, names in os.walk(os.path.join(root, 'src')):
        for f in names:
            if f.endswith('.rs'):
                rel = os.path.relpath(os.path.join(d, f), root)
                parts = rel[4:-3].split(os.sep)
                mod = tuple(parts[:-1]) if parts[-1] in ('mod', 'lib') else tuple(parts)
                files[mod] = rel
    bin_rel = os.path.join('bin', 'prtbake.rs')
    if os.path.exists(os.path.join(root, bin_rel)):
        files[('<bin>',)] = bin_rel
    texts, tests = {}, set()
    for mod, rel in files.items():
        with open(os.path.join(root, rel), encoding='utf-8') as fh:
            raw = strip(fh.read())
        if TEST_FILE.fullmatch(os.path.basename(rel)) or re.search(r'#!\s*\[\s*cfg\s*\(\s*test', raw):
            tests.add(mod)
        texts[mod], kids = drop_tests(raw)
        tests.update(mod + (k,) for k in kids)
    return files, texts, tests


def analyse(root):
    files, texts, tests = load(root)
    mods, doubts = set(files) - {('<bin>',)}, []
    refs = defaultdict(list)  # (from, to) -> ["path:line: text"]
    for src in sorted(m for m in texts if m not in tests):
        t, rel, is_bin = texts[src], files[src], src == ('<bin>',)
        line_of = lambda p: t.count('\n', 0, p) + 1
        regions = [(m.start(), brace_end(t, m.end() - 1), m.group(1)) for m in INLINE_MOD.finditer(t)]
        here_at = lambda p: (() if is_bin else src) + tuple(n for s, e, n in regions if s <= p < e)

        def resolve(segs, here, scope):
            h = segs[0]
            if (h == 'crate' and not is_bin) or (h == 'prtbake' and is_bin):
                return tuple(segs[1:])
            if h in ('self', 'super') and not is_bin:
                k = 0
                while k < len(segs) and segs[k] == 'super':
                    k += 1
                return (here[:len(here) - k] if k else here) + tuple(segs[max(k, h == 'self'):])
            return scope[h] + tuple(segs[1:]) if h in scope else None

        def target(path):
            k = max(k for k in range(len(path) + 1) if path[:k] in mods or path[:k] in tests or k == 0)
            return path[:k]

        def add(here, path, pos, what):
            if path is None:
                return
            tgt = target(path)
            if tgt in tests:
                doubts.append(f"{rel}:{line_of(pos)}: non-test code names test module {'::'.join(tgt)}")
            elif tgt != src and (tgt or () in mods):
                refs[(src, tgt)].append(f"{rel}:{line_of(pos)}: {' '.join(what.split())[:100]}")

        uses = [(m, here_at(m.start())) for m in USE.finditer(t)]
        scopes = {}
        for here in {h for _, h in uses} | {here_at(0)} | {here_at(s) for s, _, _ in regions}:
            scope = {} if is_bin else {m[-1]: m for m in mods | tests if len(m) == len(here) + 1 and m[:-1] == here}
            for _ in range(2):  # twice: a use may name a module bound by another use
                for m, h in uses:
                    if h != here:
                        continue
                    try:
                        for segs, name in use_paths(m.group(1)):
                            p = resolve(segs, here, scope) if segs else None
                            if p is None or p not in mods | tests:
                                continue
                            if name == '*':
                                scope.update({c[-1]: c for c in mods if c[:-1] == p and len(c) == len(p) + 1})
                            elif name:
                                scope[name] = p
                    except IndexError:
                        doubts.append(f"{rel}:{line_of(m.start())}: could not parse `use {m.group(1)[:60]}`")
            scopes[here] = scope
        for m, here in uses:
            try:
                for segs, _ in use_paths(m.group(1)):
                    add(here, resolve(segs, here, scopes[here]) if segs else None, m.start(), 'use ' + '::'.join(segs))
            except IndexError:
                pass
        for m, _ in uses:
            t = t[:m.start()] + blank(m.group()) + t[m.end():]
        for m in PATH.finditer(t):
            here = here_at(m.start())
            segs = [m.group(1)] + re.findall(r'\w+', m.group(2))
            add(here, resolve(segs, here, scopes.get(here, {})), m.start(), m.group())
    return mods, tests, refs, doubts


def name(m):
    return 'bin' if m == ('<bin>',) else '::'.join(m) or '(crate)'


def room(m):
    return name(m).split('::')[0]


def sccs(nodes, edges):
    """Tarjan: strongly connected components with more than one node."""
    index, low, stack, on, out, n = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = n[0]
        n[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))
    for v in sorted(nodes):
        if v not in index:
            visit(v)
    return out


def cycle_through(comp, edges):
    """Shortest cycle from comp[0] back to itself inside comp."""
    start, prev, queue = comp[0], {}, [comp[0]]
    for v in queue:
        for w in sorted(edges.get(v, ())):
            if w == start:
                path = [v]
                while path[-1] != start:
                    path.append(prev[path[-1]])
                return path[::-1] + [start]
            if w in comp and w not in prev:
                prev[w] = v
                queue.append(w)
    return comp


def evidence(lines, keep=4):
    more = f"\n        ... {len(lines) - keep} more" if len(lines) > keep else ''
    return ''.join(f"\n        {x}" for x in lines[:keep]) + more


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--root', default=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    ap.add_argument('--dot', metavar='FILE', help='write the room graph as Graphviz')
    ap.add_argument('--json', action='store_true', help='print edges and problems as JSON')
    args = ap.parse_args()
    mods, tests, refs, doubts = analyse(args.root)
    rooms = sorted({room(m) for m in mods - tests} | {room(a) for a, _ in refs})
    room_refs, room_pairs, file_edges = defaultdict(list), defaultdict(set), defaultdict(dict)
    for (a, b), lines in refs.items():
        ra, rb = room(a), room(b)
        if ra != rb:
            room_refs[(ra, rb)] += lines
            room_pairs[(ra, rb)].add((a, b))
        else:
            file_edges[ra].setdefault(name(a), set()).add(name(b))
    redges = defaultdict(set)
    for a, b in room_refs:
        redges[a].add(b)
    problems, bad = [], set()
    for comp in sccs(rooms, redges):
        cyc = cycle_through(comp, redges)
        bad.update(zip(cyc, cyc[1:]))
        problems.append(f"room cycle {{{', '.join(comp)}}}: {' -> '.join(cyc)}" + ''.join(
            f"\n    {a} -> {b}:{evidence(room_refs[(a, b)], 2)}" for a, b in zip(cyc, cyc[1:])))
    for r in sorted(file_edges):
        fe = file_edges[r]
        for comp in sccs(set(fe) | {x for v in fe.values() for x in v}, fe):
            cyc = cycle_through(comp, fe)
            by = {name(a) + '>' + name(b): v for (a, b), v in refs.items()}
            problems.append(f"file cycle in {r} {{{', '.join(comp)}}}: {' -> '.join(cyc)}" + ''.join(
                f"\n    {a} -> {b}:{evidence(by[a + '>' + b], 2)}" for a, b in zip(cyc, cyc[1:])))
    order = {r: i for i, r in enumerate(LAYERS)}
    for r in rooms:
        if r not in order and r != 'bin':
            problems.append(f"room {r} is not in LAYERS")
    for (a, b), lines in sorted(room_refs.items()):
        if a != 'bin' and a in order and b in order and order[a] < order[b]:
            bad.add((a, b))
            problems.append(f"upward arrow {a} -> {b} ({a} is below {b} in LAYERS):{evidence(lines)}")
    if args.dot:
        with open(args.dot, 'w', encoding='utf-8') as fh:
            fh.write('digraph rooms {\n  rankdir=BT;\n  node [shape=box];\n')
            for (a, b), lines in sorted(room_refs.items()):
                color = ', color=red, fontcolor=red' if (a, b) in bad else ''
                fh.write(f'  "{a}" -> "{b}" [label="{len(lines)}"{color}];\n')
            fh.write('}\n')
    if args.json:
        json.dump({'layers': LAYERS,
                   'rooms': [{'from': a, 'to': b, 'refs': len(v), 'file_edges': len(room_pairs[(a, b)])}
                             for (a, b), v in sorted(room_refs.items())],
                   'files': [{'from': name(a), 'to': name(b), 'refs': len(v), 'at': v}
                             for (a, b), v in sorted(refs.items())],
                   'problems': problems, 'doubts': doubts}, sys.stdout, indent=1)
        print()
    else:
        print(f"LAYERS (lowest first): {' < '.join(LAYERS)}\n\nRoom graph (references / file edges):")
        for r in rooms:
            outs = sorted((b, len(v), len(room_pairs[(a, b)])) for (a, b), v in room_refs.items() if a == r)
            print(f"  {r:9} -> " + (', '.join(f"{b} {n}/{f}" for b, n, f in outs) or '-'))
        print("\nFiles within rooms:")
        for r in sorted(file_edges):
            print(f"  [{r}]")
            for a in sorted(file_edges[r]):
                print(f"    {a} -> {', '.join(sorted(file_edges[r][a]))}")
        for d in doubts:
            print(f"doubt: {d}")
        print(f"\n{len(problems)} problem(s)" + ''.join(f"\n- {p}" for p in problems))
    return 1 if problems else 0


if __name__ == '__main__':
    sys.exit(main())
