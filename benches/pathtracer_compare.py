#!/usr/bin/env python3
"""The picture against a path tracer: `prtbake view`'s linear screenshot of a
bundle beside Mitsuba 3's rendering of the same mesh, camera and light.

usage:
    target/mitsuba-venv/bin/python benches/pathtracer_compare.py BUNDLE [MESH.obj|MESH.glb] \\
        (--env MAP.exr | --step K) --camera EX,EY,EZ,TX,TY,TZ [--fov 50] [--size 320x240] \\
        [--bounces B] [--spp 512] [--prtbake target/release/prtbake] -o OUTDIR [--json]

Needs numpy, mitsuba and flip-evaluator (PyPI) in a virtualenv:
    python3 -m venv target/mitsuba-venv
    target/mitsuba-venv/bin/pip install mitsuba numpy flip-evaluator
(the LLVM variant needs a shared libLLVM, see benches/mitsuba_probe.py).

The mesh is the OBJ the bundle was baked from (loaded as prtbake loads it:
Y up, no clean), every surface Lambertian and two-sided with its MTL Kd (0.8
where there is none), RGB, shaded with the mesh's vertex normals where it
gives one per vertex (OBJ `vn` through the faces, GLB NORMAL): the normals
the bake and the viewer take their cosines from (`--flat-normals`: flat
faces, as references before 2026-11-29 were). Without MESH (or with a GLB that `prtbake export`
wrote) the mesh is the bundle's own, exported into OUTDIR/prtbake_export.glb: the
triangles the bake saw after `--clean`, each material's albedo as the
viewer shades it (a GLB or glTF model as downloaded is not read here: its
node transforms and textures are prtbake's to resolve). Windows (MTL or
glTF `prtbake_role window`, or the bundle's `--window` patterns) of
transmittance 1 are left out of Mitsuba's scene: light passes them unchanged, as the bake counts it (a window of
transmittance below 1 is refused: Mitsuba would refract or reflect at it).

`--step K` compares a time-lapse step instead of an environment map: the
viewer's `view --step K`, and in Mitsuba the step's sky and sun
(examples/sky_env.rs writes them). The bundle models the sun as direct light
only (sun bits; its sky SH holds no sun), so (a) is the sky SH with B
bounces plus the sun's direct light alone; (b) is the full Preetham sky and
the sun, both with B bounces: what a user sees, the sun's bounced light
included.

Two references, each rendered by Mitsuba's `path` integrator with
max_depth = B + 2 (camera hit, light, B bounces), Russian roulette off:
- (a) under the lighting the bundle actually sees: the map projected on the
  bundle's SH bands and expanded back onto an equirect image (the projection
  onto bands 0..n-1 is the same whatever orthonormal real basis spans them,
  so numpy's own basis gives the viewer's lighting). This measures the bake:
  per-vertex storage, interpolation across triangles, ray noise, bias;
- (b) under the full map: what a user sees, SH truncation included.
With `--reference window` (an --env only), (a) follows window mode's own
model instead: light reaches the scene only through its glass (a ray whose
first hit is glass takes the map in its direction; one that escapes without
meeting glass takes nothing), path traced here with cosine-weighted bounces
on two-sided Lambertian surfaces. That is the reference for a mesh with gaps
(a car's body: window mode ignores light through them by design), where the
open one measures the gaps, not the bake. (b) stays open.

prtbake's side is `view --screenshot OUT.exr` (linear radiance) at
--supersample times the size (default 4), box-averaged (Mitsuba's box filter
averages over each pixel too). Only pixels wholly on geometry count: all 64
rays of an 8x8 grid through the pixel meet geometry, before any glass. A
pixel a silhouette crosses holds backdrop in both images, but not the same
backdrop (black in Mitsuba, the sky in the viewer): on the grey-white room's
window bars a 2x2 test let those pixels through, and they carried a quarter
of the error. Behind glass the viewer draws the backdrop and Mitsuba what
lies there (the Ferrari's hood and mirrors: 99.9% of its squared error
before they were left out).

Printed per reference: relative L2 over pixels, sqrt(sum (x-y)^2 / sum y^2)
over RGB ("image error"); mean relMSE, mean((x-y)^2 / (y^2 + 0.01 mean(y)^2));
and mean FLIP (flip-evaluator, LDR) on both images tone-mapped alike
(exposure 0.18 / the reference's mean luminance, Reinhard, sRGB). The
reference's own noise is the same L2 between two Mitsuba seeds divided by
sqrt(2); the bake's own error is then sqrt(L2^2 - noise^2) (independent
errors add in squares), printed beside the raw figure. Writes OUTDIR/{prtbake,mitsuba_a,mitsuba_b}.exr, tone-mapped PNGs, the
FLIP error maps (flip_a.png, flip_b.png), the counted pixels (mask.npy), and
where_{a,b}.png: the fewest pixels holding half of the squared error (red:
prtbake brighter, blue: darker), their count printed.
"""
import argparse
import hashlib
import json
import math
import os
import subprocess
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEFAULT_ALBEDO = 0.8


