//! Axes about which a part is round (perception::part::round_axes), on the NIST pegs as
//! committed: round ones are 48-gons built of touching bodies, whose inner walls are no part of
//! the outer surface.

use std::path::Path;

use perception::part::{Catalog, ROUND_WITHIN_M, round_axes};

#[test]
fn the_nist_round_pegs_turn_freely_about_their_axis_and_the_square_ones_do_not() {
    let catalog = Catalog::load(Path::new("../scenarios/parts/nist_pegs.toml")).expect("catalog");
    let mut round = 0;
    for spec in &catalog.parts {
        let mesh = catalog.load_mesh(spec).expect("mesh");
        let axes = round_axes(&mesh, &spec.symmetries, ROUND_WITHIN_M);
        if spec.name.starts_with("round_") {
            round += 1;
            assert_eq!(axes.len(), 1, "{}: {axes:?}", spec.name);
            let z = axes[0].into_inner();
            assert!((z.z.abs() - 1.0).abs() < 1e-12, "{}: {z:?}", spec.name);
        } else {
            assert!(axes.is_empty(), "{}: {axes:?}", spec.name);
        }
    }
    assert_eq!(round, 3);
}
