"""Re-render a `cell dataset` BOP feeder split with Blender Cycles (bpy 4.5.15), the independent
renderer of issue 45: the same scenes (scene_gt.json poses, the set's models/*.ply meshes),
camera (intrinsics, window, Brown-Conrady distortion), tag-board print and materials (nickel
shells, dark insert molds with gold pins, aluminium board) as `sim::render`, under a chosen look.

The pinhole render is resampled through the set's distortion; an instance-id render, resampled
the same way, is compared with the set's mask_visib (IoU per instance), and a set whose median
IoU is below --min-iou is refused, naming the worst images. Labels (scene_gt, scene_gt_info,
mask_visib, mask, depth, scene_camera) are copied from the source set; only rgb/ is new.

Run through scripts/cycles_render/run.sh, which provisions the venv and writes the board print.
"""

import argparse
import atexit
import importlib.metadata
import json
import math
import os
import re
import shutil
import struct
import sys
import tempfile
import time
import tomllib
import zlib

import numpy as np

BPY_VERSION = "4.5.15"
# "window" and "dim" are held-out looks (2026-11-30): written before any render or evaluation
# under them, never trained on and never tuned after, so they measure how far the nets carry.
LOOKS = ("soft", "hard", "window", "dim")
# The instance-id render's pixels per camera pixel (along each axis), at least.
ID_DENSITY = 6


def fail(message):
    """Prints an error and exits with status 1."""
    print(f"cycles_render: {message}", file=sys.stderr)
    sys.exit(1)


def read_json(path):
    """Reads a JSON file, naming it and the line and column on a syntax error."""
    try:
        with open(path, encoding="utf-8") as f:
            return json.load(f)
    except OSError as e:
        fail(f"{path}: {e.strerror}")
    except json.JSONDecodeError as e:
        fail(f"{path}:{e.lineno}:{e.colno}: {e.msg}")


def read_ply(path):
    """Reads the ASCII PLY a `cell dataset` writes: vertices (mm) and triangles."""
    try:
        with open(path, encoding="ascii") as f:
            lines = f.read().splitlines()
    except (OSError, UnicodeDecodeError) as e:
        fail(f"{path}: {e}")
    nv = nf = None
    end = None
    for i, line in enumerate(lines):
        parts = line.split()
        if parts[:2] == ["element", "vertex"]:
            nv = int(parts[2])
        elif parts[:2] == ["element", "face"]:
            nf = int(parts[2])
        elif line.strip() == "end_header":
            end = i + 1
            break
    if nv is None or nf is None or end is None:
        fail(f"{path}:1:1: not an ASCII PLY with vertex and face elements")
    try:
        verts = np.array([[float(v) for v in lines[end + i].split()[:3]] for i in range(nv)])
        faces = []
        for i in range(nf):
            row = [int(v) for v in lines[end + nv + i].split()]
            if row[0] != 3 or len(row) != 4:
                fail(f"{path}:{end + nv + i + 1}:1: only triangles are read")
            faces.append(row[1:])
    except (ValueError, IndexError):
        fail(f"{path}: truncated or malformed body after line {end}")
    faces = np.array(faces, dtype=np.int64)
    if faces.size and (faces.min() < 0 or faces.max() >= nv):
        fail(f"{path}: a face names a vertex outside 0..{nv - 1}")
    return verts, faces


def pin_triangles(verts, faces):
    """The contact pins of a moulded part, as sim::scene::model::pin_triangles finds them:
    triangles standing above the highest upward face level holding a tenth of the footprint."""
    lo, hi = verts.min(0), verts.max(0)
    footprint = (hi[0] - lo[0]) * (hi[1] - lo[1])
    a, b, c = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
    n = np.cross(b - a, c - a)
    area = np.linalg.norm(n, axis=1) / 2.0
    z = (a[:, 2] + b[:, 2] + c[:, 2]) / 3.0
    levels = []
    for i in range(len(faces)):
        if area[i] <= 0 or n[i, 2] / (2 * area[i]) < 0.99:
            continue
        for level in levels:
            if abs(level[0] - z[i]) < 1e-4:  # 0.1 µm in mm
                level[1] += area[i]
                break
        else:
            levels.append([z[i], area[i]])
    tops = [lz for lz, la in levels if la >= 0.1 * footprint]
    if not tops:
        return np.zeros(len(faces), dtype=bool)
    return z > max(tops) + 1e-4


