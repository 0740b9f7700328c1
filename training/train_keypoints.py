"""Trains the keypoint net (one net for all the catalog's parts, part given as one-hot planes) on the
crops of `cell dataset`, evaluates it on the test crops (mask IoU, keypoint error after RANSAC
voting), exports keypoints.onnx and writes keypoints.toml + keypoints_curve.csv.

Usage: python train_keypoints.py --train DATA_TRAIN --test DATA_TEST --out scenarios/models/usbc
--train may name several roots, separated by ':' (one part's crops in two looks, say).
"""

import os
import sys
import time

import numpy as np
import torch
import torch.nn.functional as F

from common import (Curve, check_export, code_commit, export_onnx, jitter, load_start, progress_lr,
                    recorded_train_minutes, setup, training_args, write_manifest)
import catalog
import symmetry
from data import flipped_keypoints, load_crop_sets, load_crops, mask_cells, parallel
from nets import N_KEYPOINTS, KeypointNet, count_macs

GRID = 64  # output cells per side (stride 2 on 128 px)


def cell_centres(device):
    """Crop-pixel centres of the output cells: x [64, 64], y [64, 64]."""
    c = torch.arange(GRID, dtype=torch.float32, device=device) * 2 + 0.5
    y, x = torch.meshgrid(c, c, indexing="ij")
    return x, y


def vector_targets(kp, cx, cy):
    """Unit vectors [..., 18, 64, 64] from every cell centre to each keypoint (x, y per keypoint)
    of labels kp [..., 9, 2] (one label a crop, [B, 9, 2], or K, [B, K, 9, 2])."""
    dx = kp[..., 0, None, None] - cx
    dy = kp[..., 1, None, None] - cy
    n = torch.sqrt(dx * dx + dy * dy).clamp_min(1e-6)
    v = torch.stack([dx / n, dy / n], dim=-3)  # ..., 9, 2, 64, 64
    return v.reshape(*kp.shape[:-2], 2 * N_KEYPOINTS, GRID, GRID)


def make_input(rgb_u8, part, n_parts, device, augment=False, gen=None):
    """[B, 3 + n_parts, 128, 128] float: RGB / 255 (optionally jittered by `jitter` with `gen`, a
    generator on `device`) + one-hot planes of the part indices `part`."""
    x = rgb_u8.to(device).float() / 255.0
    if augment:
        x = jitter(x, gen)
    b = x.shape[0]
    onehot = F.one_hot(part.to(device), n_parts).float()[:, :, None, None].expand(b, n_parts, 128, 128)
    return torch.cat([x, onehot], dim=1)


def roll_angles(b, gen, exact_share=0.5):
    """A random camera roll per crop [b], rad: a share of exact quarter turns (no resampling
    blur, as at inference), the rest uniform."""
    quarter = torch.rand(b, generator=gen) < exact_share
    return torch.where(
        quarter,
        torch.randint(0, 4, (b,), generator=gen).float() * (torch.pi / 2),
        (2 * torch.rand(b, generator=gen) - 1) * torch.pi,
    )


def rotate(x, mask, kp, angle):
    """In-plane rotation about the crop centre (a camera roll) by `angle` [B] rad: images x
    [B, C, 128, 128] (reflected at the corners), target masks [B, 128, 128] and keypoints
    [B, ..., 2] in crop px (one label a crop, [B, 9, 2], or K, [B, K, 9, 2]). The data already
    spans every yaw; turning each crop again gives the net new appearances of the same labels,
    which is what the small set lacks."""
    b = x.shape[0]
    c, s = torch.cos(angle), torch.sin(angle)
    # Output pixel p samples the input at centre + R(-angle) (p - centre); normalised coordinates
    # with align_corners=False put the origin at crop pixel 63.5, the rotation centre.
    theta = torch.stack([torch.stack([c, s, torch.zeros(b)], 1), torch.stack([-s, c, torch.zeros(b)], 1)], 1)
    grid = F.affine_grid(theta.to(x.device), list(x.shape), align_corners=False)
    x = F.grid_sample(x, grid, mode="bilinear", padding_mode="reflection", align_corners=False)
    m = F.grid_sample(mask[:, None].float(), grid, mode="bilinear", padding_mode="zeros", align_corners=False)
    centre = (x.shape[-1] - 1) / 2
    d = kp - centre
    per_crop = (b,) + (1,) * (kp.dim() - 2)
    c, s = c.to(kp.device).view(per_crop), s.to(kp.device).view(per_crop)
    kp = torch.stack([centre + c * d[..., 0] - s * d[..., 1], centre + s * d[..., 0] + c * d[..., 1]], dim=-1)
    return x, m[:, 0] >= 0.5, kp


