"""The ablation table: `cell eval` on the Cycles sets for each configuration of run.sh.

Usage: python table.py OUT CONFIG...   (reads OUT/NAME/eval_{soft,hard}/eval.json; the config
`committed` is the committed models, trained on the default randomisation at full size)
Prints a Markdown table: per look precision / recall (%), instances found as the wrong part,
right stable pose (%), assembly-grade share of the posed parts (%), refined x / y (mm, outliers
dropped), and the change of precision and recall against the configuration `all`.
"""

import json
import os
import sys


def name_of(config):
    if config in ("none", "all", "committed"):
        return config
    return "no_" + config.removeprefix("all,-")


def figures(path):
    """The pooled figures of one eval.json, or None when it is missing."""
    try:
        with open(path) as f:
            p = json.load(f)["summary"]["pooled"]
    except (OSError, KeyError, ValueError):
        return None
    poses = p.get("poses") or 0
    refined = p.get("refined", {}).get("seed_style", {})
    mean = lambda axis: (refined.get(axis) or {}).get("mean")
    pct = lambda v: None if v is None else 100 * v
    return {
        "p": pct(p.get("precision")),
        "r": pct(p.get("recall")),
        "wrong": (p.get("misses") or {}).get("wrong_part"),
        "stable": pct(p.get("stable_pose_rate")),
        "grade": 100 * p["assembly_grade"] / poses if poses and "assembly_grade" in p else None,
        "x": mean("x_mm"),
        "y": mean("y_mm"),
    }


def cell(v, fmt):
    return "–" if v is None else format(v, fmt)


def main(argv):
    if len(argv) < 2:
        sys.exit(__doc__)
    out, configs = argv[0], argv[1:]
    rows = {c: {look: figures(os.path.join(out, name_of(c), f"eval_{look}", "eval.json"))
                for look in ("soft", "hard")} for c in configs}
    head = "| families |"
    rule = "|---|"
    for look in ("soft", "hard"):
        head += (f" {look} P / R % | Δ vs all | wrong part | stable pose % | assembly-grade % |"
                 f" refined x / y mm |")
        rule += "---|---|---|---|---|---|"
    print(head)
    print(rule)
    for c in configs:
        line = f"| `{c}` |"
        for look in ("soft", "hard"):
            f, ref = rows[c][look], rows.get("all", {}).get(look)
            if f is None:
                line += " (no eval) | | | | | |"
                continue
            known = ref and c != "all" and None not in (f["p"], f["r"], ref["p"], ref["r"])
            delta = f"{f['p'] - ref['p']:+.1f} / {f['r'] - ref['r']:+.1f}" if known else ""
            line += (f" {cell(f['p'], '.1f')} / {cell(f['r'], '.1f')} | {delta} |"
                     f" {cell(f['wrong'], 'd')} |"
                     f" {cell(f['stable'], '.1f')} | {cell(f['grade'], '.1f')} |"
                     f" {cell(f['x'], '.3f')} / {cell(f['y'], '.3f')} |")
        print(line)


if __name__ == "__main__":
    main(sys.argv[1:])