def board_rects(svg_path):
    """The black rectangles of the tags of a `cell board` SVG, in board metres (x0, y0, x1, y1),
    and the plate size: page millimetres (y down, margin 10 mm) to the board frame (y up)."""
    try:
        with open(svg_path, encoding="utf-8") as f:
            text = f.read()
    except OSError as e:
        fail(f"{svg_path}: {e.strerror}")
    plate = re.search(r'<rect id="plate" x="([\d.]+)" y="([\d.]+)" width="([\d.]+)" height="([\d.]+)"', text)
    if not plate:
        fail(f"{svg_path}: no plate rectangle (not written by `cell board`?)")
    px, py, pw, ph = (float(v) for v in plate.groups())
    rects = []
    for group in re.finditer(r'<g id="tag-\d+"[^>]*>(.*?)</g>', text, re.S):
        for r in re.finditer(r'<rect x="([\d.]+)" y="([\d.]+)" width="([\d.]+)" height="([\d.]+)"/>', group.group(1)):
            x, y, w, h = (float(v) for v in r.groups())
            bx0 = (x - px - pw / 2) / 1e3
            bx1 = (x + w - px - pw / 2) / 1e3
            by1 = (py + ph / 2 - y) / 1e3
            by0 = (py + ph / 2 - y - h) / 1e3
            rects.append((bx0, by0, bx1, by1))
    if not rects:
        fail(f"{svg_path}: no tags")
    return rects, (pw / 1e3, ph / 1e3)


def board_texture(rects, plate, texel):
    """The print as a 0/1 image (1 = black ink), row 0 at the board's −y edge (Blender's v = 0)."""
    w = int(round(plate[0] / texel))
    h = int(round(plate[1] / texel))
    img = np.zeros((h, w), dtype=np.float32)
    for x0, y0, x1, y1 in rects:
        c0 = int(round((x0 + plate[0] / 2) / texel))
        c1 = int(round((x1 + plate[0] / 2) / texel))
        r0 = int(round((y0 + plate[1] / 2) / texel))
        r1 = int(round((y1 + plate[1] / 2) / texel))
        img[r0:r1, c0:c1] = 1.0
    return img


def distort(x, y, d):
    """OpenCV's Brown-Conrady model (k1, k2, p1, p2, k3) on normalised coordinates."""
    k1, k2, p1, p2, k3 = d
    r2 = x * x + y * y
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    return (x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
            y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)


def undistort(xd, yd, d):
    """Inverts `distort` by Newton-free fixed-point iteration (converges for these lenses);
    returns the ideal coordinates and the largest residual, normalised units."""
    x, y = xd.copy(), yd.copy()
    for _ in range(30):
        dx, dy = distort(x, y, d)
        x = x + (xd - dx)
        y = y + (yd - dy)
    dx, dy = distort(x, y, d)
    return x, y, float(max(np.abs(dx - xd).max(), np.abs(dy - yd).max()))


def bilinear(img, u, v):
    """Samples img (H, W, C) at float pixel coordinates (pixel centres at integers)."""
    h, w = img.shape[:2]
    u = np.clip(u, 0, w - 1.000001)
    v = np.clip(v, 0, h - 1.000001)
    u0 = np.floor(u).astype(np.int64)
    v0 = np.floor(v).astype(np.int64)
    fu = (u - u0)[..., None]
    fv = (v - v0)[..., None]
    return ((img[v0, u0] * (1 - fu) + img[v0, u0 + 1] * fu) * (1 - fv)
            + (img[v0 + 1, u0] * (1 - fu) + img[v0 + 1, u0 + 1] * fu) * fv)


def gaussian_blur(img, sigma):
    """Separable Gaussian blur of an (H, W, C) image, edges clamped."""
    if sigma <= 0:
        return img
    r = max(1, int(math.ceil(3 * sigma)))
    k = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma) ** 2)
    k /= k.sum()
    out = img
    for axis in (0, 1):
        pad = [(0, 0)] * out.ndim
        pad[axis] = (r, r)
        p = np.pad(out, pad, mode="edge")
        acc = np.zeros_like(out)
        for i, kv in enumerate(k):
            sl = [slice(None)] * out.ndim
            sl[axis] = slice(i, i + out.shape[axis])
            acc += kv * p[tuple(sl)]
        out = acc
    return out


def encode_srgb(x):
    """Linear 0–1 to 8-bit sRGB, as sim::render::sensor encodes."""
    x = np.clip(np.nan_to_num(x), 0.0, 1.0)
    s = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.clip(np.round(s * 255.0), 0, 255).astype(np.uint8)


def write_png(path, rgb):
    """Writes an 8-bit RGB PNG, every row Paeth-filtered (deterministic bytes)."""
    h, w, _ = rgb.shape
    x = rgb.reshape(h, w * 3).astype(np.int16)
    a = np.zeros_like(x)
    a[:, 3:] = x[:, :-3]
    b = np.zeros_like(x)
    b[1:] = x[:-1]
    c = np.zeros_like(x)
    c[1:, 3:] = x[:-1, :-3]
    p = a + b - c
    pa, pb, pc = np.abs(p - a), np.abs(p - b), np.abs(p - c)
    pred = np.where((pa <= pb) & (pa <= pc), a, np.where(pb <= pc, b, c))
    filtered = ((x - pred) % 256).astype(np.uint8)
    raw = b"".join(b"\x04" + filtered[y].tobytes() for y in range(h))

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    png = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
           + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))
    tmp = path + ".tmp"
    with open(tmp, "wb") as f:
        f.write(png)
    os.replace(tmp, path)


