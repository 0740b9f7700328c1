"""Whether our randomised renders contain the Cycles renders, before any training: per part kind,
the mean and the spread (standard deviation) of each visible instance's grey level, in BOP
feeder sets rendered by our renderer (with and without families) and by Cycles (the committed
sets), and the share of the Cycles instances that fall inside the range our renders span.

Usage: python coverage.py OURS_SET [OURS_SET...] -- CYCLES_SET [CYCLES_SET...]
  a set is a BOP folder with test_feeder/ (rgb/, mask_visib/, scene_gt.json); instances with
  fewer than 100 visible pixels are left out. Our range is the 2nd to 98th percentile of
  each figure over all OURS_SETs given before `--`, per part kind.
"""

import glob
import json
import os
import sys

import numpy as np
from PIL import Image


def instances(root):
    """(obj_id, mean grey, grey standard deviation) of every visible instance of a set."""
    out = []
    for scene in sorted(glob.glob(os.path.join(root, "test_feeder", "*"))):
        with open(os.path.join(scene, "scene_gt.json")) as f:
            gt = json.load(f)
        for im, objs in gt.items():
            rgb = os.path.join(scene, "rgb", f"{int(im):06d}.png")
            if not os.path.exists(rgb):
                continue
            grey = np.asarray(Image.open(rgb).convert("L"), dtype=np.float64)
            for k, o in enumerate(objs):
                m = np.asarray(Image.open(os.path.join(
                    scene, "mask_visib", f"{int(im):06d}_{k:06d}.png"))) > 127
                if m.sum() < 100:
                    continue
                v = grey[m]
                out.append((o["obj_id"], v.mean(), v.std()))
    return out


def main(argv):
    if "--" not in argv:
        sys.exit(__doc__)
    cut = argv.index("--")
    ours, theirs = argv[:cut], argv[cut + 1:]
    if not ours or not theirs:
        sys.exit(__doc__)
    sets = {name: instances(name) for name in ours + theirs}
    ids = sorted({i for s in sets.values() for i, _, _ in s})
    print("| set | part | instances | grey mean p2–p98 | grey spread p2–p98 |"
          " Cycles inside ours (mean, spread, both) |")
    print("|---|---|---|---|---|---|")
    for obj in ids:
        pooled = np.array([(m, s) for name in ours for i, m, s in sets[name] if i == obj])
        lo, hi = np.percentile(pooled, 2, axis=0), np.percentile(pooled, 98, axis=0)
        for name in ours + theirs:
            a = np.array([(m, s) for i, m, s in sets[name] if i == obj])
            if len(a) == 0:
                continue
            p2, p98 = np.percentile(a, 2, axis=0), np.percentile(a, 98, axis=0)
            inside = ""
            if name in theirs:
                im = (a[:, 0] >= lo[0]) & (a[:, 0] <= hi[0])
                isd = (a[:, 1] >= lo[1]) & (a[:, 1] <= hi[1])
                inside = f"{100 * im.mean():.0f} / {100 * isd.mean():.0f} / {100 * (im & isd).mean():.0f} %"
            print(f"| {name} | {obj} | {len(a)} | {p2[0]:.0f}–{p98[0]:.0f} |"
                  f" {p2[1]:.1f}–{p98[1]:.1f} | {inside} |")


if __name__ == "__main__":
    main(sys.argv[1:])