def losses(mask_logit, vectors, mask_t, vec_t):
    """PVNet loss: BCE on the mask + smooth-L1 on the vectors inside the true mask (1:1).
    `vec_t` [B, 18, 64, 64] is one label per crop; [B, K, 18, 64, 64] gives K equally right
    labels (a symmetric part's twins), and each crop is scored against the one it fits best."""
    l_mask = F.binary_cross_entropy_with_logits(mask_logit, mask_t)
    w = mask_t
    if vec_t.dim() == 4:
        vec_t = vec_t[:, None]
    per = F.smooth_l1_loss((vectors * w)[:, None].expand_as(vec_t), vec_t * w[:, None], reduction="none")
    l_vec = per.sum((2, 3, 4)).min(dim=1).values.sum() / (w.sum() * 2 * N_KEYPOINTS + 1.0)
    return l_mask, l_vec


def vote(mask, vectors, rng, hyps=128, cos_thr=0.99):
    """RANSAC voting of one crop (NumPy): mask bool [64, 64], vectors [18, 64, 64] -> keypoints
    [9, 2] in crop px (NaN where fewer than 8 foreground cells)."""
    ii, jj = np.nonzero(mask)
    out = np.full((N_KEYPOINTS, 2), np.nan)
    if len(ii) < 8:
        return out
    p = np.stack([2 * jj + 0.5, 2 * ii + 0.5], axis=1)  # M, 2
    v = vectors.reshape(N_KEYPOINTS, 2, GRID, GRID)[:, :, ii, jj].transpose(0, 2, 1)  # 9, M, 2
    a = rng.integers(0, len(ii), hyps)
    b = rng.integers(0, len(ii), hyps)
    pa, pb = p[a], p[b]  # H, 2
    va, vb = v[:, a], v[:, b]  # 9, H, 2
    # pa + s va = pb + t vb  ->  [va, -vb] [s, t]^T = pb - pa
    det = va[..., 0] * (-vb[..., 1]) - va[..., 1] * (-vb[..., 0])
    r = pb - pa
    s = (r[:, 0] * (-vb[..., 1]) - r[:, 1] * (-vb[..., 0])) / np.where(np.abs(det) < 1e-9, np.nan, det)
    h = pa + s[..., None] * va  # 9, H, 2
    d = h[:, :, None, :] - p[None, None]  # 9, H, M, 2
    dn = np.linalg.norm(d, axis=-1) + 1e-9
    cos = (d * v[:, None]).sum(-1) / dn
    score = np.nan_to_num((cos > cos_thr).sum(-1) * np.isfinite(s), nan=0)
    best = score.argmax(axis=1)
    for k in range(N_KEYPOINTS):
        inl = cos[k, best[k]] > cos_thr
        if inl.sum() < 2:
            continue
        vk, pk = v[k, inl], p[inl]
        n = np.stack([-vk[:, 1], vk[:, 0]], axis=1)  # line normals
        A = n.T @ n
        rhs = (n * (n * pk).sum(1, keepdims=True)).sum(0)
        if abs(np.linalg.det(A)) < 1e-9:
            out[k] = h[k, best[k]]
        else:
            out[k] = np.linalg.solve(A, rhs)
    return out


@torch.no_grad()
def predict(model, data, device, batch=64):
    """Mask logits [N, 64, 64] and vectors [N, 18, 64, 64] of a crop set."""
    model.eval()
    ms, vs = [], []
    for s in range(0, len(data["part"]), batch):
        x = make_input(data["rgb_t"][s : s + batch], data["part_t"][s : s + batch], model.n_parts, device)
        m, v = model(x)
        ms.append(m[:, 0].cpu().numpy())
        vs.append(v.cpu().numpy())
    return np.concatenate(ms), np.concatenate(vs)


