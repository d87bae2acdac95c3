#!/usr/bin/env python3
"""Converts a Mitsuba 0.5/2 scene (scene.xml with `obj` and `rectangle`
shapes) into one OBJ + MTL that prtbake loads.

    python3 scripts/convert_mitsuba.py SCENE_DIR OUT.obj [--force] [--keep-emitters]
        [--pane A:B:C]... [--pane-from-emitter NAME]... [--pane-grow G]

Used for the CC-BY dining room ("The Breakfast Room" by Wig42, Mitsuba
version from jgarciapueyo/mitsuba2-transient-scenes, folder dining-room/)
and the CC-BY "Country Kitchen" by Jay-Artist (same repository, kitchen/):
clone that repository yourself and point SCENE_DIR at the scene's folder. The
converted mesh stays out of git (it is third-party data; see its
LICENSE.txt for the credit it needs).

What it keeps, and how:
- every `obj` shape, its `toWorld` matrix applied to positions (and the
  inverse transpose to normals), as one OBJ object named after the file
  stem (so `--window` globs can pick shapes by name);
- `rectangle` shapes as two triangles of the transformed square [-1, 1]²,
  as an object named `rectangle<N>` (N = the shape's place among the
  scene's shapes, from 0);
- the `ref`ed BSDF as the material (`usemtl` = the BSDF id). Ids are found
  at any depth: Mitsuba's `twosided`, `bumpmap`, `mask` (and Mitsuba 2's
  `normalmap`) wrap an inner BSDF, and either may carry the id (the
  kitchen's `Cushion1` is a `twosided` inside a `bumpmap`). `Kd` comes from
  the innermost real BSDF under the wrappers: `reflectance` /
  `diffuseReflectance` (rgb), 0.5 grey where that is a bitmap texture (no
  image decoding here), and the mean `specularReflectance` × 0.5 for
  conductors (prtbake is diffuse-only). A shape with no `ref` uses its
  inline BSDF's id if it has one, else a 0.5 grey `default`;
- one shared vertex pool (`v`/`vt`/`vn` indices are global), so the loader
  sees the mesh as Mitsuba does. The camera and the integrator are ignored;
  the camera's eye and target are printed for `view --camera`.

Emitters. A shape with an `<emitter>` child (an area light) is dropped, and
named on stderr as "dropped emitter shape NAME (...)": kept, it would be an
opaque quad (the kitchen's `rectangle295` sits in the window opening, so in
open mode the room was black inside but for a glow on the ceiling where
light leaked past it). `--keep-emitters` keeps them, each under a material
`emitter_NAME` (Kd from its own BSDF; prtbake has no emitter role, so the
material is opaque). Scene-wide emitters (`envmap`, `sun`, ...) are not
shapes and are ignored as before.

Panes. prtbake's window mode lets light in only through glass: a material
with `prtbake_role window` (and `prtbake_transmittance 1`, clear; a bake's
`--window 'pane=0.7'` sets another). Mitsuba scenes lit by an environment
usually have open holes instead, so:
- `--pane A:B:C` (repeatable) adds a glass parallelogram: three corners in
  the scene's world coordinates, each `X,Y,Z`; the fourth is B + C - A.
  Two triangles, object `pane<K>` (K from 0), material `pane`, normal
  (B - A) × (C - A). Robust: it goes exactly where you say.
- `--pane-from-emitter NAME` (repeatable) puts a pane where the rectangle
  emitter NAME (a name from the "dropped emitter shape" lines) was, instead
  of it, with the emitter's orientation (object `pane_NAME`). Only the
  rectangles you name: the XML cannot tell a light quad outside a window
  from one inside the room (the kitchen's `rectangle296`..`298` are strip
  lights under the wall cupboards).
- `--pane-grow G` moves every edge of every pane outward by G along its
  side (G on each side of a rectangle; default 0), so a pane can reach into
  the reveal it closes instead of leaving a slit beside it.
With panes, a BSDF called `pane` would clash with their material: refused.

Examples, on the scenes' own coordinates (metres, +Y up):
- Dining room: the window is a hole in the `Walls` mesh (models/Mesh048.obj)
  at x = 5.133022, y 1.872104..6.862088, z -4.055528..2.823203; the blinds
  (material `None`, models/Mesh024.obj) hang across it, their slats reaching
  from x = 5.03 out to 5.263. Window mode lights a point when the first
  thing toward the sun is glass, so the pane goes outside the slats, at
  x = 5.27 (a pane in the hole's plane cuts them: their outer halves cast
  no shadow, and the slat shadows come out half as wide as they are), and
  0.5 m wider than the hole on every side, so oblique rays leaving the
  hole still meet it (normal -X, into the room):
      --pane 5.27,1.372104,-4.555528:5.27,1.372104,3.323203:5.27,7.362088,-4.555528
- Kitchen: `rectangle295` (x -0.7515..0.8721, y 0.8731..3.0744,
  z = -3.1173) sits inside the window's reveal (x -0.7661..0.8841,
  y 0.8631..3.0790, z -3.1613..-2.4732), 0.5 to 1.5 cm short of it on each
  side; grown by 2 cm it closes the reveal:
      --pane-from-emitter rectangle295 --pane-grow 0.02

At the end, stderr says how many shapes (and triangles) were kept, how many
emitter shapes dropped and how many panes added.

OUT.obj and OUT.mtl are written to temporaries and renamed together; an
existing OUT.obj or OUT.mtl is replaced only with --force, and never when it
is one of the scene's own files. Only the Python standard library is used.
"""