def load_obj_rgb(path):
    """Positions, triangles (fan-triangulated faces) and per-triangle material
    index; materials [(name, rgb)]; and the shading normal of each position
    when the file gives every position one (`vn` through the faces), else None."""
    positions, tris, tri_mat, materials, index = [], [], [], [], {}
    file_normals, corner_normal = [], {}
    one_normal_each = True
    kd = {}
    current = None
    base = os.path.dirname(path)

    def material(name):
        if name not in index:
            index[name] = len(materials)
            materials.append([name, kd.get(name, (DEFAULT_ALBEDO,) * 3)])
        return index[name]

    current = material("default")
    with open(path) as f:
        for line in f:
            parts = line.split()
            if not parts:
                continue
            if parts[0] == "v":
                positions.append([float(x) for x in parts[1:4]])
            elif parts[0] == "vn":
                file_normals.append([float(x) for x in parts[1:4]])
            elif parts[0] == "f":
                ids = []
                for p in parts[1:]:
                    fields = p.split("/")
                    i = int(fields[0])
                    ids.append(i - 1 if i > 0 else len(positions) + i)
                    if len(fields) > 2 and fields[2]:
                        n = int(fields[2])
                        n = n - 1 if n > 0 else len(file_normals) + n
                        if corner_normal.setdefault(ids[-1], n) != n:
                            one_normal_each = False
                    else:
                        one_normal_each = False
                for k in range(1, len(ids) - 1):
                    tris.append([ids[0], ids[k], ids[k + 1]])
                    tri_mat.append(current)
            elif parts[0] == "usemtl":
                current = material(" ".join(parts[1:]))
            elif parts[0] == "mtllib":
                kd.update(load_mtl(os.path.join(base, " ".join(parts[1:]))))
                for m in materials:
                    m[1] = kd.get(m[0], m[1])
    normals = None
    if one_normal_each and file_normals and len(corner_normal) == len(positions):
        fn = np.array(file_normals, dtype=np.float32)
        normals = fn[[corner_normal[i] for i in range(len(positions))]]
    return np.array(positions, dtype=np.float32), np.array(tris, dtype=np.uint32), np.array(tri_mat), materials, normals


def is_export_glb(path):
    """Whether `path` is a GLB that `prtbake export` wrote (its JSON's extras name prtbake)."""
    import struct
    with open(path, "rb") as f:
        head = f.read(20)
        if len(head) < 20 or head[:4] != b"glTF":
            return False
        try:
            return "prtbake" in json.loads(f.read(struct.unpack_from("<I", head, 12)[0])).get("extras", {})
        except ValueError:
            return False


def load_export_glb(path):
    """A GLB as `prtbake export` writes it: one triangle primitive per mesh,
    nodes without transforms, albedo in baseColorFactor, the role and the
    transmittance in the material. Returns what load_obj_rgb returns, plus
    {material: role} and {material: transmittance}."""
    import struct
    with open(path, "rb") as f:
        data = f.read()
    if len(data) < 20 or data[:4] != b"glTF":
        sys.exit(f"{path}: not a GLB")
    json_len = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20:20 + json_len])
    bin_start = 20 + json_len + 8
    if "prtbake" not in doc.get("extras", {}):
        sys.exit(f"{path}: not written by `prtbake export` (give the bundle alone and the script exports its mesh)")

    def accessor(i):
        a = doc["accessors"][i]
        view = doc["bufferViews"][a["bufferView"]]
        width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[a["type"]]
        dtype = {5126: np.float32, 5125: np.uint32, 5123: np.uint16, 5121: np.uint8}[a["componentType"]]
        offset = bin_start + view.get("byteOffset", 0) + a.get("byteOffset", 0)
        return np.frombuffer(data, dtype=dtype, count=a["count"] * width, offset=offset).reshape(a["count"], width)

    materials, roles, tau = [], {}, {}
    for m in doc.get("materials", []):
        name = m.get("name", f"material{len(materials)}")
        rgb = m.get("pbrMetallicRoughness", {}).get("baseColorFactor", [DEFAULT_ALBEDO] * 3)[:3]
        materials.append([name, tuple(min(max(float(x), 0.0), 1.0) for x in rgb)])
        roles[name] = m.get("extras", {}).get("prtbake_role", "opaque")
        tau[name] = m.get("extensions", {}).get("KHR_materials_transmission", {}).get("transmissionFactor", 1.0)
    # Primitives index vertex pools (prtbake's export shares one): each pool once.
    positions, normals, tris, tri_mat, pool_base = [], [], [], [], {}
    base = 0
    for node in doc.get("nodes", []):
        if any(k in node for k in ("matrix", "translation", "rotation", "scale", "children")):
            sys.exit(f"{path}: node {node.get('name')!r} has a transform: not a GLB that `prtbake export` wrote")
        for prim in doc["meshes"][node["mesh"]]["primitives"] if "mesh" in node else []:
            if prim.get("mode", 4) != 4:
                sys.exit(f"{path}: a primitive of mode {prim['mode']}: triangles only")
            pool = prim["attributes"]["POSITION"]
            if pool not in pool_base:
                pool_base[pool] = base
                positions.append(accessor(pool).astype(np.float32))
                normal = prim["attributes"].get("NORMAL")
                normals.append(accessor(normal).astype(np.float32) if normal is not None else None)
                base += len(positions[-1])
            t = accessor(prim["indices"]).reshape(-1, 3).astype(np.uint32) + pool_base[pool]
            tris.append(t)
            tri_mat.append(np.full(len(t), prim.get("material", 0)))
    normals = np.concatenate(normals) if normals and all(n is not None for n in normals) else None
    return np.concatenate(positions), np.concatenate(tris), np.concatenate(tri_mat), materials, roles, tau, normals


