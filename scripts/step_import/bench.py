#!/usr/bin/env python3
"""Measures OpenCASCADE's STEP import as cell uses it (tessellate.py) on real STEP files.

Usage: bench.py CHORDAL_TOLERANCE_MM STEP_FILE...   (run with the provisioned venv's python)

For each file: read + transfer time, tessellation time, solids, triangles, how many solids are
closed (every edge of the welded mesh used by exactly two triangles, consistently oriented),
the B-rep's exact volume (OpenCASCADE's GProp) against the tessellated volume, and the largest
chordal deviation OpenCASCADE reports. One JSON line per file. docs/reference/step-import.md
quotes these figures.
"""

import json
import sys
import time
from collections import Counter

from OCP.BRepGProp import BRepGProp
from OCP.BRepMesh import BRepMesh_IncrementalMesh
from OCP.GProp import GProp_GProps

import tessellate as t


def closed(triangles):
    """Every directed edge once and its reverse once: closed and consistently oriented."""
    edges = Counter()
    for a, b, c in triangles:
        for e in ((a, b), (b, c), (c, a)):
            edges[e] += 1
    return all(n == 1 and edges.get((e[1], e[0]), 0) == 1 for e, n in edges.items())


def mesh_volume(vertices, triangles):
    """Signed volume by the divergence theorem (positive for outward normals)."""
    v = 0.0
    for a, b, c in triangles:
        (ax, ay, az), (bx, by, bz), (cx, cy, cz) = vertices[a], vertices[b], vertices[c]
        v += (ax * (by * cz - bz * cy) - ay * (bx * cz - bz * cx) + az * (bx * cy - by * cx)) / 6
    return v


def main(argv):
    tol = float(argv[1])
    for path in argv[2:]:
        row = {"file": path.rsplit("/", 1)[-1], "tolerance_mm": tol}
        t0 = time.perf_counter()
        try:
            shape = t.read_shape(path)
            row["read_s"] = round(time.perf_counter() - t0, 3)
            solids = t.solids_of(shape)
        except t.StepError as e:
            row["error"] = str(e)
            print(json.dumps(row), flush=True)
            continue
        t1 = time.perf_counter()
        for s in solids:
            BRepMesh_IncrementalMesh(s, tol, False, 0.5, False)
        bodies = [t.tessellate_solid(s, i + 1) for i, s in enumerate(solids)]
        row["mesh_s"] = round(time.perf_counter() - t1, 3)
        exact = 0.0
        for s in solids:
            props = GProp_GProps()
            BRepGProp.VolumeProperties_s(s, props)
            exact += props.Mass()
        tess = sum(mesh_volume(v, tr) for v, tr, _ in bodies)
        row.update(
            solids=len(solids),
            closed=sum(closed(tr) for _, tr, _ in bodies),
            triangles=sum(len(tr) for _, tr, _ in bodies),
            volume_exact_mm3=round(exact, 3),
            volume_mesh_mm3=round(tess, 3),
            volume_error_pct=round(100 * (tess - exact) / exact, 4),
            max_deviation_mm=round(max(b[2] for b in bodies), 4),
        )
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main(sys.argv)
