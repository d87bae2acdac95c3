#!/usr/bin/env python3
"""Independent reference for prtbake's per-vertex DC transfer with bounces, by Mitsuba 3.

usage:
    target/mitsuba-venv/bin/python benches/mitsuba_probe.py MESH.obj --rings RINGS.csv \\
        --bounces B --points P --rays R --seed S -o OUT.csv [--up y|z] [--variant llvm_ad_mono]

    # test helper: write RINGS.csv for N random vertices in the OBJ's own vertex order
    target/mitsuba-venv/bin/python benches/mitsuba_probe.py MESH.obj --write-rings RINGS.csv \\
        --random-ids N --seed S [--up y|z]

Needs numpy and mitsuba (PyPI) only, in a virtualenv:
    python3 -m venv target/mitsuba-venv
    target/mitsuba-venv/bin/pip install mitsuba numpy
The LLVM variants need a shared libLLVM that Dr.Jit finds (Debian 12: `apt-get
install libllvm19`; libLLVM 15 loads but crashes compiling the path integrator's
kernel, "Cannot select ... fmaximum"). Dr.Jit picks the newest it finds;
DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1 picks one by path.
Only the vectorised variants work here (llvm_ad_mono, the default, or
llvm_ad_rgb, which gives the same numbers on a grey scene); scalar_* do not.

What it computes (docs/conventions.md, "Transfer and shading", "Per-vertex
transfer"): for each vertex id in RINGS.csv, the hat-weighted mean over its
one-ring of the total DC transfer t_0 = Σ_{b=0..B} t_0^(b), open mode:
- the scene is the OBJ, every surface Lambertian and two-sided, albedo = the
  mean of its MTL Kd (0.8 where there is none, like prtbake), no windows;
- under an environment of radiance 1 everywhere, L_0 = ∫ 1·y_0 dω = √(4π) and
  prtbake shades L_out = ρ Σ L_i t_i = ρ √(4π) t_0, while a Lambertian surface
  shades L_out = ρ E/π, with E = ∫ L_in max(n·ω,0) dω the irradiance.
  So t_0(x) = E(x) / (π √(4π)). With cosine-distributed rays (pdf = cos/π),
  E ≈ π · mean(L_in), so t_0(x) ≈ mean(L_in) / √(4π);
- L_in along each ray is Mitsuba's `path` integrator with max_depth = B + 1
  (max_depth 1 = what the ray sees directly, the sky: bounce 0; each extra
  depth adds one bounce), Russian roulette off;
- n in the cosine is the shading normal, interpolated from the corners'
  normals when RINGS.csv gives them (prtbake's `point.normal`), else the face
  normal; ray origins are pushed off the face by a tiny offset along the face
  normal, to the side the ray leaves on (prtbake's `Scene::offset_origin`).
  An unoccluded plane gives t_0 = 1/√(4π) = y_0 = 0.282095.

Points: for each vertex, P points over its one-ring with density ∝ its hat
function: a triangle with probability ∝ its area (the hat integrates to |T|/3
on each), then barycentrics from Dirichlet(2,1,1) with the 2 on the vertex's
corner (density ∝ the vertex's barycentric). The plain mean of t_0 over the
points then estimates ∫ φ_v t dA / ∫ φ_v dA. A point is dropped as inside
geometry when more than 16 of 32 extra cosine rays (traced closest-hit) hit a
back face (ray direction · the hit's geometric normal > 0) closer than 0.05 ×
the scene's bounding-box diagonal, prtbake's rule in open mode; the mean is
over the points kept, and a vertex with none kept gets 0.

RINGS.csv, one row per (vertex, one-ring triangle), optional header line:
    id,tri,ax,ay,az,bx,by,bz,cx,cy,cz,corner[,nax,nay,naz,nbx,nby,nbz,ncx,ncy,ncz]
- id: the vertex id, copied to the output (prtbake's vertex index);
- tri: the triangle's index (only informative);
- a, b, c: the triangle's corner positions in prtbake's winding and in its
  loaded frame (after `--up`: the same frame this script puts the OBJ in);
  the front is n = normalise(cross(b − a, c − a));
- corner: which corner is the vertex: a, b or c (or 0, 1, 2);
- na, nb, nc (optional): the corners' shading normals; without them the
  cosine is taken against the face normal.
Give only the triangles prtbake samples (not windows); zero-area ones are
never drawn anyway.

Before tracing, each vertex's largest ring triangle is checked to lie on the
loaded mesh (a ray back onto it from just in front); a warning counts those
that do not (RINGS.csv from another file or frame, or a wrong `--up`).

OUT.csv: id,dc_mean,dc_stderr,points_used,points_dropped
(dc_stderr from the spread of the per-point values: it includes ray noise;
dc_mean is 0 where no point was kept, points_used = points_dropped = 0 where
the ring has no area, and dc_stderr is nan where fewer than 2 points were kept).
Other options: --face-normals (cosine about the face normal, and no shading
normals in Mitsuba), --batch-rays (rays per Mitsuba launch, default 2^21:
memory), --variant.

Differences from prtbake that remain (a converged prtbake should agree only
up to them): prtbake's bounces gather the previous bounce at hit points by
linear interpolation of vertex values, Mitsuba uses the exact transfer at
the hit; Mitsuba's diffuse BSDF uses the hit's shading frame (interpolated
normals, from the OBJ's vn, or computed area-and-angle weighted like prtbake
where the OBJ has none); a back face prtbake gives no twin (one whose back
cannot be lit) reflects nothing there and is dark here too only because it
receives no light.
"""
import argparse
import csv
import math
import os
import sys
import time

