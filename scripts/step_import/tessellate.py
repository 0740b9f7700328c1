#!/usr/bin/env python3
"""Tessellates the solids of a STEP file with OpenCASCADE (the pinned cadquery-ocp-novtk wheel).

Usage: tessellate.py STEP_FILE OUT_OBJ CHORDAL_TOLERANCE_MM ANGULAR_TOLERANCE_RAD

Writes OUT_OBJ (atomically: a temporary file beside it, then a rename) with one `o solid_N` group
per solid of the file, in metres, each solid's vertices welded where OpenCASCADE shares them
(the faces' common edges), so each solid is one closed body. Units come from the STEP file
(OpenCASCADE converts them to millimetres on reading; this script writes metres). The mesh is
deterministic: one thread, the solids and faces in the file's order, numbers written with
Python's shortest round-trip repr.

Exit status 0: written; 2: the STEP file is unusable, and the last stderr line says why, as
"error: ..." (not a STEP file, a syntax error with its line, no solids, a face that does not
tessellate). Cell's mesh loader (perception/src/part/step_io.rs) runs this script and reads the
OBJ back; it is also the tool bench.py measures.
"""

import os
import re
import sys
import tempfile

from OCP.BRep import BRep_Tool
from OCP.BRepMesh import BRepMesh_IncrementalMesh
from OCP.IFSelect import IFSelect_RetDone
from OCP.STEPControl import STEPControl_Reader
from OCP.TopAbs import TopAbs_FACE, TopAbs_REVERSED, TopAbs_SHELL, TopAbs_SOLID
from OCP.TopExp import TopExp_Explorer
from OCP.TopLoc import TopLoc_Location
from OCP.TopoDS import TopoDS


class StepError(Exception):
    """The STEP file cannot give solids; the message says why."""


def capture_stdout(action):
    """Runs action() with the process's file descriptor 1 sent to a temporary file (OpenCASCADE's
    reader prints its syntax errors there); returns (result, captured text)."""
    sys.stdout.flush()
    saved = os.dup(1)
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 1)
        try:
            result = action()
        finally:
            sys.stdout.flush()
            os.dup2(saved, 1)
            os.close(saved)
        sink.seek(0)
        text = sink.read().decode("utf-8", "replace")
    return result, text


def check_header(path):
    """A STEP (ISO 10303-21) file starts with ISO-10303-21; after optional blanks."""
    with open(path, "rb") as f:
        head = f.read(256).lstrip()
    if not head.startswith(b"ISO-10303-21;"):
        raise StepError("not a STEP file: it does not start with ISO-10303-21;")


def read_shape(path):
    """Reads the file and transfers every root; the shape is in millimetres."""
    check_header(path)
    reader = STEPControl_Reader()
    status, log = capture_stdout(lambda: reader.ReadFile(path))
    if status != IFSelect_RetDone:
        log = re.sub(r"\x1b\[[0-9;]*m", "", log)
        lines = [m.group(0) for m in re.finditer(r"[^\n]*\b[Ll]ine\s*:?\s*\d+[^\n]*", log)]
        where = f": {lines[0].strip(' *')}" if lines else ""
        raise StepError(f"the STEP file does not parse (OpenCASCADE status {int(status)}){where}")
    capture_stdout(reader.TransferRoots)
    return reader.OneShape()


def count(shape, kind, outside=None):
    """How many sub-shapes of a kind the shape holds (optionally only those outside another kind)."""
    explorer = (
        TopExp_Explorer(shape, kind) if outside is None else TopExp_Explorer(shape, kind, outside)
    )
    n = 0
    while explorer.More():
        n += 1
        explorer.Next()
    return n


