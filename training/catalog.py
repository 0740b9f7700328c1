"""What a part catalog tells the trainers: the parts its models handle and their keypoints.

The models handle a catalog's assembled parts (every part without `role = "fixture"`), in catalog
order: `cell dataset` numbers them 1.. in that order, the segmenter's logit channels and the
keypoint net's one-hot planes follow it, and the Rust side checks a model folder's manifests
against the catalog the same way (perception::learned::models::LearnedModels::check_catalog).
"""

import tomllib

import numpy as np


def load(path):
    """The catalog TOML at `path` as a dict; exits with the file named when it cannot be read."""
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except (OSError, tomllib.TOMLDecodeError) as e:
        raise SystemExit(f"{path}: cannot read the part catalog: {e}")


def family(path):
    """The catalog's `name`, which names its models (e.g. "usbc" -> "usbc-segmenter")."""
    name = load(path).get("name")
    if not isinstance(name, str) or not name:
        raise SystemExit(f"{path}: the catalog has no `name`")
    return name


def assembled_parts(path):
    """Names of the catalog's assembled parts, in catalog order."""
    parts = [p["name"] for p in load(path).get("part", []) if p.get("role") != "fixture"]
    if not parts:
        raise SystemExit(f"{path}: the catalog has no assembled part (every part is a fixture)")
    return parts


def keypoints(path, parts):
    """The 9 keypoints (mm, part frame) of each of `parts`, from the prepared catalog."""
    by_name = {p["name"]: p for p in load(path).get("part", [])}
    out = []
    for name in parts:
        if name not in by_name:
            raise SystemExit(f"{path}: no part named {name}")
        kp = np.asarray(by_name[name].get("keypoints", []), dtype=np.float64).reshape(-1, 3) * 1000.0
        if kp.shape != (9, 3):
            raise SystemExit(
                f"{path}: part {name} has {kp.shape[0]} keypoints, want 9 (run `cell parts prepare {path}`)"
            )
        out.append(kp)
    return out


def symmetries(path, parts):
    """Each of `parts`' exact symmetries as (axis, order) pairs: the catalog's `symmetries`
    without the near ones (`exact = false`), which vision must still tell apart."""
    by_name = {p["name"]: p for p in load(path).get("part", [])}
    out = []
    for name in parts:
        try:
            declared = by_name[name].get("symmetries", [])
            out.append([(s["axis"], int(s["order"])) for s in declared if s.get("exact", True)])
        except (KeyError, TypeError, ValueError) as e:
            raise SystemExit(f"{path}: part {name}: a symmetry wants `axis` and `order` ({e})")
    return out
