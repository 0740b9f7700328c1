"""Drop a catalog's parts as the seed's stable-pose experiment did, in Blender's Bullet, and compare.

The seed (github.com/yangfei4/StablePose_simulation, generate_stable_poses.py) dropped 30 copies of a
part at once, 2 000 times per part, with BlenderProc 2.5.0. This script rebuilds that experiment in
Blender itself (bpy from PyPI) without BlenderProc, whose installer downloads Blender:

- 30 parts placed within +-0.15 m, their centres 30-40 mm above a passive board (the seed's 21 cm tag board
  scaled three times), orientations uniform on SO(3), none overlapping at release;
- BlenderProc's `enable_rigidbody` defaults: convex-hull collision with a 1 mm margin, mass 0.1 kg,
  friction 0.5, angular / linear damping 0.1 / 0.04; its `simulate_physics`: origin moved to the
  mesh's centre of volume, 10 substeps a frame at 24 fps (240 Hz), 10 solver iterations, and its
  stop rule (from 0.2 s, every second, until no part moved more than 1 cm or 0.1 rad in the last
  second, at most 10 s);
- each rest orientation assigned to the nearest stable pose of the prepared catalog (its
  `up_in_part`), and the shares printed beside the catalog's.

`--margin`, `--parts-per-scene`, `--drop-height`, `--substeps`, `--solver-iterations` and `--com`
change one setting at a time, to tell
which of BlenderProc's choices moves the shares. Bullet computes a convex hull's inertia from its
bounding box, whatever the mass distribution; that cannot be changed from Blender.

Usage (bpy 4.5.15 in the venv that scripts/cycles_render/venv.sh provisions):

    python="$(scripts/cycles_render/venv.sh)"
    "$python" scripts/bullet_drops/drops.py CATALOG.toml PART [--scenes N] [--out FILE.json] [options]

200 scenes (6 000 drops) of a USB-C part take 2-6 minutes on one core.
"""

import argparse
import json
import math
import random
import sys
import tomllib
from pathlib import Path

import bpy
import mathutils

FPS = 24
UNIT_SCALE = {"m": 1.0, "mm": 1e-3}


def fail(message):
    """Stops with a message on stderr and exit status 2."""
    print(f"drops.py: {message}", file=sys.stderr)
    sys.exit(2)


def load_part(catalog_path, part_name):
    """The part's entry of a prepared catalog, its mesh path, the mesh unit's length in metres
    and the catalog's recorded drop height (None if it has none)."""
    try:
        catalog = tomllib.loads(Path(catalog_path).read_text())
    except (OSError, tomllib.TOMLDecodeError) as error:
        fail(f"{catalog_path}: {error}")
    parts = {p["name"]: p for p in catalog.get("part", [])}
    if part_name not in parts:
        fail(f"{catalog_path}: no part named {part_name!r} (parts: {', '.join(parts)})")
    part = parts[part_name]
    if not part.get("stable_pose"):
        fail(f"{catalog_path}: part {part_name!r} has no stable poses; run `cell parts prepare` first")
    mesh = Path(catalog_path).parent / part["mesh"]
    if mesh.suffix.lower() != ".obj":
        fail(f"{mesh}: only OBJ meshes are dropped here (BlenderProc's loader); got {mesh.suffix}")
    unit = part.get("unit", "mm")
    if unit not in UNIT_SCALE:
        fail(f"{catalog_path}: part {part_name!r} has unit {unit!r}; expected one of {list(UNIT_SCALE)}")
    return part, mesh, UNIT_SCALE[unit], catalog.get("drop_height")


def with_object(obj):
    """A context override that makes `obj` the active, selected, editable object for an operator."""
    return bpy.context.temp_override(
        object=obj, active_object=obj, selected_objects=[obj], selected_editable_objects=[obj]
    )


def template(mesh_path, scale, com):
    """The part imported in its file's frame, in metres, its origin where the physics takes its
    centre of mass; returns the object and that origin in the file's frame (metres)."""
    bpy.ops.wm.obj_import(filepath=str(mesh_path), forward_axis="Y", up_axis="Z")
    parts = list(bpy.context.selected_objects)
    if len(parts) != 1:
        with bpy.context.temp_override(
            active_object=parts[0], selected_objects=parts, selected_editable_objects=parts
        ):
            bpy.ops.object.join()
    obj = bpy.context.view_layer.objects.active or parts[0]
    obj.scale = (scale, scale, scale)
    with with_object(obj):
        bpy.ops.object.transform_apply(location=True, rotation=True, scale=True)
        if com == "volume":
            bpy.ops.object.origin_set(type="ORIGIN_CENTER_OF_VOLUME")
    origin = mathutils.Vector(obj.location)
    obj.location = (0.0, 0.0, 0.0)
    return obj, origin


