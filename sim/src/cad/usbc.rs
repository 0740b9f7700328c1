//! The USB Type-C receptacle parts, authored by this project to the outer dimensions of the seed's
//! parts (the real CAD is not ours to ship), and the fixture nest and tag board of the cell.
//!
//! All three parts really mate, top-down: the main shell sits in the nest; the insert mold's lower
//! body drops into the shell's cavity with 0.09 mm total clearance in width (USB-C's plug-in-
//! receptacle figure) and rests on the shell floor; the top shell's side skirts slide down outside
//! the shell walls with 0.045 mm per side and its plate rests on the insert. Dimensions in mm,
//! assembled frame: z = 0 at the shell's underside.

use nalgebra::Isometry3;
use perception::part::TriMesh;

use super::solid::{Rect, Solid};

/// Total clearance between the insert mold's lower body and the shell cavity, per axis (mm).
pub const INSERT_CLEARANCE_MM: f64 = 0.09;
/// Clearance between the top shell's skirts and the shell walls, per side (mm).
pub const TOP_SKIRT_GAP_MM: f64 = 0.045;
/// Lead-in chamfer at the top of the shell cavity (mm).
pub const SHELL_CHAMFER_MM: f64 = 0.10;
/// Lead-in flare at the bottom inner edge of the top shell's skirts (mm).
pub const TOP_LEAD_IN_MM: f64 = 0.10;
/// Clearance between the shell and the nest pocket, per side (mm).
pub const NEST_GAP_MM: f64 = 0.03;
/// Lead-in chamfer at the top of the nest pocket (mm).
pub const NEST_CHAMFER_MM: f64 = 0.30;
/// Half-size of the square reliefs milled at the nest pocket's corners (mm): an end mill leaves
/// round inside corners, so pockets for sharp-cornered parts get corner reliefs; they also let
/// a shell arriving off-centre on both axes slide down both chamfers instead of landing its
/// corner on an unchamfered corner.
pub const NEST_CORNER_RELIEF_MM: f64 = 0.40;

// Main shell.
const SHELL_BODY: Rect = Rect::new(-4.32, 4.32, -4.535, 4.535);
const SHELL_HEIGHT: f64 = 3.00;
const SHELL_FLOOR: f64 = 0.30;
const SHELL_TAB_X: f64 = 4.42;
const SHELL_TAB_Y: (f64, f64) = (2.0, 3.5);
const SHELL_TAB_HEIGHT: f64 = 1.2;

// Insert mold.
const INSERT_LOWER: (f64, f64) = (8.20, 8.40);
const INSERT_LOWER_HEIGHT: f64 = SHELL_HEIGHT - SHELL_FLOOR;
const INSERT_UPPER: Rect = Rect::new(-4.20, 4.20, -4.27, 4.27);
const INSERT_HEIGHT: f64 = 4.15;
const PIN_HEIGHT: f64 = 0.05;

// Top shell.
const TOP_PLATE_THICKNESS: f64 = 0.25;
const TOP_HEIGHT: f64 = 4.39;
const TOP_SKIRT_THICKNESS: f64 = 0.25;
const TOP_HALF_DEPTH: f64 = 4.455;
const TOP_SKIRT_Y: (f64, f64) = (-TOP_HALF_DEPTH, 1.5);
const TOP_FLANGE_X: f64 = 5.90;
const TOP_FLANGE_Y: (f64, f64) = (-2.5, 0.5);

// Nest.
const NEST_SIZE: f64 = 24.0;
const NEST_BASE: f64 = 5.0;
const NEST_POCKET_DEPTH: f64 = 1.0;

fn cavity() -> Rect {
    Rect::centred(
        INSERT_LOWER.0 + INSERT_CLEARANCE_MM,
        INSERT_LOWER.1 + INSERT_CLEARANCE_MM,
    )
}