import numpy as np

Y0 = 0.5 / math.sqrt(math.pi)  # 0.282095
INSIDE_PROBE_RAYS = 32
INSIDE_DISTANCE = 0.05
DEFAULT_ALBEDO = 0.8


# --------------------------------------------------------------------------- OBJ


def load_mtl(path):
    """{material name: mean Kd}."""
    albedo = {}
    name = None
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            for line in f:
                parts = line.split()
                if not parts:
                    continue
                if parts[0] == "newmtl":
                    name = " ".join(parts[1:])
                    albedo.setdefault(name, DEFAULT_ALBEDO)
                elif parts[0] == "Kd" and name is not None and len(parts) >= 4:
                    albedo[name] = float(np.mean([float(x) for x in parts[1:4]]))
    except OSError as e:
        print(f"warning: cannot read {path}: {e}; albedo {DEFAULT_ALBEDO}", file=sys.stderr)
    return albedo


def load_obj(path, up="y"):
    """Triangles of an OBJ (polygons fanned), grouped by material.

    Returns dict with positions (V,3), tri_v (T,3) position indices,
    tri_n (T,3) normal indices or -1, normals (N,3), tri_mat (T,) material
    index, materials [(name, albedo)].
    """
    positions, normals = [], []
    tri_v, tri_n, tri_mat = [], [], []
    mat_index = {}
    materials = []
    albedo = {}
    current = None

    def material(name):
        if name not in mat_index:
            mat_index[name] = len(materials)
            materials.append([name, albedo.get(name, DEFAULT_ALBEDO)])
        return mat_index[name]

    base = os.path.dirname(os.path.abspath(path))
    with open(path, encoding="utf-8", errors="replace") as f:
        for line in f:
            if not line or line[0] == "#":
                continue
            parts = line.split()
            if not parts:
                continue
            tag = parts[0]
            if tag == "v":
                positions.append((float(parts[1]), float(parts[2]), float(parts[3])))
            elif tag == "vn":
                normals.append((float(parts[1]), float(parts[2]), float(parts[3])))
            elif tag == "f":
                if current is None:
                    current = material("")
                corners = []
                for p in parts[1:]:
                    fields = p.split("/")
                    vi = int(fields[0])
                    vi = vi - 1 if vi > 0 else len(positions) + vi
                    ni = -1
                    if len(fields) >= 3 and fields[2]:
                        ni = int(fields[2])
                        ni = ni - 1 if ni > 0 else len(normals) + ni
                    corners.append((vi, ni))
                for k in range(1, len(corners) - 1):
                    tri = (corners[0], corners[k], corners[k + 1])
                    tri_v.append([c[0] for c in tri])
                    tri_n.append([c[1] for c in tri])
                    tri_mat.append(current)
            elif tag == "usemtl":
                current = material(" ".join(parts[1:]))
            elif tag == "mtllib":
                for name in parts[1:]:
                    albedo.update(load_mtl(os.path.join(base, name)))
                for m in materials:  # materials named before their mtllib
                    m[1] = albedo.get(m[0], m[1])
    positions = np.array(positions, dtype=np.float64).reshape(-1, 3)
    normals = np.array(normals, dtype=np.float64).reshape(-1, 3)
    if up == "z":  # prtbake --up z: (x, y, z) -> (x, z, -y), winding kept
        positions = np.stack([positions[:, 0], positions[:, 2], -positions[:, 1]], axis=1)
        if len(normals):
            normals = np.stack([normals[:, 0], normals[:, 2], -normals[:, 1]], axis=1)
    return {
        "positions": positions,
        "normals": normals,
        "tri_v": np.array(tri_v, dtype=np.int64).reshape(-1, 3),
        "tri_n": np.array(tri_n, dtype=np.int64).reshape(-1, 3),
        "tri_mat": np.array(tri_mat, dtype=np.int64),
        "materials": [tuple(m) for m in materials],
    }


