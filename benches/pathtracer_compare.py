#!/usr/bin/env python3
"""The picture against a path tracer: `prtbake view`'s linear screenshot of a
bundle beside Mitsuba 3's rendering of the same mesh, camera and light.

usage:
    target/mitsuba-venv/bin/python benches/pathtracer_compare.py BUNDLE MESH.obj \\
        (--env MAP.exr | --step K) --camera EX,EY,EZ,TX,TY,TZ [--fov 50] [--size 320x240] \\
        [--bounces B] [--spp 512] [--prtbake target/release/prtbake] -o OUTDIR [--json]

Needs numpy, mitsuba and flip-evaluator (PyPI) in a virtualenv:
    python3 -m venv target/mitsuba-venv
    target/mitsuba-venv/bin/pip install mitsuba numpy flip-evaluator
(the LLVM variant needs a shared libLLVM, see benches/mitsuba_probe.py).

The mesh is the OBJ the bundle was baked from (loaded as prtbake loads it:
Y up, no clean), every surface Lambertian and two-sided with its MTL Kd (0.8
where there is none), RGB. Windows (MTL `prtbake_role window`, or the
bundle's `--window` patterns) of transmittance 1 are left out of Mitsuba's
scene: light passes them unchanged, as the bake counts it (a window of
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

prtbake's side is `view --screenshot OUT.exr` (linear radiance) at
--supersample times the size (default 4), box-averaged (Mitsuba's box filter
averages over each pixel too). Only pixels wholly on geometry count: all 64
rays of an 8x8 grid through the pixel meet geometry. A pixel a silhouette
crosses holds backdrop in both images, but not the same backdrop (black in
Mitsuba, the sky in the viewer): on the grey-white room's window bars a 2x2
test let those pixels through, and they carried a quarter of the error.

Printed per reference: relative L2 over pixels, sqrt(sum (x-y)^2 / sum y^2)
over RGB ("image error"); mean relMSE, mean((x-y)^2 / (y^2 + 0.01 mean(y)^2));
and mean FLIP (flip-evaluator, LDR) on both images tone-mapped alike
(exposure 0.18 / the reference's mean luminance, Reinhard, sRGB). The
reference's own noise is the same L2 between two Mitsuba seeds divided by
sqrt(2); the bake's own error is then sqrt(L2^2 - noise^2) (independent
errors add in squares), printed beside the raw figure. Writes OUTDIR/{prtbake,mitsuba_a,mitsuba_b}.exr, tone-mapped PNGs and
the FLIP error maps (flip_a.png, flip_b.png).
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
    """Positions, triangles (fan-triangulated faces) and per-triangle material index; materials [(name, rgb)]."""
    positions, tris, tri_mat, materials, index = [], [], [], [], {}
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
            elif parts[0] == "f":
                ids = []
                for p in parts[1:]:
                    i = int(p.split("/")[0])
                    ids.append(i - 1 if i > 0 else len(positions) + i)
                for k in range(1, len(ids) - 1):
                    tris.append([ids[0], ids[k], ids[k + 1]])
                    tri_mat.append(current)
            elif parts[0] == "usemtl":
                current = material(" ".join(parts[1:]))
            elif parts[0] == "mtllib":
                kd.update(load_mtl(os.path.join(base, " ".join(parts[1:]))))
                for m in materials:
                    m[1] = kd.get(m[0], m[1])
    return np.array(positions, dtype=np.float32), np.array(tris, dtype=np.uint32), np.array(tri_mat), materials


def window_materials(obj_path, materials, meta):
    """Names of the OBJ's window materials: MTL `prtbake_role window`, or a
    match of the bundle's recorded `--window` patterns. Exits on one whose
    transmittance is below 1."""
    import fnmatch
    roles, tau = {}, {}
    base = os.path.dirname(obj_path)
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
    ap.add_argument("mesh")
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
    ap.add_argument("--prtbake", default=os.path.join(ROOT, "target", "release", "prtbake"))
    ap.add_argument("--variant", default="llvm_ad_rgb")
    ap.add_argument("-o", "--out", required=True)
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

    positions, tris, tri_mat, materials = load_obj_rgb(args.mesh)
    windows = window_materials(args.mesh, materials, meta)
    shapes = {}
    for m, (name, rgb) in enumerate(materials):
        sel = tris[tri_mat == m]
        if len(sel) == 0 or name in windows:
            continue
        used, remap = np.unique(sel, return_inverse=True)
        mesh = mi.Mesh(f"m{m}", len(used), len(sel), has_vertex_normals=False)
        params = mi.traverse(mesh)
        params["vertex_positions"] = mi.Float(positions[used].ravel())
        params["faces"] = mi.UInt32(remap.astype(np.uint32).ravel())
        params.update()
        mesh.set_bsdf(mi.load_dict({"type": "twosided", "material": {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(rgb)}}}))
        shapes[f"m{m}"] = mesh
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

    mask = coverage_mask(mi, dr, mi.load_dict({"type": "scene", **shapes, "sensor": sensor}), width, height)
    # The references depend on the scene, light, camera and samples only: kept
    # in --cache (default: OUTDIR) under a key of those, so bundles of one
    # scene are compared against the same images.
    scene_key = [os.path.abspath(args.mesh), os.path.getsize(args.mesh), *light_key] + ([sorted(windows)] if windows else [])
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
        result[name] = {"rel_l2": l2, "rel_l2_without_reference_noise": bake_only, "relmse": relmse, "flip_mean": mean_flip}
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
              f"relMSE {r['relmse']:.4f}, FLIP {r['flip_mean']:.4f}")


MASK_GRID = 8


def coverage_mask(mi, dr, scene, width, height):
    """Pixels wholly on geometry: all rays of a MASK_GRID x MASK_GRID grid
    through the pixel meet it. The backdrop and the pixels a silhouette
    crosses, which are not the bake's, are left out."""
    sensor = scene.sensors()[0]
    hits = np.ones((height, width), dtype=bool)
    ys, xs = np.meshgrid(np.arange(height), np.arange(width), indexing="ij")
    steps = (np.arange(MASK_GRID) + 0.5) / MASK_GRID
    for dy in steps:
        for dx in steps:
            pos = mi.Point2f(mi.Float(((xs + dx) / width).ravel()), mi.Float(((ys + dy) / height).ravel()))
            rays, _ = sensor.sample_ray(0.0, 0.5, pos, mi.Point2f(0.5, 0.5))
            si = scene.ray_intersect(rays)
            hits &= np.array(si.is_valid()).reshape(height, width)
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