/// The main shell: a sheet-metal tray with an open top, a floor window off-centre toward −y, and
/// two mounting tabs near +y (which break its near 180° symmetry about z).
pub fn main_shell() -> TriMesh {
    let mut s = Solid::new();
    let window = Rect::new(-1.5, 1.5, -3.2, -1.8);
    s.plate_with_holes(SHELL_BODY, 0.0, SHELL_FLOOR, &[window], None);
    let inner = cavity();
    let chamfer_z = SHELL_HEIGHT - SHELL_CHAMFER_MM;
    s.ring(
        SHELL_FLOOR,
        chamfer_z,
        (SHELL_BODY, inner),
        (SHELL_BODY, inner),
    );
    s.ring(
        chamfer_z,
        SHELL_HEIGHT,
        (SHELL_BODY, inner),
        (SHELL_BODY, inner.grown(SHELL_CHAMFER_MM)),
    );
    for sign in [-1.0, 1.0] {
        let (a, b) = if sign > 0.0 {
            (SHELL_BODY.x1, SHELL_TAB_X)
        } else {
            (-SHELL_TAB_X, SHELL_BODY.x0)
        };
        s.cuboid(
            Rect::new(a, b, SHELL_TAB_Y.0, SHELL_TAB_Y.1),
            0.0,
            SHELL_TAB_HEIGHT,
        );
    }
    s.into_part_mesh()
}

/// The insert mold: a dark plastic body whose lower part fits the shell cavity and whose upper
/// tongue carries a row of twelve gold contact pins near +y.
pub fn insert_mold() -> TriMesh {
    let mut s = Solid::new();
    s.cuboid(
        Rect::centred(INSERT_LOWER.0, INSERT_LOWER.1),
        0.0,
        INSERT_LOWER_HEIGHT,
    );
    let top = INSERT_HEIGHT - PIN_HEIGHT;
    s.cuboid(INSERT_UPPER, INSERT_LOWER_HEIGHT, top);
    let pitch = 0.5;
    for i in 0..12 {
        let x = (i as f64 - 5.5) * pitch;
        s.cuboid(
            Rect::new(x - 0.125, x + 0.125, 2.6, 3.6),
            top,
            INSERT_HEIGHT,
        );
    }
    s.into_part_mesh()
}

/// The top shell: a cover plate with a window over the pins near +y, rear and front walls that
/// locate it on the insert's tongue, two side skirts (toward −y) that slide down outside the shell
/// walls, and solder flanges that make it the widest part.
pub fn top_shell() -> TriMesh {
    let mut s = Solid::new();
    let skirt_in = SHELL_BODY.x1 + TOP_SKIRT_GAP_MM;
    let skirt_out = skirt_in + TOP_SKIRT_THICKNESS;
    let top = TOP_HEIGHT;
    let plate_z = top - TOP_PLATE_THICKNESS;
    let window = Rect::new(-3.2, 3.2, 2.4, 3.8);
    let plate = Rect::new(-skirt_out, skirt_out, -TOP_HALF_DEPTH, TOP_HALF_DEPTH);
    s.plate_with_holes(plate, plate_z, top, &[window], None);
    // Rear and front walls between the skirts, down to just above the shell's top edge: they
    // locate the cover along y on the insert's tongue (0.045 mm a side), their inner bottom
    // edges flared by the lead-in like the skirts'.
    let wall_in = INSERT_UPPER.y1 + TOP_SKIRT_GAP_MM;
    let insert_over_shell = INSERT_HEIGHT - INSERT_LOWER_HEIGHT;
    let wall_bottom = plate_z - insert_over_shell + 0.10;
    let flare_height = 2.0 * TOP_LEAD_IN_MM;
    for sign in [-1.0, 1.0] {
        let wall = if sign > 0.0 {
            Rect::new(-skirt_in, skirt_in, wall_in, TOP_HALF_DEPTH)
        } else {
            Rect::new(-skirt_in, skirt_in, -TOP_HALF_DEPTH, -wall_in)
        };
        let mut flared = wall;
        if sign > 0.0 {
            flared.y0 += TOP_LEAD_IN_MM;
        } else {
            flared.y1 -= TOP_LEAD_IN_MM;
        }
        s.frustum(flared, wall_bottom, wall, wall_bottom + flare_height);
        s.cuboid(wall, wall_bottom + flare_height, plate_z);
    }
    for sign in [-1.0, 1.0] {
        let (a, b) = if sign > 0.0 {
            (skirt_in, skirt_out)
        } else {
            (-skirt_out, -skirt_in)
        };
        // The skirt's inner bottom edge is flared by the lead-in so it guides over the shell.
        let skirt = Rect::new(a, b, TOP_SKIRT_Y.0, TOP_SKIRT_Y.1);
        let mut flared = skirt;
        if sign > 0.0 {
            flared.x0 += TOP_LEAD_IN_MM;
        } else {
            flared.x1 -= TOP_LEAD_IN_MM;
        }
        let flare_top = 0.25 + flare_height;
        s.frustum(flared, 0.25, skirt, flare_top);
        s.cuboid(skirt, flare_top, plate_z);
        let (fa, fb) = if sign > 0.0 {
            (skirt_out, TOP_FLANGE_X)
        } else {
            (-TOP_FLANGE_X, -skirt_out)
        };
        s.cuboid(Rect::new(fa, fb, TOP_FLANGE_Y.0, TOP_FLANGE_Y.1), 0.0, 0.25);
    }
    s.into_part_mesh()
}

