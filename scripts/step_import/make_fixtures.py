#!/usr/bin/env python3
"""Writes the STEP test fixtures in cell/tests/fixtures/step/ with OpenCASCADE, deterministically.

Usage: "$(scripts/step_import/venv.sh)" scripts/step_import/make_fixtures.py [OUT_DIR]

- block_with_hole.step: a 20 x 16 x 8 mm block with a 6 mm hole through it along z (one solid;
  volume 2560 - 72 pi mm^3), in millimetres.
- block_with_hole_inch.step: the same block in inches: its numbers are the millimetres / 25.4
  and its length unit is CONVERSION_BASED_UNIT('INCH', 25.4 mm), as AP203 exporters write it.
- peg_and_block.step: two separate solids: a 6 mm x 12 mm peg and an 8 x 8 x 4 mm block 15 mm
  beside it (volume 108 pi + 256 mm^3).
- shell_only.step: the block's faces as a shell and one free face, with no solid.
- truncated.step: block_with_hole.step cut off in its DATA section.
The header's time stamp is fixed, so running this again writes the same bytes.
"""

import math
import os
import re
import sys

from OCP.BRepAlgoAPI import BRepAlgoAPI_Cut
from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace, BRepBuilderAPI_Transform
from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox, BRepPrimAPI_MakeCylinder
from OCP.BRep import BRep_Builder
from OCP.gp import gp_Ax2, gp_Dir, gp_Pln, gp_Pnt, gp_Trsf
from OCP.IFSelect import IFSelect_RetDone
from OCP.Interface import Interface_Static
from OCP.STEPControl import STEPControl_AsIs, STEPControl_Writer
from OCP.TopAbs import TopAbs_SHELL
from OCP.TopExp import TopExp_Explorer
from OCP.TopoDS import TopoDS_Compound


def block_with_hole():
    box = BRepPrimAPI_MakeBox(gp_Pnt(-10, -8, -4), 20.0, 16.0, 8.0).Shape()
    hole = BRepPrimAPI_MakeCylinder(gp_Ax2(gp_Pnt(0, 0, -5), gp_Dir(0, 0, 1)), 3.0, 10.0).Shape()
    return BRepAlgoAPI_Cut(box, hole).Shape()


def peg_and_block():
    peg = BRepPrimAPI_MakeCylinder(gp_Ax2(gp_Pnt(0, 0, -6), gp_Dir(0, 0, 1)), 3.0, 12.0).Shape()
    block = BRepPrimAPI_MakeBox(gp_Pnt(11, -4, -2), 8.0, 8.0, 4.0).Shape()
    return compound([peg, block])


def shell_only():
    box = BRepPrimAPI_MakeBox(gp_Pnt(-5, -5, -5), 10.0, 10.0, 10.0).Shape()
    shell = TopExp_Explorer(box, TopAbs_SHELL).Current()
    face = BRepBuilderAPI_MakeFace(gp_Pln(gp_Pnt(0, 0, 10), gp_Dir(0, 0, 1)), -5, 5, -5, 5).Face()
    return compound([shell, face])


def compound(shapes):
    c = TopoDS_Compound()
    b = BRep_Builder()
    b.MakeCompound(c)
    for s in shapes:
        b.Add(c, s)
    return c


MM_UNIT = "( LENGTH_UNIT() NAMED_UNIT(*) SI_UNIT(.MILLI.,.METRE.) )"


def in_inches(shape):
    """The shape's numbers divided by 25.4 and its millimetre unit replaced by the inch."""
    scale = gp_Trsf()
    scale.SetScale(gp_Pnt(0, 0, 0), 1 / 25.4)
    return BRepBuilderAPI_Transform(shape, scale, True).Shape()


def inch_unit(text):
    """Replaces the millimetre length unit by the inch (25.4 mm) in a written STEP file's text."""
    ids = [int(n) for n in re.findall(r"^#(\d+)", text, re.M)]
    a, b, c = max(ids) + 1, max(ids) + 2, max(ids) + 3
    assert text.count(MM_UNIT) == 1, "one millimetre unit"
    text = text.replace(
        MM_UNIT, f"( CONVERSION_BASED_UNIT('INCH',#{a}) LENGTH_UNIT() NAMED_UNIT(#{b}) )")
    extra = (f"#{a} = LENGTH_MEASURE_WITH_UNIT(LENGTH_MEASURE(25.4),#{c});\n"
             f"#{b} = DIMENSIONAL_EXPONENTS(1.,0.,0.,0.,0.,0.,0.);\n"
             f"#{c} = {MM_UNIT};\n")
    return text.replace("ENDSEC;\nEND-ISO-10303-21;", extra + "ENDSEC;\nEND-ISO-10303-21;")


def write(shape, path, inches=False):
    Interface_Static.SetCVal_s("write.step.schema", "AP214IS")
    writer = STEPControl_Writer()
    writer.Transfer(shape, STEPControl_AsIs)
    assert writer.Write(path) == IFSelect_RetDone, path
    with open(path) as f:
        text = f.read()
    text = re.sub(r"'\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d'", "'2026-01-01T00:00:00'", text)
    if inches:
        text = inch_unit(text)
    with open(path, "w") as f:
        f.write(text)
    return text


def main(argv):
    out = argv[1] if len(argv) > 1 else os.path.join(
        os.path.dirname(__file__), "../../cell/tests/fixtures/step")
    os.makedirs(out, exist_ok=True)
    text = write(block_with_hole(), os.path.join(out, "block_with_hole.step"))
    write(in_inches(block_with_hole()), os.path.join(out, "block_with_hole_inch.step"), inches=True)
    write(peg_and_block(), os.path.join(out, "peg_and_block.step"))
    write(shell_only(), os.path.join(out, "shell_only.step"))
    lines = text.splitlines(keepends=True)
    data = next(i for i, l in enumerate(lines) if l.startswith("DATA;"))
    with open(os.path.join(out, "truncated.step"), "w") as f:
        f.writelines(lines[: data + (len(lines) - data) // 2])
    print(f"block volume {2560 - 72 * math.pi:.6f} mm^3; peg and block {108 * math.pi + 256:.6f} mm^3")


if __name__ == "__main__":
    main(sys.argv)