def load_image(bpy, path, channels):
    """Reads an image file through Blender as float (H, W, channels), row 0 at the top."""
    img = bpy.data.images.load(path, check_existing=False)
    w, h = img.size
    buf = np.empty(w * h * 4, dtype=np.float32)
    img.pixels.foreach_get(buf)
    bpy.data.images.remove(img)
    return buf.reshape(h, w, 4)[::-1, :, :channels].copy()


def parse_args():
    """Command line."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("source", help="a `cell dataset` output folder (camera.json, models/, the split)")
    p.add_argument("out", help="output folder (must not exist)")
    p.add_argument("--board-svg", required=True, help="the board's print from `cell board`")
    p.add_argument("--board", required=True, help="the board file the print was made from (its thickness)")
    p.add_argument("--catalog", required=True, help="the part catalog the set was made from")
    p.add_argument("--split", default="test_feeder")
    p.add_argument("--look", choices=LOOKS, default="soft")
    p.add_argument("--frames", type=int, default=0, help="first N images of the split (0: all)")
    p.add_argument("--samples", type=int, default=64, help="Cycles samples per pixel")
    p.add_argument("--scale", type=float, default=1.5, help="pinhole render scale over the camera's")
    p.add_argument("--seed", type=int, default=0, help="seed of the look's draws and Cycles' sampling")
    p.add_argument("--min-iou", type=float, default=0.98,
                   help="refuse the set when the median mask IoU is below this")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--slim", action="store_true",
                   help="copy only mask_visib of the labels' images (what `cell eval` reads), not mask/ or depth/")
    return p.parse_args()


def material(bpy, name, base, metallic, roughness, anisotropy=0.0, specular=0.5):
    """A Principled BSDF material."""
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    bsdf = m.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*base, 1.0)
    bsdf.inputs["Metallic"].default_value = metallic
    bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["Anisotropic"].default_value = anisotropy
    bsdf.inputs["Specular IOR Level"].default_value = specular
    return m


def board_material(bpy, texture, white, black):
    """The tag board's print: white and black Principled BSDFs mixed by the print image."""
    h, w = texture.shape
    img = bpy.data.images.new("board_print", width=w, height=h, float_buffer=True, is_data=True)
    rgba = np.repeat(texture[:, :, None], 4, axis=2)
    rgba[:, :, 3] = 1.0
    img.pixels.foreach_set(rgba.ravel())
    img.pack()
    m = bpy.data.materials.new("board")
    m.use_nodes = True
    nt = m.node_tree
    out = nt.nodes["Material Output"]
    nt.nodes.remove(nt.nodes["Principled BSDF"])
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = img
    tex.interpolation = "Closest"
    tex.extension = "CLIP"
    bw = nt.nodes.new("ShaderNodeBsdfPrincipled")
    bw.inputs["Base Color"].default_value = (*white, 1.0)
    bw.inputs["Roughness"].default_value = 0.6
    bb = nt.nodes.new("ShaderNodeBsdfPrincipled")
    bb.inputs["Base Color"].default_value = (*black, 1.0)
    bb.inputs["Roughness"].default_value = 0.55
    mix = nt.nodes.new("ShaderNodeMixShader")
    nt.links.new(tex.outputs["Color"], mix.inputs["Fac"])
    nt.links.new(bw.outputs["BSDF"], mix.inputs[1])
    nt.links.new(bb.outputs["BSDF"], mix.inputs[2])
    nt.links.new(mix.outputs["Shader"], out.inputs["Surface"])
    return m


def emission(bpy, name, value):
    """A flat emission of (value, 0, 0): the instance-id render."""
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    nt = m.node_tree
    nt.nodes.remove(nt.nodes["Principled BSDF"])
    e = nt.nodes.new("ShaderNodeEmission")
    e.inputs["Color"].default_value = (value, 0.0, 0.0, 1.0)
    e.inputs["Strength"].default_value = 1.0
    nt.links.new(e.outputs["Emission"], nt.nodes["Material Output"].inputs["Surface"])
    return m


