#!/usr/bin/env python3
"""Seconds against error for prtbake and Mitsuba 3 on the same quantity
(each vertex's hat-weighted one-ring mean of the DC transfer), and the
seconds each needs for the same error (docs/speed-accuracy.md).

usage: benches/mitsuba_equal_error.py DIR REF_B0.csv REF_B3.csv [--vertices N] [--probe-rings PATH]

DIR holds, for B in 0 and 3, Mitsuba runs `mi-bB-pK.csv` (+ `.log`, from
benches/mitsuba_probe.py with --points K --rays K) and prtbake bakes
`pb-bB-rR.prtb` (+ `.log`, the bake's text output); REF_B*.csv are
independent high-sample Mitsuba references of the same vertices. Error is
the relative RMS difference from the reference with the reference's own
noise removed in quadrature. Mitsuba samples only the chosen one-rings:
its tracing time is scaled to all N vertices (--vertices, default the
grey-white room's 88,997), its load and scene set-up counted once.
"""
import argparse, csv, math, re, subprocess, glob, os
ap = argparse.ArgumentParser()
ap.add_argument('dir'); ap.add_argument('ref0'); ap.add_argument('ref3')
ap.add_argument('--vertices', type=int, default=88997)
ap.add_argument('--probe-rings', default='target/release/examples/probe_rings')
args = ap.parse_args()
probe = os.path.abspath(args.probe_rings)
REF = {0: os.path.abspath(args.ref0), 3: os.path.abspath(args.ref3)}
VERTICES = args.vertices
os.chdir(args.dir)
def load(p):
    d = {}
    for row in csv.reader(open(p)):
        if row[0] == 'id': continue
        i, m, s, u = int(row[0]), float(row[1]), float(row[2]), int(row[3])
        if u >= 2 and math.isfinite(s): d[i] = (m, s)
    return d
def err(diff, noise):
    return math.sqrt(max(diff*diff - noise*noise, 0.0))
for B in (0, 3):
    ref = load(REF[B])
    rows = []
    for p in sorted(glob.glob(f'mi-b{B}-p*.csv'), key=lambda x: int(re.findall(r'p(\d+)', x)[0])):
        d = load(p)
        ids = [i for i in ref if i in d]
        diff2 = sum((d[i][0]-ref[i][0])**2 for i in ids); ref2 = sum(ref[i][0]**2 for i in ids); n2 = sum(ref[i][1]**2 for i in ids)
        log = open(p.replace('.csv', '.log')).read()
        total = float(re.findall(r'total ([0-9.]+) s', log)[-1]); nv = int(re.findall(r'^(\d+) vertices', log, re.M)[-1])
        pr = re.findall(r'p(\d+)', p)[0]
        tracing = float(re.findall(r'tracing ([0-9.]+) s', log)[-1])
        rows.append(('Mitsuba 3', f'{pr} points × {pr} rays per one-ring', total, total - tracing + tracing * VERTICES / nv, math.sqrt(diff2/ref2), math.sqrt(n2/ref2)))
    for b in sorted(glob.glob(f'pb-b{B}-r*.prtb'), key=lambda x: int(re.findall(r'r(\d+)', x)[0])):
        out = subprocess.run([probe, 'compare', b, REF[B]], capture_output=True, text=True).stdout
        cells = [c.strip() for c in out.strip().splitlines()[-1].split('|')[1:-1]]
        log = open(b.replace('.prtb', '.log')).read()
        t = float(re.findall(r'^time: ([0-9.]+) s', log, re.M)[-1])
        r = re.findall(r'r(\d+)', b)[0]
        rows.append(('prtbake', f'`--rays {r}`', t, t, float(cells[2]), float(cells[3])))
    print(f'\n### {B} bounces (reference: {os.path.basename(REF[B])})\n')
    print('| tool | setting | seconds measured | seconds for all 88,997 vertices | difference | reference noise | error (noise removed) |')
    print('|---|---|---:|---:|---:|---:|---:|')
    for tool, s, t, tall, diff, noise in rows:
        print(f'| {tool} | {s} | {t:.1f} | {tall:.0f} | {diff:.4f} | {noise:.4f} | {err(diff, noise):.4f} |')
    for target in (0.10, 0.05):
        at = {}
        for tool in ('prtbake', 'Mitsuba 3'):
            pts = [(r[3], err(r[4], r[5])) for r in rows if r[0] == tool]
            at[tool] = None
            for (t0, e0), (t1, e1) in zip(pts, pts[1:]):
                if e0 >= target >= e1 and e1 < e0:
                    a = math.log(e0 / e1) / math.log(t1 / t0) if t1 > t0 else float('inf')
                    at[tool] = t0 if a == float('inf') else t0 * (e0 / target) ** (1 / a)
                    break
        p, m = at['prtbake'], at['Mitsuba 3']
        print(f'equal error {target:.0%}: prtbake {p if p is None else round(p, 1)} s, Mitsuba {m if m is None else round(m)} s, ratio {None if not (p and m) else round(m / p, 1)}')
