"""Our Rust pipeline against the seed paper's way of doing it, on the same frames and crops.

The seed's way: the same two networks in PyTorch eager (CPU, 2 threads, as ours), instance
grouping and RANSAC voting in NumPy (`group` in training/train_segmenter.py, `vote` in
training/train_keypoints.py: 128 hypotheses, cos 0.99, least-squares refinement) and OpenCV's
EPnP on the 9 voted keypoints. Ours: `cell eval` (ONNX Runtime, Rust grouping, voting with
covariances, SQPnP + LM, planar refinement), whose eval.json this script reads.

Per frame of eval.json the seed's way runs in this one process, timed per stage with
time.perf_counter (after one untimed warm-up pass over the first frame): preprocess (pad to 16,
/255) → segment (torch) → instances (NumPy grouping) → crops → keypoint_net (torch, one batch
per frame) → voting (NumPy) → pose (EPnP). Image decoding is outside the timing on both sides. The
grouping's own instances are counted but, so that both sides are compared on the SAME crops, the
crops are cut at exactly the `crop_origin`s our pipeline used (128 × 128 of the full image, edge
pixels replicated) with the part our pipeline assigned.

Accuracy pairs the two raw PnP poses of each crop matched to a counted ground-truth instance
(ours: `raw` of eval.json, before planar refinement; also estimates our reprojection gate
refused, as in our Table 1). Errors as the seed's Table 1: |e_x|, |e_y|, |e_z| in mm in the
camera frame and the geodesic angle e_θ in degrees; outliers are e_θ > 10° or undefined
(cell/src/eval/table1.rs, perception::metrics). Means are given over all paired estimates and
seed-style (outliers dropped), with counts.

Usage: compare.py --models DIR --check-models   (only the torch / ONNX Runtime agreement)
       compare.py --eval EVAL_JSON --dataset DATASET --split SPLIT --models DIR --catalog TOML
                  --out OUTDIR [--rust-load "1.2 1.1 1.0"]
Writes OUTDIR/seed_compare.json (atomically) and prints the table.
"""

import argparse
import json
import os
import sys
import time
import tomllib

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, os.path.join(REPO, "training"))

import cv2  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402
from PIL import Image  # noqa: E402

from nets import N_KEYPOINTS, KeypointNet, Segmenter  # noqa: E402

PARTS = ["main_shell", "insert_mold", "top_shell"]
"""The seed's three parts, in the order of the USB-C catalog and of its models' channels."""
from train_keypoints import vote  # noqa: E402
from train_segmenter import group, pad16  # noqa: E402

STAGES = ["preprocess", "segment", "instances", "crops", "keypoint_net", "voting", "pose", "total"]
CROP = 128
OUTLIER_DEG = 10.0
"""The seed's outlier angle (EvalOptions::outlier_deg in cell/src/eval/mod.rs)."""
AGREE = 1e-3
"""Largest |torch − ONNX Runtime| accepted on a random input."""
THREADS = 2


class InputError(Exception):
    """Bad input: the message names the file and what is wrong."""


def load_json(path):
    try:
        with open(path) as f:
            return json.load(f)
    except FileNotFoundError:
        raise InputError(f"{path}: no such file")
    except json.JSONDecodeError as e:
        raise InputError(f"{path}:{e.lineno}:{e.colno}: {e.msg}")


def load_manifest(path):
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except FileNotFoundError:
        raise InputError(f"{path}: no such file")
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"{path}: {e}")