def mesh_object(bpy, name, verts, faces, mats, face_mat=None):
    """A mesh object from vertices (m) and triangles, with material slots."""
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(v) for v in verts], [], [tuple(int(i) for i in f) for f in faces])
    me.update()
    for m in mats:
        me.materials.append(m)
    if face_mat is not None:
        me.polygons.foreach_set("material_index", face_mat.astype(np.int32))
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def look_lights(bpy, look, rng):
    """The look's lights and world, drawn from rng (deterministic per frame). Returns the sensor
    settings the look applies after rendering: blur sigma px, read noise, shot noise, and
    optionally "tint" (white-balance gains per channel) and "expose" (the metered level)."""
    world = bpy.context.scene.world
    world.use_nodes = True
    bg = world.node_tree.nodes["Background"]
    if look == "soft":
        # A grey room around the cell for the metal to reflect, and two large ceiling panels
        # off to the sides (not above the camera, whose mirror image the flat tops would show).
        grey = rng.uniform(0.3, 0.45)
        bg.inputs["Color"].default_value = (grey, grey, grey * 0.97, 1.0)
        bg.inputs["Strength"].default_value = 1.0
        phi = rng.uniform(0, 2 * math.pi)
        for i, (r, h, size, power) in enumerate([(rng.uniform(0.6, 0.9), 1.5, 0.8, 400.0),
                                                  (rng.uniform(0.6, 0.9), 1.3, 0.6, 200.0)]):
            a = phi + i * rng.uniform(0.6, 1.0) * math.pi
            add_area(bpy, f"panel{i}", (r * math.cos(a), r * math.sin(a), h), size, power)
        return {"blur": 0.0, "read": 0.0, "shot": 0.0}
    if look == "window":
        # Daylight through one large window low at the side, a warm room and a small warm ceiling
        # lamp; the camera's white balance left uncorrected, mild blur and noise.
        warm = rng.uniform(0.35, 0.5)
        bg.inputs["Color"].default_value = (warm, warm * 0.9, warm * 0.75, 1.0)
        bg.inputs["Strength"].default_value = 1.0
        phi = rng.uniform(0, 2 * math.pi)
        r, h = rng.uniform(1.2, 1.6), rng.uniform(0.6, 1.0)
        add_area(bpy, "window", (r * math.cos(phi), r * math.sin(phi), h), 1.2, rng.uniform(800.0, 1500.0),
                 color=(0.8, 0.9, 1.0))
        a = phi + rng.uniform(0.5, 1.5) * math.pi
        add_area(bpy, "lamp", (0.4 * math.cos(a), 0.4 * math.sin(a), 1.4), 0.3, rng.uniform(100.0, 200.0),
                 color=(1.0, 0.75, 0.5))
        tint = (rng.uniform(0.92, 1.08), 1.0, rng.uniform(0.9, 1.1))
        return {"blur": rng.uniform(0.3, 0.7), "read": rng.uniform(0.004, 0.008),
                "shot": rng.uniform(0.0005, 0.001), "tint": tint}
    if look == "dim":
        # One overhead panel in a dark room, underexposed at a high gain: strong noise and a
        # slightly defocused lens.
        grey = rng.uniform(0.08, 0.15)
        bg.inputs["Color"].default_value = (grey, grey, grey, 1.0)
        bg.inputs["Strength"].default_value = 1.0
        phi, r = rng.uniform(0, 2 * math.pi), rng.uniform(0.2, 0.5)
        add_area(bpy, "panel", (r * math.cos(phi), r * math.sin(phi), 2.0), 0.5, rng.uniform(150.0, 300.0))
        return {"blur": rng.uniform(1.4, 2.0), "read": rng.uniform(0.015, 0.025),
                "shot": rng.uniform(0.003, 0.005), "expose": rng.uniform(0.5, 0.7)}
    # Hard: one small key light low and off-axis (40–55° from the vertical), a dim room.
    bg.inputs["Color"].default_value = (0.03, 0.03, 0.03, 1.0)
    bg.inputs["Strength"].default_value = 1.0
    phi = rng.uniform(0, 2 * math.pi)
    tilt = math.radians(rng.uniform(40, 55))
    dist = 1.5
    pos = (dist * math.sin(tilt) * math.cos(phi), dist * math.sin(tilt) * math.sin(phi), dist * math.cos(tilt))
    add_area(bpy, "key", pos, 0.04, rng.uniform(500.0, 700.0))
    return {"blur": rng.uniform(0.8, 1.3), "read": rng.uniform(0.006, 0.012), "shot": rng.uniform(0.001, 0.002)}


def add_area(bpy, name, pos, size, power, color=(1.0, 1.0, 1.0)):
    """A square area light at pos (table frame, m) facing the board centre."""
    light = bpy.data.lights.new(name, type="AREA")
    light.size = size
    light.energy = power
    light.color = color
    ob = bpy.data.objects.new(name, light)
    bpy.context.scene.collection.objects.link(ob)
    ob.location = pos
    d = -np.array(pos, dtype=float)
    d /= np.linalg.norm(d)
    # Area lights emit along their local −z: rotate −z onto d.
    import mathutils
    ob.rotation_mode = "QUATERNION"
    ob.rotation_quaternion = mathutils.Vector((0.0, 0.0, -1.0)).rotation_difference(mathutils.Vector(d))