/// The fixture nest: an aluminium block with a pocket for the main shell (small clearance,
/// chamfered lead-in, corner reliefs) and reliefs where the top shell's skirts come down.
pub fn fixture_nest() -> TriMesh {
    let mut s = Solid::new();
    let outer = Rect::centred(NEST_SIZE, NEST_SIZE);
    s.cuboid(outer, 0.0, NEST_BASE);
    let pocket =
        Rect::new(-SHELL_TAB_X, SHELL_TAB_X, SHELL_BODY.y0, SHELL_BODY.y1).grown(NEST_GAP_MM);
    let relief = |sign: f64| {
        let (a, b) = if sign > 0.0 {
            (pocket.x1, 6.4)
        } else {
            (-6.4, pocket.x0)
        };
        // Down to the corner reliefs' edge: no cut may fall inside the pocket's chamfer band.
        Rect::new(a, b, pocket.y0 - NEST_CORNER_RELIEF_MM, TOP_SKIRT_Y.1 + 0.3)
    };
    let r = NEST_CORNER_RELIEF_MM;
    let corner = |x: f64, y: f64| Rect::new(x - r, x + r, y - r, y + r);
    s.plate_with_holes(
        outer,
        NEST_BASE,
        NEST_BASE + NEST_POCKET_DEPTH,
        &[
            pocket,
            relief(-1.0),
            relief(1.0),
            corner(pocket.x0, pocket.y0),
            corner(pocket.x1, pocket.y0),
            corner(pocket.x1, pocket.y1),
            corner(pocket.x0, pocket.y1),
        ],
        Some((NEST_CHAMFER_MM, pocket)),
    );
    s.into_part_mesh()
}

/// The tag board: a 210 × 210 × 2 mm aluminium plate (its tag pattern is a texture).
pub fn tag_board() -> TriMesh {
    let mut s = Solid::new();
    s.cuboid(Rect::centred(210.0, 210.0), 0.0, 2.0);
    s.into_part_mesh()
}

/// Where each part's frame sits when assembled, relative to the frame it goes into.
pub struct AssemblyTargets {
    /// `nest_T_main`: the main shell seated in the nest pocket.
    pub nest_t_main: Isometry3<f64>,
    /// `main_T_insert`: the insert mold seated on the shell floor.
    pub main_t_insert: Isometry3<f64>,
    /// `main_T_top`: the top shell resting on the insert.
    pub main_t_top: Isometry3<f64>,
}

/// The seated poses, from the same dimensions that built the meshes (part frames are bounding-box
/// centres, so each offset is a difference of box centres).
pub fn assembly_targets() -> AssemblyTargets {
    let mm = |x: f64, y: f64, z: f64| Isometry3::translation(x * 1e-3, y * 1e-3, z * 1e-3);
    let shell_centre_z = SHELL_HEIGHT / 2.0;
    let shell_y_centre = 0.0;
    // Nest: bounding box from 0 to NEST_BASE + depth; pocket floor at NEST_BASE.
    let nest_centre_z = (NEST_BASE + NEST_POCKET_DEPTH) / 2.0;
    let nest_t_main = mm(
        0.0,
        shell_y_centre,
        NEST_BASE + shell_centre_z - nest_centre_z,
    );
    let insert_bottom = SHELL_FLOOR;
    let main_t_insert = mm(
        0.0,
        0.0,
        insert_bottom + INSERT_HEIGHT / 2.0 - shell_centre_z,
    );
    let insert_top = insert_bottom + INSERT_HEIGHT - PIN_HEIGHT;
    let top_bottom = insert_top + TOP_PLATE_THICKNESS - TOP_HEIGHT;
    let main_t_top = mm(0.0, 0.0, top_bottom + TOP_HEIGHT / 2.0 - shell_centre_z);
    AssemblyTargets {
        nest_t_main,
        main_t_insert,
        main_t_top,
    }
}
