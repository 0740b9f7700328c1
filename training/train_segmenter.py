"""Trains the feeder segmenter (class logits + instance-centre offsets at stride 4) on the
feeder frames of `cell dataset` (train_feeder/), evaluates it on test_feeder/ (per-class cell
accuracy, instance precision/recall at IoU 0.5 after grouping cells by their voted centres),
exports segmenter.onnx and writes segmenter.toml + segmenter_curve.csv.

Usage: python train_segmenter.py --train DATA_TRAIN --test DATA_TEST --out scenarios/models/usbc
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
from data import load_feeder, load_feeder_sets, obj_ids, table_px_per_mm
from nets import Segmenter, count_macs

IGNORE = -100
MIN_GT_CELLS = 16
"""GT instances with fewer visible stride-4 cells (256 px, ~6 % of a part) are not counted."""


def quarter_turn(rgb, lab, off, k):
    """Turns a square crop, its cell labels and its offsets by k quarter turns (np.rot90's
    sense): a camera roll, exact because cell centres map onto cell centres and each offset
    vector turns with the image (one turn: x' = y, y' = S - 1 - x, so (dx, dy) -> (dy, -dx))."""
    rgb, lab = np.rot90(rgb, k), np.rot90(lab, k)
    o = np.rot90(off, k, axes=(1, 2))
    for _ in range(k % 4):
        o = np.stack([o[1], -o[0]])
    return rgb, lab, o


def batch_of(frames, idx, size, rng, turn=False):
    """Random `size` x `size` crops (origins on the 4-px grid) of the frames `idx`, each turned
    by a random number of quarter turns when `turn`; frames smaller than `size` are padded by
    edge replication with ignored labels. Returns uint8 images [B, 3, size, size], classes and
    offsets at stride 4."""
    xs, cls, off = [], [], []
    c = size // 4
    for i in idx:
        f = frames[i]
        H, W = f["rgb"].shape[:2]
        ph, pw = max(0, size - H), max(0, size - W)
        rgb = f["rgb"]
        lab = f["cls"]
        o = f["offset"]
        if ph or pw:
            rgb = np.pad(rgb, ((0, ph), (0, pw), (0, 0)), mode="edge")
            lab = np.pad(lab, ((0, ph // 4 + 1), (0, pw // 4 + 1)), constant_values=IGNORE)
            o = np.pad(o, ((0, 0), (0, ph // 4 + 1), (0, pw // 4 + 1)))
        Hp, Wp = rgb.shape[:2]
        y0 = 4 * rng.integers(0, (Hp - size) // 4 + 1)
        x0 = 4 * rng.integers(0, (Wp - size) // 4 + 1)
        crop = (
            rgb[y0 : y0 + size, x0 : x0 + size],
            lab[y0 // 4 : y0 // 4 + c, x0 // 4 : x0 // 4 + c],
            o[:, y0 // 4 : y0 // 4 + c, x0 // 4 : x0 // 4 + c],
        )
        if turn:
            crop = quarter_turn(*crop, int(rng.integers(0, 4)))
        xs.append(np.ascontiguousarray(crop[0]))
        cls.append(np.ascontiguousarray(crop[1]))
        off.append(np.ascontiguousarray(crop[2]))
    x = torch.from_numpy(np.stack(xs)).permute(0, 3, 1, 2)
    return x, torch.from_numpy(np.stack(cls)).long(), torch.from_numpy(np.stack(off))


class Batches(torch.utils.data.IterableDataset):
    """Endless training batches of `batch_of`, drawn by each loader worker from its own seed."""

    def __init__(self, frames, batch, size, turn, seed):
        self.frames, self.batch, self.size, self.turn, self.seed = frames, batch, size, turn, seed

    def __iter__(self):
        worker = torch.utils.data.get_worker_info()
        rng = np.random.default_rng([self.seed, worker.id if worker else 0])
        while True:
            idx = rng.integers(0, len(self.frames), self.batch)
            yield batch_of(self.frames, idx, self.size, rng, self.turn)


def losses(logits, offsets, cls, off):
    """Cross entropy on the classes + smooth-L1 on the offsets (in units of 32 px) of part cells."""
    l_cls = F.cross_entropy(logits, cls, ignore_index=IGNORE)
    fg = (cls > 0).float()[:, None]
    s = Segmenter.OFFSET_SCALE
    l_off = F.smooth_l1_loss(offsets * fg / s, off * fg / s, reduction="sum") / (2 * fg.sum() + 1.0)
    return l_cls, l_off


def pad16(rgb):
    """Pads an HxWx3 image to multiples of 16 by edge replication (what the Rust caller does)."""
    H, W = rgb.shape[:2]
    return np.pad(rgb, ((0, (-H) % 16), (0, (-W) % 16), (0, 0)), mode="edge")


def group(cls_pred, offsets, probs, radius=20.0, cross_radius=10.0, contested_min_score=0.75, min_votes=30):
    """Instances from a class map [h, w] and offsets [2, h, w] (NumPy), as the Rust grouper
    (perception::learned::instances) forms them: every part cell votes for its centre (cell
    centre + offset) on its class's histogram (4-px bins, 3x3 sum, at least `min_votes`); peaks
    at least `radius` px from a stronger peak of the same class and `cross_radius` px from one
    of another class are the centres; each cell joins the nearest centre of its class within
    `radius`, else the nearest of any class; a centre within `radius` of a stronger one of
    another class whose cells' mean probability `probs` [classes, h, w] of its class is below
    `contested_min_score` is dropped and its cells join again. Returns (instance map [h, w]
    with -1 for none, class of each instance)."""
    h, w = cls_pred.shape
    fg = cls_pred > 0
    ii, jj = np.nonzero(fg)
    inst = np.full((h, w), -1, dtype=np.int64)
    if len(ii) == 0:
        return inst, []
    cc = cls_pred[ii, jj]
    vx = 4 * jj + 1.5 + offsets[0, ii, jj]
    vy = 4 * ii + 1.5 + offsets[1, ii, jj]
    bx = np.clip(np.floor(vx / 4).astype(int), 0, w - 1)
    by = np.clip(np.floor(vy / 4).astype(int), 0, h - 1)
    peaks = []  # (votes, class, centre)
    for c in range(1, probs.shape[0]):
        sel = cc == c
        hist = np.zeros((h + 2, w + 2))
        np.add.at(hist, (by[sel] + 1, bx[sel] + 1), 1)
        acc = sum(hist[1 + dy : h + 1 + dy, 1 + dx : w + 1 + dx] for dy in (-1, 0, 1) for dx in (-1, 0, 1))
        pad = np.pad(acc, 1, constant_values=-1)
        neigh = np.stack([pad[1 + dy : h + 1 + dy, 1 + dx : w + 1 + dx] for dy in (-1, 0, 1) for dx in (-1, 0, 1) if dy or dx])
        # Local maxima; plateaus give several, merged below (centres closer than `radius`).
        py, px = np.nonzero((acc >= min_votes) & (acc >= neigh.max(0)))
        peaks += [(acc[y, x], c, np.array([4 * x + 2.0, 4 * y + 2.0])) for y, x in zip(py, px)]
    centres, classes = [], []
    for _, c, p in sorted(peaks, key=lambda t: -t[0]):
        if all(np.linalg.norm(p - q) > (radius if k == c else cross_radius) for q, k in zip(centres, classes)):
            centres.append(p)
            classes.append(c)
    if not centres:
        return inst, []
    centres, classes = np.array(centres), np.array(classes)

    def assign(centres, classes):
        d = np.hypot(vx[:, None] - centres[None, :, 0], vy[:, None] - centres[None, :, 1])
        d[d > radius] = np.inf
        own = np.where(classes[None, :] == cc[:, None], d, np.inf)
        near = np.where(np.isfinite(own.min(1)), own.argmin(1), d.argmin(1))
        return np.where(np.isfinite(d[np.arange(len(near)), near]), near, -1)

    owner = assign(centres, classes)
    keep = []
    for n, (p, c) in enumerate(zip(centres, classes)):
        contested = any(k != c and np.linalg.norm(p - q) < radius for q, k in zip(centres[:n], classes[:n]))
        mine = owner == n
        score = probs[c, ii[mine], jj[mine]].mean() if mine.any() else 0.0
        keep.append(not contested or score >= contested_min_score)
    if not all(keep):
        centres, classes = centres[keep], classes[keep]
        owner = assign(centres, classes)
    ok = owner >= 0
    inst[ii[ok], jj[ok]] = owner[ok]
    return inst, [int(c) for c in classes]


@torch.no_grad()
def evaluate(model, frames, parts, device, max_frames=None):
    """Per-class cell accuracy (recall of each class's cells), overall cell accuracy, and
    instance precision/recall at IoU >= 0.5 with the class required to match."""
    model.eval()
    n_cls = len(parts) + 1
    conf = np.zeros((n_cls, n_cls), dtype=np.int64)
    tp = n_pred = n_gt = 0
    for f in frames[:max_frames]:
        H, W = f["rgb"].shape[:2]
        x = torch.from_numpy(pad16(f["rgb"])).permute(2, 0, 1)[None].float().to(device) / 255.0
        logits, offsets = model(x)
        h, w = H // 4, W // 4
        pred = logits[0].argmax(0).cpu().numpy()[:h, :w]
        off = offsets[0].cpu().numpy()[:, :h, :w]
        conf += np.bincount(f["cls"].ravel().astype(np.int64) * n_cls + pred.ravel(), minlength=n_cls * n_cls).reshape(n_cls, n_cls)
        inst, classes = group(pred, off, logits[0].softmax(0).cpu().numpy()[:, :h, :w])
        gt_ids = [k for k in range(len(f["inst_part"])) if (f["inst"] == k).sum() >= MIN_GT_CELLS]
        n_gt += len(gt_ids)
        n_pred += len(classes)
        used = set()
        for k in gt_ids:
            g = f["inst"] == k
            best, best_iou = None, 0.5
            for q, c in enumerate(classes):
                if q in used or c != f["inst_part"][k] + 1:
                    continue
                p = inst == q
                iou = (g & p).sum() / max((g | p).sum(), 1)
                if iou >= best_iou:
                    best, best_iou = q, iou
            if best is not None:
                used.add(best)
                tp += 1
    m = {"cell_accuracy": float(np.trace(conf) / max(conf.sum(), 1))}
    for c, name in enumerate(["background"] + parts):
        m[f"cell_accuracy_{name}"] = float(conf[c, c] / max(conf[c].sum(), 1))
    m["instance_precision"] = tp / max(n_pred, 1)
    m["instance_recall"] = tp / max(n_gt, 1)
    m["instances_gt"] = float(n_gt)
    return m


def trained_scale(path):
    """The one table scale (px/mm) the segmenter weights in `path` were trained at with
    `--fixed-scale`, as the `.pt` beside a model records it; None for a bare checkpoint, weights
    trained at the rendered scales, or no path."""
    if not path:
        return None
    state = torch.load(path, map_location="cpu")
    return state.get("px_per_mm") if "state_dict" in state else None


def main(argv=None):
    ap = training_args(__doc__, "{split}_feeder/", "segmenter", "frames per split")
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--batch", type=int, default=8)
    ap.add_argument("--size", type=int, default=256, help="training crop side, px (multiple of 16)")
    ap.add_argument("--eval-every", type=int, default=250)
    ap.add_argument("--workers", type=int, default=0, help="processes preparing batches (0: the training process)")
    ap.add_argument("--widths", default=",".join(map(str, Segmenter.WIDTHS)), help="channels at strides 2, 4, 8, 16")
    ap.add_argument("--rotate", type=int, default=1, help="1: turn each training crop by random quarter turns (augmentation)")
    ap.add_argument(
        "--fixed-scale",
        action="store_true",
        help="resample every frame to the middle of the training frames' table scales, the scale the cell shows "
        "the net, so that it learns parts' sizes (a 12 mm peg from a 16 mm one); the manifest and the .pt beside the "
        "model then record that one scale, and --eval-only of those weights evaluates at it",
    )
    args = ap.parse_args(argv)
    if args.size % 16:
        sys.exit(f"--size {args.size} must be a multiple of 16")

    device = setup(args.seed, args.threads)
    t0 = time.time()
    parts = catalog.assembled_parts(args.catalog)
    scales = table_px_per_mm(args.train, "train_feeder")
    shown = float(np.sqrt(scales[0] * scales[1])) if args.fixed_scale else None
    trained = trained_scale(args.eval_only or args.init)
    if args.eval_only and trained is not None:
        # Weights learned at one scale are evaluated (and their manifest written) at that scale,
        # whichever training set or flag the re-export names.
        shown = trained
    elif trained is not None and shown is None:
        print(f"note: {args.init} was trained at one scale ({trained:.4f} px/mm); this cycle trains "
              "at the rendered scales (add --fixed-scale to keep one)", flush=True)
    if shown is not None:
        scales = (shown, shown)
        print(f"frames resampled to {shown:.4f} px/mm", flush=True)
    train = load_feeder_sets(args.train, "train_feeder", parts, args.limit, px_per_mm=shown)
    test = load_feeder(args.test, "test_feeder", obj_ids(args.test, parts), args.limit, px_per_mm=shown)
    print(f"loaded {len(train)} train / {len(test)} test feeder frames in {time.time() - t0:.0f} s", flush=True)

    model = Segmenter(len(parts), tuple(int(w) for w in args.widths.split(","))).to(device)
    macs = count_macs(model, torch.zeros(1, 3, 448, 576, device=device))
    print(f"segmenter: {macs / 1e6:.0f} MMAC per 576x448 window, {sum(p.numel() for p in model.parameters())} parameters")
    opt = torch.optim.Adam(model.parameters(), lr=args.lr, weight_decay=1e-5)
    os.makedirs(args.out, exist_ok=True)
    curve_name = "segmenter_curve.csv"
    load_start(model, args, device)
    if args.eval_only:
        train_minutes = recorded_train_minutes(args.out, "segmenter", model)
        args.steps = 0
    curve = None if args.eval_only else Curve(
        os.path.join(args.out, curve_name),
        ["step", "elapsed_s", "lr", "train_loss", "train_cls_loss", "train_offset_loss", "test_cell_accuracy", "test_instance_precision", "test_instance_recall"],
    )
    batches = iter(
        torch.utils.data.DataLoader(
            Batches(train, args.batch, args.size, bool(args.rotate), args.seed),
            batch_size=None,
            num_workers=args.workers,
            pin_memory=device.type == "cuda",
            prefetch_factor=4 if args.workers else None,
        )
    )
    gen = torch.Generator(device=device).manual_seed(args.seed)
    t_train = time.time()
    # Losses summed on the device since the last curve row (no host sync per step).
    acc, k = torch.zeros(3, device=device), 0
    for step in range(1, args.steps + 1):
        model.train()
        lr, progress = progress_lr(opt, args.lr, step - 1, args.steps, time.time() - t_train, 60 * args.max_minutes)
        x, cls, off = next(batches)
        x = jitter(x.to(device, non_blocking=True).float() / 255.0, gen)
        logits, offsets = model(x)
        l_cls, l_off = losses(logits, offsets, cls.to(device, non_blocking=True), off.to(device, non_blocking=True))
        loss = l_cls + l_off
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        acc += torch.stack([loss, l_cls, l_off]).detach()
        k += 1
        out_of_time = (time.time() - t_train) / 60 >= args.max_minutes
        if step % args.eval_every == 0 or step == args.steps or out_of_time:
            met = evaluate(model, test, parts, device, max_frames=20)
            acc = acc.cpu().numpy()
            curve.row(
                step=step,
                elapsed_s=time.time() - t_train,
                lr=lr,
                train_loss=acc[0] / k,
                train_cls_loss=acc[1] / k,
                train_offset_loss=acc[2] / k,
                test_cell_accuracy=met["cell_accuracy"],
                test_instance_precision=met["instance_precision"],
                test_instance_recall=met["instance_recall"],
            )
            print(
                f"step {step}/{args.steps} {time.time() - t_train:.0f} s loss {acc[0] / k:.4f} (cls {acc[1] / k:.4f} "
                f"off {acc[2] / k:.4f}) test acc {met['cell_accuracy']:.3f} P {met['instance_precision']:.3f} "
                f"R {met['instance_recall']:.3f}",
                flush=True,
            )
            acc, k = torch.zeros(3, device=device), 0
        if out_of_time:
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
        {"widths": list(model.widths), "parts": parts, "px_per_mm": shown, "state_dict": model.cpu().state_dict()},
        os.path.join(args.out, "segmenter.pt"),
    )
    model.to(device)

    met = evaluate(model, test, parts, device)
    if train_minutes is not None:
        met["train_minutes"] = train_minutes
    met["mmac_576x448"] = macs / 1e6
    for k_, v_ in met.items():
        print(f"  {k_} = {v_:.4g}")

    onnx_path = os.path.join(args.out, "segmenter.onnx")
    export_onnx(
        model,
        torch.zeros(1, 3, 256, 320),
        onnx_path,
        ["image"],
        ["logits", "offsets"],
        {"image": {0: "n", 2: "h", 3: "w"}, "logits": {0: "n", 2: "h4", 3: "w4"}, "offsets": {0: "n", 2: "h4", 3: "w4"}},
    )
    ms = check_export(onnx_path, model, torch.rand(1, 3, 448, 576), 1e-2, "per 576x448 window")
    if ms is not None:
        met["ort_ms_576x448"] = ms
    write_manifest(
        os.path.join(args.out, "segmenter.toml"),
        f"{catalog.family(args.catalog)}-segmenter",
        parts,
        onnx_path,
        [("image", [-1, 3, -1, -1])],
        [("logits", [-1, 1 + len(parts), -1, -1]), ("offsets", [-1, 2, -1, -1])],
        {
            "script": "train_segmenter.py",
            "dataset_seed": args.dataset_seed,
            "dataset_size": len(train),
            "table_px_per_mm": scales,
            "code_commit": code_commit(),
            "curve": curve_name,
            "test_metrics": met,
        },
    )
    print(f"wrote {onnx_path} and segmenter.toml")


if __name__ == "__main__":
    main()