def main():
    args = parse_args()
    try:
        have = importlib.metadata.version("bpy")
    except importlib.metadata.PackageNotFoundError:
        fail("bpy is not installed (scripts/cycles_render/venv.sh installs it)")
    if have != BPY_VERSION:
        fail(f"bpy {have} is installed; this script was written and checked for bpy {BPY_VERSION} only")
    import bpy
    import mathutils

    if os.path.exists(args.out):
        fail(f"{args.out}: already exists (refusing to overwrite)")
    if args.frames < 0 or args.samples < 1 or args.scale < 1.0 or not 0.0 < args.min_iou <= 1.0:
        fail("--frames >= 0, --samples >= 1, --scale >= 1 and 0 < --min-iou <= 1")

    src = args.source
    if not os.path.isfile(os.path.join(src, "camera.json")):
        fail(f"{src}: no camera.json (not a `cell dataset` output folder?)")
    split_dir = os.path.join(src, args.split)
    scenes = sorted(d for d in os.listdir(split_dir) if d.isdigit()) if os.path.isdir(split_dir) else []
    if not scenes:
        fail(f"{split_dir}: no scene folders")
    try:
        with open(args.catalog, "rb") as f:
            catalog = tomllib.load(f)
    except OSError as e:
        fail(f"{args.catalog}: {e.strerror}")
    except tomllib.TOMLDecodeError as e:
        fail(f"{args.catalog}: {e}")
    materials_by_id = {i + 1: p.get("material") for i, p in enumerate(catalog.get("part", []))}
    rects, plate = board_rects(args.board_svg)
    texture = board_texture(rects, plate, 0.0000625)
    try:
        with open(args.board, "rb") as f:
            thickness = float(tomllib.load(f).get("thickness", 0.003))  # BoardSpec's default
    except OSError as e:
        fail(f"{args.board}: {e.strerror}")
    except (tomllib.TOMLDecodeError, ValueError, TypeError) as e:
        fail(f"{args.board}: {e}")

    # Materials, as sim::render::appearance gives them (nominal, untinted).
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    if scene.world is None:
        scene.world = bpy.data.worlds.new("world")
    mats = {
        # Isotropic: sim brushes along the part's x axis (anisotropy 0.3, randomised 0–0.7);
        # Cycles would need a tangent field for it, and 0 lies inside sim's range.
        "metal": material(bpy, "metal", (0.66, 0.65, 0.62), 1.0, 0.35),
        "dark_plastic": material(bpy, "dark_plastic", (0.035, 0.035, 0.04), 0.0, 0.45, specular=0.56),
        "gold": material(bpy, "gold", (1.0, 0.77, 0.34), 1.0, 0.25),
        "aluminium": material(bpy, "aluminium", (0.91, 0.92, 0.92), 1.0, 0.5),
    }
    board_mat = board_material(bpy, texture, (0.78, 0.78, 0.76), (0.025, 0.025, 0.025))

    models = {}
    for name in sorted(os.listdir(os.path.join(src, "models"))):
        m = re.fullmatch(r"obj_(\d+)\.ply", name)
        if m:
            oid = int(m.group(1))
            if materials_by_id.get(oid) not in ("metal", "dark_plastic", "aluminium"):
                fail(f"{args.catalog}: object {oid} has material {materials_by_id.get(oid)!r}, not a part material")
            models[oid] = read_ply(os.path.join(src, "models", name))

    tmp_out = tempfile.mkdtemp(prefix="cycles_render_")
    atexit.register(shutil.rmtree, tmp_out, True)  # also when a later check refuses the set
    out_root = os.path.join(tmp_out, "set")
    os.makedirs(os.path.join(out_root, args.split))
    shutil.copy(os.path.join(src, "camera.json"), out_root)
    shutil.copytree(os.path.join(src, "models"), os.path.join(out_root, "models"))

    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.render.threads_mode = "FIXED"
    scene.render.threads = args.threads
    scene.cycles.use_adaptive_sampling = False
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.render.image_settings.exr_codec = "ZIP"
    scene.render.use_persistent_data = False

    report = {"bpy": have, "look": args.look, "samples": args.samples, "scale": args.scale,
              "seed": args.seed, "min_iou": args.min_iou, "source": os.path.abspath(src), "images": []}
    all_ious = []
    total = 0
    t_render = 0.0
    for scene_name in scenes:
        sdir = os.path.join(split_dir, scene_name)
        cams = read_json(os.path.join(sdir, "scene_camera.json"))
        gts = read_json(os.path.join(sdir, "scene_gt.json"))
        infos = read_json(os.path.join(sdir, "scene_gt_info.json"))
        ims = sorted(cams, key=int)
        if args.frames:
            ims = ims[: max(0, args.frames - total)]
        if not ims:
            break
        odir = os.path.join(out_root, args.split, scene_name)
        copied = ("mask_visib",) if args.slim else ("mask_visib", "mask")
        for sub in ("rgb",) + copied + (() if args.slim else ("depth",)):
            os.makedirs(os.path.join(odir, sub), exist_ok=True)
        for im in ims:
            if im not in gts or im not in infos:
                fail(f"{sdir}: image {im} has no scene_gt or scene_gt_info entry")
            t0 = time.time()
            rgb, iou = render_frame(bpy, mathutils, args, scene, mats, board_mat, models, materials_by_id,
                                    plate, thickness, cams[im], gts[im], infos[im], sdir, int(im))
            dt = time.time() - t0
            t_render += dt
            write_png(os.path.join(odir, "rgb", f"{int(im):06d}.png"), rgb)
            for k in range(len(gts[im])):
                stem = f"{int(im):06d}_{k:06d}.png"
                for sub in copied:
                    shutil.copy(os.path.join(sdir, sub, stem), os.path.join(odir, sub))
            depth = os.path.join(sdir, "depth", f"{int(im):06d}.png")
            if not args.slim and os.path.exists(depth):
                shutil.copy(depth, os.path.join(odir, "depth"))
            valid = [v for v in iou if v is not None]
            all_ious += valid
            report["images"].append({"scene": scene_name, "image": int(im), "seconds": round(dt, 2),
                                     "iou": [None if v is None else round(v, 4) for v in iou]})
            print(f"{args.split}/{scene_name}/rgb/{int(im):06d}.png: {dt:.1f} s, "
                  f"mask IoU median {np.median(valid) if valid else float('nan'):.4f}, min {min(valid, default=float('nan')):.4f}",
                  flush=True)
        for name, table in (("scene_camera.json", cams), ("scene_gt.json", gts), ("scene_gt_info.json", infos)):
            with open(os.path.join(odir, name), "w", encoding="utf-8") as f:
                json.dump({im: table[im] for im in ims}, f, indent=1)
        total += len(ims)
        if args.frames and total >= args.frames:
            break
    if not all_ious:
        fail("no visible instances rendered")
    median = float(np.median(all_ious))
    report["median_iou"] = round(median, 4)
    report["frames"] = total
    report["seconds_per_frame"] = round(t_render / total, 2)
    if median < args.min_iou:
        worst = sorted(((min((v for v in r["iou"] if v is not None), default=1.0), r) for r in report["images"]),
                       key=lambda t: t[0])[:5]
        names = ", ".join(f"{args.split}/{r['scene']}/rgb/{r['image']:06d}.png (min IoU {w:.3f})" for w, r in worst)
        shutil.rmtree(tmp_out)
        fail(f"the rendered masks do not line up with mask_visib: median IoU {median:.4f} < {args.min_iou} "
             f"over {len(all_ious)} instances; worst images: {names}. Nothing written.")
    with open(os.path.join(out_root, "cycles.json"), "w", encoding="utf-8") as f:
        json.dump(report, f, indent=1)
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    shutil.move(out_root, args.out)
    shutil.rmtree(tmp_out, ignore_errors=True)
    print(f"{args.out}: {total} frames, look {args.look}, {args.samples} samples, median mask IoU {median:.4f} "
          f"over {len(all_ious)} instances, {t_render / total:.1f} s per frame on {args.threads} threads")