import math
import os
import sys
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

# BSDFs that wrap one inner BSDF (the material is the inner one's).
WRAPPERS = ("twosided", "bumpmap", "mask", "normalmap")
PANE_MATERIAL = "pane"


def matrix_of(shape):
    """The shape's toWorld matrix, row-major 4×4 (identity when absent)."""
    transform = shape.find("transform[@name='toWorld']")
    if transform is None:
        return [[1.0 if i == j else 0.0 for j in range(4)] for i in range(4)]
    m = transform.find("matrix")
    if m is None:
        raise SystemExit(f"shape {shape.attrib}: only <matrix> transforms are supported")
    try:
        values = [float(x) for x in m.attrib["value"].replace(",", " ").split()]
    except ValueError as e:
        raise SystemExit(f"shape {shape.attrib}: bad matrix: {e}")
    if len(values) != 16 or not all(abs(v) < float("inf") for v in values):
        raise SystemExit(f"shape {shape.attrib}: matrix needs 16 finite values, got {values}")
    return [values[4 * r:4 * r + 4] for r in range(4)]


def apply_point(m, p):
    return tuple(sum(m[r][c] * p[c] for c in range(3)) + m[r][3] for r in range(3))


def determinant(m):
    return sum(m[0][c] * (m[1][(c + 1) % 3] * m[2][(c + 2) % 3] - m[1][(c + 2) % 3] * m[2][(c + 1) % 3]) for c in range(3))


def normal_matrix(m):
    """Inverse transpose of the upper 3×3 (cofactor form, no numpy)."""
    a = [row[:3] for row in m[:3]]
    cof = [[a[(r + 1) % 3][(c + 1) % 3] * a[(r + 2) % 3][(c + 2) % 3] - a[(r + 1) % 3][(c + 2) % 3] * a[(r + 2) % 3][(c + 1) % 3]
            for c in range(3)] for r in range(3)]
    det = sum(a[0][c] * cof[0][c] for c in range(3))
    if det == 0.0:
        return [[0.0] * 3 for _ in range(3)]
    return [[cof[r][c] / det for c in range(3)] for r in range(3)]


def apply_normal(n3, v):
    x, y, z = (sum(n3[r][c] * v[c] for c in range(3)) for r in range(3))
    length = (x * x + y * y + z * z) ** 0.5
    return (x / length, y / length, z / length) if length > 0.0 else (0.0, 1.0, 0.0)


def rgb(element):
    values = [float(x) for x in element.attrib["value"].replace(",", " ").split()]
    return values * 3 if len(values) == 1 else values[:3]


def index_bsdfs(root, scene_file):
    """Every BSDF with an id, at any depth (a wrapper's inner BSDF may carry it)."""
    bsdfs = {}
    for bsdf in root.iter("bsdf"):
        name = bsdf.attrib.get("id")
        if name is None:
            continue
        if name in bsdfs:
            sys.exit(f"{scene_file}: BSDF id {name!r} is defined twice")
        bsdfs[name] = bsdf
    return bsdfs