def evaluate(model, data, device, voting=False):
    """Test metrics: mask IoU (pooled over cells), mean vector angle error inside the true mask
    (deg); with `voting`, keypoint errors (px) after RANSAC voting, overall and per part."""
    m, v = predict(model, data, device)
    pred = m > 0
    gt = data["mask64"]
    inter = (pred & gt).sum()
    union = (pred | gt).sum()
    metrics = {"mask_iou": float(inter / max(union, 1))}
    ious = (pred & gt).sum((1, 2)) / np.maximum((pred | gt).sum((1, 2)), 1)
    metrics["mask_iou_median"] = float(np.median(ious))
    vt = data["vec64"]
    dot = (v * vt).reshape(len(v), N_KEYPOINTS, 2, GRID, GRID).sum(2)
    ang = np.degrees(np.arccos(np.clip(dot, -1, 1)))  # N, 9, 64, 64
    sel = np.broadcast_to(gt[:, None], ang.shape)
    metrics["vector_angle_mean_deg"] = float(ang[sel].mean())
    if voting:
        # One generator a crop: the votes are the same on any number of threads.
        votes = parallel(vote, [(pred[i], v[i], np.random.default_rng(i)) for i in range(len(v))])
        errs = np.stack([np.linalg.norm(votes[i] - data["keypoints"][i], axis=1) for i in range(len(v))])
        ok = np.isfinite(errs)
        errs_f = np.where(ok, errs, 1e3)  # a failed vote counts as a large error in the median
        metrics["keypoint_px_median"] = float(np.median(errs_f))
        metrics["keypoint_px_mean"] = float(errs[ok].mean()) if ok.any() else float("nan")
        metrics["centre_px_median"] = float(np.median(errs_f[:, 8]))
        metrics["vote_failed_fraction"] = float(1 - ok.mean())
        if "flipped" in data:
            # Up to the parts' near 180-degree symmetry: the better of the true and turned labels.
            errs_t = np.stack([np.linalg.norm(votes[i] - data["flipped"][i], axis=1) for i in range(len(v))])
            errs_t = np.where(np.isfinite(errs_t), errs_t, 1e3)
            turned = errs_t.mean(1) < errs_f.mean(1)
            metrics["flip_fraction"] = float(turned.mean())
            metrics["keypoint_px_median_up_to_flip"] = float(np.median(np.where(turned[:, None], errs_t, errs_f)))
        if "twin_kp" in data:
            # A symmetric part's pose is right in any twin: the error to the nearest one.
            twins = data["twin_kp"].numpy()
            real = data["twin_coef"].numpy()[..., 2] > -1e8
            errs_any = np.stack([np.linalg.norm(votes[i][None] - twins[i], axis=2) for i in range(len(v))])
            errs_any = np.where(np.isfinite(errs_any) & real[:, :, None], errs_any, 1e3)
            best = np.median(errs_any, axis=2).argmin(1)
            errs_any = errs_any[np.arange(len(v)), best]
            metrics["keypoint_px_median_nearest_twin"] = float(np.median(errs_any))
        for p, name in enumerate(data["names"]):
            sel_p = data["part"] == p
            metrics[f"keypoint_px_median_{name}"] = float(np.median(errs_f[sel_p]))
            metrics[f"mask_iou_median_{name}"] = float(np.median(ious[sel_p]))
    return metrics


def prepare(raw, device, targets):
    """Adds the tensors to a crop set, and with `targets` the stride-2 mask and vector targets
    the evaluation compares with (18 planes of 64 x 64 floats a crop: 7 GB for 24 000 training
    crops, which only the test set needs)."""
    raw["rgb_t"] = torch.from_numpy(raw.pop("rgb")).permute(0, 3, 1, 2).contiguous()
    raw["part_t"] = torch.from_numpy(raw["part"])
    raw["mask_t"] = torch.from_numpy(raw["mask"])
    raw["kp_t"] = torch.from_numpy(raw["keypoints"])
    if not targets:
        return raw
    raw["mask64"] = mask_cells(raw["mask"], 2)
    cx, cy = cell_centres("cpu")
    raw["vec64"] = np.concatenate(
        [vector_targets(raw["kp_t"][s : s + 256], cx, cy).numpy() for s in range(0, len(raw["part"]), 256)]
    )
    return raw