def load_net(models, name):
    """The torch net `name` ("segmenter" / "keypoints") from MODELS/name.pt and an ONNX Runtime
    session of MODELS/name.onnx (the file the manifest names); refuses when they disagree by
    more than AGREE on a random input."""
    import onnxruntime as ort

    manifest = load_manifest(os.path.join(models, f"{name}.toml"))
    if list(manifest.get("parts", [])) != PARTS:
        raise InputError(f"{models}/{name}.toml: parts {manifest.get('parts')} differ from the seed's {PARTS}")
    pt = os.path.join(models, f"{name}.pt")
    onnx_path = os.path.join(models, manifest.get("file", f"{name}.onnx"))
    for p in (pt, onnx_path):
        if not os.path.isfile(p):
            raise InputError(f"{p}: no such file")
    try:
        ckpt = torch.load(pt, map_location="cpu", weights_only=True)
        widths = tuple(int(w) for w in ckpt["widths"])
        net = (Segmenter if name == "segmenter" else KeypointNet)(len(PARTS), widths)
        net.load_state_dict(ckpt["state_dict"])
    except (KeyError, TypeError, RuntimeError, ValueError) as e:
        raise InputError(f"{pt}: not a {{'widths', 'state_dict'}} checkpoint of the {name} net: {e}")
    net.eval()
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = THREADS
    opts.inter_op_num_threads = 1
    sess = ort.InferenceSession(onnx_path, opts, providers=["CPUExecutionProvider"])
    gen = torch.Generator().manual_seed(1)
    if name == "segmenter":
        x = torch.rand(1, 3, 256, 320, generator=gen)
    else:
        x = torch.rand(3, 6, CROP, CROP, generator=gen)
        x[:, 3:] = torch.nn.functional.one_hot(torch.arange(3) % len(PARTS), len(PARTS)).float()[:, :, None, None]
    # The keypoint graph is exported without normalising its vectors (training/README.md):
    # compare the raw ones, then let the eager net give unit vectors as the seed's voting expects.
    keypoints = name == "keypoints"
    if keypoints:
        net.unit_vectors = False
    with torch.inference_mode():
        ref = net(x)
    if keypoints:
        net.unit_vectors = True
    outs = sess.run(None, {sess.get_inputs()[0].name: x.numpy()})
    diff = max(float(np.abs(o - r.numpy()).max()) for o, r in zip(outs, ref))
    if not diff < AGREE:
        raise InputError(
            f"{pt} and {onnx_path} disagree: max |torch − ONNX Runtime| = {diff:.3g} on a random input "
            f"(limit {AGREE}); the .pt is not the weights of the .onnx"
        )
    return net, diff


def catalog_keypoints(path):
    """Part name → the 9 keypoints [9, 3] in metres (part frame), from the catalog TOML."""
    cat = load_manifest(path)
    out = {}
    for p in cat.get("part", []):
        if "keypoints" not in p:
            continue
        kp = np.asarray(p["keypoints"], dtype=np.float64)
        if kp.shape != (N_KEYPOINTS, 3):
            raise InputError(f"{path}: part {p.get('name')} has keypoints of shape {kp.shape}, want ({N_KEYPOINTS}, 3)")
        out[p["name"]] = kp
    missing = [n for n in PARTS if n not in out]
    if missing:
        raise InputError(f"{path}: no keypoints for {missing}")
    return out


def cut(rgb, origin):
    """The 128 × 128 crop of `rgb` [H, W, 3] whose top-left is image pixel `origin` = [col, row],
    edge pixels replicated outside the image (as perception::learned::crops)."""
    h, w = rgb.shape[:2]
    rows = np.clip(origin[1] + np.arange(CROP), 0, h - 1)
    cols = np.clip(origin[0] + np.arange(CROP), 0, w - 1)
    return rgb[rows[:, None], cols[None, :]]


