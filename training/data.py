"""Loading what `cell dataset` writes: keypoint crops (crops/PART/SPLIT/) and feeder frames (BOP
scenes under train_feeder/ or test_feeder/), into NumPy arrays with the training targets.

Conventions (OpenCV): pixel centres at integer coordinates. A keypoint-net output cell (i, j)
has its centre at crop pixel (2j + 0.5, 2i + 0.5); a segmenter cell (i, j) at window pixel
(4j + 1.5, 4i + 1.5).
"""

import json
import os
import sys

from concurrent.futures import ThreadPoolExecutor

import numpy as np
from PIL import Image


def _png(path):
    with Image.open(path) as im:
        return np.asarray(im)


def _crop(d, name, stem):
    """One crop of part `name` in folder `d`: (rgb, mask, keypoints, pose)."""
    path = os.path.join(d, stem + ".json")
    with open(path) as f:
        label = json.load(f)
    if label["part"] != name:
        raise ValueError(f"{path}: part {label['part']!r} in the folder of {name!r}")
    rgb = _png(os.path.join(d, label["rgb"]))
    mask = _png(os.path.join(d, label["mask"])) > 127
    if rgb.shape != (128, 128, 3) or mask.shape != (128, 128):
        raise ValueError(f"{path}: crop is {rgb.shape}, mask {mask.shape}; want 128x128")
    kp = np.asarray(label["keypoints"], dtype=np.float32)
    if kp.shape != (9, 2):
        raise ValueError(f"{path}: {kp.shape[0]} keypoints, want 9")
    pose = (
        np.asarray(label["cam_R_m2c"], dtype=np.float64).reshape(3, 3),
        np.asarray(label["cam_t_m2c"], dtype=np.float64),
        np.asarray(label["cam_K"], dtype=np.float64),
        np.asarray(label["dist_coeffs"], dtype=np.float64),
    )
    return rgb, mask, kp, pose


def parallel(fn, items):
    """`fn` over `items` (argument tuples) in order, on a thread pool (PNG decoding and large NumPy
    operations release the GIL)."""
    with ThreadPoolExecutor(max_workers=min(16, os.cpu_count() or 1)) as pool:
        return list(pool.map(lambda a: fn(*a), items))


def load_crops(root, split, parts, limit=None):
    """All crops of `split` ("train"/"test") under `root`/crops, in the order of `parts`.

    Returns dict: rgb uint8 [N,128,128,3], mask bool [N,128,128], keypoints float32 [N,9,2]
    (crop px), part int64 [N]."""
    items, indices = [], []
    for p, name in enumerate(parts):
        d = os.path.join(root, "crops", name, split)
        if not os.path.isdir(d):
            raise FileNotFoundError(f"{d}: no crops of part {name} (run `cell dataset` first)")
        stems = sorted(f[:-5] for f in os.listdir(d) if f.endswith(".json"))
        if limit is not None:
            stems = stems[:limit]
        items += [(d, name, stem) for stem in stems]
        indices += [p] * len(stems)
    rgbs, masks, kps, poses = zip(*parallel(_crop, items))
    return {
        "poses": list(poses),
        "rgb": np.stack(rgbs),
        "mask": np.stack(masks),
        "keypoints": np.stack(kps),
        "part": np.asarray(indices, dtype=np.int64),
        "names": list(parts),
    }


def load_crop_sets(roots, split, parts, limit=None):
    """`load_crops` of each root in `roots` (`--train A:B`: two looks of a part's crops, say),
    concatenated in that order."""
    sets = [load_crops(r, split, parts, limit) for r in roots]
    out = {"poses": [p for s in sets for p in s["poses"]], "names": list(parts)}
    for key in ("rgb", "mask", "keypoints", "part"):
        out[key] = np.concatenate([s[key] for s in sets])
    return out


def load_feeder_sets(roots, folder, parts, limit=None, px_per_mm=None):
    """`load_feeder` of each root in `roots` (`--train A:B`: two looks of the feeder frames), each
    with its own object-id map, concatenated in that order."""
    return [f for r in roots for f in load_feeder(r, folder, obj_ids(r, parts), limit, px_per_mm)]


