//! Contour alignment on rendered feeder frames: started 1–2 px and a few degrees off each
//! part's true pose, the outline fit must land on the truth to a fraction of a pixel, touching
//! neighbours included. The renderer and the fit share nothing but the mesh and the camera model.

mod feeder_support;

use feeder_support::{catalog, render_feeder, snapped};
use nalgebra::Point3;
use perception::contour::{ContourAligner, ContourConfig, ContourView, GreyPatch, PartOutline};

#[test]
#[allow(non_snake_case)]
fn outline_fits_land_on_the_true_pose_from_a_perturbed_start() {
    let catalog = catalog();
    let mut xy_um = Vec::new();
    let mut yaw_deg = Vec::new();
    let mut lost = 0;
    // 24 frames: a quantile of a few frames' parts moves with the frames' luck.
    for seed in 21..45 {
        let feeder = render_feeder(&catalog, seed);
        let camera_T_table = feeder.table_T_camera.inverse();
        let aligner = ContourAligner::new(camera_T_table, ContourConfig::default());
        for (name, table_T_part) in &feeder.truth {
            let spec = catalog.part(name).expect("a catalog part");
            let outline = PartOutline::new(&catalog.load_mesh(spec).expect("its mesh"));
            // The truth on its stable pose: only parts resting on the table are on one (a part
            // leaning on a neighbour or lying on top of one is not).
            let truth = snapped(&catalog, &camera_T_table, name, table_T_part);
            if !truth.rests(table_T_part) {
                continue;
            }
            let stable = &spec.stable_poses[truth.class];
            let centre = feeder
                .camera
                .project(&(camera_T_table * table_T_part * Point3::origin()))
                .expect("in view");
            let patch = GreyPatch::cut(
                &feeder.image.pixels,
                feeder.image.origin,
                [centre.x as i64 - 72, centre.y as i64 - 72, 144, 144],
            );
            let t = table_T_part.translation.vector;
            // About 1.4 px and 1 px off (0.14 mm/px), and 4° turned.
            let start = (t.x + 2e-4, t.y - 1.5e-4, truth.yaw + 4f64.to_radians());
            let view = ContourView {
                outline: &outline,
                stable,
                camera: &feeder.camera,
                patch: &patch,
            };
            let Some(fit) = aligner.align(view, start) else {
                lost += 1;
                continue;
            };
            xy_um.push(((fit.x - t.x).hypot(fit.y - t.y)) * 1e6);
            let d = (fit.yaw - truth.yaw).rem_euclid(std::f64::consts::TAU);
            yaw_deg.push(d.min(std::f64::consts::TAU - d).to_degrees());
        }
    }
    let n = xy_um.len();
    let quantile = |v: &mut Vec<f64>, q: f64| {
        v.sort_by(f64::total_cmp);
        v[((v.len() - 1) as f64 * q).round() as usize]
    };
    let (xy50, xy90) = (quantile(&mut xy_um, 0.5), quantile(&mut xy_um, 0.9));
    let (yaw50, yaw90) = (quantile(&mut yaw_deg, 0.5), quantile(&mut yaw_deg, 0.9));
    eprintln!(
        "{n} parts aligned, {lost} lost: xy error median {xy50:.1} µm, 90 % {xy90:.1} µm; \
         yaw error median {yaw50:.3}°, 90 % {yaw90:.3}°"
    );
    assert!(
        n >= 150,
        "only {n} parts resting on a stable pose were aligned"
    );
    assert!(lost <= 1, "{lost} fits found too few edges");
    // Measured over these 24 frames: 65.2 / 227 µm, 0.25 / 1.35° (184 parts). The misses over
    // 150 µm are mostly main shells, whose inner rims pull the outline in a crowd. Before the
    // drops' contacts between parts were stiffened (parts heaped on each other sank up to 3 mm
    // into each other) the same frames gave 61.9 / 249 µm, 0.24 / 1.53° (173 parts), where the
    // first 12 alone gave 0.26 / 1.14°: 12 frames were too few to bound the 90 % yaw quantile.
    // Parts lying flat on top of another one are not resting and are left out; with stiff
    // contacts they lie 3 mm up, where a fit on the table plane misses by 0.2–1 mm.
    assert!(xy50 < 70.0, "median xy error {xy50:.1} µm");
    assert!(xy90 < 250.0, "90 % xy error {xy90:.1} µm");
    assert!(yaw50 < 0.3, "median yaw error {yaw50:.3}°");
    assert!(yaw90 < 1.45, "90 % yaw error {yaw90:.3}°");
}