def innermost(bsdf, bsdfs):
    """The real BSDF under any `twosided` / `bumpmap` / `mask` / `normalmap`
    wrappers (an inner `<ref id=...>` is followed too)."""
    seen = set()
    while bsdf.attrib.get("type") in WRAPPERS and id(bsdf) not in seen:
        seen.add(id(bsdf))
        inner = bsdf.find("bsdf")
        if inner is None:
            ref = bsdf.find("ref")
            inner = bsdfs.get(ref.attrib.get("id")) if ref is not None else None
        if inner is None:
            break
        bsdf = inner
    return bsdf


def albedo_of(bsdf, bsdfs):
    """Kd for a BSDF element: its innermost real BSDF's reflectance."""
    bsdf = innermost(bsdf, bsdfs)
    for name in ("reflectance", "diffuseReflectance"):
        element = bsdf.find(f"rgb[@name='{name}']")
        if element is not None:
            return rgb(element)
        if bsdf.find(f"texture[@name='{name}']") is not None:
            return [0.5, 0.5, 0.5]
    element = bsdf.find("rgb[@name='specularReflectance']")
    if element is not None:
        mean = sum(rgb(element)) / 3.0
        return [0.5 * mean] * 3
    return [0.5, 0.5, 0.5]


def read_obj(path):
    """(positions, uvs, normals, faces) of a plain OBJ; faces as lists of
    (v, vt, vn) 0-based indices (vt, vn may be None), polygons fanned."""
    positions, uvs, normals, faces = [], [], [], []
    for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            positions.append(tuple(float(x) for x in parts[1:4]))
        elif parts[0] == "vt":
            uvs.append(tuple(float(x) for x in parts[1:3]))
        elif parts[0] == "vn":
            normals.append(tuple(float(x) for x in parts[1:4]))
        elif parts[0] == "f":
            corners = []
            for token in parts[1:]:
                fields = token.split("/") + ["", ""]
                index = lambda s, count: (int(s) - 1 if int(s) > 0 else count + int(s)) if s else None
                corners.append((index(fields[0], len(positions)), index(fields[1], len(uvs)), index(fields[2], len(normals))))
            for k in range(1, len(corners) - 1):
                faces.append([corners[0], corners[k], corners[k + 1]])
    return positions, uvs, normals, faces


def usage_error(message):
    print(__doc__.split("\n\n")[1], file=sys.stderr)
    print(f"error: {message}", file=sys.stderr)
    sys.exit(2)


def parse_args(argv):
    """(scene_dir, out, options); options: force, keep_emitters, panes (lists
    of three corners), pane_emitters (names), pane_grow."""
    options = {"force": False, "keep_emitters": False, "panes": [], "pane_emitters": [], "pane_grow": 0.0}
    positional = []
    i = 0
    while i < len(argv):
        arg = argv[i]
        i += 1
        if arg in ("-h", "--help"):
            print(__doc__)
            sys.exit(0)
        if arg == "--":
            positional.extend(argv[i:])
            break
        if not arg.startswith("--"):
            positional.append(arg)
            continue
        name, has_value, value = arg.partition("=")
        if name in ("--force", "--keep-emitters"):
            if has_value:
                usage_error(f"{name} takes no value")
            options[name[2:].replace("-", "_")] = True
            continue
        if name not in ("--pane", "--pane-from-emitter", "--pane-grow"):
            usage_error(f"unknown option {arg}")
        if not has_value:
            if i >= len(argv):
                usage_error(f"{name} needs a value")
            value = argv[i]
            i += 1
        if name == "--pane":
            options["panes"].append(parse_pane(value))
        elif name == "--pane-from-emitter":
            options["pane_emitters"].append(value)
        else:
            try:
                grow = float(value)
            except ValueError:
                grow = float("nan")
            if not (math.isfinite(grow) and grow >= 0.0):
                usage_error(f"--pane-grow {value!r}: needs a finite distance >= 0")
            options["pane_grow"] = grow
    if len(positional) != 2:
        usage_error(f"expected SCENE_DIR and OUT.obj, got {len(positional)} argument(s)")
    return Path(positional[0]), Path(positional[1]), options


