#!/usr/bin/env python3
"""prtbake against Cycles on the grey-white room: time against error.

    python3 benches/cycles_compare.py [--out DIR] [--quick]

Optional for users; it needs ../shared/data/room-grey-white and Blender's
`bpy` from PyPI. bpy 4.5 LTS has CPython 3.11 wheels, which Debian 12's
python3 is (so does bpy 5.0.1; only 5.1 and later need CPython 3.13). The script installs bpy into
a virtualenv (target/cycles-venv) on its first run and re-runs itself there.

Both bake the same cleaned mesh (`prtbake clean` → OBJ, whose vertices are
the bundle's) per vertex, grey, open mode, under the same light: the
order-3 SH projection of sky19.exr (examples/sh_shade.rs, averaged over
RGB) plus the uniform light that lifts its minimum to zero (the sun makes
the projection ring negative below the horizon, and Cycles cannot emit
negative light), drawn for Cycles as a 512×256 equirectangular map in its axes.
- prtbake: `bake --order 3 --bounces 3 --channels 1 --quantize f32
  --threads 2`, shaded as Σ L_i t_i per vertex (per unit albedo).
- Cycles: `bake(type='DIFFUSE', pass_filter={'DIRECT', 'INDIRECT'})`
  into a float colour attribute on the points (no colour: per unit albedo),
  3 bounces (diffuse 3, all others 0), no denoising, no adaptive sampling,
  no clamping, 2 threads.
Errors are relative RMS over the vertices, sqrt(Σ (b − r)² / Σ r²).
- prtbake's: against its own converged bake (`--rays 256 --adaptive 3`;
  two seeds of it are compared to show how converged it is; the curves use
  a third seed, so they share no samples with it): total error, printed
  raw and without the reference's own noise (its two seeds' difference
  over √2, taken out in quadrature).
- Cycles': its noise, from two seeds at each sample count: the RMS
  difference over √2, on the scale of the mean of the two seeds at the
  most samples (one seed's values would put that seed's noise in the
  denominator). Cycles is unbiased, so that is its error against its own
  converged answer; a converged Cycles bake of this room takes hours here.
- The two answers against each other. The two tools define a vertex's
  value differently: prtbake's is the hat-weighted mean over its one-ring,
  Cycles' the value at the vertex (each corner evaluated just inside its
  triangle, the corners averaged). Where a vertex's one-ring lies within
  3 cm of it ("free" vertices) the two agree, so the comparison is made
  there and on all vertices apart: prtbake's reference against the mean of
  Cycles' two seeds at the most samples, with that mean's own noise (half
  the two seeds' difference) taken out in quadrature.
Seconds are wall time of the bake: prtbake's whole process, Cycles'
`bpy.ops.object.bake` (scene already built; the first call's BVH build included).

Writes DIR/cycles-compare.csv, DIR/cycles-compare.svg and
DIR/cycles-compare-summary.json (default DIR: target/cycles-compare).
"""

import argparse
import json
import math
import os
import struct
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT.parent / "shared" / "data" / "room-grey-white"
VENV = ROOT / "target" / "cycles-venv"
BPY = "bpy==4.5.15"


def ensure_bpy():
    """Re-runs this script inside the virtualenv that has bpy, creating it first."""
    try:
        import bpy  # noqa: F401
        return
    except ImportError:
        pass
    python = VENV / "bin" / "python"
    if not python.exists():
        print(f"installing {BPY} into {VENV} (about 400 MB, once)", file=sys.stderr)
        subprocess.run([sys.executable, "-m", "venv", str(VENV)], check=True)
        subprocess.run([str(python), "-m", "pip", "install", "--quiet", BPY], check=True)
    os.execv(str(python), [str(python), __file__, *sys.argv[1:]])


def read_f32(path):
    data = Path(path).read_bytes()
    return list(struct.unpack(f"<{len(data) // 4}f", data))


def relative_rms(values, reference):
    num = sum((b - r) ** 2 for b, r in zip(values, reference))
    den = sum(r * r for r in reference)
    return math.sqrt(num / den)


# ---------------------------------------------------------------- Cycles side


def sh_basis_order3(x, y, z):
    """prtbake's real SH, bands 0-2 (docs/conventions.md), at unit (x, y, z)."""
    return [
        0.282095,
        0.488603 * y,
        0.488603 * z,
        0.488603 * x,
        1.092548 * x * y,
        1.092548 * y * z,
        0.315392 * (3 * z * z - 1),
        1.092548 * x * z,
        0.546274 * (x * x - y * y),
    ]


