#!/usr/bin/env python3
"""Independent validator for BOP datasets (and our keypoint crop set).

Stdlib only (json, zlib, struct): it shares no code with the Rust writer. It checks the file
layout, JSON key names and types, units (millimetres, OpenCV camera frame: objects in front of
the camera), rotations, PNG formats and sizes, and that mask pixel counts and boxes match
scene_gt_info.json.

Usage: bop_check.py DATASET_DIR      (exit status 0 when valid; problems are listed)
"""
import json
import math
import os
import struct
import sys
import zlib

PNG_SIG = b"\x89PNG\r\n\x1a\n"


def read_png(path):
    """Decodes a non-interlaced 8/16-bit grey or RGB PNG: (width, height, channels, depth, rows)."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:8] != PNG_SIG:
        raise ValueError("not a PNG")
    pos, idat, ihdr = 8, b"", None
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos:pos + 4])
        kind = data[pos + 4:pos + 8]
        body = data[pos + 8:pos + 8 + length]
        if zlib.crc32(kind + body) & 0xFFFFFFFF != struct.unpack(">I", data[pos + 8 + length:pos + 12 + length])[0]:
            raise ValueError("bad CRC in chunk %r" % kind)
        if kind == b"IHDR":
            ihdr = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat += body
        elif kind == b"IEND":
            break
        pos += 12 + length
    if ihdr is None:
        raise ValueError("no IHDR")
    width, height, depth, color, _, _, interlace = ihdr
    if interlace:
        raise ValueError("interlaced PNG")
    channels = {0: 1, 2: 3, 4: 2, 6: 4}[color]
    bpp = max(1, channels * depth // 8)
    stride = width * channels * depth // 8
    raw = zlib.decompress(idat)
    rows, prev, i = [], bytearray(stride), 0
    for _ in range(height):
        ftype = raw[i]
        line = bytearray(raw[i + 1:i + 1 + stride])
        i += 1 + stride
        for x in range(stride):
            a = line[x - bpp] if x >= bpp else 0
            b = prev[x]
            c = prev[x - bpp] if x >= bpp else 0
            if ftype == 1:
                line[x] = (line[x] + a) & 0xFF
            elif ftype == 2:
                line[x] = (line[x] + b) & 0xFF
            elif ftype == 3:
                line[x] = (line[x] + (a + b) // 2) & 0xFF
            elif ftype == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                pred = a if pa <= pb and pa <= pc else (b if pb <= pc else c)
                line[x] = (line[x] + pred) & 0xFF
        rows.append(bytes(line))
        prev = line
    return width, height, channels, depth, rows


class Checker:
    def __init__(self):
        self.problems = []

    def fail(self, where, msg):
        self.problems.append("%s: %s" % (where, msg))

    def keys(self, where, obj, required):
        if not isinstance(obj, dict):
            self.fail(where, "expected an object")
            return False
        missing = [k for k in required if k not in obj]
        if missing:
            self.fail(where, "missing keys %s" % missing)
            return False
        return True

    def numbers(self, where, value, n):
        if not (isinstance(value, list) and len(value) == n and all(isinstance(v, (int, float)) for v in value)):
            self.fail(where, "expected %d numbers, got %r" % (n, value))
            return False
        return True

    def rotation(self, where, r):
        if not self.numbers(where, r, 9):
            return
        m = [r[0:3], r[3:6], r[6:9]]
        for i in range(3):
            for j in range(3):
                dot = sum(m[k][i] * m[k][j] for k in range(3))
                if abs(dot - (1.0 if i == j else 0.0)) > 1e-6:
                    self.fail(where, "not a rotation matrix")
                    return
        det = (m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
               + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]))
        if det < 0:
            self.fail(where, "rotation has determinant %f" % det)


def mask_stats(rows, width):
    count, xs, ys = 0, [], []
    for y, row in enumerate(rows):
        for x in range(width):
            if row[x] > 127:
                count += 1
                xs.append(x)
                ys.append(y)
    if not count:
        return 0, [-1, -1, -1, -1]
    return count, [min(xs), min(ys), max(xs) - min(xs) + 1, max(ys) - min(ys) + 1]


def check_dataset(root):
    c = Checker()
    cam_path = os.path.join(root, "camera.json")
    cam = json.load(open(cam_path))
    c.keys(cam_path, cam, ["cx", "cy", "depth_scale", "fx", "fy", "height", "width"])
    info_path = os.path.join(root, "models", "models_info.json")
    models = json.load(open(info_path))
    for oid, info in models.items():
        where = "%s[%s]" % (info_path, oid)
        if not oid.isdigit():
            c.fail(where, "object ids must be integers")
        if c.keys(where, info, ["diameter", "min_x", "min_y", "min_z", "size_x", "size_y", "size_z"]):
            if not 1.0 < info["diameter"] < 5000.0:
                c.fail(where, "diameter %r is not in millimetres" % info["diameter"])
            span = math.sqrt(info["size_x"] ** 2 + info["size_y"] ** 2 + info["size_z"] ** 2)
            if info["diameter"] > span * 1.0001:
                c.fail(where, "diameter exceeds the bounding-box diagonal")
        for s in info.get("symmetries_discrete", []):
            if c.numbers(where + " symmetry", s, 16):
                c.rotation(where + " symmetry", s[0:3] + s[4:7] + s[8:11])
        ply = os.path.join(root, "models", "obj_%06d.ply" % int(oid))
        if not os.path.exists(ply) or not open(ply, "rb").read(4) == b"ply\n":
            c.fail(ply, "missing or not a PLY file")
    scenes = 0
    for split in sorted(os.listdir(root)):
        split_dir = os.path.join(root, split)
        if split in ("models", "crops") or not os.path.isdir(split_dir):
            continue
        for scene in sorted(os.listdir(split_dir)):
            sdir = os.path.join(split_dir, scene)
            if not scene.isdigit():
                continue
            scenes += 1
            check_scene(c, sdir, models)
    crops = os.path.join(root, "crops")
    n_crops = 0
    if os.path.isdir(crops):
        for part in sorted(os.listdir(crops)):
            for split in sorted(os.listdir(os.path.join(crops, part))):
                d = os.path.join(crops, part, split)
                for name in sorted(os.listdir(d)):
                    if name.endswith(".json"):
                        n_crops += 1
                        check_crop(c, d, name, models)
    return c, scenes, n_crops


def check_scene(c, sdir, models):
    cams = json.load(open(os.path.join(sdir, "scene_camera.json")))
    gts = json.load(open(os.path.join(sdir, "scene_gt.json")))
    infos = json.load(open(os.path.join(sdir, "scene_gt_info.json")))
    if set(cams) != set(gts) or set(cams) != set(infos):
        c.fail(sdir, "scene_camera, scene_gt and scene_gt_info list different images")
    for im, cam in cams.items():
        where = "%s image %s" % (sdir, im)
        if not c.keys(where, cam, ["cam_K", "depth_scale", "cam_R_w2c", "cam_t_w2c"]):
            continue
        c.numbers(where + " cam_K", cam["cam_K"], 9)
        c.rotation(where + " cam_R_w2c", cam["cam_R_w2c"])
        rgb = read_png(os.path.join(sdir, "rgb", "%06d.png" % int(im)))
        width, height = rgb[0], rgb[1]
        if rgb[2] != 3 or rgb[3] != 8:
            c.fail(where, "rgb must be 8-bit RGB")
        depth = read_png(os.path.join(sdir, "depth", "%06d.png" % int(im)))
        if depth[2] != 1 or depth[3] != 16 or depth[0] != width or depth[1] != height:
            c.fail(where, "depth must be a 16-bit grey PNG of the image size")
        for k, (gt, info) in enumerate(zip(gts.get(im, []), infos.get(im, []))):
            w2 = "%s gt %d" % (where, k)
            if not c.keys(w2, gt, ["cam_R_m2c", "cam_t_m2c", "obj_id"]):
                continue
            if not c.keys(w2, info, ["bbox_obj", "bbox_visib", "px_count_all", "px_count_valid",
                                     "px_count_visib", "visib_fract"]):
                continue
            c.rotation(w2 + " cam_R_m2c", gt["cam_R_m2c"])
            if str(gt["obj_id"]) not in models:
                c.fail(w2, "obj_id %r has no model" % gt["obj_id"])
            t = gt["cam_t_m2c"]
            if c.numbers(w2 + " cam_t_m2c", t, 3) and not (10.0 < t[2] < 10000.0):
                c.fail(w2, "cam_t_m2c z = %r is not millimetres in front of the camera" % t[2])
            for name, key, bkey in (("mask", "px_count_all", "bbox_obj"), ("mask_visib", "px_count_visib", "bbox_visib")):
                m = read_png(os.path.join(sdir, name, "%06d_%06d.png" % (int(im), k)))
                if m[2] != 1 or m[3] != 8 or m[0] != width or m[1] != height:
                    c.fail(w2, "%s must be an 8-bit grey PNG of the image size" % name)
                    continue
                count, box = mask_stats(m[4], width)
                if count != info[key]:
                    c.fail(w2, "%s has %d pixels, %s says %d" % (name, count, key, info[key]))
                if box != info[bkey]:
                    c.fail(w2, "%s box %s, %s says %s" % (name, box, bkey, info[bkey]))
            if info["px_count_all"] and abs(info["visib_fract"] - info["px_count_visib"] / info["px_count_all"]) > 1e-9:
                c.fail(w2, "visib_fract inconsistent with pixel counts")


def check_crop(c, d, name, models):
    where = os.path.join(d, name)
    lab = json.load(open(where))
    if not c.keys(where, lab, ["cam_K", "cam_R_m2c", "cam_t_m2c", "obj_id", "keypoints", "width", "height",
                               "rgb", "mask", "bbox_visib", "px_count_visib"]):
        return
    c.rotation(where, lab["cam_R_m2c"])
    if len(lab["keypoints"]) != 9:
        c.fail(where, "expected 9 keypoints")
    rgb = read_png(os.path.join(d, lab["rgb"]))
    mask = read_png(os.path.join(d, lab["mask"]))
    if (rgb[0], rgb[1], rgb[2]) != (lab["width"], lab["height"], 3):
        c.fail(where, "rgb size/channels do not match the label")
    count, box = mask_stats(mask[4], mask[0])
    if count != lab["px_count_visib"] or box != lab["bbox_visib"]:
        c.fail(where, "mask has %d px box %s; label says %d, %s" % (count, box, lab["px_count_visib"], lab["bbox_visib"]))


def main():
    if len(sys.argv) != 2:
        print(__doc__)
        return 2
    c, scenes, crops = check_dataset(sys.argv[1])
    for p in c.problems:
        print("INVALID", p)
    print("%d scene folders, %d crops checked: %s" % (scenes, crops, "OK" if not c.problems else "%d problems" % len(c.problems)))
    return 1 if c.problems else 0


if __name__ == "__main__":
    sys.exit(main())