def solids_of(shape):
    """The solids, in the file's order (assembly instances each placed where the file puts them)."""
    explorer = TopExp_Explorer(shape, TopAbs_SOLID)
    solids = []
    while explorer.More():
        solids.append(TopoDS.Solid(explorer.Current()))
        explorer.Next()
    if not solids:
        shells = count(shape, TopAbs_SHELL)
        faces = count(shape, TopAbs_FACE, TopAbs_SHELL)
        raise StepError(
            f"the STEP file has no solids: {shells} shells and {faces} free faces only "
            "(export the part as a solid body)"
        )
    return solids


def tessellate_solid(solid, index):
    """One solid's welded triangles: (vertices in mm, triangles as vertex indices), and the largest
    chordal deviation OpenCASCADE reports for its faces."""
    vertices, triangles, index_of = [], [], {}
    deflection = 0.0
    explorer = TopExp_Explorer(solid, TopAbs_FACE)
    face_no = 0
    while explorer.More():
        face = TopoDS.Face(explorer.Current())
        explorer.Next()
        face_no += 1
        location = TopLoc_Location()
        tri = BRep_Tool.Triangulation_s(face, location)
        if tri is None or tri.NbTriangles() == 0:
            raise StepError(f"solid {index}: face {face_no} does not tessellate")
        deflection = max(deflection, tri.Deflection())
        trsf = location.Transformation()
        local = []
        for i in range(1, tri.NbNodes() + 1):
            p = tri.Node(i).Transformed(trsf)
            key = (p.X(), p.Y(), p.Z())
            if key not in index_of:
                index_of[key] = len(vertices)
                vertices.append(key)
            local.append(index_of[key])
        reversed_face = face.Orientation() == TopAbs_REVERSED
        for i in range(1, tri.NbTriangles() + 1):
            a, b, c = tri.Triangle(i).Get()
            t = (local[a - 1], local[c - 1], local[b - 1]) if reversed_face else (
                local[a - 1], local[b - 1], local[c - 1])
            if len(set(t)) == 3:
                triangles.append(t)
    return vertices, triangles, deflection


def tessellate(path, tolerance_mm, angular_rad):
    """The solids of a STEP file as [(vertices mm, triangles, deflection mm)]."""
    shape = read_shape(path)
    solids = solids_of(shape)
    for solid in solids:
        BRepMesh_IncrementalMesh(solid, tolerance_mm, False, angular_rad, False)
    return [tessellate_solid(s, i + 1) for i, s in enumerate(solids)]


def write_obj(bodies, out, header):
    """Writes the bodies as OBJ groups in metres, atomically."""
    lines = [f"# {h}" for h in header]
    base = 1
    for n, (vertices, triangles, _) in enumerate(bodies, 1):
        lines.append(f"o solid_{n}")
        lines.extend(f"v {x * 1e-3!r} {y * 1e-3!r} {z * 1e-3!r}" for x, y, z in vertices)
        lines.extend(f"f {a + base} {b + base} {c + base}" for a, b, c in triangles)
        base += len(vertices)
    folder = os.path.dirname(os.path.abspath(out))
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=".tess-", suffix=".obj")
    try:
        with os.fdopen(fd, "w") as f:
            f.write("\n".join(lines) + "\n")
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, 0o644)
        os.replace(tmp, out)
    except BaseException:
        os.unlink(tmp)
        raise


def main(argv):
    if len(argv) != 5:
        print("usage: tessellate.py STEP_FILE OUT_OBJ CHORDAL_TOLERANCE_MM ANGULAR_TOLERANCE_RAD",
              file=sys.stderr)
        return 64
    path, out, tolerance, angular = argv[1], argv[2], float(argv[3]), float(argv[4])
    try:
        bodies = tessellate(path, tolerance, angular)
    except StepError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    header = [
        "tessellated by scripts/step_import/tessellate.py (OpenCASCADE, cadquery-ocp-novtk)",
        f"chordal tolerance {tolerance!r} mm, angular tolerance {angular!r} rad",
        f"{len(bodies)} solids; largest reported deviation "
        f"{max(b[2] for b in bodies)!r} mm; vertices in metres",
    ]
    write_obj(bodies, out, header)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