def board():
    """The passive board the parts land on: a 63 x 63 cm, 1 cm slab whose top is at z = 0."""
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.0, 0.0, -0.005))
    slab = bpy.context.active_object
    slab.scale = (0.63, 0.63, 0.01)
    with with_object(slab):
        bpy.ops.object.transform_apply(location=False, rotation=False, scale=True)
        bpy.ops.rigidbody.object_add(type="PASSIVE")
    rigid(slab, margin=0.001, mass=1.0)
    return slab


def rigid(obj, margin, mass):
    """BlenderProc 2.5.0's `enable_rigidbody` settings on an object that has a rigid body."""
    body = obj.rigid_body
    body.collision_shape = "CONVEX_HULL"
    body.collision_margin = margin
    body.use_margin = True
    body.mesh_source = "FINAL"
    body.friction = 0.5
    body.angular_damping = 0.1
    body.linear_damping = 0.04
    body.mass = mass


def uniform_rotation(rng):
    """A rotation drawn uniformly on SO(3) (Shoemake's quaternion)."""
    u1, u2, u3 = rng.random(), rng.random(), rng.random()
    a, b = math.sqrt(1.0 - u1), math.sqrt(u1)
    q = mathutils.Quaternion(
        (b * math.cos(2 * math.pi * u3), a * math.sin(2 * math.pi * u2),
         a * math.cos(2 * math.pi * u2), b * math.sin(2 * math.pi * u3))
    )
    return q.to_matrix()


def place(objects, radius, rng, drop_low, drop_high):
    """Positions within +-0.15 m, `drop_low`-`drop_high` above the board, no two bounding spheres
    overlapping (BlenderProc resamples a pose that collides, up to 1 000 times)."""
    placed = []
    for obj in objects:
        for _ in range(1000):
            p = mathutils.Vector(
                (rng.uniform(-0.15, 0.15), rng.uniform(-0.15, 0.15), rng.uniform(drop_low, drop_high))
            )
            if all((p - q).length > 2 * radius for q in placed):
                break
        else:
            fail("could not place the parts apart from each other")
        placed.append(p)
        obj.matrix_world = mathutils.Matrix.Translation(p) @ uniform_rotation(rng).to_4x4()


def poses(objects):
    """Each object's location and XYZ Euler angles, as BlenderProc's stop rule reads them."""
    out = []
    for obj in objects:
        m = obj.matrix_world
        out.append((m.translation.copy(), mathutils.Vector(m.to_euler())))
    return out


def stopped(old, new, location_threshold=0.01, rotation_threshold=0.1):
    """BlenderProc 2.5.0's `have_objects_stopped_moving`, signs and all (old minus new, no abs)."""
    for (l0, r0), (l1, r1) in zip(old, new):
        if any(l0[i] - l1[i] > location_threshold for i in range(3)):
            return False
        if any(r0[i] - r1[i] > rotation_threshold for i in range(3)):
            return False
    return True


def simulate(objects, min_time=0.2, max_time=10.0, interval=1.0):
    """Steps the rigid-body world frame by frame, stopping by BlenderProc's rule; returns the
    simulated time."""
    scene = bpy.context.scene
    world = scene.rigidbody_world
    world.point_cache.frame_start = 1
    world.point_cache.frame_end = int(max_time * FPS) + 1
    scene.frame_set(1)
    history = {1: poses(objects)}
    frame = 1
    t = min_time
    while t < max_time:
        check = int(t * FPS)
        while frame < check:
            frame += 1
            scene.frame_set(frame)
            history[frame] = poses(objects)
        before = history.get(check - FPS, history[1])
        if stopped(before, history[check]) or t + interval >= max_time:
            return check / FPS
        t += interval
    return frame / FPS


