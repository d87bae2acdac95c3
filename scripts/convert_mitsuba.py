#!/usr/bin/env python3
"""Converts a Mitsuba 0.5/2 scene (scene.xml with `obj` and `rectangle`
shapes) into one OBJ + MTL that prtbake loads.

    python3 scripts/convert_mitsuba.py SCENE_DIR OUT.obj [--force]

Used for the CC-BY dining room ("The Breakfast Room" by Wig42, Mitsuba
version from jgarciapueyo/mitsuba2-transient-scenes, folder dining-room/):
clone that repository yourself and point SCENE_DIR at dining-room/. The
converted mesh stays out of git (it is third-party data; see its
LICENSE.txt for the credit it needs).

What it keeps, and how:
- every `obj` shape, its `toWorld` matrix applied to positions (and the
  inverse transpose to normals), as one OBJ object named after the file
  stem (so `--window` globs can pick shapes by name);
- `rectangle` shapes as two triangles of the transformed square [-1, 1]²;
- the `ref`ed BSDF as the material (`usemtl` = the BSDF id), with `Kd` from
  `reflectance` / `diffuseReflectance` (rgb), 0.5 grey where that is a
  bitmap texture (no image decoding here), and the mean `specularReflectance`
  × 0.5 for conductors (prtbake is diffuse-only);
- one shared vertex pool (`v`/`vt`/`vn` indices are global), so the loader
  sees the mesh as Mitsuba does. Emitters, the camera and the integrator
  are ignored; the camera's eye and target are printed for `view --camera`.
OUT.obj and OUT.mtl are written to temporaries and renamed together; an
existing OUT.obj or OUT.mtl is replaced only with --force, and never when it
is one of the scene's own files. Only the Python standard library is used.
"""

import os
import sys
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path


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


def albedo_of(bsdf):
    """Kd for a BSDF element (twosided unwrapped)."""
    while bsdf.attrib.get("type") == "twosided" and bsdf.find("bsdf") is not None:
        bsdf = bsdf.find("bsdf")
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


def main():
    args = [a for a in sys.argv[1:] if a != "--force"]
    force = len(args) < len(sys.argv) - 1
    if len(args) != 2:
        print(__doc__.split("\n\n")[1], file=sys.stderr)
        sys.exit(2)
    scene_dir, out = Path(args[0]), Path(args[1])
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
    bsdfs = {b.attrib["id"]: b for b in root.findall("bsdf") if "id" in b.attrib}

    lines_v, lines_vt, lines_vn, body = [], [], [], []
    used_materials = {}
    counts = {"v": 0, "vt": 0, "vn": 0, "triangles": 0}
    for number, shape in enumerate(root.findall("shape")):
        kind = shape.attrib.get("type")
        ref = shape.find("ref")
        material = ref.attrib["id"] if ref is not None else "default"
        if material not in bsdfs and ref is not None:
            sys.exit(f"{scene_file}: shape {number} refers to BSDF {material!r}, which is not defined")
        used_materials[material] = albedo_of(bsdfs[material]) if material in bsdfs else [0.5] * 3
        m = matrix_of(shape)
        n3 = normal_matrix(m)
        if kind == "obj":
            filename = shape.find("string[@name='filename']").attrib["value"]
            name = Path(filename).stem
            try:
                positions, uvs, normals, faces = read_obj(scene_dir / filename)
            except (OSError, ValueError, IndexError) as e:
                sys.exit(f"{scene_dir / filename}: cannot read it as OBJ: {e}")
        elif kind == "rectangle":
            name = f"rectangle{number}"
            positions = [(-1.0, -1.0, 0.0), (1.0, -1.0, 0.0), (1.0, 1.0, 0.0), (-1.0, 1.0, 0.0)]
            uvs, normals = [], [(0.0, 0.0, 1.0)] * 4
            faces = [[(0, None, 0), (1, None, 1), (2, None, 2)], [(0, None, 0), (2, None, 2), (3, None, 3)]]
        else:
            print(f"skipping shape {number} of type {kind!r}", file=sys.stderr)
            continue
        base = dict(counts)
        lines_v.extend("v %.7g %.7g %.7g" % apply_point(m, p) for p in positions)
        lines_vt.extend("vt %.7g %.7g" % t for t in uvs)
        lines_vn.extend("vn %.7g %.7g %.7g" % apply_normal(n3, n) for n in normals)
        counts["v"] += len(positions)
        counts["vt"] += len(uvs)
        counts["vn"] += len(normals)
        body.append(f"o {name}\nusemtl {material}")
        # A mirroring transform flips the winding back to counter-clockwise.
        det = sum(m[0][c] * (m[1][(c + 1) % 3] * m[2][(c + 2) % 3] - m[1][(c + 2) % 3] * m[2][(c + 1) % 3]) for c in range(3))
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

    # Both files to temporaries beside their targets, then renamed together.
    staged = []
    try:
        for target, write in (
            (mtl, lambda f: f.write("".join(f"newmtl {name}\nKd {r:.6g} {g:.6g} {b:.6g}\n\n" for name, (r, g, b) in used_materials.items()))),
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


if __name__ == "__main__":
    main()