def window_materials(obj_path, materials, meta, glb_roles=None):
    """Names of the mesh's window materials: `prtbake_role window` (MTL, or
    the GLB's materials given as `glb_roles`), or a match of the bundle's
    recorded `--window` patterns. Exits on one whose
    transmittance is below 1."""
    import fnmatch
    roles, tau = glb_roles or ({}, {})
    base = os.path.dirname(obj_path)
    libs = []
    if glb_roles is None:
        with open(obj_path) as f:
            libs = [" ".join(l.split()[1:]) for l in f if l.startswith("mtllib")]
    for lib in libs:
        name = None
        with open(os.path.join(base, lib)) as f:
            for line in f:
                parts = line.split()
                if parts and parts[0] == "newmtl":
                    name = " ".join(parts[1:])
                elif parts and parts[0] == "prtbake_role" and name is not None:
                    roles[name] = parts[1]
                elif parts and parts[0] == "prtbake_transmittance" and name is not None:
                    tau[name] = float(parts[1])
    patterns = [p.split("=")[0] for p in (meta.get("window_patterns") or [])]
    names = {m[0] for m in materials if roles.get(m[0]) == "window" or any(fnmatch.fnmatchcase(m[0], p) for p in patterns)}
    for n in names:
        if tau.get(n, 1.0) < 1.0:
            sys.exit(f"{obj_path}: window material {n!r} has transmittance {tau[n]}: only panes of transmittance 1 are modelled")
    return names


def load_mtl(path):
    kd, name = {}, None
    with open(path) as f:
        for line in f:
            parts = line.split()
            if parts and parts[0] == "newmtl":
                name = " ".join(parts[1:])
                kd.setdefault(name, (DEFAULT_ALBEDO,) * 3)
            elif parts and parts[0] == "Kd" and name is not None:
                kd[name] = tuple(min(max(float(x), 0.0), 1.0) for x in parts[1:4])
    return kd


def equirect_dirs(width, height):
    """prtbake's equirect convention (sh::equirect_direction): theta = pi v from +Y,
    phi = 2 pi (u - 0.5), direction (sin t sin p, cos t, -sin t cos p), at texel centres."""
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height
    theta = math.pi * v[:, None]
    phi = 2 * math.pi * (u[None, :] - 0.5)
    return np.stack([np.sin(theta) * np.sin(phi), np.cos(theta) * np.ones_like(phi), -np.sin(theta) * np.cos(phi)], -1)


