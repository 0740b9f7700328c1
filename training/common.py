"""Shared training helpers: device and thread setup, ONNX export and check, manifests, curves."""

import argparse
import csv
import hashlib
import os
import subprocess
import sys
import time

import numpy as np
import torch

OPSET = 17


def training_args(doc, data, model, limit_what):
    """The options both trainers share: data roots (`data` names what a root holds, e.g.
    "crops/PART/{split}"), the output folder for `model`.onnx/.toml/_curve.csv, the dataset seed,
    learning rate, time budget, load limit, seed, checkpoint, threads, starting weights and
    evaluation-only runs."""
    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--train", required=True, type=lambda s: s.split(os.pathsep),
                    help=f"dataset root with {data.format(split='train')}; several, separated by "
                    f"'{os.pathsep}', are read as one set (two looks of the same scenes, say)")
    ap.add_argument("--test", required=True, help=f"dataset root with {data.format(split='test')}")
    ap.add_argument("--out", required=True, help=f"folder for {model}.onnx/.toml/_curve.csv")
    ap.add_argument("--dataset-seed", type=int, required=True, help="seed of the training set")
    ap.add_argument("--lr", type=float, default=2e-3)
    ap.add_argument("--max-minutes", type=float, default=30.0, help="stop training after this long")
    ap.add_argument("--limit", type=int, default=None, help=f"{limit_what} to load (smoke tests)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--checkpoint", help="also save the torch weights here")
    ap.add_argument("--threads", type=int, default=2, help="CPU threads for torch")
    ap.add_argument("--init", metavar="CHECKPOINT", help="start from these weights (a further training cycle)")
    ap.add_argument(
        "--pretrained",
        metavar="CHECKPOINT",
        help="start from another part family's weights (the .pt beside its model): every layer is copied, and "
        "the rows or planes of each new part start from the mean of the source's parts",
    )
    ap.add_argument("--eval-only", metavar="CHECKPOINT", help="skip training: evaluate and export these weights")
    ap.add_argument(
        "--catalog", default="../scenarios/parts/usbc.toml", help="part catalog: the parts (and keypoints) the net handles"
    )
    return ap


def load_start(model, args, device):
    """Loads `--eval-only`, `--init` or `--pretrained` weights into `model`, if one is given."""
    given = [o for o in ("eval_only", "init", "pretrained") if getattr(args, o)]
    if len(given) > 1:
        sys.exit("give one of --" + ", --".join(o.replace("_", "-") for o in given))
    if args.pretrained:
        transferred = transfer(model, args.pretrained, device)
        print(f"started from {args.pretrained}: {transferred}", flush=True)
    elif given:
        model.load_state_dict(state_dict_in(getattr(args, given[0]), device))


def transfer(model, path, device="cpu"):
    """Copies another part family's weights in `path` into `model` (same widths, any parts).

    The tensors the net's `PART_SLOTS` names hold one slice per part along an axis, from a
    first slot; their other slices are copied, and each of `model`'s parts starts from the mean
    of the source's part slices (the net has learned what "a part" looks like, not which one).
    Returns what was copied, for the log."""
    state = torch.load(path, map_location=device)
    if "state_dict" not in state or "parts" not in state:
        sys.exit(f"--pretrained {path}: not the .pt a trainer writes beside a model (no parts recorded)")
    source, own = state["state_dict"], model.state_dict()
    if source.keys() != own.keys():
        sys.exit(f"--pretrained {path}: a different net ({len(source)} tensors, this one has {len(own)})")
    slots, n_parts = type(model).PART_SLOTS, model.n_parts
    for key, target in own.items():
        src = source[key]
        if key in slots:
            axis, first = slots[key]
            same_elsewhere = src.shape[:axis] + src.shape[axis + 1:] == target.shape[:axis] + target.shape[axis + 1:]
            n_src = src.shape[axis] - (target.shape[axis] - n_parts)
            if not same_elsewhere or n_src < 1:
                sys.exit(f"--pretrained {path}: {key} is {tuple(src.shape)}, this net's {tuple(target.shape)}")
            parts = src.narrow(axis, first, n_src)
            mean = parts.mean(axis, keepdim=True).expand_as(target.narrow(axis, first, n_parts))
            tail = target.shape[axis] - first - n_parts
            new = torch.cat([src.narrow(axis, 0, first), mean, src.narrow(axis, first + n_src, tail)], axis)
        elif src.shape != target.shape:
            sys.exit(f"--pretrained {path}: {key} is {tuple(src.shape)}, this net's {tuple(target.shape)} "
                     "(other widths: give --widths of the source)")
        else:
            new = src
        own[key] = new.to(target.dtype)
    model.load_state_dict(own)
    return f"{len(own)} tensors, parts {', '.join(state['parts'])} -> {n_parts} parts"