def mask_cells(mask, stride):
    """Downsamples boolean masks [..., H, W] to cells of `stride` px: true where at least half
    of the cell's pixels are set."""
    h, w = mask.shape[-2:]
    m = mask.reshape(*mask.shape[:-2], h // stride, stride, w // stride, stride)
    return m.mean(axis=(-3, -1)) >= 0.5


def project(K, dist, p_cam):
    """OpenCV projection of camera-frame points [N,3] with distortion (k1, k2, p1, p2, k3)."""
    x = p_cam[:, 0] / p_cam[:, 2]
    y = p_cam[:, 1] / p_cam[:, 2]
    k1, k2, p1, p2, k3 = dist
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    K = np.asarray(K).reshape(3, 3)
    return np.stack([K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]], axis=1)


def load_feeder(root, folder, obj_to_part, limit=None, px_per_mm=None):
    """Feeder frames of BOP split folder `folder` (train_feeder / test_feeder).

    Each frame: rgb uint8 [H,W,3]; at stride 4: cls int8 [H/4,W/4] (0 background, 1+part),
    inst int16 (-1 background, else instance index; both narrow, as a thousand frames are held),
    offset float32 [2,H/4,W/4] (to the instance centre, px); centres float32 [K,2] (projected
    part origins), inst_part [K].
    With `px_per_mm`, each frame and its masks are resampled so that the table shows at that
    scale (what the cell does before the nets see a frame), else they are as rendered.
    Window sides not divisible by 4 are cropped to the multiple (the right/bottom rows)."""
    base = os.path.join(root, folder)
    if not os.path.isdir(base):
        raise FileNotFoundError(f"{base}: no feeder frames (cell dataset --train-feeder/--test-feeder)")
    items = []
    for scene in sorted(os.listdir(base)):
        sdir = os.path.join(base, scene)
        if not scene.isdigit() or not os.path.isdir(sdir):
            continue
        with open(os.path.join(sdir, "scene_camera.json")) as f:
            cams = json.load(f)
        with open(os.path.join(sdir, "scene_gt.json")) as f:
            gts = json.load(f)
        items += [
            (sdir, f"{folder}/{scene}", int(k), cams[k], gts[k], obj_to_part, px_per_mm) for k in sorted(cams, key=int)
        ]
    return parallel(_feeder_frame, items[:limit])


def table_px_per_mm(roots, folder):
    """The table's scale over the feeder frames of `folder` in every root of `roots`, pixels per
    mm, lowest and highest: the focal length over the camera's distance from the table plane
    (world z = 0). The segmenter's manifest records it, and the cell shows the nets frames at its
    middle."""
    scales = []
    for root in roots:
        base = os.path.join(root, folder)
        found = len(scales)
        for scene in sorted(os.listdir(base)):
            path = os.path.join(base, scene, "scene_camera.json")
            if not scene.isdigit() or not os.path.isfile(path):
                continue
            with open(path) as f:
                scales += [frame_px_per_mm(cam) for cam in json.load(f).values()]
        if len(scales) == found:
            raise FileNotFoundError(f"{base}: no scene_camera.json to read the table's scale from")
    return min(scales), max(scales)


def frame_px_per_mm(cam):
    """The table's scale in one frame, pixels per mm: the focal length over the camera's distance
    from the table plane (world z = 0), from the frame's BOP `scene_camera` entry."""
    r = np.asarray(cam["cam_R_w2c"], dtype=np.float64).reshape(3, 3)
    distance = abs(r[:, 2] @ np.asarray(cam["cam_t_w2c"], dtype=np.float64))
    return cam["cam_K"][0] / distance


def _resampled(image, size):
    """`image` (uint8, HxW or HxWx3) resampled to `size` (w, h) with PIL's antialiased triangle
    filter, the filter the cell resamples its frames with."""
    return np.asarray(Image.fromarray(image).resize(size, Image.Resampling.BILINEAR))