def parse_obj(path):
    """prtbake's OBJ: one vertex pool (v i = vn i = bundle vertex i), `usemtl` per run, triangles."""
    positions, normals, faces, face_material, materials = [], [], [], [], {}
    current = 0
    for line in open(path):
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            positions.append(tuple(float(p) for p in parts[1:4]))
        elif parts[0] == "vn":
            normals.append(tuple(float(p) for p in parts[1:4]))
        elif parts[0] == "usemtl":
            current = materials.setdefault(parts[1], len(materials))
        elif parts[0] == "f":
            faces.append(tuple(int(p.split("/")[0]) - 1 for p in parts[1:4]))
            face_material.append(current)
    albedo = {}
    mtl = Path(path).with_suffix(".mtl")
    name = None
    for line in open(mtl):
        parts = line.split()
        if parts[:1] == ["newmtl"]:
            name = parts[1]
        elif parts[:1] == ["Kd"] and name is not None:
            albedo[name] = sum(float(p) for p in parts[1:4]) / 3.0
    return positions, normals, faces, face_material, [(m, albedo.get(m, 0.8)) for m in sorted(materials, key=materials.get)]


def cycles_bakes(obj_path, lighting, samples, seeds, out_dir):
    """Bakes the mesh in Cycles at each sample count and seed."""
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    positions, normals, faces, face_material, materials = parse_obj(obj_path)
    mesh = bpy.data.meshes.new("room")
    mesh.from_pydata(positions, [], faces)
    mesh.update()
    for name, grey in materials:
        material = bpy.data.materials.new(name)
        material.use_nodes = True
        nodes = material.node_tree.nodes
        nodes.clear()
        diffuse = nodes.new("ShaderNodeBsdfDiffuse")
        diffuse.inputs["Color"].default_value = (grey, grey, grey, 1.0)
        output = nodes.new("ShaderNodeOutputMaterial")
        material.node_tree.links.new(diffuse.outputs["BSDF"], output.inputs["Surface"])
        mesh.materials.append(material)
    mesh.polygons.foreach_set("material_index", face_material)
    mesh.polygons.foreach_set("use_smooth", [True] * len(faces))
    if not os.environ.get("CYCLES_NO_CUSTOM_NORMALS"):
        mesh.normals_split_custom_set_from_vertices(normals)
    obj = bpy.data.objects.new("room", mesh)
    scene = bpy.context.scene
    scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)

    # The SH light as an equirectangular map in Cycles' axes: column u looks
    # along φ = π(1 − 2u) from +X toward +Y, row v (from the bottom) at
    # elevation π(v − ½) toward +Z. The mesh keeps prtbake's coordinates, so
    # the basis is evaluated at the same world direction.
    width, height = 512, 256
    coefficients = lighting["coefficients"]
    pixels = []
    lowest = float("inf")
    for row in range(height):
        elevation = math.pi * ((row + 0.5) / height - 0.5)
        for col in range(width):
            phi = math.pi * (1.0 - 2.0 * (col + 0.5) / width)
            d = (math.cos(elevation) * math.cos(phi), math.cos(elevation) * math.sin(phi), math.sin(elevation))
            value = sum(c * y for c, y in zip(coefficients, sh_basis_order3(*d)))
            lowest = min(lowest, value)
            pixels += [value, value, value, 1.0]
    image = bpy.data.images.new("sh-light", width, height, float_buffer=True)
    image.pixels.foreach_set(pixels)
    world = bpy.data.worlds.new("sh-light")
    scene.world = world
    world.use_nodes = True
    nodes = world.node_tree.nodes
    nodes.clear()
    texture = nodes.new("ShaderNodeTexEnvironment")
    texture.image = image
    texture.interpolation = "Linear"
    background = nodes.new("ShaderNodeBackground")
    output = nodes.new("ShaderNodeOutputWorld")
    world.node_tree.links.new(texture.outputs["Color"], background.inputs["Color"])
    world.node_tree.links.new(background.outputs["Background"], output.inputs["Surface"])

    scene.render.engine = "CYCLES"
    cycles = scene.cycles
    cycles.device = "CPU"
    scene.render.threads_mode = "FIXED"
    scene.render.threads = 2
    cycles.use_adaptive_sampling = False
    cycles.use_denoising = False
    cycles.sample_clamp_direct = 0.0
    cycles.sample_clamp_indirect = 0.0
    cycles.max_bounces = 3
    cycles.diffuse_bounces = 3
    cycles.glossy_bounces = 0
    cycles.transmission_bounces = 0
    cycles.volume_bounces = 0
    cycles.transparent_max_bounces = 0
    attribute = mesh.color_attributes.new("bake", "FLOAT_COLOR", "POINT")
    mesh.color_attributes.active_color = attribute
    scene.render.bake.target = "VERTEX_COLORS"

    runs = [(n, seed) for n in samples for seed in seeds]
    results = []
    for n, seed in runs:
        cycles.samples = n
        cycles.seed = seed
        started = time.perf_counter()
        bpy.ops.object.bake(type="DIFFUSE", pass_filter={"DIRECT", "INDIRECT"}, target="VERTEX_COLORS")
        seconds = time.perf_counter() - started
        colours = [0.0] * (4 * len(positions))
        mesh.color_attributes["bake"].data.foreach_get("color", colours)
        values = colours[0::4]
        path = out_dir / f"cycles-{n}-seed{seed}.f32"
        path.write_bytes(struct.pack(f"<{len(values)}f", *values))
        results.append({"samples": n, "seed": seed, "seconds": seconds, "values": str(path)})
        print(f"cycles {n} samples, seed {seed}: {seconds:.1f} s", file=sys.stderr)
    return results, lowest