def normalise(v, fallback=None):
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    out = v / np.where(n > 0, n, 1.0)
    if fallback is not None:
        out = np.where(n > 1e-10, out, fallback)
    return out


def computed_vertex_normals(positions, tri_v):
    """prtbake's compute_vertex_normals: Σ cross(b−a, c−a) · angle at the corner."""
    a, b, c = (positions[tri_v[:, k]] for k in range(3))
    face = np.cross(b - a, c - a)
    ok = np.sum(face * face, axis=1) >= 1e-20
    sums = np.zeros_like(positions)
    pts = [a, b, c]
    for k in range(3):
        e1 = normalise(pts[(k + 1) % 3] - pts[k])
        e2 = normalise(pts[(k + 2) % 3] - pts[k])
        angle = np.arccos(np.clip(np.sum(e1 * e2, axis=1), -1.0, 1.0))
        np.add.at(sums, tri_v[ok, k], face[ok] * angle[ok, None])
    return normalise(sums, fallback=np.array([0.0, 1.0, 0.0]))


def corner_normals(obj):
    """(T,3,3) shading normals of every triangle corner: the file's vn, or computed."""
    tri_v, tri_n = obj["tri_v"], obj["tri_n"]
    have = tri_n >= 0
    out = np.zeros(tri_v.shape + (3,))
    if have.any():
        out[have] = normalise(obj["normals"][tri_n[have]])
    bad = ~have | (np.linalg.norm(out, axis=2) < 1e-10)
    if bad.any():
        computed = computed_vertex_normals(obj["positions"], tri_v)
        out[bad] = computed[tri_v[bad]]
    return out


# ------------------------------------------------------------------------ rings