def rot_angle_deg(ra, rb):
    c = (np.trace(ra.T @ rb) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def errors(gt, r_est, t_est_m):
    """(|e_x|, |e_y|, |e_z|) mm and e_θ deg of an estimate against a scene_gt entry (mm)."""
    r_gt = np.asarray(gt["cam_R_m2c"], dtype=np.float64).reshape(3, 3)
    t_gt = np.asarray(gt["cam_t_m2c"], dtype=np.float64) * 1e-3
    d = np.abs(t_est_m - t_gt) * 1e3
    return [float(d[0]), float(d[1]), float(d[2]), rot_angle_deg(r_gt, r_est)]


def project(K, dist, p_cam):
    """Camera-frame points [N, 3] to pixels with OpenCV's model."""
    px, _ = cv2.projectPoints(p_cam, np.zeros(3), np.zeros(3), K, dist)
    return px.reshape(-1, 2)


def is_outlier(e):
    return not (e[3] <= OUTLIER_DEG)


def table1(errs):
    """Means over all estimates and seed-style (outliers dropped), with counts."""
    e = np.asarray(errs, dtype=np.float64).reshape(-1, 4)
    keep = np.array([not is_outlier(x) for x in e], dtype=bool)
    row = {"n": int(len(e)), "outliers": int((~keep).sum())}
    for label, sel in (("all", np.ones(len(e), dtype=bool)), ("seed_style", keep)):
        sub = e[sel]
        row[label] = {
            "n": int(len(sub)),
            "mean": [float(v) for v in sub.mean(axis=0)] if len(sub) else [float("nan")] * 4,
            "std": [float(v) for v in sub.std(axis=0)] if len(sub) else [float("nan")] * 4,
            "median": [float(v) for v in np.median(sub, axis=0)] if len(sub) else [float("nan")] * 4,
        }
    return row


_SCENE_FILES = {}


def scene_json(sdir, name):
    """scene_camera.json / scene_gt.json of a scene folder, read once."""
    path = os.path.join(sdir, name)
    if path not in _SCENE_FILES:
        _SCENE_FILES[path] = load_json(path)
    return _SCENE_FILES[path]


def median(v):
    return float(np.median(v)) if len(v) else float("nan")


def run_seed(frames_json, dataset, split, seg, kpn, kp3d, rng):
    """The seed's way over the frames of eval.json; returns per-frame times and per-detection
    results keyed by (frame index, detection index)."""
    times = []
    results = {}
    instance_counts = []
    for fi, fr in enumerate(frames_json):
        sdir = os.path.join(dataset, split, f"{fr['scene']:06d}")
        cams = scene_json(sdir, "scene_camera.json")
        key = str(fr["image"])
        if key not in cams:
            raise InputError(f"{sdir}/scene_camera.json: no image {fr['image']} (eval.json has it)")
        cam = cams[key]
        K = np.asarray(cam["cam_K"], dtype=np.float64).reshape(3, 3)
        dist = np.asarray(cam.get("dist_coeffs", [0.0] * 5), dtype=np.float64)
        png = os.path.join(sdir, "rgb", f"{fr['image']:06d}.png")
        try:
            with Image.open(png) as im:
                rgb = np.asarray(im.convert("RGB"))
        except FileNotFoundError:
            raise InputError(f"{png}: no such file")
        if (rgb.shape[1], rgb.shape[0]) != (cam["width"], cam["height"]):
            raise InputError(
                f"{png}: {rgb.shape[1]} × {rgb.shape[0]}, scene_camera.json says {cam['width']} × {cam['height']}"
            )
        dets = fr["detections"]
        for d in dets:
            if d["part"] not in kp3d:
                raise InputError(f"eval.json: scene {fr['scene']} image {fr['image']}: unknown part {d['part']!r}")
        t = {}
        t0 = time.perf_counter()
        H, W = rgb.shape[:2]
        x = torch.from_numpy(pad16(rgb)).permute(2, 0, 1)[None].float() / 255.0
        t1 = time.perf_counter()
        with torch.inference_mode():
            logits, offsets = seg(x)
        h, w = H // 4, W // 4
        pred = logits[0].argmax(0).numpy()[:h, :w]
        off = offsets[0].numpy()[:, :h, :w]
        t2 = time.perf_counter()
        _, classes = group(pred, off, logits[0].softmax(0).numpy()[:, :h, :w])
        t3 = time.perf_counter()
        # The crops our pipeline cut, with its parts.
        n = len(dets)
        if n:
            crops = np.stack([cut(rgb, d["crop_origin"]) for d in dets])
            batch = torch.from_numpy(crops).permute(0, 3, 1, 2).float() / 255.0
            part = torch.tensor([PARTS.index(d["part"]) for d in dets])
            onehot = torch.nn.functional.one_hot(part, len(PARTS)).float()[:, :, None, None]
            onehot = onehot.expand(n, len(PARTS), CROP, CROP)
            batch = torch.cat([batch, onehot], dim=1)
        t4 = time.perf_counter()
        if n:
            with torch.inference_mode():
                mask, vectors = kpn(batch)
            mask = mask[:, 0].numpy() > 0
            vectors = vectors.numpy()
        t5 = time.perf_counter()
        votes = [vote(mask[i], vectors[i], rng) for i in range(n)]
        t6 = time.perf_counter()
        poses = []
        for d, v in zip(dets, votes):
            img = v + np.asarray(d["crop_origin"], dtype=np.float64)
            if not np.isfinite(img).all():
                poses.append(None)
                continue
            try:
                ok, rvec, tvec = cv2.solvePnP(kp3d[d["part"]], img, K, dist, flags=cv2.SOLVEPNP_EPNP)
            except cv2.error:
                ok = False
            poses.append((rvec, tvec) if ok else None)
        t7 = time.perf_counter()
        for name, a, b in zip(STAGES, (t0, t1, t2, t3, t4, t5, t6, t0), (t1, t2, t3, t4, t5, t6, t7, t7)):
            t[name] = (b - a) * 1e3
        t["load1"] = os.getloadavg()[0]
        times.append(t)
        instance_counts.append((len(classes), n))
        gts = scene_json(sdir, "scene_gt.json")
        for di, (d, v, pose) in enumerate(zip(dets, votes, poses)):
            res = {"keypoints_px": (v + np.asarray(d["crop_origin"])).tolist(), "errors": None}
            if d.get("truth") is not None:
                gt = gts[key][d["truth"]]
                r_gt = np.asarray(gt["cam_R_m2c"], dtype=np.float64).reshape(3, 3)
                t_gt = np.asarray(gt["cam_t_m2c"], dtype=np.float64) * 1e-3
                truth_px = project(K, dist, kp3d[d["part"]] @ r_gt.T + t_gt)
                res["truth_px"] = truth_px
                if pose is not None:
                    r_est, _ = cv2.Rodrigues(pose[0])
                    res["errors"] = errors(gt, r_est, np.asarray(pose[1], dtype=np.float64).reshape(3))
            results[(fi, di)] = res
    return times, results, instance_counts


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--eval", help="eval.json written by `cell eval`")
    ap.add_argument("--dataset", help="the BOP dataset `cell eval` read")
    ap.add_argument("--split", default="test_feeder")
    ap.add_argument("--models", required=True, help="folder with segmenter/keypoints .pt, .onnx, .toml")
    ap.add_argument("--catalog", help="part catalog TOML (3D keypoints)")
    ap.add_argument("--out", help="folder for seed_compare.json")
    ap.add_argument("--rust-load", default=None, help="load average when `cell eval` started (informational)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the voting's RANSAC")
    ap.add_argument("--check-models", action="store_true", help="only check that torch and ONNX Runtime agree")
    args = ap.parse_args(argv)
    torch.set_num_threads(THREADS)
    if args.check_models:
        for name in ("segmenter", "keypoints"):
            _, diff = load_net(args.models, name)
            print(f"{args.models}/{name}: torch and ONNX Runtime agree (max |diff| {diff:.2e})")
        return 0
    for opt in ("eval", "dataset", "catalog", "out"):
        if getattr(args, opt) is None:
            ap.error(f"--{opt} is required")

    if not os.path.isdir(os.path.join(args.dataset, args.split)):
        raise InputError(f"{os.path.join(args.dataset, args.split)}: no such split folder")
    ev = load_json(args.eval)
    try:
        frames = ev["frames"]
        for f in frames:
            for d in f["detections"]:
                d["crop_origin"], d["part"]
    except (KeyError, TypeError) as e:
        raise InputError(f"{args.eval}: not eval.json of a `cell eval` with crop origins (missing {e})")
    if not frames:
        raise InputError(f"{args.eval}: no frames")
    kp3d = catalog_keypoints(args.catalog)

    cv2.setNumThreads(1)
    seg, seg_diff = load_net(args.models, "segmenter")
    kpn, kpn_diff = load_net(args.models, "keypoints")
    print(f"models {args.models}: torch vs ONNX Runtime max |diff| segmenter {seg_diff:.2e}, keypoints {kpn_diff:.2e}")

    # One untimed pass over the first frame: torch's first calls (allocator, kernel selection)
    # would otherwise count against the seed's way.
    run_seed(frames[:1], args.dataset, args.split, seg, kpn, kp3d, np.random.default_rng(args.seed + 1))
    load_before = os.getloadavg()
    started = time.perf_counter()
    rng = np.random.default_rng(args.seed)
    times, results, counts = run_seed(frames, args.dataset, args.split, seg, kpn, kp3d, rng)
    wall = time.perf_counter() - started
    load_after = os.getloadavg()

    # Timing: frames both sides ran (ours has no times where the detector failed outright).
    rust_times = [f["times"] for f in frames]
    both = [i for i, rt in enumerate(rust_times) if rt is not None]
    stage_rows = []
    for s in STAGES:
        r = [rust_times[i][s] for i in both]
        p = [times[i][s] for i in both]
        stage_rows.append({"stage": s, "ours_median_ms": median(r), "seed_median_ms": median(p),
                           "ours_mean_ms": float(np.mean(r)) if r else float("nan"),
                           "seed_mean_ms": float(np.mean(p)) if p else float("nan")})
    total = stage_rows[-1]
    ratio = total["seed_median_ms"] / total["ours_median_ms"]
    ratio_mean = total["seed_mean_ms"] / total["ours_mean_ms"]

    # Accuracy on the same crops.
    paired = {"all": ([], [])}
    counts_acc = {"matched": 0, "paired": 0, "ours_only": 0, "seed_only": 0, "neither": 0}
    kp_err = {"ours": [], "seed": [], "ours_vs_seed": []}
    for fi, f in enumerate(frames):
        for di, d in enumerate(f["detections"]):
            t = d.get("truth")
            if t is None or f["truths"][t]["ignored"]:
                continue
            counts_acc["matched"] += 1
            res = results[(fi, di)]
            ours = d.get("raw")
            ours_e = None if ours is None else [ours["x_mm"], ours["y_mm"], ours["z_mm"], ours["angle_deg"]]
            seed_e = res["errors"]
            truth_px = res.get("truth_px")
            seed_kp = np.asarray(res["keypoints_px"])
            if truth_px is not None and np.isfinite(seed_kp).all():
                kp_err["seed"].extend(np.linalg.norm(seed_kp - truth_px, axis=1).tolist())
            if truth_px is not None and len(d.get("keypoints_px") or []) == N_KEYPOINTS:
                ours_kp = np.asarray(d["keypoints_px"], dtype=np.float64)
                kp_err["ours"].extend(np.linalg.norm(ours_kp - truth_px, axis=1).tolist())
                if np.isfinite(seed_kp).all():
                    kp_err["ours_vs_seed"].extend(np.linalg.norm(ours_kp - seed_kp, axis=1).tolist())
            if ours_e is not None and seed_e is not None:
                counts_acc["paired"] += 1
                for key in ("all", d["part"]):
                    paired.setdefault(key, ([], []))
                    paired[key][0].append(ours_e)
                    paired[key][1].append(seed_e)
            elif ours_e is not None:
                counts_acc["ours_only"] += 1
            elif seed_e is not None:
                counts_acc["seed_only"] += 1
            else:
                counts_acc["neither"] += 1
    acc_rows = []
    for key in [p for p in PARTS if p in paired] + ["all"]:
        acc_rows.append({"part": key, "ours": table1(paired[key][0]), "seed": table1(paired[key][1])})
    kp_summary = {k: {"n": len(v), "median_px": median(v), "mean_px": float(np.mean(v)) if v else float("nan")}
                  for k, v in kp_err.items()}
    seed_instances = sum(c[0] for c in counts)
    ours_instances = sum(c[1] for c in counts)

    all_row = acc_rows[-1]
    o_all, s_all = all_row["ours"]["all"]["mean"], all_row["seed"]["all"]["mean"]
    at_least_as_accurate = bool(all(o <= s for o, s in zip(o_all, s_all))) and (
        all_row["ours"]["outliers"] <= all_row["seed"]["outliers"]
    )

    out = {
        "eval_json": os.path.abspath(args.eval),
        "dataset": os.path.abspath(args.dataset),
        "split": args.split,
        "models": os.path.abspath(args.models),
        "frames": len(frames),
        "frames_timed": len(both),
        "torch": torch.__version__,
        "opencv": cv2.__version__,
        "threads": THREADS,
        "torch_vs_onnxruntime_max_abs_diff": {"segmenter": seg_diff, "keypoints": kpn_diff},
        "cpus": os.cpu_count(),
        "load_average": {
            "before_cell_eval": args.rust_load,
            "before_seed": list(load_before),
            "after_seed": list(load_after),
        },
        "seed_wall_s": wall,
        "stages": stage_rows,
        "per_frame_ms": [
            {"scene": f["scene"], "image": f["image"], "crops": len(f["detections"]),
             "ours": f["times"], "seed": times[i]}
            for i, f in enumerate(frames)
        ],
        "speed_ratio_median": ratio,
        "speed_ratio_mean": ratio_mean,
        "instances": {"ours": ours_instances, "seed_grouping": seed_instances},
        "detections": counts_acc,
        "table1_raw_pnp": acc_rows,
        "keypoint_error_px": kp_summary,
        "ours_at_least_3x_faster": bool(ratio >= 3.0),
        "ours_at_least_as_accurate": at_least_as_accurate,
    }
    os.makedirs(args.out, exist_ok=True)
    path = os.path.join(args.out, "seed_compare.json")
    with open(path + ".tmp", "w") as f:
        json.dump(out, f, indent=2)
        f.write("\n")
    os.replace(path + ".tmp", path)

    print(f"{len(frames)} frames of {args.dataset}/{args.split}; torch {torch.__version__} eager, "
          f"OpenCV {cv2.__version__}, "
          f"{THREADS} threads each")
    print(f"load average (1, 5, 15 min): before cell eval {args.rust_load or '?'}; before the seed's way "
          + " ".join(f"{v:.2f}" for v in load_before) + "; after " + " ".join(f"{v:.2f}" for v in load_after))
    busy = [i for i in both if times[i]["load1"] > os.cpu_count()]
    if busy:
        print(f"WARNING: the 1-min load average exceeded the {os.cpu_count()} CPUs during {len(busy)} of "
              f"{len(both)} frames of the seed's way (first at frame {busy[0]}); its times there are inflated "
              "(see per_frame_ms in seed_compare.json)")
    print(f"\nTime per frame, ms (median over {len(both)} frames; mean in brackets)")
    print(f"{'stage':<13} {'ours (Rust)':>20} {'seed way (Python)':>22}")
    for r in stage_rows:
        print(f"{r['stage']:<13} {r['ours_median_ms']:>9.2f} ({r['ours_mean_ms']:>7.2f}) "
              f"{r['seed_median_ms']:>11.2f} ({r['seed_mean_ms']:>7.2f})")
    print(f"speed ratio seed way / ours: {ratio:.2f}× (medians), {ratio_mean:.2f}× (means)"
          f" — ours ≥ 3× faster: {'yes' if ratio >= 3 else 'NO'}")
    print(f"instances: ours {ours_instances}, the seed's NumPy grouping {seed_instances} (crops compared: ours)")
    c = counts_acc
    print(f"\nTable 1, raw PnP on the same crops: {c['matched']} crops matched to a counted instance, "
          f"{c['paired']} with a pose both ways (paired); ours only {c['ours_only']}, seed way only "
          f"{c['seed_only']}, neither {c['neither']}")
    print("|error| in the camera frame, mean (all paired) and seed-style (e_θ > 10° dropped; 'out' counts them)")
    hdr = f"{'part':<12} {'method':<26} {'n':>5} {'out':>4} {'x mm':>7} {'y mm':>7} {'z mm':>8} {'θ deg':>7}"
    print(hdr)
    for r in acc_rows:
        for who, label in (("ours", "ours SQPnP+LM"), ("seed", "seed EPnP")):
            t = r[who]
            for style in ("all", "seed_style"):
                m = t[style]["mean"]
                name = r["part"] if (who, style) == ("ours", "all") else ""
                method = label + (", all" if style == "all" else ", seed-style")
                print(f"{name:<12} {method:<26} "
                      f"{t[style]['n']:>5} {t['outliers']:>4} {m[0]:>7.3f} {m[1]:>7.3f} {m[2]:>8.2f} {m[3]:>7.2f}")
    print(f"ours at least as accurate (all-paired means and outlier count): {'yes' if at_least_as_accurate else 'NO'}")
    k = kp_summary
    print(f"keypoints vs the projected truth, median px: ours {k['ours']['median_px']:.2f}, seed way "
          f"{k['seed']['median_px']:.2f}; ours vs seed way on the same crop {k['ours_vs_seed']['median_px']:.2f}")
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except InputError as e:
        sys.exit(f"seed_compare: {e}")