# ---------------------------------------------------------------- prtbake side


def run(cmd, **kw):
    print("$ " + " ".join(str(c) for c in cmd), file=sys.stderr)
    return subprocess.run([str(c) for c in cmd], check=True, **kw)


def prtbake_bakes(binary, obj_path, settings, out_dir):
    results = []
    for name, args in settings:
        bundle = out_dir / f"{name}.prtb"
        base = ["bake", obj_path, "-o", bundle, "--order", "3", "--bounces", "3", "--channels", "1", "--quantize", "f32", "--threads", "2"]
        started = time.perf_counter()
        run([binary, *base, *args, "--json", "--quiet"], stdout=subprocess.DEVNULL)
        results.append({"name": name, "args": " ".join(args), "seconds": time.perf_counter() - started, "bundle": bundle})
    return results


def svg_chart(curves, path):
    """Log-log error against seconds, one polyline per curve."""
    points = [p for c in curves for p in c["points"]]
    xs = [math.log10(p[0]) for p in points]
    ys = [math.log10(p[1]) for p in points]
    x0, x1, y0, y1 = min(xs) - 0.1, max(xs) + 0.1, min(ys) - 0.1, max(ys) + 0.1
    w, h, m = 640, 420, 60
    sx = lambda x: m + (math.log10(x) - x0) / (x1 - x0) * (w - 2 * m)
    sy = lambda y: h - m - (math.log10(y) - y0) / (y1 - y0) * (h - 2 * m)
    colours = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd"]
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12">',
           f'<rect width="{w}" height="{h}" fill="white"/>',
           f'<line x1="{m}" y1="{h - m}" x2="{w - m}" y2="{h - m}" stroke="black"/><line x1="{m}" y1="{m}" x2="{m}" y2="{h - m}" stroke="black"/>',
           f'<text x="{w / 2}" y="{h - 20}" text-anchor="middle">wall seconds (log), 2 threads</text>',
           f'<text x="15" y="{h / 2}" transform="rotate(-90 15 {h / 2})" text-anchor="middle">relative RMS error (log)</text>']
    for decade in range(math.floor(x0), math.ceil(x1) + 1):
        if x0 <= decade <= x1:
            out.append(f'<text x="{sx(10 ** decade)}" y="{h - m + 16}" text-anchor="middle">{10 ** decade:g}</text>')
    for e in (0.01, 0.02, 0.05, 0.1, 0.2, 0.5):
        if y0 <= math.log10(e) <= y1:
            out.append(f'<line x1="{m}" y1="{sy(e)}" x2="{w - m}" y2="{sy(e)}" stroke="#ddd"/><text x="{m - 6}" y="{sy(e) + 4}" text-anchor="end">{e:g}</text>')
    for k, c in enumerate(curves):
        colour = colours[k % len(colours)]
        line = " ".join(f"{sx(s):.1f},{sy(e):.1f}" for s, e in c["points"])
        out.append(f'<polyline points="{line}" fill="none" stroke="{colour}" stroke-width="2"/>')
        out += [f'<circle cx="{sx(s):.1f}" cy="{sy(e):.1f}" r="3" fill="{colour}"/>' for s, e in c["points"]]
        out.append(f'<text x="{w - m - 4}" y="{m + 16 * k}" text-anchor="end" fill="{colour}">{c["name"]}</text>')
    out.append("</svg>")
    Path(path).write_text("\n".join(out))