def write_rings(obj, path, ids):
    """One-ring CSV for `ids` (positions indices of the OBJ, its own order)."""
    tri_v = obj["tri_v"]
    pos = obj["positions"]
    nrm = corner_normals(obj)
    wanted = set(int(i) for i in ids)
    rows = 0
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["id", "tri", "ax", "ay", "az", "bx", "by", "bz", "cx", "cy", "cz", "corner",
                    "nax", "nay", "naz", "nbx", "nby", "nbz", "ncx", "ncy", "ncz"])
        by_vertex = {}
        for t in range(len(tri_v)):
            for k in range(3):
                v = int(tri_v[t, k])
                if v in wanted:
                    by_vertex.setdefault(v, []).append((t, k))
        for v in ids:
            for t, k in by_vertex.get(int(v), []):
                corners = [f"{x:.9g}" for x in pos[tri_v[t]].reshape(-1)]
                normals = [f"{x:.9g}" for x in nrm[t].reshape(-1)]
                w.writerow([int(v), t] + corners + ["abc"[k]] + normals)
                rows += 1
    return rows


def read_rings(path):
    """{id: (tris (K,3,3), corner (K,), normals (K,3,3) or None)} in file order."""
    rings = {}
    with open(path, newline="") as f:
        for row in csv.reader(f):
            if not row or row[0].strip().startswith("#"):
                continue
            try:
                vid = int(row[0])
            except ValueError:
                continue  # header
            corners = [float(x) for x in row[2:11]]
            c = row[11].strip().lower()
            corner = {"a": 0, "b": 1, "c": 2, "0": 0, "1": 1, "2": 2}[c]
            normals = [float(x) for x in row[12:21]] if len(row) >= 21 and row[12].strip() else None
            rings.setdefault(vid, []).append((corners, corner, normals))
    out = {}
    for vid, items in rings.items():
        tris = np.array([i[0] for i in items], dtype=np.float64).reshape(-1, 3, 3)
        corner = np.array([i[1] for i in items], dtype=np.int64)
        if all(i[2] is not None for i in items):
            normals = np.array([i[2] for i in items], dtype=np.float64).reshape(-1, 3, 3)
        else:
            normals = None
        out[vid] = (tris, corner, normals)
    return out


# ------------------------------------------------------------------------ points