def parse_pane(value):
    """`X,Y,Z:X,Y,Z:X,Y,Z` -> three corners, checked finite and not collinear."""
    corners = []
    for text in value.split(":"):
        try:
            corner = tuple(float(x) for x in text.split(","))
        except ValueError:
            corner = ()
        if len(corner) != 3 or not all(math.isfinite(x) for x in corner):
            usage_error(f"--pane {value!r}: corner {text!r} is not three finite numbers X,Y,Z")
        corners.append(corner)
    if len(corners) != 3:
        usage_error(f"--pane {value!r}: needs three corners A:B:C (the fourth is B + C - A), got {len(corners)}")
    a, b, c = corners
    u, v = sub(b, a), sub(c, a)
    if length(cross(u, v)) <= 1e-9 * max(length(u) * length(v), 1e-300):
        usage_error(f"--pane {value!r}: the corners are collinear (or repeated); the pane has no area")
    return a, b, c


def sub(p, q):
    return tuple(p[k] - q[k] for k in range(3))


def add(p, q):
    return tuple(p[k] + q[k] for k in range(3))


def scale(p, s):
    return tuple(x * s for x in p)


def cross(u, v):
    return (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])


def length(u):
    return sum(x * x for x in u) ** 0.5


def pane_geometry(a, b, c, grow):
    """Positions, normals and faces of the parallelogram A, B, C, B + C - A
    (two triangles, normal (B - A) × (C - A)), each edge moved out by `grow`."""
    u, v = sub(b, a), sub(c, a)
    du, dv = scale(u, grow / length(u)), scale(v, grow / length(v))
    a = sub(sub(a, du), dv)
    u, v = add(u, scale(du, 2.0)), add(v, scale(dv, 2.0))
    positions = [a, add(a, u), add(add(a, u), v), add(a, v)]
    n = cross(u, v)
    normal = scale(n, 1.0 / length(n))
    faces = [[(0, None, 0), (1, None, 0), (2, None, 0)], [(0, None, 0), (2, None, 0), (3, None, 0)]]
    return positions, [normal], faces


def shape_name(shape, number):
    kind = shape.attrib.get("type")
    if kind == "obj":
        element = shape.find("string[@name='filename']")
        if element is not None and "value" in element.attrib:
            return Path(element.attrib["value"]).stem
    if kind == "rectangle":
        return f"rectangle{number}"
    return f"{kind}{number}"


