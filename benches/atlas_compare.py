#!/usr/bin/env python3
"""Lightmap atlases for texel mode: xatlas against uvunwrap on the same mesh.

usage:
    target/mitsuba-venv/bin/python benches/atlas_compare.py MESH.obj|MESH.glb \\
        [--texels 4000000] [--padding 2] [--json]

Needs numpy, trimesh (GLB), xatlas (PyPI: the C++ xatlas that Godot and
others use) and uvunwrap (PyPI: bindings of the pure-Rust crate), in a
virtualenv:
    target/mitsuba-venv/bin/pip install numpy trimesh xatlas uvunwrap

Both get the same triangles (an OBJ's faces fan-triangulated, a GLB's
meshes merged by trimesh with their node transforms) and the same texel
density: `--texels` texels over the mesh's surface area (texels per unit =
sqrt(texels / area)), padding 2 texels between charts. Per tool, one run:
- seconds of `generate` (wall, this machine; both tools use every core);
- charts, atlas size, pages (both grow one page to fit: xatlas resolution 0,
  uvunwrap page_size None);
- texel use: the tool's own utilization (chart texels over atlas texels);
- seams: the input's interior edges (two triangles) cut by a chart
  boundary (the UVs on the two sides differ), as a count and as a share of
  the interior edges' length (a seam is where a lightmap can show a line,
  and where texel mode dilates across charts).
"""
import argparse
import json
import math
import os
import sys
import time

import numpy as np


def load(path):
    if path.lower().endswith((".glb", ".gltf")):
        import trimesh
        scene = trimesh.load(path, force="mesh", process=False)
        return np.asarray(scene.vertices, dtype=np.float32), np.asarray(scene.faces, dtype=np.uint32)
    from pathtracer_compare import load_obj_rgb  # the OBJ read as the pixel comparison reads it
    positions, tris, _, _, _ = load_obj_rgb(path)
    return positions, tris


def surface_area(positions, tris):
    a, b, c = positions[tris[:, 0]], positions[tris[:, 1]], positions[tris[:, 2]]
    return float(0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum())


def seams(positions, tris, out_indices):
    """Interior edges of the input (exactly two triangles) whose two sides
    carry different output vertices: count, and share of interior edge length."""
    out = out_indices.reshape(-1, 3)
    rows = []
    for k in range(3):
        a, b = tris[:, k], tris[:, (k + 1) % 3]
        oa, ob = out[:, k], out[:, (k + 1) % 3]
        swap = a > b
        lo, hi = np.where(swap, b, a), np.where(swap, a, b)
        olo, ohi = np.where(swap, ob, oa), np.where(swap, oa, ob)
        rows.append(np.stack([lo, hi, olo, ohi], 1))
    edges = np.concatenate(rows).astype(np.int64)
    order = np.lexsort((edges[:, 3], edges[:, 2], edges[:, 1], edges[:, 0]))
    edges = edges[order]
    key = edges[:, 0] * (len(positions) + 1) + edges[:, 1]
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    counts = np.diff(np.r_[starts, len(key)])
    interior = starts[counts == 2]
    cut = (edges[interior, 2] != edges[interior + 1, 2]) | (edges[interior, 3] != edges[interior + 1, 3])
    length = np.linalg.norm(positions[edges[interior, 0]] - positions[edges[interior, 1]], axis=1)
    return int(cut.sum()), float(length[cut].sum() / max(length.sum(), 1e-30)), int(len(interior))


def run_xatlas(positions, tris, texels_per_unit, padding):
    import xatlas
    atlas = xatlas.Atlas()
    atlas.add_mesh(positions, tris)
    pack = xatlas.PackOptions()
    pack.texels_per_unit = texels_per_unit
    pack.padding = padding
    started = time.time()
    atlas.generate(xatlas.ChartOptions(), pack)
    seconds = time.time() - started
    _, indices, _ = atlas[0]
    return {"seconds": seconds, "charts": atlas.chart_count, "width": atlas.width, "height": atlas.height,
            "pages": atlas.atlas_count, "texel_use": float(np.mean(atlas.utilization)), "indices": np.asarray(indices)}


def run_uvunwrap(positions, tris, texels_per_unit, padding):
    import uvunwrap
    mesh = uvunwrap.Mesh(positions, tris.ravel())
    started = time.time()
    atlas = uvunwrap.generate([mesh], texels_per_unit=texels_per_unit, padding=padding, page_size=None)
    seconds = time.time() - started
    out = atlas.meshes[0]
    return {"seconds": seconds, "charts": atlas.chart_count, "width": atlas.width, "height": atlas.height,
            "pages": atlas.page_count, "texel_use": float(np.mean(atlas.utilization)), "indices": np.asarray(out.indices)}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("mesh")
    ap.add_argument("--texels", type=float, default=4e6)
    ap.add_argument("--padding", type=int, default=2)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    positions, tris = load(args.mesh)
    area = surface_area(positions, tris)
    texels_per_unit = math.sqrt(args.texels / area)
    rows = []
    for name, run in [("xatlas", run_xatlas), ("uvunwrap", run_uvunwrap)]:
        try:
            r = run(positions, tris, texels_per_unit, args.padding)
        except Exception as e:  # a tool that fails on a mesh is a result too
            rows.append({"tool": name, "error": str(e)})
            continue
        count, share, interior = seams(positions, tris, r.pop("indices"))
        rows.append({"tool": name, **r, "seam_edges": count, "seam_length_share": share, "interior_edges": interior})
    result = {"mesh": os.path.basename(args.mesh), "triangles": int(len(tris)), "vertices": int(len(positions)),
              "area": area, "texels_per_unit": texels_per_unit, "tools": rows}
    if args.json:
        print(json.dumps(result))
        return
    print(f"{result['mesh']}: {len(tris)} triangles, area {area:.2f}, {texels_per_unit:.1f} texels per unit")
    print("| tool | seconds | charts | atlas | pages | texel use | seam edges | seam length share |")
    print("|---|---:|---:|---|---:|---:|---:|---:|")
    for r in rows:
        if "error" in r:
            print(f"| {r['tool']} | failed: {r['error']} |")
            continue
        print(f"| {r['tool']} | {r['seconds']:.2f} | {r['charts']} | {r['width']}x{r['height']} | {r['pages']} | "
              f"{100 * r['texel_use']:.1f}% | {r['seam_edges']} of {r['interior_edges']} | {100 * r['seam_length_share']:.1f}% |")


if __name__ == "__main__":
    sys.exit(main())