def free_vertices(obj_path, size):
    """Vertices whose one-ring lies within `size` of them, where a one-ring
    mean and the value at the vertex agree."""
    positions, _, faces, _, _ = parse_obj(obj_path)
    reach = [0.0] * len(positions)
    for face in faces:
        for v in face:
            for w in face:
                if w != v:
                    reach[v] = max(reach[v], math.dist(positions[v], positions[w]))
    return [v for v in range(len(positions)) if 0.0 < reach[v] <= size]


def subset(values, indices):
    return [values[i] for i in indices]


def time_at(points, target):
    """Seconds at which a curve first reaches `target` error (log-log interpolation), or None."""
    for (s0, e0), (s1, e1) in zip(points, points[1:]):
        if e0 > target >= e1:
            f = (math.log(target) - math.log(e0)) / (math.log(e1) - math.log(e0))
            return math.exp(math.log(s0) + f * (math.log(s1) - math.log(s0)))
    return points[0][0] if points and points[0][1] <= target else None


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "target" / "cycles-compare")
    parser.add_argument("--quick", action="store_true", help="a small sweep (minutes), for checking the script")
    args = parser.parse_args()
    room = DATA / "grey_white_room_flat.obj"
    sky = DATA / "sky19.exr"
    if not room.exists() or not sky.exists():
        print(f"skipped: {DATA} is absent (the room and sky19.exr)", file=sys.stderr)
        return 0
    ensure_bpy()
    out = args.out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    run(["cargo", "build", "--release", "--quiet", "--example", "sh_shade"], cwd=ROOT)
    run(["cargo", "build", "--release", "--quiet"], cwd=ROOT)
    binary = ROOT / "target" / "release" / "prtbake"
    obj_path = out / "room.obj"
    if not obj_path.exists():
        run([binary, "clean", room, "-o", obj_path, "--quiet"])

    if args.quick:
        sweep = [("prtbake-r16", ["--rays", "16", "--adaptive", "0"]), ("prtbake-r64", ["--rays", "64", "--adaptive", "0"])]
        adaptive = [("prtbake-a1-r32", ["--rays", "32", "--adaptive", "1"])]
        references = [("prtbake-ref-s1", ["--rays", "128", "--adaptive", "0", "--seed", "1"]), ("prtbake-ref-s2", ["--rays", "128", "--adaptive", "0", "--seed", "2"])]
        samples = [4, 16]
    else:
        sweep = [(f"prtbake-r{r}", ["--rays", str(r), "--adaptive", "0"]) for r in (16, 32, 64, 128, 256)]
        # Per vertex only: texel mode's vertices converge to another answer
        # (bounces read from texels, less biased) than the per-vertex reference.
        adaptive = [(f"prtbake-a1-r{r}", ["--rays", str(r), "--adaptive", "1"]) for r in (16, 32, 64, 128)]
        references = [(f"prtbake-ref-s{s}", ["--rays", "256", "--adaptive", "3", "--seed", str(s)]) for s in (1, 2)]
        samples = [4, 16, 64, 128]
    seed3 = ["--seed", "3"]
    bakes = prtbake_bakes(binary, obj_path, references + [(n, a + seed3) for n, a in sweep + adaptive], out)
    run([ROOT / "target" / "release" / "examples" / "sh_shade", sky, "3", out, *[b["bundle"] for b in bakes]])
    lighting = json.loads((out / "lighting.json").read_text())
    shade = {b["name"]: read_f32(out / f"{b['name']}.shade.f32") for b in bakes}
    # The bundle's vertices must be the OBJ's, in order (the Cycles mesh is built from the OBJ).
    bundle_positions = read_f32(out / f"{bakes[0]['name']}.positions.f32")
    obj_positions = [c for p in parse_obj(obj_path)[0] for c in p]
    assert len(bundle_positions) == len(obj_positions), "the bundle and the OBJ have different vertex counts"
    drift = max(abs(a - b) for a, b in zip(bundle_positions, obj_positions))
    assert drift < 1e-4, f"the bundle's vertices are not the OBJ's in order (max difference {drift})"

    cycles_runs, lowest = cycles_bakes(obj_path, lighting, samples, [1, 2], out)
    cycles = {(r["samples"], r["seed"]): read_f32(r["values"]) for r in cycles_runs}
    seconds = {(r["samples"], r["seed"]): r["seconds"] for r in cycles_runs}

    p_ref = shade[references[0][0]]
    c_best = [(a + b) / 2 for a, b in zip(cycles[(samples[-1], 1)], cycles[(samples[-1], 2)])]
    # The reference's own noise, taken out of every prtbake figure in quadrature.
    p_ref_noise = relative_rms(shade[references[1][0]], p_ref) / math.sqrt(2)
    quiet = lambda error, noise: math.sqrt(max(error * error - noise * noise, 0.0))
    rows, curves = [], []
    for b in bakes[len(references):]:
        raw = relative_rms(shade[b["name"]], p_ref)
        rows.append({"tool": "prtbake", "setting": b["args"], "seconds": b["seconds"], "raw": raw, "error": quiet(raw, p_ref_noise)})
    c_scale = math.sqrt(sum(m * m for m in c_best))
    for n in samples:
        difference = math.sqrt(sum((a - b) ** 2 for a, b in zip(cycles[(n, 2)], cycles[(n, 1)])))
        noise = difference / math.sqrt(2) / c_scale
        rows.append({"tool": "cycles", "setting": f"{n} samples", "seconds": (seconds[(n, 1)] + seconds[(n, 2)]) / 2, "raw": noise, "error": noise})
    # The two answers on the vertices where their definitions agree, and on all.
    free = free_vertices(obj_path, 0.03)
    agreement = {}
    for label, chosen in (("free", free), ("all", list(range(len(p_ref))))):
        c1, c2 = subset(cycles[(samples[-1], 1)], chosen), subset(cycles[(samples[-1], 2)], chosen)
        mean = subset(c_best, chosen)
        mean_noise = relative_rms(c2, c1) / 2 * math.sqrt(sum(a * a for a in c1) / sum(m * m for m in mean))
        raw = relative_rms(subset(p_ref, chosen), mean)
        agreement[label] = {"vertices": len(chosen), "raw": raw, "cycles_mean_noise": mean_noise, "without_cycles_noise": quiet(raw, mean_noise),
                            "mean_ratio_prtbake_over_cycles": sum(subset(p_ref, chosen)) / sum(mean)}
    for label, rows_of in (("prtbake (rays 16…256)", lambda r: r["tool"] == "prtbake" and "adaptive 0" in r["setting"]),
                           ("prtbake --adaptive 1", lambda r: r["tool"] == "prtbake" and "adaptive 1" in r["setting"]),
                           ("Cycles (samples)", lambda r: r["tool"] == "cycles")):
        points = sorted((r["seconds"], r["error"]) for r in rows if rows_of(r))
        curves.append({"name": label, "points": points})
    summary = {
        "date": time.strftime("%Y-%m-%d"),
        "vertices": len(p_ref),
        "lighting": lighting,
        "sh_light_minimum": lowest,
        "prtbake_reference": {"setting": references[0][1], "seconds": bakes[0]["seconds"], "seed_difference": relative_rms(shade[references[1][0]], p_ref),
                              "noise": p_ref_noise},
        "cycles_most_samples": samples[-1],
        "prtbake_reference_against_cycles_mean": agreement,
        "seconds_to_reach": {},
    }
    for target in (0.1, 0.05, 0.02):
        reached = {c["name"]: time_at(c["points"], target) for c in curves}
        summary["seconds_to_reach"][f"{target:g}"] = reached
    with open(out / "cycles-compare.csv", "w") as f:
        f.write("tool,setting,seconds,raw_error,error\n")
        for r in rows:
            f.write(f"{r['tool']},{r['setting']},{r['seconds']:.3f},{r['raw']:.6f},{r['error']:.6f}\n")
    svg_chart(curves, out / "cycles-compare.svg")
    (out / "cycles-compare-summary.json").write_text(json.dumps(summary, indent=1))
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