def main():
    scene_dir, out, options = parse_args(sys.argv[1:])
    force = options["force"]
    scene_file = scene_dir / "scene.xml"
    if not scene_file.is_file():
        sys.exit(f"{scene_file}: not found")
    if out.suffix.lower() != ".obj":
        sys.exit(f"{out}: the output must end in .obj")
    mtl = out.with_suffix(".mtl")
    scene_root = scene_dir.resolve()
    for target in (out, mtl):
        if target.resolve().is_relative_to(scene_root):
            sys.exit(f"{target}: inside the scene folder {scene_dir}; write the conversion elsewhere")
        if target.exists() and not force:
            sys.exit(f"{target}: exists; pass --force to replace it")
        if target.exists() and not target.is_file():
            sys.exit(f"{target}: exists and is not a regular file")
    try:
        root = ET.parse(scene_file).getroot()
    except ET.ParseError as e:
        sys.exit(f"{scene_file}: not valid XML: {e}")
    bsdfs = index_bsdfs(root, scene_file)
    if (options["panes"] or options["pane_emitters"]) and PANE_MATERIAL in bsdfs:
        sys.exit(f"{scene_file}: a BSDF is called {PANE_MATERIAL!r}, the name of the pane material; rename it")
    shapes = root.findall("shape")

    # Emitters named by --pane-from-emitter must be rectangle emitters: checked
    # before any mesh is read.
    emitter_rectangles = [shape_name(s, n) for n, s in enumerate(shapes)
                          if s.find("emitter") is not None and s.attrib.get("type") == "rectangle"]
    for name in options["pane_emitters"]:
        if name not in emitter_rectangles:
            known = ", ".join(emitter_rectangles) or "none"
            sys.exit(f"{scene_file}: --pane-from-emitter {name}: no rectangle emitter of that name (the scene's: {known})")
    pane_emitters = set(options["pane_emitters"])

    lines_v, lines_vt, lines_vn, body = [], [], [], []
    used_materials = {}
    counts = {"v": 0, "vt": 0, "vn": 0, "triangles": 0}
    kept = {"shapes": 0, "triangles": 0}
    dropped = {"shapes": 0, "triangles": 0}
    skipped = 0
    panes = []  # (object name, (a, b, c))

    def emit(name, material, m, positions, uvs, normals, faces):
        """Appends one object (already in world space when `m` is None)."""
        base = dict(counts)
        if m is None:
            lines_v.extend("v %.7g %.7g %.7g" % p for p in positions)
            lines_vn.extend("vn %.7g %.7g %.7g" % n for n in normals)
            det = 1.0
        else:
            n3 = normal_matrix(m)
            lines_v.extend("v %.7g %.7g %.7g" % apply_point(m, p) for p in positions)
            lines_vn.extend("vn %.7g %.7g %.7g" % apply_normal(n3, n) for n in normals)
            # A mirroring transform flips the winding back to counter-clockwise.
            det = determinant(m)
        lines_vt.extend("vt %.7g %.7g" % t for t in uvs)
        counts["v"] += len(positions)
        counts["vt"] += len(uvs)
        counts["vn"] += len(normals)
        body.append(f"o {name}\nusemtl {material}")
        for face in faces:
            if det < 0.0:
                face = [face[0], face[2], face[1]]
            tokens = []
            for v, t, n in face:
                token = str(base["v"] + v + 1)
                if t is not None or n is not None:
                    token += "/" + (str(base["vt"] + t + 1) if t is not None else "")
                if n is not None:
                    token += "/" + str(base["vn"] + n + 1)
                tokens.append(token)
            body.append("f " + " ".join(tokens))
        counts["triangles"] += len(faces)

    for number, shape in enumerate(shapes):
        kind = shape.attrib.get("type")
        name = shape_name(shape, number)
        emitter = shape.find("emitter")
        m = matrix_of(shape)
        if name in pane_emitters and emitter is not None and kind == "rectangle":
            corners = [apply_point(m, p) for p in ((-1.0, -1.0, 0.0), (1.0, -1.0, 0.0), (-1.0, 1.0, 0.0))]
            if determinant(m) < 0.0:  # keep the emitter's facing
                corners = [corners[0], corners[2], corners[1]]
            panes.append((f"pane_{name}", tuple(corners)))
            dropped["shapes"] += 1
            dropped["triangles"] += 2
            print(f"dropped emitter shape {name} (shape {number}, {kind}, {emitter.attrib.get('type')} emitter): "
                  f"a pane takes its place", file=sys.stderr)
            continue
        if emitter is not None and not options["keep_emitters"]:
            triangles = 2 if kind == "rectangle" else None
            if kind == "obj":
                try:
                    triangles = len(read_obj(scene_dir / shape.find("string[@name='filename']").attrib["value"])[3])
                except (OSError, ValueError, IndexError, AttributeError, KeyError):
                    triangles = None
            dropped["shapes"] += 1
            dropped["triangles"] += triangles or 0
            print(f"dropped emitter shape {name} (shape {number}, {kind}, {emitter.attrib.get('type')} emitter"
                  f"{'' if triangles is None else f', {triangles} triangles'}); --keep-emitters keeps it", file=sys.stderr)
            continue
        refs = [r for r in shape.findall("ref") if r.attrib.get("name", "bsdf") == "bsdf"]
        if refs and refs[0].attrib.get("id") not in bsdfs:
            sys.exit(f"{scene_file}: shape {number} refers to BSDF {refs[0].attrib.get('id')!r}, which is not defined")
        own = bsdfs[refs[0].attrib["id"]] if refs else shape.find("bsdf")
        if emitter is not None:  # kept by --keep-emitters
            material = f"emitter_{name}"
            if material in bsdfs:
                sys.exit(f"{scene_file}: a BSDF is called {material!r}, the name --keep-emitters gives shape {number}'s material")
            albedo = albedo_of(own, bsdfs) if own is not None else [0.5] * 3
        elif refs or (own is not None and "id" in own.attrib):
            material, albedo = own.attrib["id"], albedo_of(own, bsdfs)
        else:
            material, albedo = "default", [0.5] * 3
        if kind == "obj":
            filename = shape.find("string[@name='filename']").attrib["value"]
            try:
                positions, uvs, normals, faces = read_obj(scene_dir / filename)
            except (OSError, ValueError, IndexError) as e:
                sys.exit(f"{scene_dir / filename}: cannot read it as OBJ: {e}")
        elif kind == "rectangle":
            positions = [(-1.0, -1.0, 0.0), (1.0, -1.0, 0.0), (1.0, 1.0, 0.0), (-1.0, 1.0, 0.0)]
            uvs, normals = [], [(0.0, 0.0, 1.0)] * 4
            faces = [[(0, None, 0), (1, None, 1), (2, None, 2)], [(0, None, 0), (2, None, 2), (3, None, 3)]]
        else:
            print(f"skipping shape {number} of type {kind!r}", file=sys.stderr)
            skipped += 1
            continue
        used_materials[material] = albedo
        emit(name, material, m, positions, uvs, normals, faces)
        kept["shapes"] += 1
        kept["triangles"] += len(faces)

    panes = [(f"pane{k}", corners) for k, corners in enumerate(options["panes"])] + panes
    for name, (a, b, c) in panes:
        positions, normals, faces = pane_geometry(a, b, c, options["pane_grow"])
        emit(name, PANE_MATERIAL, None, positions, [], normals, faces)
        corners = [positions[0], positions[1], positions[3]]
        print(f"added pane {name}: --pane {':'.join(','.join('%.7g' % x for x in p) for p in corners)}", file=sys.stderr)
    if panes:
        used_materials[PANE_MATERIAL] = None

    def mtl_entry(name, albedo):
        if albedo is None:  # the pane: clear glass in prtbake's window mode
            return f"newmtl {name}\nKd 0 0 0\nprtbake_role window\nprtbake_transmittance 1\n\n"
        r, g, b = albedo
        return f"newmtl {name}\nKd {r:.6g} {g:.6g} {b:.6g}\n\n"

    # Both files to temporaries beside their targets, then renamed together.
    staged = []
    try:
        for target, write in (
            (mtl, lambda f: f.write("".join(mtl_entry(name, albedo) for name, albedo in used_materials.items()))),
            (out, lambda f: [f.write(f"# converted from {scene_file} by scripts/convert_mitsuba.py\nmtllib {mtl.name}\n")]
             + [f.write("\n".join(block) + "\n") for block in (lines_v, lines_vt, lines_vn, body)]),
        ):
            fd, temporary = tempfile.mkstemp(prefix=".convert-", suffix=".tmp", dir=target.parent or ".")
            staged.append((temporary, target))
            with os.fdopen(fd, "w") as f:
                write(f)
        for temporary, target in staged:
            os.replace(temporary, target)
    finally:
        for temporary, _ in staged:
            if os.path.exists(temporary):
                os.remove(temporary)
    sensor = root.find("sensor")
    if sensor is not None:
        cm = matrix_of(sensor)
        eye = (cm[0][3], cm[1][3], cm[2][3])
        target = tuple(eye[r] + cm[r][2] for r in range(3))
        print(f"camera: --camera {','.join('%.4g' % x for x in eye + target)}", file=sys.stderr)
    print(f"wrote {out}: {counts['triangles']} triangles, {counts['v']} positions, {len(used_materials)} materials", file=sys.stderr)

    def count(n, noun):
        return f"{n} {noun}" + ("" if n == 1 else "s")
    print(f"kept {count(kept['shapes'], 'shape')} ({count(kept['triangles'], 'triangle')}); "
          f"dropped {count(dropped['shapes'], 'emitter shape')} ({count(dropped['triangles'], 'triangle')}); "
          f"added {count(len(panes), 'pane')} ({count(2 * len(panes), 'triangle')})"
          + (f"; skipped {count(skipped, 'shape')} of unsupported types" if skipped else ""), file=sys.stderr)


if __name__ == "__main__":
    main()