def cosine_directions(normal, u1, u2):
    """Cosine-distributed unit directions about unit `normal` (broadcast (n,3) with (n,k))."""
    r = np.sqrt(u1)
    phi = 2.0 * math.pi * u2
    x, y = r * np.cos(phi), r * np.sin(phi)
    z = np.sqrt(np.maximum(0.0, 1.0 - u1))
    n = normal[:, None, :]
    # Frisvad / Duff et al. orthonormal basis
    sign = np.where(normal[:, 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + normal[:, 2])
    b = normal[:, 0] * normal[:, 1] * a
    t = np.stack([1.0 + sign * normal[:, 0] ** 2 * a, sign * b, -sign * normal[:, 0]], axis=1)
    s = np.stack([b, sign + normal[:, 1] ** 2 * a, -normal[:, 1]], axis=1)
    return x[..., None] * t[:, None, :] + y[..., None] * s[:, None, :] + z[..., None] * n


def sample_points(rings, ids, points, rng):
    """P points per vertex with density ∝ its hat: positions, face normals, shading normals."""
    pos, fn, sn, owner = [], [], [], []
    for j, vid in enumerate(ids):
        tris, corner, normals = rings[vid]
        a, b, c = tris[:, 0], tris[:, 1], tris[:, 2]
        cross = np.cross(b - a, c - a)
        area = 0.5 * np.linalg.norm(cross, axis=1)
        if not np.any(area > 0):
            continue
        pick = rng.choice(len(tris), size=points, p=area / area.sum())
        alpha = np.ones((points, 3))
        alpha[np.arange(points), corner[pick]] = 2.0
        # Dirichlet(alpha): normalised gamma draws
        g = rng.gamma(alpha)
        bary = g / g.sum(axis=1, keepdims=True)
        p = np.einsum("pk,pkd->pd", bary, tris[pick])
        f = normalise(cross[pick])
        if normals is not None:
            s = normalise(np.einsum("pk,pkd->pd", bary, normals[pick]), fallback=f)
        else:
            s = f
        pos.append(p)
        fn.append(f)
        sn.append(s)
        owner.append(np.full(points, j))
    if not pos:
        z = np.zeros((0, 3))
        return z, z, z, np.zeros(0, dtype=np.int64)
    return np.concatenate(pos), np.concatenate(fn), np.concatenate(sn), np.concatenate(owner)


# ------------------------------------------------------------------------ mitsuba


def build_scene(mi, obj, use_normals=True):
    """One mesh per material (unwelded corners, so corner normals stay exact), two-sided diffuse."""
    tri_v, tri_mat = obj["tri_v"], obj["tri_mat"]
    cnorm = corner_normals(obj) if use_normals else None
    scene = {"type": "scene", "sky": {"type": "constant", "radiance": {"type": "rgb", "value": 1.0}}}
    for m, (name, albedo) in enumerate(obj["materials"]):
        sel = np.nonzero(tri_mat == m)[0]
        if len(sel) == 0:
            continue
        verts = obj["positions"][tri_v[sel]].reshape(-1, 3).astype(np.float32)
        bsdf = mi.load_dict({"type": "twosided",
                             "material": {"type": "diffuse", "reflectance": {"type": "rgb", "value": float(albedo)}}})
        props = mi.Properties()
        props["bsdf"] = bsdf
        mesh = mi.Mesh(f"mat{m}", len(verts), len(sel), props=props, has_vertex_normals=use_normals)
        params = mi.traverse(mesh)
        params["vertex_positions"] = mi.Float(verts.reshape(-1))
        params["faces"] = mi.UInt32(np.arange(len(verts), dtype=np.uint32))
        if use_normals:
            params["vertex_normals"] = mi.Float(cnorm[sel].reshape(-1).astype(np.float32))
        params.update()
        scene[f"mat{m}"] = mesh
    return mi.load_dict(scene)


def trace_li(mi, dr, scene, integrator, origins, dirs, seed):
    """Incoming radiance along each ray (mono/grey: mean over channels)."""
    n = len(origins)
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(seed, n)
    o = origins.astype(np.float32)
    d = dirs.astype(np.float32)
    ray = mi.Ray3f(mi.Point3f(o[:, 0], o[:, 1], o[:, 2]), mi.Vector3f(d[:, 0], d[:, 1], d[:, 2]))
    spec, _valid, _aov = integrator.sample(scene, sampler, ray)
    dr.eval(spec)
    arr = np.array(spec)
    if arr.ndim == 2 and arr.shape[0] != n:
        arr = arr.mean(axis=0)
    elif arr.ndim == 2:
        arr = arr.mean(axis=1)
    return arr.reshape(n)


def trace_inside(mi, dr, scene, origins, dirs, reject):
    """Per ray: hit a back face (d · geometric normal > 0) closer than `reject`."""
    o = origins.astype(np.float32)
    d = dirs.astype(np.float32)
    ray = mi.Ray3f(mi.Point3f(o[:, 0], o[:, 1], o[:, 2]), mi.Vector3f(d[:, 0], d[:, 1], d[:, 2]))
    si = scene.ray_intersect(ray)
    back = si.is_valid() & (dr.dot(ray.d, si.n) > 0) & (si.t < reject)
    dr.eval(back)
    return np.array(back, dtype=bool)


def offset_origins(pos, face_normal, dirs, eps):
    """prtbake's offset_origin: push along the face normal to the side the ray leaves on."""
    side = np.where(np.einsum("pd,pkd->pk", face_normal, dirs) >= 0.0, 1.0, -1.0)
    return pos[:, None, :] + face_normal[:, None, :] * (side[..., None] * eps)


def check_rings_on_mesh(mi, dr, scene, rings, ids, diag):
    """Warns when a ring's triangles are not on the scene's surface (wrong frame, `--up`, or file)."""
    cents, norms = [], []
    for vid in ids:
        tris = rings[vid][0]
        cross = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
        k = int(np.argmax(np.linalg.norm(cross, axis=1)))
        if np.linalg.norm(cross[k]) > 0:
            cents.append(tris[k].mean(axis=0))
            norms.append(normalise(cross[k]))
    if not cents:
        return
    c, n = np.array(cents), np.array(norms)
    delta = 1e-4 * diag
    o = (c + n * delta).astype(np.float32)
    d = (-n).astype(np.float32)
    ray = mi.Ray3f(mi.Point3f(o[:, 0], o[:, 1], o[:, 2]), mi.Vector3f(d[:, 0], d[:, 1], d[:, 2]))
    si = scene.ray_intersect(ray)
    t = np.where(np.array(si.is_valid(), dtype=bool), np.array(si.t), np.inf)
    # a surface closer than delta (a thin layer over the triangle) is fine; nothing there is not
    off = int(np.sum(t > 1.1 * delta))
    if off:
        print(f"warning: {off} of {len(c)} vertices' largest ring triangle is not on the mesh "
              f"(RINGS.csv in another frame, --up, or another file?)", file=sys.stderr)


# ------------------------------------------------------------------------ main


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("mesh")
    ap.add_argument("--rings", "--points-file", dest="rings", help="one-ring CSV (see the docstring)")
    ap.add_argument("--bounces", type=int, default=3)
    ap.add_argument("--points", type=int, default=64, help="points per vertex")
    ap.add_argument("--rays", type=int, default=64, help="rays per point")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("-o", "--out", help="output CSV")
    ap.add_argument("--up", choices=["y", "z"], default="y")
    ap.add_argument("--variant", default="llvm_ad_mono",
                    help="Mitsuba variant (default llvm_ad_mono; the scene is grey, so mono = rgb)")
    ap.add_argument("--face-normals", action="store_true",
                    help="ignore shading normals: cosine about the face normal, flat shading in Mitsuba")
    ap.add_argument("--batch-rays", type=int, default=1 << 21, help="rays per Mitsuba launch")
    ap.add_argument("--write-rings", metavar="CSV",
                    help="test helper: write a one-ring CSV in the OBJ's own vertex order and exit")
    ap.add_argument("--random-ids", type=int, metavar="N", help="with --write-rings: N random vertices")
    ap.add_argument("--ids", help="with --write-rings: comma-separated vertex ids (0-based OBJ order)")
    args = ap.parse_args()

    t_start = time.perf_counter()
    obj = load_obj(args.mesh, args.up)
    print(f"{args.mesh}: {len(obj['positions'])} vertices, {len(obj['tri_v'])} triangles, "
          f"{len(obj['materials'])} materials (albedo {sorted(set(round(a, 4) for _, a in obj['materials']))}), "
          f"loaded in {time.perf_counter() - t_start:.1f} s", file=sys.stderr)

    if args.write_rings:
        if args.ids:
            ids = [int(x) for x in args.ids.split(",")]
        else:
            used = np.unique(obj["tri_v"])
            n = min(args.random_ids or 100, len(used))
            ids = sorted(np.random.default_rng(args.seed).choice(used, size=n, replace=False).tolist())
        rows = write_rings(obj, args.write_rings, ids)
        print(f"wrote {args.write_rings}: {len(ids)} vertices, {rows} rows", file=sys.stderr)
        return

    if not args.rings or not args.out:
        ap.error("--rings and -o are required (or --write-rings)")

    import drjit as dr
    import mitsuba as mi
    mi.set_variant(args.variant)
    if not args.variant.startswith(("llvm_", "cuda_")) or mi.is_spectral or mi.is_polarized:
        ap.error("use a vectorised rgb or mono variant (llvm_ad_mono, llvm_ad_rgb): the scene is grey")

    rings = read_rings(args.rings)
    ids = list(rings.keys())
    if args.face_normals:
        rings = {k: (t, c, None) for k, (t, c, _n) in rings.items()}

    lo, hi = obj["positions"].min(axis=0), obj["positions"].max(axis=0)
    diag = float(np.linalg.norm(hi - lo))
    reject = INSIDE_DISTANCE * diag
    # prtbake: diagonal · 1e-6 (floor: a few ulps); float32 here, so keep ≥ 16 ulps of the largest coordinate.
    extent = float(np.abs(np.concatenate([lo, hi])).max())
    eps = max(diag * 1e-6, 16 * np.spacing(np.float32(max(extent, 1e-30))).item())

    t0 = time.perf_counter()
    scene = build_scene(mi, obj, use_normals=not args.face_normals)
    integrator = mi.load_dict({"type": "path", "max_depth": args.bounces + 1,
                               "rr_depth": args.bounces + 100, "hide_emitters": False})
    t_scene = time.perf_counter() - t0

    check_rings_on_mesh(mi, dr, scene, rings, ids, diag)

    rng = np.random.default_rng(args.seed)
    pos, fn, sn, owner = sample_points(rings, ids, args.points, rng)
    npts = len(pos)
    rays = args.rays
    k_dirs = max(rays, INSIDE_PROBE_RAYS)

    point_value = np.zeros(npts)
    inside = np.zeros(npts, dtype=bool)
    traced = 0
    t_trace = time.perf_counter()
    per_batch = max(1, args.batch_rays // k_dirs)
    launch = 0
    for start in range(0, npts, per_batch):
        stop = min(npts, start + per_batch)
        m = stop - start
        u = rng.random((m, k_dirs, 2))
        dirs = cosine_directions(sn[start:stop], u[..., 0], u[..., 1])
        origins = offset_origins(pos[start:stop], fn[start:stop], dirs, eps)
        # inside test: the first 32 directions, closest hit
        probe = trace_inside(mi, dr, scene, origins[:, :INSIDE_PROBE_RAYS].reshape(-1, 3),
                             dirs[:, :INSIDE_PROBE_RAYS].reshape(-1, 3), reject)
        traced += m * INSIDE_PROBE_RAYS
        ins = probe.reshape(m, INSIDE_PROBE_RAYS).sum(axis=1) > INSIDE_PROBE_RAYS // 2
        inside[start:stop] = ins
        keep = np.nonzero(~ins)[0]
        if len(keep):
            o = origins[keep, :rays].reshape(-1, 3)
            d = dirs[keep, :rays].reshape(-1, 3)
            li = trace_li(mi, dr, scene, integrator, o, d, (args.seed * 1000003 + launch) & 0x7FFFFFFF)
            launch += 1
            traced += len(o)
            point_value[start + keep] = li.reshape(len(keep), rays).mean(axis=1) / math.sqrt(4.0 * math.pi)
        done = stop
        el = time.perf_counter() - t_trace
        print(f"  {done}/{npts} points, {traced / max(el, 1e-9) / 1e6:.2f} M primary rays/s", file=sys.stderr)
    t_trace = time.perf_counter() - t_trace

    with open(args.out, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["id", "dc_mean", "dc_stderr", "points_used", "points_dropped"])
        for j, vid in enumerate(ids):
            sel = owner == j
            vals = point_value[sel & ~inside]
            used, dropped = len(vals), int(np.sum(sel & inside))
            mean = float(vals.mean()) if used else 0.0
            err = float(vals.std(ddof=1) / math.sqrt(used)) if used > 1 else float("nan")
            w.writerow([vid, f"{mean:.7g}", f"{err:.3g}", used, dropped])

    total = time.perf_counter() - t_start
    print(f"{len(ids)} vertices, {npts} points ({int(inside.sum())} dropped as inside), "
          f"{traced} primary rays (path depth ≤ {args.bounces + 1}); scene {t_scene:.1f} s, "
          f"tracing {t_trace:.1f} s = {traced / max(t_trace, 1e-9) / 1e6:.3f} M primary rays/s; "
          f"total {total:.1f} s", file=sys.stderr)
    print(f"wrote {args.out}", file=sys.stderr)


if __name__ == "__main__":
    main()