def _feeder_frame(sdir, name, im, cam, gt, obj_to_part, px_per_mm=None):
    """Frame `im` of scene folder `sdir` with its stride-4 targets (see `load_feeder`)."""
    rgb = _png(os.path.join(sdir, "rgb", f"{im:06d}.png"))
    masks = [_png(os.path.join(sdir, "mask_visib", f"{im:06d}_{k:06d}.png")) for k in range(len(gt))]
    t = np.asarray([g["cam_t_m2c"] for g in gt], dtype=np.float64)
    centres = project(cam["cam_K"], cam["dist_coeffs"], t)
    if px_per_mm is not None:
        # Pixel centres at integer coordinates: x' = (x + 0.5) * w' / w - 0.5 (and so for y).
        f = px_per_mm / frame_px_per_mm(cam)
        h0, w0 = rgb.shape[:2]
        size = (max(4, round(w0 * f)), max(4, round(h0 * f)))
        rgb = _resampled(rgb, size)
        masks = [_resampled(m, size) for m in masks]
        centres = (centres + 0.5) * np.asarray([size[0] / w0, size[1] / h0]) - 0.5
    centres = centres.astype(np.float32)
    H, W = rgb.shape[0] // 4 * 4, rgb.shape[1] // 4 * 4
    rgb = rgb[:H, :W]
    inst_part = np.asarray([obj_to_part[g["obj_id"]] for g in gt], dtype=np.int64)
    masks = np.stack([m[:H, :W] > 127 for m in masks])
    # Share of each 4x4 cell per instance; background is what is left.
    share = masks.reshape(len(gt), H // 4, 4, W // 4, 4).mean(axis=(2, 4))
    bg = 1.0 - share.sum(axis=0)
    best = share.argmax(axis=0)
    fg = share.max(axis=0) > bg
    inst = np.where(fg, best, -1)
    cls = np.where(fg, inst_part[best] + 1, 0)
    jj, ii = np.meshgrid(np.arange(W // 4), np.arange(H // 4))
    cx = 4 * jj + 1.5
    cy = 4 * ii + 1.5
    offset = np.zeros((2, H // 4, W // 4), dtype=np.float32)
    offset[0] = np.where(fg, centres[best, 0] - cx, 0)
    offset[1] = np.where(fg, centres[best, 1] - cy, 0)
    return {
        "rgb": rgb,
        "cls": cls.astype(np.int8),
        "inst": inst.astype(np.int16),
        "offset": offset,
        "centres": centres,
        "inst_part": inst_part,
        "name": f"{name}/{im:06d}",
    }

def obj_ids(root, parts):
    """obj_id -> index in `parts`, from any crop label or the models' order under `root`."""
    mapping = {}
    for p, name in enumerate(parts):
        for split in ("train", "test"):
            d = os.path.join(root, "crops", name, split)
            if os.path.isdir(d):
                js = sorted(f for f in os.listdir(d) if f.endswith(".json"))
                if js:
                    with open(os.path.join(d, js[0])) as f:
                        mapping[json.load(f)["obj_id"]] = p
                    break
    if len(mapping) != len(parts):
        # Without crops: `cell dataset` numbers the parts 1.. in catalog order.
        mapping = {i + 1: i for i in range(len(parts))}
        print(f"{root}: no crop labels to map obj ids; assuming catalog order", file=sys.stderr)
    return mapping


def flipped_keypoints(data, kp3d):
    """Per crop, the 2D keypoints of the pose turned 180 degrees about the part's z axis (the
    parts' near symmetry), [N, 9, 2]; and the max reprojection difference of the unturned
    keypoints from the labels (a check of the conventions), px."""
    flip = np.diag([-1.0, -1.0, 1.0])
    out = np.zeros_like(data["keypoints"], dtype=np.float64)
    worst = 0.0
    for i, (R, t, K, dist) in enumerate(data["poses"]):
        p = kp3d[data["part"][i]]
        same = project(K, dist, p @ R.T + t)
        worst = max(worst, float(np.abs(same - data["keypoints"][i]).max()))
        out[i] = project(K, dist, (p @ flip.T) @ R.T + t)
    return out, worst
