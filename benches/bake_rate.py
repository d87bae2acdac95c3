#!/usr/bin/env python3
"""Whole-bake effective rate against the raw ray rate, measured in pairs.

usage: python3 benches/bake_rate.py [MESH] [--window Glass_Gray] [--order 3] [--rays 64]
                                    [--bounces 3] [--threads 2] [--pairs 5]

Whether the bake keeps up with its tracer: a bake's effective rate (rays traced / bake seconds,
from `prtbake bake --json`) within 20% of the raw closest-hit rate on the
same mesh (`examples/trace_rate`, median of 3 runs). This VM's speed drifts
by 10-20% over minutes, so each bake is paired with a raw run just before
it, and the ratio is taken per pair. Prints every pair, then min / median /
max of the ratios. MESH defaults to the Ferrari in ../shared/data.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FERRARI = os.path.join(ROOT, "..", "shared", "data", "car-ferrari458", "ferrari_nodraco.glb")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("mesh", nargs="?", default=FERRARI)
    ap.add_argument("--window", default="Glass_Gray", help="window material pattern ('' for open mode)")
    ap.add_argument("--order", type=int, default=3)
    ap.add_argument("--rays", type=int, default=64)
    ap.add_argument("--bounces", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--pairs", type=int, default=5)
    a = ap.parse_args()
    if not os.path.exists(a.mesh):
        sys.exit(f"{a.mesh}: not found (pass a mesh, or put ../shared/data beside the repo)")
    subprocess.run(["cargo", "build", "--release", "-q", "--bin", "prtbake", "--example", "trace_rate"], cwd=ROOT, check=True)
    prtbake = os.path.join(ROOT, "target", "release", "prtbake")
    trace_rate = os.path.join(ROOT, "target", "release", "examples", "trace_rate")
    ratios = []
    with tempfile.TemporaryDirectory() as tmp:
        for pair in range(1, a.pairs + 1):
            out = subprocess.run([trace_rate, a.mesh, "--runs", "3", "--threads", str(a.threads)],
                                 capture_output=True, text=True, check=True).stdout
            raw = next(float(line.split()[6]) for line in out.splitlines() if line.startswith("closest_hit"))
            bake = [prtbake, "bake", a.mesh, "--order", str(a.order), "--rays", str(a.rays), "--bounces", str(a.bounces),
                    "--adaptive", "0", "--threads", str(a.threads), "-o", os.path.join(tmp, "bake.prtb"), "--json"]
            if a.window:
                bake += ["--window", a.window]
            stats = json.loads(subprocess.run(bake, capture_output=True, text=True, check=True).stdout)["stats"]
            effective = stats["rays_traced"] / stats["seconds"] / 1e6
            ratios.append(effective / raw)
            per_bounce = stats["seconds_per_bounce"]
            print(f"pair {pair}: raw {raw:.2f} Mrays/s, bake {stats['seconds']:.2f} s (bounce 0 {per_bounce[0]:.2f} s, "
                  f"later bounces {sum(per_bounce[1:]):.2f} s), effective {effective:.2f} Mrays/s = {100 * ratios[-1]:.0f}% of raw",
                  flush=True)
    print(f"effective / raw over {len(ratios)} pairs: min {100 * min(ratios):.0f}%  median "
          f"{100 * statistics.median(ratios):.0f}%  max {100 * max(ratios):.0f}%")


if __name__ == "__main__":
    main()