def main(argv=None):
    ap = training_args(__doc__, "crops/PART/{split}", "keypoints", "crops per part")
    ap.add_argument("--epochs", type=int, default=20)
    ap.add_argument("--batch", type=int, default=32)
    ap.add_argument("--rotate", type=int, default=1, help="1: turn each training crop about its centre (augmentation)")
    ap.add_argument("--widths", default=",".join(map(str, KeypointNet.WIDTHS)), help="channels at strides 2, 4, 8, 16, 32")
    ap.add_argument("--eval-every", type=int, default=1, help="epochs between test evaluations")
    ap.add_argument("--twins", type=int, default=1,
                    help="symmetric parts: score each crop against the best of its K twins nearest the "
                         "canonical one (1: the canonical label alone)")
    args = ap.parse_args(argv)
    if args.twins < 1:
        sys.exit(f"--twins {args.twins}: want at least 1")

    device = setup(args.seed, args.threads)
    t0 = time.time()
    parts = catalog.assembled_parts(args.catalog)
    train = load_crop_sets(args.train, "train", parts, args.limit)
    test = load_crops(args.test, "test", parts, args.limit)
    print(f"loaded {len(train['part'])} train / {len(test['part'])} test crops in {time.time() - t0:.0f} s", flush=True)
    kp3d = catalog.keypoints(args.catalog, parts)
    test["flipped"], worst = flipped_keypoints(test, kp3d)
    if worst > 0.05:
        sys.exit(f"{args.catalog}: keypoints reproject {worst:.3f} px off the crop labels")
    symmetries = catalog.symmetries(args.catalog, parts)
    if any(symmetries):
        # Symmetric parts: each crop labelled with its canonical twin pose (symmetry.py).
        groups = [symmetry.group(s) for s in symmetries]
        for raw in (train, test):
            worst = symmetry.canonicalise(raw, kp3d, groups)
            if worst > 0.05:
                sys.exit(f"{args.catalog}: keypoints reproject {worst:.3f} px off the crop labels")
        print("twin poses per part: " + ", ".join(f"{p} {len(g)}" for p, g in zip(parts, groups)), flush=True)
    train, test = prepare(train, device, targets=False), prepare(test, device, targets=True)

    widths = tuple(int(w) for w in args.widths.split(","))
    model = KeypointNet(len(parts), widths).to(device)
    macs = count_macs(model, torch.zeros(1, 3 + len(parts), 128, 128, device=device))
    print(f"keypoint net: {macs / 1e6:.1f} MMAC per crop, {sum(p.numel() for p in model.parameters())} parameters")
    opt = torch.optim.Adam(model.parameters(), lr=args.lr, weight_decay=1e-5)
    n = len(train["part"])
    steps_per_epoch = max(1, n // args.batch)
    total = steps_per_epoch * args.epochs
    cx, cy = cell_centres(device)
    gen = torch.Generator().manual_seed(args.seed)
    gen_dev = torch.Generator(device=device).manual_seed(args.seed)
    # On a GPU the training set lives there: batches are gathered without host copies.
    for key in ("rgb_t", "part_t", "mask_t", "kp_t", "twin_kp", "twin_coef"):
        if key in train:
            train[key] = train[key].to(device)
    os.makedirs(args.out, exist_ok=True)
    curve_name = "keypoints_curve.csv"
    load_start(model, args, device)
    if args.eval_only:
        train_minutes = recorded_train_minutes(args.out, "keypoints", model)
        args.epochs = 0
    curve = None if args.eval_only else Curve(
        os.path.join(args.out, curve_name),
        ["epoch", "step", "elapsed_s", "lr", "train_loss", "train_mask_loss", "train_vec_loss", "test_mask_iou", "test_vector_angle_mean_deg"],
    )
    t_train = time.time()
    step = 0
    stopped = False
    # Losses summed on the device since the last curve row (no host sync per step).
    acc, k = torch.zeros(3, device=device), 0
    for epoch in range(args.epochs):
        model.train()
        perm = torch.randperm(n, generator=gen)
        for s in range(steps_per_epoch):
            lr, progress = progress_lr(opt, args.lr, step, total, time.time() - t_train, 60 * args.max_minutes)
            idx = perm[s * args.batch : (s + 1) * args.batch].to(device)
            x = make_input(train["rgb_t"][idx], train["part_t"][idx], len(parts), device, augment=True, gen=gen_dev)
            mask, kp = train["mask_t"][idx], train["kp_t"][idx]
            if args.rotate:
                angle = roll_angles(len(idx), gen)
                if "twin_kp" in train:
                    # The twin to label a rolled crop with depends on the roll.
                    a = angle.to(device)
                    kp = symmetry.nearest_twins(train["twin_kp"][idx], train["twin_coef"][idx], a, args.twins)
                x, mask, kp = rotate(x, mask, kp, angle)
            mask_t = F.avg_pool2d(mask[:, None].float(), 2).ge(0.5).float()
            vec_t = vector_targets(kp, cx, cy)
            m, v = model(x)
            l_mask, l_vec = losses(m, v, mask_t, vec_t)
            loss = l_mask + l_vec
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            step += 1
            k += 1
            acc += torch.stack([loss, l_mask, l_vec]).detach()
            if (time.time() - t_train) / 60 >= args.max_minutes:
                stopped = True
                break
        if (epoch + 1) % args.eval_every and not stopped and epoch + 1 < args.epochs:
            continue
        met = evaluate(model, test, device)
        acc = acc.cpu().numpy()
        curve.row(
            epoch=epoch + 1,
            step=step,
            elapsed_s=time.time() - t_train,
            lr=lr,
            train_loss=acc[0] / k,
            train_mask_loss=acc[1] / k,
            train_vec_loss=acc[2] / k,
            test_mask_iou=met["mask_iou"],
            test_vector_angle_mean_deg=met["vector_angle_mean_deg"],
        )
        print(
            f"epoch {epoch + 1}/{args.epochs} step {step} {time.time() - t_train:.0f} s loss {acc[0] / k:.4f} "
            f"(mask {acc[1] / k:.4f} vec {acc[2] / k:.4f}) test IoU {met['mask_iou']:.3f} angle {met['vector_angle_mean_deg']:.2f} deg",
            flush=True,
        )
        acc, k = torch.zeros(3, device=device), 0
        if stopped:
            print(f"stopped at the {args.max_minutes} min budget", flush=True)
            break
    if curve is not None:
        curve.close()
    if not args.eval_only:
        train_minutes = (time.time() - t_train) / 60
    if args.checkpoint:
        torch.save(model.state_dict(), args.checkpoint)
    # The torch weights travel with the ONNX file: scripts/seed_compare runs them in eager mode.
    torch.save(
        {"widths": list(widths), "parts": parts, "state_dict": model.cpu().state_dict()},
        os.path.join(args.out, "keypoints.pt"),
    )
    model.to(device)

    met = evaluate(model, test, device, voting=True)
    if train_minutes is not None:
        met["train_minutes"] = train_minutes
    met["mmac_per_crop"] = macs / 1e6
    for k_, v_ in met.items():
        print(f"  {k_} = {v_:.4g}")

    onnx_path = os.path.join(args.out, "keypoints.onnx")
    dummy = make_input(test["rgb_t"][:2], test["part_t"][:2], len(parts), "cpu")
    # The graph gives raw directions; the Rust voter normalises them (see KeypointNet).
    model.unit_vectors = False
    export_onnx(
        model,
        dummy,
        onnx_path,
        ["crop"],
        ["mask", "vectors"],
        {"crop": {0: "n"}, "mask": {0: "n"}, "vectors": {0: "n"}},
    )
    ms = check_export(onnx_path, model, make_input(test["rgb_t"][:12], test["part_t"][:12], len(parts), "cpu"), 5e-3, "for 12 crops")
    model.unit_vectors = True
    if ms is not None:
        met["ort_ms_12_crops"] = ms
    write_manifest(
        os.path.join(args.out, "keypoints.toml"),
        f"{catalog.family(args.catalog)}-keypoints",
        parts,
        onnx_path,
        [("crop", [-1, 3 + len(parts), 128, 128])],
        [("mask", [-1, 1, 64, 64]), ("vectors", [-1, 18, 64, 64])],
        {
            "script": "train_keypoints.py",
            "dataset_seed": args.dataset_seed,
            "dataset_size": n,
            "code_commit": code_commit(),
            "curve": curve_name,
            "test_metrics": met,
        },
    )
    print(f"wrote {onnx_path} and keypoints.toml")


if __name__ == "__main__":
    main()