def render_frame(bpy, mathutils, args, scene, mats, board_mat, models, materials_by_id, plate, thickness,
                 cam, gt, info, sdir, im):
    """Builds, renders and resamples one frame; returns the 8-bit image and the IoU per instance
    (None where the set's mask_visib is empty)."""
    for ob in list(scene.collection.objects):
        bpy.data.objects.remove(ob, do_unlink=True)
    for coll in (bpy.data.meshes, bpy.data.lights, bpy.data.cameras):
        for block in list(coll):
            if block.users == 0:
                coll.remove(block)
    rng = np.random.default_rng([args.seed, im, LOOKS.index(args.look)])

    w, h = int(cam["width"]), int(cam["height"])
    K = np.array(cam["cam_K"], dtype=float).reshape(3, 3)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    dist = [float(v) for v in cam.get("dist_coeffs", [0, 0, 0, 0, 0])]
    if len(dist) != 5:
        fail(f"{sdir}/scene_camera.json: image {im}: dist_coeffs must have 5 entries")
    R_w2c = np.array(cam["cam_R_w2c"], dtype=float).reshape(3, 3)
    t_w2c = np.array(cam["cam_t_w2c"], dtype=float) / 1e3
    table_T_cam = np.eye(4)
    table_T_cam[:3, :3] = R_w2c.T
    table_T_cam[:3, 3] = -R_w2c.T @ t_w2c

    # Board plate (top face at z = 0, UV over the plate) and the table below it.
    hx, hy = plate[0] / 2, plate[1] / 2
    bv = [(-hx, -hy, 0), (hx, -hy, 0), (hx, hy, 0), (-hx, hy, 0),
          (-hx, -hy, -thickness), (hx, -hy, -thickness), (hx, hy, -thickness), (-hx, hy, -thickness)]
    bf = [(0, 1, 2, 3), (4, 7, 6, 5), (0, 4, 5, 1), (1, 5, 6, 2), (2, 6, 7, 3), (3, 7, 4, 0)]
    me = bpy.data.meshes.new("board")
    me.from_pydata(bv, [], bf)
    uv = me.uv_layers.new(name="UVMap")
    for poly in me.polygons:
        for li in poly.loop_indices:
            x, y, _ = bv[me.loops[li].vertex_index]
            uv.data[li].uv = ((x + hx) / plate[0], (y + hy) / plate[1])
    me.materials.append(board_mat)
    me.materials.append(mats["aluminium"])
    me.polygons.foreach_set("material_index", [0, 1, 1, 1, 1, 1])
    board = bpy.data.objects.new("board", me)
    scene.collection.objects.link(board)
    grey = rng.uniform(0.2, 0.45)
    table_mat = bpy.data.materials.get("table") or material(bpy, "table", (grey, grey * 0.95, grey * 0.9), 0.0, 0.7)
    table_mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (grey, grey * 0.95, grey * 0.9, 1)
    tme = bpy.data.meshes.new("table")
    tme.from_pydata([(-3, -3, -thickness), (3, -3, -thickness), (3, 3, -thickness), (-3, 3, -thickness)], [],
                    [(0, 1, 2, 3)])
    tme.materials.append(table_mat)
    table = bpy.data.objects.new("table", tme)
    scene.collection.objects.link(table)

    # Parts: table_T_part = table_T_cam · cam_T_part.
    parts = []
    for k, g in enumerate(gt):
        oid = int(g["obj_id"])
        if oid not in models:
            fail(f"{sdir}/scene_gt.json: image {im}: object {oid} has no models/obj_{oid:06d}.ply")
        verts, faces = models[oid]
        mat_name = materials_by_id[oid]
        if mat_name == "dark_plastic":
            pins = pin_triangles(verts, faces)
            ob = mesh_object(bpy, f"part{k}", verts / 1e3, faces, [mats["dark_plastic"], mats["gold"]],
                             pins.astype(np.int32))
        else:
            ob = mesh_object(bpy, f"part{k}", verts / 1e3, faces, [mats[mat_name]])
        cam_T_part = np.eye(4)
        cam_T_part[:3, :3] = np.array(g["cam_R_m2c"], dtype=float).reshape(3, 3)
        cam_T_part[:3, 3] = np.array(g["cam_t_m2c"], dtype=float) / 1e3
        ob.matrix_world = mathutils.Matrix((table_T_cam @ cam_T_part).tolist())
        parts.append(ob)

    # The pinhole render covering the window's undistorted footprint.
    uu, vv = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    x, y, resid = undistort((uu - cx) / fx, (vv - cy) / fy, dist)
    if resid > 1e-9:
        fail(f"{sdir}/scene_camera.json: image {im}: distortion could not be inverted (residual {resid:.2e})")
    f_r = max(fx, fy) * args.scale
    margin = 3
    x0, x1, y0, y1 = x.min(), x.max(), y.min(), y.max()
    wr = int(math.ceil((x1 - x0) * f_r)) + 2 * margin + 1
    hr = int(math.ceil((y1 - y0) * f_r)) + 2 * margin + 1
    # Blender measures both shifts in units of the wider side: keep the width the wider one.
    pad = max(0, hr - wr)
    # Render index of pixel centres: j = f_r·x + crx, with crx putting x0 at index `margin`.
    crx = margin - f_r * x0 + pad / 2
    cry = margin - f_r * y0
    wr += pad
    cam_data = bpy.data.cameras.new("camera")
    cam_data.sensor_fit = "HORIZONTAL"
    cam_data.sensor_width = 36.0
    cam_data.lens = f_r * 36.0 / wr
    cam_data.clip_start = 0.05
    cam_data.clip_end = 10.0
    # Blender's principal point in continuous coordinates (left/top edge 0) is
    # (W/2 − shift_x·W, H/2 + shift_y·W); pixel index j has its centre at j + 0.5.
    cam_data.shift_x = (wr / 2 - (crx + 0.5)) / wr
    cam_data.shift_y = ((cry + 0.5) - hr / 2) / wr
    cam_ob = bpy.data.objects.new("camera", cam_data)
    scene.collection.objects.link(cam_ob)
    flip = np.diag([1.0, -1.0, -1.0, 1.0])
    cam_ob.matrix_world = mathutils.Matrix((table_T_cam @ flip).tolist())
    scene.camera = cam_ob
    scene.render.resolution_x = wr
    scene.render.resolution_y = hr
    scene.render.resolution_percentage = 100
    scene.render.pixel_aspect_x = 1.0
    scene.render.pixel_aspect_y = 1.0
    ju = f_r * x + crx
    jv = f_r * y + cry
    # Resampling footprint: average a scale × scale box of render pixels per output pixel.
    offs = [(a - (args.scale - 1) / 2) for a in np.linspace(0, args.scale - 1, max(1, int(round(args.scale))))]

    id_scale = int(math.ceil(ID_DENSITY / args.scale))
    tmpdir = tempfile.mkdtemp(prefix="cycles_frame_")
    try:
        # Instance ids: flat emission (k + 1) / 1000, one sample at the pixel centre, no bounces.
        # Slots are reassigned, never cleared: clearing them resets every face's material index
        # (the pins, the board's sides).
        black = emission(bpy, "id_black", 0.0)
        saved = {}
        for k, ob in enumerate(parts + [board, table]):
            saved[ob.name] = list(ob.data.materials)
            em = emission(bpy, f"id{k}", (k + 1) / 1000.0) if k < len(parts) else black
            for i in range(len(ob.data.materials)):
                ob.data.materials[i] = em
        scene.world.use_nodes = True
        bg = scene.world.node_tree.nodes["Background"]
        bg.inputs["Color"].default_value = (0, 0, 0, 1)
        scene.cycles.samples = 1
        scene.cycles.use_denoising = False
        scene.cycles.max_bounces = 0
        scene.cycles.filter_width = 0.01
        scene.cycles.seed = 0
        # At id_scale times the render's resolution, so the nearest id sample lies within
        # 1 / (2 ID_DENSITY) of a pixel of the output pixel's centre (sim labels by the centre ray).
        scene.render.resolution_percentage = 100 * id_scale
        scene.render.filepath = os.path.join(tmpdir, "ids.exr")
        bpy.ops.render.render(write_still=True)
        scene.render.resolution_percentage = 100
        ids_r = np.round(load_image(bpy, scene.render.filepath, 1)[:, :, 0] * 1000.0).astype(np.int64)
        iu = np.clip(np.round(id_scale * (ju + 0.5) - 0.5).astype(np.int64), 0, id_scale * wr - 1)
        iv = np.clip(np.round(id_scale * (jv + 0.5) - 0.5).astype(np.int64), 0, id_scale * hr - 1)
        ids = ids_r[iv, iu]

        # Restore the materials and render the look.
        for ob in parts + [board, table]:
            for i, m in enumerate(saved[ob.name]):
                ob.data.materials[i] = m
        for m in list(bpy.data.materials):
            if m.name.startswith("id"):
                bpy.data.materials.remove(m)
        sensor = look_lights(bpy, args.look, rng)
        scene.cycles.samples = args.samples
        scene.cycles.use_denoising = True
        scene.cycles.denoiser = "OPENIMAGEDENOISE"
        scene.cycles.max_bounces = 8
        scene.cycles.glossy_bounces = 4
        scene.cycles.diffuse_bounces = 3
        scene.cycles.transmission_bounces = 0
        scene.cycles.filter_width = 1.5
        scene.cycles.seed = int(rng.integers(0, 2**31 - 1))
        scene.render.filepath = os.path.join(tmpdir, "rgb.exr")
        bpy.ops.render.render(write_still=True)
        lin = load_image(bpy, scene.render.filepath, 3).astype(np.float64)
    finally:
        shutil.rmtree(tmpdir, ignore_errors=True)
    acc = np.zeros((h, w, 3))
    for du in offs:
        for dv in offs:
            acc += bilinear(lin, ju + du, jv + dv)
    lin = acc / (len(offs) ** 2)

    # Highlight-priority metering on the parts, as sim's SensorModel::metered: 99.5 % of the parts'
    # pixels below 0.9 of full scale.
    part_px = lin[ids > 0].max(axis=1)
    level = np.quantile(part_px, 0.995) if part_px.size else 1.0
    lin = lin * (sensor.get("expose", 0.9) / max(level, 1e-6))
    lin = lin * np.asarray(sensor.get("tint", (1.0, 1.0, 1.0)))
    lin = gaussian_blur(lin, sensor["blur"])
    if sensor["read"] > 0 or sensor["shot"] > 0:
        sd = np.sqrt(sensor["read"] ** 2 + sensor["shot"] * np.maximum(lin, 0))
        lin = lin + sd * rng.standard_normal(lin.shape)
    rgb = encode_srgb(lin)

    ious = []
    for k, inf in enumerate(info):
        truth = load_image(bpy, os.path.join(sdir, "mask_visib", f"{im:06d}_{k:06d}.png"), 1)[:, :, 0] > 0.5
        if truth.shape != (h, w):
            fail(f"{sdir}/mask_visib/{im:06d}_{k:06d}.png: {truth.shape[1]}×{truth.shape[0]}, not the image's {w}×{h}")
        ours = ids == k + 1
        union = np.logical_or(truth, ours).sum()
        ious.append(None if truth.sum() == 0 else float(np.logical_and(truth, ours).sum() / union))
    return rgb, ious


if __name__ == "__main__":
    main()