def real_sh(order, d):
    """Orthonormal real SH of bands 0..order-1 at unit directions d (..., 3), by
    Gram-Schmidt-free closed forms up to band 4."""
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    out = [0.5 * math.sqrt(1 / math.pi) * np.ones_like(x)]
    if order > 1:
        c = math.sqrt(3 / (4 * math.pi))
        out += [c * y, c * z, c * x]
    if order > 2:
        out += [
            0.5 * math.sqrt(15 / math.pi) * x * y,
            0.5 * math.sqrt(15 / math.pi) * y * z,
            0.25 * math.sqrt(5 / math.pi) * (3 * z * z - 1),
            0.5 * math.sqrt(15 / math.pi) * x * z,
            0.25 * math.sqrt(15 / math.pi) * (x * x - y * y),
        ]
    if order > 3:
        out += [
            0.25 * math.sqrt(35 / (2 * math.pi)) * y * (3 * x * x - y * y),
            0.5 * math.sqrt(105 / math.pi) * x * y * z,
            0.25 * math.sqrt(21 / (2 * math.pi)) * y * (5 * z * z - 1),
            0.25 * math.sqrt(7 / math.pi) * z * (5 * z * z - 3),
            0.25 * math.sqrt(21 / (2 * math.pi)) * x * (5 * z * z - 1),
            0.25 * math.sqrt(105 / math.pi) * z * (x * x - y * y),
            0.25 * math.sqrt(35 / (2 * math.pi)) * x * (x * x - 3 * y * y),
        ]
    if order > 4:
        sys.exit(f"SH order {order}: this script expands bands 0..3 only")
    return np.stack(out, -1)


def band_limited(image, order):
    """The equirect `image` projected on SH bands 0..order-1 and expanded back (exact texel solid angles)."""
    h, w, _ = image.shape
    d = equirect_dirs(w, h)
    v0 = np.arange(h) / h
    v1 = (np.arange(h) + 1) / h
    solid = (2 * math.pi / w) * (np.cos(math.pi * v0) - np.cos(math.pi * v1))
    basis = real_sh(order, d)  # h, w, n
    weights = basis * solid[:, None, None]
    coeffs = np.einsum("hwn,hwc->nc", weights, image.astype(np.float64))
    return np.einsum("hwn,nc->hwc", basis, coeffs).astype(np.float32)


def luminance(rgb):
    return 0.2126 * rgb[..., 0] + 0.7152 * rgb[..., 1] + 0.0722 * rgb[..., 2]


def tonemap(rgb, key):
    x = rgb * key
    x = x / (1 + x)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(np.maximum(x, 0), 1 / 2.4) - 0.055).clip(0, 1).astype(np.float32)