def state_dict_in(path, device="cpu"):
    """The weights in `path`: a checkpoint (a bare state dict) or the `.pt` the trainers commit
    beside a model (the state dict under "state_dict", with the net's widths)."""
    state = torch.load(path, map_location=device)
    return state["state_dict"] if "state_dict" in state else state


def recorded_train_minutes(out, name, model):
    """The training time in `out/name.toml` when `out/name.pt` holds exactly `model`'s weights, so
    that an `--eval-only` re-export of the same weights keeps their training record; else None."""
    import tomllib

    weights, manifest = os.path.join(out, f"{name}.pt"), os.path.join(out, f"{name}.toml")
    if not (os.path.exists(weights) and os.path.exists(manifest)):
        return None
    saved = state_dict_in(weights)
    current = model.state_dict()
    if saved.keys() != current.keys() or not all(torch.equal(saved[k], current[k].cpu()) for k in saved):
        return None
    with open(manifest, "rb") as f:
        return tomllib.load(f).get("training", {}).get("test_metrics", {}).get("train_minutes")


def setup(seed, threads=2):
    """Seeds torch and NumPy, limits CPU threads; returns the device (CUDA when present)."""
    torch.manual_seed(seed)
    np.random.seed(seed)
    torch.set_num_threads(threads)
    return torch.device("cuda" if torch.cuda.is_available() else "cpu")


def jitter(x, gen):
    """Photometric augmentation of images x [B, 3, H, W] in 0..1, on x's device with `gen` (a
    generator there): a gain of ±15 %, a tint of ±5 % per channel and 1 % Gaussian noise."""
    b = x.shape[0]
    gain = 1 + 0.15 * (2 * torch.rand(b, 1, 1, 1, generator=gen, device=x.device) - 1)
    tint = 1 + 0.05 * (2 * torch.rand(b, 3, 1, 1, generator=gen, device=x.device) - 1)
    noise = 0.01 * torch.randn(x.shape, generator=gen, device=x.device)
    return (x * gain * tint + noise).clamp(0, 1)


