#!/usr/bin/env python3
"""Trace the same rays with prtbake and with Embree (PyPI `embreex`), side by side.

usage: python3 benches/embree_compare.py [MESH|cabin] [--runs 3] [--rays-per-point 64] [--points 16384] [--share G] [--sort]

It runs `cargo run --release --example trace_rate` (which measures prtbake and
exports the exact rays it traced) and traces those rays with Embree, on 1 and
2 threads, alternating the two tracers run by run, and prints Mrays/s
(min/median/max over the runs) and the ratio prtbake / Embree. Optional for users: on first use it creates a virtualenv
.venv-embree/ with embreex and numpy (from PyPI).
"""
import argparse
import os
import re
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
VENV = os.path.join(ROOT, ".venv-embree")


def ensure_embree():
    try:
        import embreex  # noqa: F401
        import numpy  # noqa: F401
        return
    except ImportError:
        pass
    python = os.path.join(VENV, "bin", "python")
    if os.environ.get("PRTBAKE_EMBREE_VENV") != "1":
        if not os.path.exists(python):
            print("creating", VENV, "with embreex and numpy ...", file=sys.stderr)
            subprocess.check_call([sys.executable, "-m", "venv", VENV])
            subprocess.check_call([python, "-m", "pip", "install", "-q", "embreex", "numpy"])
        os.environ["PRTBAKE_EMBREE_VENV"] = "1"
        os.execv(python, [python] + sys.argv)
    sys.exit("embreex is not importable even in " + VENV)


def prtbake_rates(args, threads, export_dir, runs):
    cmd = ["cargo", "run", "--quiet", "--release", "--example", "trace_rate", "--", args.mesh,
           "--runs", str(runs), "--threads", str(threads),
           "--rays-per-point", str(args.rays_per_point), "--points", str(args.points)] + args.trace_rate_args
    if export_dir:
        cmd += ["--export", export_dir]
    out = subprocess.check_output(cmd, cwd=ROOT, text=True)
    print(out.strip(), file=sys.stderr)
    rates = {}
    for name in ("occlusion", "closest_hit"):
        m = re.search(name + r".*min ([\d.]+)\s+median ([\d.]+)\s+max ([\d.]+)", out)
        rates[name] = tuple(float(x) for x in m.groups())
    return rates


def embree_rates(export_dir, runs, threads):
    import numpy as np
    from concurrent.futures import ThreadPoolExecutor
    from embreex import rtcore_scene, mesh_construction
    tris = np.fromfile(os.path.join(export_dir, "triangles.f32"), dtype=np.float32).reshape(-1, 3, 3)
    rays = np.fromfile(os.path.join(export_dir, "rays.f32"), dtype=np.float32).reshape(-1, 2, 3)
    origins = np.ascontiguousarray(rays[:, 0, :])
    directions = np.ascontiguousarray(rays[:, 1, :])
    start = time.perf_counter()
    scene = rtcore_scene.EmbreeScene()
    mesh_construction.TriangleMesh(scene, tris)
    scene.run(origins[:1], directions[:1], query="OCCLUDED")  # Embree builds lazily: force the build.
    build = time.perf_counter() - start
    rates = {}
    chunks = np.array_split(np.arange(len(origins)), threads * 8)
    for name, query in (("occlusion", "OCCLUDED"), ("closest_hit", "INTERSECT")):
        samples = []
        for _ in range(runs):
            t = time.perf_counter()
            with ThreadPoolExecutor(threads) as pool:
                list(pool.map(lambda idx: scene.run(origins[idx], directions[idx], query=query), chunks))
            samples.append(len(origins) / (time.perf_counter() - t) / 1e6)
        samples.sort()
        rates[name] = (samples[0], samples[len(samples) // 2], samples[-1])
    return rates, build, len(origins)


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("mesh", nargs="?", default="cabin")
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--rays-per-point", type=int, default=64)
    p.add_argument("--points", type=int, default=16384)
    p.add_argument("--share", type=int, help="trace_rate --share G: G neighbouring points share one direction set")
    p.add_argument("--sort", action="store_true", help="trace_rate --sort: a point's rays in Morton order of their Sobol pairs")
    args = p.parse_args()
    args.trace_rate_args = (["--share", str(args.share)] if args.share else []) + (["--sort"] if args.sort else [])
    ensure_embree()
    names = ("occlusion", "closest_hit")
    ours = {t: {n: [] for n in names} for t in (1, 2)}
    theirs = {t: {n: [] for n in names} for t in (1, 2)}
    with tempfile.TemporaryDirectory() as tmp:
        # Rounds interleave the two tracers (one run each per thread count), so
        # a slow spell on a shared machine hits both alike.
        for round_index in range(args.runs):
            for threads in (1, 2):
                export = tmp if round_index == 0 and threads == 1 else None
                a = prtbake_rates(args, threads, export, 1)
                b, build, count = embree_rates(tmp, 1, threads)
                for name in names:
                    ours[threads][name].append(a[name][1])
                    theirs[threads][name].append(b[name][1])
    summary = lambda xs: (min(xs), sorted(xs)[len(xs) // 2], max(xs))
    fmt = lambda r: "%.2f / %.2f / %.2f" % r
    print("| query | threads | prtbake Mrays/s (min/med/max) | Embree Mrays/s (min/med/max) | ratio (median) |")
    print("|---|---|---|---|---|")
    for threads in (1, 2):
        for name in names:
            a, b = summary(ours[threads][name]), summary(theirs[threads][name])
            print("| %s | %d | %s | %s | %.2f |" % (name, threads, fmt(a), fmt(b), a[1] / b[1]))
    print("(%d rays, %d interleaved rounds; Embree scene build %.3fs)" % (count, args.runs, build), file=sys.stderr)

if __name__ == "__main__":
    main()
