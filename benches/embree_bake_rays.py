#!/usr/bin/env python3
"""A whole bake's seconds beside Embree's seconds for the very rays it traced.

usage: python3 benches/embree_bake_rays.py MESH [--runs 3] [--threads 2] [-- BAKE ARGS...]
  e.g. python3 benches/embree_bake_rays.py f0.glb -- --window Glass_Gray

Each round, on the same machine one after another:
  1. `prtbake bake MESH BAKE ARGS`, timed (wall clock; the JSON's transfer
     seconds and rays traced);
  2. the same rays alone through prtbake's batch queries (`trace_rate --rays`,
     each batch with the query it was traced with);
  3. the same rays through Embree 4 (PyPI `embreex`, rtcIntersect1 /
     rtcOccluded1 per ray, robust mode off), with each ray's reach.
The rays come from one more bake run with PRTBAKE_LOG_RAYS set (its bundle
must equal the timed one's: the log changes nothing). Prints min / median /
max seconds per row. Creates .venv-embree as benches/embree_compare.py does.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from embree_compare import ROOT, ensure_embree  # noqa: E402

RECORD = 32  # bytes per logged ray: origin, direction, reach (f32), query (u32)


def bake(binary, mesh, args, out, log=None):
    env = dict(os.environ)
    if log:
        env["PRTBAKE_LOG_RAYS"] = log
    start = time.perf_counter()
    run = subprocess.run([binary, "bake", mesh, "-o", out, "--json"] + args, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if run.returncode != 0:
        sys.exit("bake failed:\n" + run.stderr)
    stats = json.loads(run.stdout)["stats"]
    return wall, stats["seconds"], stats["rays_traced"]


def prtbake_seconds(mesh, log, threads, export=None):
    cmd = [os.path.join(ROOT, "target", "release", "examples", "trace_rate"), mesh, "--rays", log,
           "--threads", str(threads), "--runs", "1"]
    if export:
        cmd += ["--export", export]
    out = subprocess.check_output(cmd, text=True)
    seconds = {}
    for line in out.splitlines():
        if line.startswith("logged "):
            kind = {"ClosestHit": "closest_hit", "Occlusion": "occlusion"}[line.split()[1]]
            seconds[kind] = float(line.split("median")[1].split()[0])
    return seconds


class EmbreeRays:
    def __init__(self, export_dir, log):
        import numpy as np
        from embreex import rtcore_scene, mesh_construction
        tris = np.fromfile(os.path.join(export_dir, "triangles.f32"), dtype=np.float32).reshape(-1, 3, 3)
        raw = np.fromfile(log, dtype=np.uint8)
        records = raw.view(np.float32).reshape(-1, RECORD // 4)
        query = raw.view(np.uint32).reshape(-1, RECORD // 4)[:, 7]
        self.batches = []
        for code, name, kind in ((0, "INTERSECT", "closest_hit"), (1, "OCCLUDED", "occlusion")):
            pick = query == code
            if pick.any():
                self.batches.append((kind, name, np.ascontiguousarray(records[pick, 0:3]), np.ascontiguousarray(records[pick, 3:6]),
                                     np.ascontiguousarray(records[pick, 6])))
        self.count = len(records)
        start = time.perf_counter()
        self.scene = rtcore_scene.EmbreeScene()
        mesh_construction.TriangleMesh(self.scene, tris)
        self.scene.run(records[:1, 0:3].copy(), records[:1, 3:6].copy(), query="OCCLUDED")  # Embree builds lazily.
        self.build = time.perf_counter() - start

    def seconds(self, threads):
        import numpy as np
        from concurrent.futures import ThreadPoolExecutor
        seconds = {}
        for kind, name, origins, directions, reach in self.batches:
            chunks = np.array_split(np.arange(len(origins)), threads * 64)
            start = time.perf_counter()
            with ThreadPoolExecutor(threads) as pool:
                list(pool.map(lambda idx: self.scene.run(origins[idx], directions[idx], dists=reach[idx], query=name), chunks))
            seconds[kind] = time.perf_counter() - start
        return seconds

    def counts(self):
        return {kind: len(origins) for kind, _, origins, _, _ in self.batches}


def main():
    argv = sys.argv[1:]
    bake_args = argv[argv.index("--") + 1:] if "--" in argv else []
    argv = argv[:argv.index("--")] if "--" in argv else argv
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("mesh")
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--threads", type=int, default=2)
    args = p.parse_args(argv)
    ensure_embree()
    subprocess.check_call(["cargo", "build", "--quiet", "--release", "--bin", "prtbake", "--example", "trace_rate"], cwd=ROOT)
    binary = os.path.join(ROOT, "target", "release", "prtbake")
    mesh = os.path.abspath(args.mesh)
    bake_args = bake_args + ["--threads", str(args.threads)]
    rows = {"bake": [], "transfer": []}
    with tempfile.TemporaryDirectory() as tmp:
        log = os.path.join(tmp, "rays.log")
        bake(binary, mesh, bake_args, os.path.join(tmp, "logged.prtb"), log)
        prtbake_seconds(mesh, log, args.threads, export=tmp)
        embree = EmbreeRays(tmp, log)
        for _ in range(args.runs):
            wall, transfer, rays = bake(binary, mesh, bake_args, os.path.join(tmp, "timed.prtb"))
            with open(os.path.join(tmp, "timed.prtb"), "rb") as a, open(os.path.join(tmp, "logged.prtb"), "rb") as b:
                if a.read() != b.read():
                    sys.exit("the logged bake's bundle differs from the timed one's: the rays are not the same")
            if rays != embree.count:
                sys.exit("the bake traced %d rays, the log holds %d" % (rays, embree.count))
            rows["bake"].append(wall)
            rows["transfer"].append(transfer)
            for tracer, seconds in (("prtbake", prtbake_seconds(mesh, log, args.threads)), ("embree", embree.seconds(args.threads))):
                for kind, s in seconds.items():
                    rows.setdefault((tracer, kind), []).append(s)
                rows.setdefault((tracer, "all"), []).append(sum(seconds.values()))
    summary = lambda xs: (min(xs), sorted(xs)[len(xs) // 2], max(xs))
    counts = embree.counts()
    counts["all"] = embree.count
    print("| %s, %d threads | rays | seconds min / median / max | Mrays/s (median) | Embree / prtbake (median s) |" % (os.path.basename(mesh), args.threads))
    print("|---|---:|---|---:|---:|")
    for key, label in (("bake", "prtbake bake, whole process (wall)"), ("transfer", "prtbake bake, transfer (JSON stats.seconds)")):
        lo, med, hi = summary(rows[key])
        print("| %s | %d | %.2f / %.2f / %.2f | %.2f | |" % (label, embree.count, lo, med, hi, embree.count / med / 1e6))
    for kind in [k for k in ("closest_hit", "occlusion", "all") if ("prtbake", k) in rows]:
        ours, theirs = summary(rows[("prtbake", kind)]), summary(rows[("embree", kind)])
        for tracer, r in (("prtbake, the bake's rays alone (trace_rate --rays)", ours), ("Embree, the same rays", theirs)):
            ratio = "%.2f" % (theirs[1] / ours[1]) if tracer.startswith("Embree") else ""
            print("| %s: %s | %d | %.2f / %.2f / %.2f | %.2f | %s |" % (kind, tracer, counts[kind], r[0], r[1], r[2], counts[kind] / r[1] / 1e6, ratio))
    print("(bake args: %s; Embree scene build %.3f s; %d rounds)" % (" ".join(bake_args), embree.build, args.runs), file=sys.stderr)


if __name__ == "__main__":
    main()