def code_commit():
    """The git commit of the training code (HEAD of the repository holding this file), with
    "-dirty" when training/ has uncommitted changes; CELL_CODE_COMMIT names it where the tree is
    a copy without git (a lent GPU machine)."""
    if os.environ.get("CELL_CODE_COMMIT"):
        return os.environ["CELL_CODE_COMMIT"]
    here = os.path.dirname(os.path.abspath(__file__))
    try:
        head = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=here, capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--", "."], cwd=here, capture_output=True, text=True, check=True
        ).stdout.strip()
        return head + ("-dirty" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def sha256(path):
    """Lower-case hex sha256 of a file."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def export_onnx(model, dummy, path, input_names, output_names, dynamic):
    """Exports with the TorchScript exporter (dynamo=False), opset 17, weights inside the file;
    checks the graph with onnx.checker."""
    import onnx

    model = model.cpu().eval()
    torch.onnx.export(
        model,
        dummy,
        path,
        input_names=input_names,
        output_names=output_names,
        dynamic_axes=dynamic,
        opset_version=OPSET,
        dynamo=False,
        do_constant_folding=True,
    )
    onnx.checker.check_model(onnx.load(path), full_check=True)


def ort_check(path, model, dummy, reps=20):
    """When onnxruntime is importable: max abs difference between ONNX Runtime and torch on
    `dummy`, and the median CPU latency (ms, 2 threads) over `reps` runs. None otherwise."""
    try:
        import onnxruntime as ort
    except ImportError:
        return None
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 2
    opts.inter_op_num_threads = 1
    sess = ort.InferenceSession(path, opts, providers=["CPUExecutionProvider"])
    name = sess.get_inputs()[0].name
    x = dummy.numpy()
    outs = sess.run(None, {name: x})
    with torch.no_grad():
        ref = model.cpu().eval()(dummy)
    diff = max(float(np.abs(o - r.numpy()).max()) for o, r in zip(outs, ref))
    times = []
    for _ in range(reps):
        t = time.perf_counter()
        sess.run(None, {name: x})
        times.append((time.perf_counter() - t) * 1000)
    return {"max_abs_diff": diff, "latency_ms": float(np.median(times))}


def check_export(path, model, dummy, tolerance, what):
    """Runs `ort_check` and prints it (`what` says what one run covers); exits when ONNX Runtime
    and torch differ by more than `tolerance`. Returns the latency in ms, or None without
    onnxruntime."""
    chk = ort_check(path, model, dummy)
    if chk is None:
        return None
    print(f"  onnxruntime: max |diff| {chk['max_abs_diff']:.2e}, {chk['latency_ms']:.2f} ms {what} (2 threads)")
    if chk["max_abs_diff"] > tolerance:
        sys.exit(f"{path}: ONNX Runtime disagrees with torch by {chk['max_abs_diff']}")
    return chk["latency_ms"]


def write_manifest(path, name, parts, onnx_file, inputs, outputs, training):
    """Writes a perception::onnx::manifest::ModelManifest TOML next to the model."""
    lines = [
        f"# Trained by training/{training.pop('script')}; rebuild with training/build_models.sh.",
        f'name = "{name}"',
        "parts = [" + ", ".join(f'"{p}"' for p in parts) + "]",
        f'file = "{os.path.basename(onnx_file)}"',
        f'sha256 = "{sha256(onnx_file)}"',
        f"opset = {OPSET}",
    ]
    for kind, specs in (("inputs", inputs), ("outputs", outputs)):
        for n, shape in specs:
            lines += ["", f"[[{kind}]]", f'name = "{n}"', f"shape = {list(shape)}", 'dtype = "f32"']
    lines += [
        "",
        "[training]",
        f"dataset_seed = {int(training['dataset_seed'])}",
        f"dataset_size = {int(training['dataset_size'])}",
        f'code_commit = "{training["code_commit"]}"',
        f'curve = "{training["curve"]}"',
    ]
    if "table_px_per_mm" in training:
        lo, hi = training["table_px_per_mm"]
        lines.append(f"table_px_per_mm = [{lo:.4f}, {hi:.4f}]")
    lines += [
        "",
        "[training.test_metrics]",
    ]
    for k, v in sorted(training["test_metrics"].items()):
        lines.append(f"{k} = {float(v):.6g}")
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")


class Curve:
    """A training curve written as CSV, one row per evaluation, flushed as it goes."""

    def __init__(self, path, fields):
        self.f = open(path, "w", newline="")
        self.w = csv.DictWriter(self.f, fieldnames=fields)
        self.w.writeheader()

    def row(self, **values):
        self.w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in values.items()})
        self.f.flush()

    def close(self):
        self.f.close()


def progress_lr(opt, max_lr, step, total_steps, elapsed_s, budget_s, warmup=0.03):
    """Sets and returns the learning rate for training progress = max(step share, time share):
    linear warm-up over the first `warmup`, then cosine decay to zero, so the rate anneals
    whether the step count or the time budget ends the run. Returns (lr, progress)."""
    import math

    progress = max(step / total_steps, elapsed_s / budget_s)
    if progress < warmup:
        lr = max_lr * (0.1 + 0.9 * progress / warmup)
    else:
        lr = max_lr * 0.5 * (1 + math.cos(math.pi * min(1.0, (progress - warmup) / (1 - warmup))))
    for g in opt.param_groups:
        g["lr"] = lr
    return lr, progress