def errors(test, ref, mask):
    t, r = test[mask], ref[mask]
    l2 = math.sqrt(float(((t - r) ** 2).sum()) / max(float((r**2).sum()), 1e-30))
    eps = 0.01 * float((r**2).mean())
    relmse = float((((t - r) ** 2) / (r**2 + eps)).mean())
    return l2, relmse


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("bundle")
    ap.add_argument("mesh", nargs="?", default=None,
                    help="the OBJ the bundle was baked from, or a GLB of `prtbake export`; default: the bundle's own mesh, exported")
    light = ap.add_mutually_exclusive_group(required=True)
    light.add_argument("--env")
    light.add_argument("--step", type=int, help="a time-lapse step: its sky and sun (needs examples/sky_env)")
    ap.add_argument("--camera", required=True)
    ap.add_argument("--fov", type=float, default=50.0)
    ap.add_argument("--size", default="320x240")
    ap.add_argument("--bounces", type=int, default=None, help="default: the bundle's (prtbake inspect)")
    ap.add_argument("--order", type=int, default=None, help="SH order; default: the bundle's")
    ap.add_argument("--spp", type=int, default=512)
    ap.add_argument("--supersample", type=int, default=4, help="prtbake renders at K times the size, box-averaged K x K")
    ap.add_argument("--env-yaw", type=float, default=180.0,
                    help="Mitsuba's envmap turned about +Y so its texels point where prtbake's do (its u = 0 looks down -Z, prtbake's u = 0.5)")
    ap.add_argument("--reference", choices=["open", "window"], default="open",
                    help="(a)'s light transport: open (windows removed, light enters wherever the mesh lets it: "
                         "right for a closed room) or window (window mode's own model: a ray counts the sky only "
                         "where its first hit is glass; for meshes with gaps, such as a car)")
    ap.add_argument("--prtbake", default=os.path.join(ROOT, "target", "release", "prtbake"))
    ap.add_argument("--variant", default="llvm_ad_rgb")
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--flat-normals", action="store_true",
                    help="Mitsuba shades flat faces even where the mesh gives vertex normals (the references before 2026-11-29)")
    ap.add_argument("--cache", default=None, help="folder for the Mitsuba references (default: OUTDIR)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    width, height = (int(x) for x in args.size.lower().split("x"))

    info = json.loads(subprocess.run([args.prtbake, "inspect", args.bundle, "--json"], check=True, capture_output=True, text=True).stdout)
    meta = info.get("meta", info)
    order = args.order or int(find_key(meta, "order") or 3)
    # A direct-only bake records 0 bounces: not "absent".
    recorded = find_key(meta, "bounces")
    bounces = args.bounces if args.bounces is not None else int(recorded if recorded is not None else 1)

    # prtbake's side: linear radiance at K times the size, K x K averaged.
    k = args.supersample
    shot = os.path.join(args.out, f"prtbake_{k}x.exr")
    started = time.time()
    light_args = ["--env", args.env] if args.env else ["--step", str(args.step)]
    subprocess.run([args.prtbake, "view", args.bundle, *light_args, f"--camera={args.camera}", "--fov", str(args.fov),
                    "--size", f"{k * width}x{k * height}", "--screenshot", shot], check=True, capture_output=True)
    view_seconds = time.time() - started

    import mitsuba as mi
    import drjit as dr
    mi.set_variant(args.variant)
    ours = np.array(mi.Bitmap(shot).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32))[..., :3]
    ours = ours.reshape(height, k, width, k, 3).mean(axis=(1, 3))

    def read_map(path):
        return np.array(mi.Bitmap(path).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32))[..., :3]

    sun = None
    if args.env:
        env = read_map(args.env)
        env_sh = band_limited(env, order)
        light_key = [os.path.abspath(args.env)]
    else:
        # The step's sky as the viewer applies it, the full sky, and the sun.
        tool = os.path.join(os.path.dirname(args.prtbake), "examples", "sky_env")
        sh_path, full_path = os.path.join(args.out, "sky_sh.exr"), os.path.join(args.out, "sky_full.exr")
        step = json.loads(subprocess.run([tool, args.bundle, str(args.step), str(order), sh_path, full_path],
                                         check=True, capture_output=True, text=True).stdout)
        env_sh, env = read_map(sh_path), read_map(full_path)
        sun = None if step["night"] else step
        # Bundles of one scene and day share their references.
        light_key = [args.step, step, hashlib.sha256(env_sh.tobytes() + env.tobytes()).hexdigest()]

    if args.mesh is None:
        # Into OUTDIR, never over a file the script did not write there.
        args.mesh = os.path.join(args.out, "prtbake_export.glb")
        if os.path.exists(args.mesh) and not is_export_glb(args.mesh):
            sys.exit(f"{args.mesh}: exists and is not a GLB of `prtbake export`; not overwritten")
        subprocess.run([args.prtbake, "export", args.bundle, "-o", args.mesh], check=True, capture_output=True)
    if args.mesh.lower().endswith((".glb", ".gltf")):
        positions, tris, tri_mat, materials, roles, tau, normals = load_export_glb(args.mesh)
        windows = window_materials(args.mesh, materials, meta, (roles, tau))
    else:
        positions, tris, tri_mat, materials, normals = load_obj_rgb(args.mesh)
        windows = window_materials(args.mesh, materials, meta)
    if normals is None or args.flat_normals:
        normals = None
        print("Mitsuba shades flat faces (the mesh gives no normal per vertex, or --flat-normals)", file=sys.stderr)
    shapes, glass = {}, {}
    for m, (name, rgb) in enumerate(materials):
        sel = tris[tri_mat == m]
        if len(sel) == 0:
            continue
        used, remap = np.unique(sel, return_inverse=True)
        mesh = mi.Mesh(f"m{m}", len(used), len(sel), has_vertex_normals=normals is not None)
        params = mi.traverse(mesh)
        params["vertex_positions"] = mi.Float(positions[used].ravel())
        params["faces"] = mi.UInt32(remap.astype(np.uint32).ravel())
        if normals is not None:
            # The viewer's shading normals: the cosines of both renderers are the same ones.
            params["vertex_normals"] = mi.Float(normals[used].ravel())
        params.update()
        mesh.set_bsdf(mi.load_dict({"type": "twosided", "material": {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(rgb)}}}))
        (glass if name in windows else shapes)[f"m{m}"] = mesh
    if args.reference == "window" and not args.env:
        sys.exit("--reference window is for --env (a step's sun through glass is not modelled there yet)")
    if args.reference == "window" and not glass:
        sys.exit(f"{args.mesh}: --reference window needs window materials, and this mesh has none")
    e = [float(x) for x in args.camera.split(",")]
    sensor = {
        "type": "perspective", "fov": args.fov, "fov_axis": "y",
        "to_world": mi.ScalarTransform4f().look_at(origin=e[:3], target=e[3:], up=[0, 1, 0]),
        "film": {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"}, "pixel_format": "rgb"},
        "sampler": {"type": "independent", "sample_count": args.spp},
    }

    def sun_emitter():
        # Mitsuba's direction is the light's travel, away from the sun; irradiance on a facing surface.
        return {"type": "directional", "direction": [-x for x in sun["direction"]],
                "irradiance": {"type": "rgb", "value": list(sun["sun_rgb"])}}

    def render(env_image, seed, spp=None, with_sun=False, depth=None):
        emitters = {}
        if env_image is not None:
            emitters["emitter"] = {"type": "envmap", "bitmap": mi.Bitmap(env_image.astype(np.float32)),
                                   "to_world": mi.ScalarTransform4f().rotate([0, 1, 0], args.env_yaw)}
        if with_sun and sun is not None:
            emitters["sun"] = sun_emitter()
        scene = mi.load_dict({
            "type": "scene", **shapes, "sensor": sensor, **emitters,
            "integrator": {"type": "path", "max_depth": depth or bounces + 2, "rr_depth": 1000, "hide_emitters": True},
        })
        return np.array(mi.render(scene, seed=seed, spp=spp or args.spp))[..., :3]

    def render_a(seed):
        if args.reference == "window":
            return render_window_mode(mi, dr, shapes, glass, sensor, env_sh, bounces, args.spp, seed, width, height)
        # The lighting the bundle sees: the SH sky with its bounces, the sun direct only.
        image = render_signed(env_sh, seed)
        if sun is not None:
            image = image + render(None, seed + 2000, with_sun=True, depth=2)
        return image

    def render_signed(env_image, seed):
        # A band-limited map dips below zero; light is linear, so its
        # positive and negative parts render apart and subtract.
        positive, negative = np.maximum(env_image, 0), np.maximum(-env_image, 0)
        image = render(positive, seed)
        if negative.max() > 0:
            image = image - render(negative, seed + 1000)
        return image

    mask = coverage_mask(mi, dr, mi.load_dict({"type": "scene", **shapes, "sensor": sensor}), width, height,
                         mi.load_dict({"type": "scene", **glass}) if glass else None)
    # The references depend on the scene, light, camera and samples only: kept
    # in --cache (default: OUTDIR) under a key of those, so bundles of one
    # scene are compared against the same images.
    # The triangles' corners, not the vertex arrays: the same triangles however the vertices are pooled.
    mesh_hash = hashlib.sha256(positions[tris].tobytes() + tri_mat.astype(np.int64).tobytes() + json.dumps(materials).encode()
                               + (normals[tris].tobytes() if normals is not None else b"")).hexdigest()
    scene_key = [mesh_hash, *light_key] + ([args.reference] if args.reference != "open" else []) + ([sorted(windows)] if windows else [])
    key = hashlib.sha256(json.dumps(scene_key + [args.camera, args.fov, width, height, args.spp, bounces, order, args.env_yaw]).encode()).hexdigest()[:16]
    cache = os.path.join(args.cache or args.out, f"mitsuba-{key}.npz")
    if os.path.exists(cache):
        stored = np.load(cache)
        refs, second, mitsuba_seconds = {"a": stored["a"], "b": stored["b"]}, stored["second"], float(stored["seconds"])
    else:
        started = time.time()
        refs = {"a": render_a(1), "b": render(env, 1, with_sun=True)}
        mitsuba_seconds = (time.time() - started) / 2
        second = render_a(2)
        os.makedirs(os.path.dirname(cache), exist_ok=True)
        np.savez(cache + ".tmp.npz", a=refs["a"], b=refs["b"], second=second, seconds=mitsuba_seconds)
        os.replace(cache + ".tmp.npz", cache)
    ref_noise = errors(second, refs["a"], mask)[0] / math.sqrt(2)

    import flip_evaluator as flip
    key = 0.18 / max(float(luminance(refs["b"])[mask].mean()), 1e-30)
    result = {"bundle": args.bundle, "size": [width, height], "spp": args.spp, "bounces": bounces, "order": order,
              "covered_pixels": int(mask.sum()), "supersample": k, "mask_grid": MASK_GRID, "view_seconds": view_seconds, "mitsuba_seconds_per_image": mitsuba_seconds,
              "reference_noise_rel_l2": ref_noise}
    mi.Bitmap(ours.astype(np.float32)).write(os.path.join(args.out, "prtbake.exr"))
    np.save(os.path.join(args.out, "mask.npy"), mask)
    save_png(mi, tonemap(ours, key), os.path.join(args.out, "prtbake.png"))
    for name, ref in refs.items():
        mi.Bitmap(ref.astype(np.float32)).write(os.path.join(args.out, f"mitsuba_{name}.exr"))
        save_png(mi, tonemap(ref, key), os.path.join(args.out, f"mitsuba_{name}.png"))
        l2, relmse = errors(ours, ref, mask)
        a, b = tonemap(ref, key), tonemap(ours, key)
        a[~mask] = 0
        b[~mask] = 0
        error_map, _, _ = flip.evaluate(a, b, "LDR")
        save_png(mi, np.asarray(error_map, dtype=np.float32), os.path.join(args.out, f"flip_{name}.png"))
        flip_plain, _, _ = flip.evaluate(a, b, "LDR", applyMagma=False)
        mean_flip = float(np.asarray(flip_plain)[mask].mean())
        diff = np.abs(luminance(ours) - luminance(ref)) / max(float(luminance(ref)[mask].mean()), 1e-30)
        diff[~mask] = 0
        save_png(mi, np.repeat(np.clip(diff * 5, 0, 1)[..., None], 3, -1).astype(np.float32), os.path.join(args.out, f"diff_{name}.png"))
        # The bake and the reference are independent, so their squared errors
        # add: what the bake alone is off by, with the reference's noise taken out.
        bake_only = math.sqrt(max(l2 * l2 - ref_noise * ref_noise, 0.0))
        result[name] = {"rel_l2": l2, "rel_l2_without_reference_noise": bake_only, "relmse": relmse, "flip_mean": mean_flip,
                        "half_error_pixels": where_error_lies(mi, ours, ref, mask, os.path.join(args.out, f"where_{name}.png"))}
    with open(os.path.join(args.out, "result.json"), "w") as f:
        json.dump(result, f, indent=1)
    if args.json:
        print(json.dumps(result))
        return
    print(f"{args.bundle}: {width}x{height}, {int(mask.sum())} covered pixels, Mitsuba {args.spp} spp "
          f"(max_depth {bounces + 2}, {mitsuba_seconds:.1f} s/image; its noise {100 * ref_noise:.2f}% rel L2)")
    full = "full map" if args.env else f"full sky and sun, both with {bounces} bounce(s)"
    seen = ("lighting the bundle sees (SH order %d" % order) + (")" if args.env else ", the sun direct)")
    for name, what in [("a", seen), ("b", full)]:
        r = result[name]
        print(f"  ({name}) {what}: image error {100 * r['rel_l2']:.2f}% rel L2 "
              f"({100 * r['rel_l2_without_reference_noise']:.2f}% without the reference's noise), "
              f"relMSE {r['relmse']:.4f}, FLIP {r['flip_mean']:.4f}; half of its squared error in "
              f"{r['half_error_pixels']} pixels (where_{name}.png)")


def where_error_lies(mi, ours, ref, mask, path):
    """The fewest pixels that hold half of the squared error, drawn over the
    reference's luminance: red where prtbake is brighter, blue where darker.
    Returns their count: a few hundred pixels mean a few features (a thin
    part, a contact line), a large share means noise or a bias everywhere."""
    err = ((ours - ref) ** 2).sum(-1) * mask
    total = float(err.sum())
    if total <= 0:
        save_png(mi, np.zeros(ours.shape, dtype=np.float32), path)
        return 0
    order = np.sort(err.ravel())[::-1]
    count = int(np.searchsorted(np.cumsum(order), 0.5 * total)) + 1
    top = err >= order[count - 1]
    lum_ref, lum_ours = luminance(ref), luminance(ours)
    grey = np.clip(lum_ref / max(float(np.percentile(lum_ref[mask], 99)), 1e-30), 0, 1) ** 0.5 * 0.6
    image = np.repeat(np.where(mask, grey, 0.0)[..., None], 3, -1)
    image[top & (lum_ours > lum_ref)] = [1.0, 0.2, 0.2]
    image[top & (lum_ours <= lum_ref)] = [0.2, 0.5, 1.0]
    save_png(mi, image.astype(np.float32), path)
    return count


MASK_GRID = 8


def render_window_mode(mi, dr, shapes, glass, sensor_dict, env, bounces, spp, seed, width, height, batch=8):
    """Window mode's model, path traced: from each camera hit, cosine-sampled
    bounces (two-sided Lambertian); a ray whose first hit is glass takes the
    equirect `env` (prtbake's convention, nearest texel) in its direction, a
    ray that escapes without meeting glass takes nothing (a gap in the body).
    Camera rays see through glass. Box filter: uniform jitter in the pixel."""
    opaque = mi.load_dict({"type": "scene", **shapes, "sensor": sensor_dict})
    everything = mi.load_dict({"type": "scene", **shapes, **glass})
    sensor = opaque.sensors()[0]
    env_h, env_w = env.shape[:2]
    ys, xs = np.meshgrid(np.arange(height), np.arange(width), indexing="ij")
    xs, ys = np.tile(xs.ravel(), batch), np.tile(ys.ravel(), batch)
    n = xs.size
    rng = np.random.default_rng(seed)
    total = np.zeros((n, 3))
    passes = max(1, spp // batch)
    for _ in range(passes):
        jitter = rng.random((n, 2))
        pos = mi.Point2f(mi.Float((xs + jitter[:, 0]) / width), mi.Float((ys + jitter[:, 1]) / height))
        rays, _ = sensor.sample_ray(0.0, 0.5, pos, mi.Point2f(0.5, 0.5))
        si = opaque.ray_intersect(rays)
        alive = np.array(si.is_valid())
        throughput = np.ones((n, 3))
        for _depth in range(bounces + 1):
            albedo = np.array(si.bsdf().eval_diffuse_reflectance(si, mi.Bool(alive)))
            albedo = albedo.T if albedo.shape == (3, n) else albedo  # Dr.Jit gives channels first
            throughput *= np.where(alive[:, None], albedo, 0.0)
            u = rng.random((n, 2))
            local = mi.warp.square_to_cosine_hemisphere(mi.Point2f(mi.Float(u[:, 0]), mi.Float(u[:, 1])))
            # Two-sided: sample the side the ray arrived on.
            flip = mi.Float(np.where(np.array(si.wi.z) < 0, -1.0, 1.0))
            local = mi.Vector3f(local.x, local.y, local.z * flip)
            ray = si.spawn_ray(si.to_world(local))
            hit_opaque = opaque.ray_intersect(ray)
            hit_any = everything.ray_intersect(ray)
            t_opaque = np.where(np.array(hit_opaque.is_valid()), np.array(hit_opaque.t), np.inf)
            t_any = np.where(np.array(hit_any.is_valid()), np.array(hit_any.t), np.inf)
            through_glass = alive & (t_any < t_opaque)
            d = np.stack([np.array(ray.d.x), np.array(ray.d.y), np.array(ray.d.z)], -1)
            v = np.arccos(np.clip(d[:, 1], -1, 1)) / math.pi
            uu = np.mod(np.arctan2(d[:, 0], -d[:, 2]) / (2 * math.pi) + 0.5, 1.0)
            texel = env[np.minimum((v * env_h).astype(int), env_h - 1), np.minimum((uu * env_w).astype(int), env_w - 1)]
            total += np.where(through_glass[:, None], throughput * texel, 0.0)
            alive = alive & ~through_glass & np.isfinite(t_opaque)
            si = hit_opaque
    return (total / passes).reshape(batch, height, width, 3).mean(axis=0).astype(np.float32)


def coverage_mask(mi, dr, scene, width, height, glass_only=None):
    """Pixels wholly on geometry: all rays of a MASK_GRID x MASK_GRID grid
    through the pixel meet it, and (given `glass_only`, a scene of the
    windows alone) meet it clear of any glass. The backdrop, the pixels a silhouette
    crosses and those seen through glass (the viewer draws the backdrop
    behind glass, Mitsuba what lies there: a car's hood, its mirrors), which
    are not the bake's, are left out."""
    sensor = scene.sensors()[0]
    hits = np.ones((height, width), dtype=bool)
    ys, xs = np.meshgrid(np.arange(height), np.arange(width), indexing="ij")
    steps = (np.arange(MASK_GRID) + 0.5) / MASK_GRID
    for dy in steps:
        for dx in steps:
            pos = mi.Point2f(mi.Float(((xs + dx) / width).ravel()), mi.Float(((ys + dy) / height).ravel()))
            rays, _ = sensor.sample_ray(0.0, 0.5, pos, mi.Point2f(0.5, 0.5))
            si = scene.ray_intersect(rays)
            hit = np.array(si.is_valid())
            if glass_only is not None:
                # Glass in front of the hit, or within a thousandth of its
                # distance behind it (a pane's rim in a frame): the viewer may
                # draw the pane there.
                pane = glass_only.ray_intersect(rays)
                hit &= ~(np.array(pane.is_valid()) & (np.array(pane.t) <= np.array(si.t) * (1 + 1e-3)))
            hits &= hit.reshape(height, width)
    return hits


def find_key(tree, key):
    if isinstance(tree, dict):
        if key in tree and not isinstance(tree[key], (dict, list)):
            return tree[key]
        for v in tree.values():
            found = find_key(v, key)
            if found is not None:
                return found
    elif isinstance(tree, list):
        for v in tree:
            found = find_key(v, key)
            if found is not None:
                return found
    return None


def save_png(mi, ldr, path):
    """`ldr` already display-encoded (0..1): written as 8-bit sRGB-tagged PNG without re-encoding."""
    mi.Bitmap((np.clip(ldr, 0, 1) * 255 + 0.5).astype(np.uint8), mi.Bitmap.PixelFormat.RGB).write(path)


if __name__ == "__main__":
    main()