def scene_drops(mesh_path, scale, args, rng):
    """One scene of `parts_per_scene` parts dropped together; each part's up direction in its own
    frame and its centre's height above the board at the end."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps = FPS
    bpy.ops.rigidbody.world_add()
    world = scene.rigidbody_world
    world.substeps_per_frame = args.substeps
    world.solver_iterations = args.solver_iterations
    board()
    part, origin = template(mesh_path, scale, args.com)
    radius = max((mathutils.Vector(v.co)).length for v in part.data.vertices)
    objects = [part] + [part.copy() for _ in range(args.parts_per_scene - 1)]
    for obj in objects[1:]:
        scene.collection.objects.link(obj)
    for obj in objects:
        with with_object(obj):
            bpy.ops.rigidbody.object_add(type="ACTIVE")
        rigid(obj, margin=args.margin, mass=0.1)
    if args.drop_height <= radius:
        fail(f"--drop-height {args.drop_height} m would start the part in the board (its radius: {radius:.4f} m)")
    place(objects, radius, rng, args.drop_height, args.drop_height + 0.01)
    seconds = simulate(objects)
    results = []
    for obj in objects:
        rotation = obj.matrix_world.to_3x3()
        up = rotation.transposed() @ mathutils.Vector((0.0, 0.0, 1.0))
        results.append({"up": list(up), "height": obj.matrix_world.translation.z})
    return results, seconds, origin


def classify(drops, part):
    """Shares of the catalog's stable poses, each drop counted at the nearest `up_in_part`
    (drops more than 0.2 rad from every class are counted as `other`)."""
    classes = [(p["name"], mathutils.Vector(p["up_in_part"]).normalized()) for p in part["stable_pose"]]
    counts = {name: 0 for name, _ in classes}
    counts["other"] = 0
    for drop in drops:
        up = mathutils.Vector(drop["up"]).normalized()
        name, angle = min(((n, up.angle(u)) for n, u in classes), key=lambda c: c[1])
        counts[name if angle <= 0.2 else "other"] += 1
    return counts


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("catalog", help="a prepared part catalog (TOML)")
    parser.add_argument("part", help="the part's name in the catalog")
    parser.add_argument("--scenes", type=int, default=100, help="scenes to drop (the seed: 2000)")
    parser.add_argument("--parts-per-scene", type=int, default=30, help="parts dropped together (the seed: 30)")
    parser.add_argument("--seed", type=int, default=1, help="seed of positions and orientations")
    parser.add_argument("--margin", type=float, default=0.001,
                        help="the parts' collision margin, metres, added around each hull (BlenderProc: "
                        "0.001; the board keeps 0.001, which only raises its flat top)")
    parser.add_argument("--drop-height", type=float, default=0.03,
                        help="height of a part's centre of mass above the board at release, metres, plus up to "
                        "1 cm (the seed: 0.03)")
    parser.add_argument("--substeps", type=int, default=10,
                        help="physics steps per 1/24 s frame (BlenderProc: 10, so 240 Hz)")
    parser.add_argument("--solver-iterations", type=int, default=10,
                        help="constraint solver iterations per step (BlenderProc: 10)")
    parser.add_argument("--com", choices=["volume", "origin"], default="volume",
                        help="centre of mass: the mesh's centre of volume (BlenderProc) or the file's origin")
    parser.add_argument("--out", help="write every drop's up vector and height here (JSON)")
    args = parser.parse_args()
    if min(args.scenes, args.parts_per_scene, args.substeps, args.solver_iterations) < 1:
        fail("--scenes, --parts-per-scene, --substeps and --solver-iterations must be at least 1")
    part, mesh, scale, catalog_height = load_part(args.catalog, args.part)
    if not mesh.is_file():
        fail(f"{mesh}: no such mesh file")
    rng = random.Random(args.seed)
    drops, times = [], []
    for index in range(args.scenes):
        results, seconds, origin = scene_drops(mesh, scale, args, rng)
        drops.extend(results)
        times.append(seconds)
        if (index + 1) % 10 == 0:
            print(f"{index + 1} / {args.scenes} scenes", file=sys.stderr, flush=True)
    counts = classify(drops, part)
    total = len(drops)
    print(f"{args.part}: {total} drops in {args.scenes} scenes, centre of mass at "
          f"({origin.x * 1e3:.3f}, {origin.y * 1e3:.3f}, {origin.z * 1e3:.3f}) mm in the file's frame, "
          f"simulated {sum(times) / len(times):.1f} s a scene")
    dropped = "an unrecorded height" if catalog_height is None else f"{catalog_height * 1e3:.1f} mm"
    print(f"  the catalog's table was dropped from {dropped}")
    print(f"  {'class':<14} {'catalog %':>10} {'Bullet %':>10} {'diff':>7}")
    for pose in part["stable_pose"]:
        name = pose["name"]
        share = 100.0 * counts[name] / total
        print(f"  {name:<14} {100.0 * pose['probability']:>10.2f} {share:>10.2f} {share - 100.0 * pose['probability']:>+7.2f}")
    print(f"  {'other':<14} {'':>10} {100.0 * counts['other'] / total:>10.2f}")
    if args.out:
        tmp = Path(args.out + ".tmp")
        tmp.write_text(json.dumps({"part": args.part, "settings": vars(args), "counts": counts, "drops": drops}))
        tmp.replace(args.out)


if __name__ == "__main__":
    main()
