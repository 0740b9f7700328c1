//! The initial, global PnP solution (SQPnP), and the input checks every PnP solve runs first.

use nalgebra::{
    Isometry3, Matrix2, Matrix3, Point2, Point3, Rotation3, Translation3, UnitQuaternion, Vector2,
    Vector3,
};

use super::PnpError;

/// Relative size below which the second principal spread counts as zero (collinear points).
const COLLINEAR_RATIO: f64 = 1e-5;

/// Checks counts, finiteness and degeneracy of a PnP problem's points.
pub fn check_geometry(model: &[Point3<f64>], normalized: &[Point2<f64>]) -> Result<(), PnpError> {
    let n = model.len();
    if normalized.len() != n {
        return Err(PnpError::LengthMismatch {
            what: "image points",
            expected: n,
            got: normalized.len(),
        });
    }
    if n < 4 {
        return Err(PnpError::TooFewPoints(n));
    }
    if model
        .iter()
        .any(|p| !p.coords.iter().all(|v| v.is_finite()))
    {
        return Err(PnpError::NonFinite("model points"));
    }
    if normalized
        .iter()
        .any(|p| !p.coords.iter().all(|v| v.is_finite()))
    {
        return Err(PnpError::NonFinite("image points"));
    }
    let mean3 = model.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / n as f64;
    let scatter3 = model.iter().fold(Matrix3::zeros(), |a, p| {
        let d = p.coords - mean3;
        a + d * d.transpose()
    });
    let mut l3 = scatter3.symmetric_eigenvalues();
    l3.as_mut_slice().sort_by(|a, b| b.total_cmp(a));
    if l3[0].sqrt() < 1e-12 {
        return Err(PnpError::DegenerateModel("coincident"));
    }
    if l3[1].sqrt() < COLLINEAR_RATIO * l3[0].sqrt() {
        return Err(PnpError::DegenerateModel("collinear"));
    }
    let mean2 = normalized
        .iter()
        .fold(Vector2::zeros(), |a, p| a + p.coords)
        / n as f64;
    let scatter2 = normalized.iter().fold(Matrix2::zeros(), |a, p| {
        let d = p.coords - mean2;
        a + d * d.transpose()
    });
    let l2 = scatter2.symmetric_eigenvalues();
    let (big, small) = (l2.max(), l2.min());
    if big.sqrt() < 1e-12 {
        return Err(PnpError::DegenerateImage("coincident"));
    }
    if small.max(0.0).sqrt() < COLLINEAR_RATIO * big.sqrt() {
        return Err(PnpError::DegenerateImage("collinear"));
    }
    Ok(())
}

/// The SQPnP solution for model points and undistorted normalised image points.
///
/// `sqpnp` works in single precision (glam); the model is centred first so that its small
/// coordinates keep their relative precision, and the result is re-orthonormalised in f64.
/// Refinement then reaches full double precision.
pub fn initial_pose(
    model: &[Point3<f64>],
    normalized: &[Point2<f64>],
) -> Result<Isometry3<f64>, PnpError> {
    check_geometry(model, normalized)?;
    let centroid = model.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / model.len() as f64;
    // sqpnp speaks glam 0.30 (f32); nalgebra's `convert-glam030` feature, which sqpnp itself
    // enables, converts at the boundary without this crate naming that glam version.
    let points_3d: Vec<_> = model
        .iter()
        .map(|p| nalgebra::Vector3::<f32>::from((p.coords - centroid).map(|v| v as f32)).into())
        .collect();
    let points_2d: Vec<_> = normalized
        .iter()
        .map(|p| nalgebra::Vector2::<f32>::new(p.x as f32, p.y as f32).into())
        .collect();
    let mut solver = sqpnp::Solver::<InitialParameters>::new();
    if !solver.solve(points_3d.as_slice(), points_2d.as_slice(), None) {
        return Err(PnpError::NoSolution("SQPnP found no solution"));
    }
    let best = solver
        .best_solution()
        .ok_or(PnpError::NoSolution("SQPnP found no solution"))?;
    let m32: Matrix3<f32> = best.rotation_matrix().into();
    let m: Matrix3<f64> = m32.map(f64::from);
    if !m.iter().all(|v| v.is_finite()) {
        return Err(PnpError::NoSolution("SQPnP returned a non-finite rotation"));
    }
    let rotation = UnitQuaternion::from_rotation_matrix(&nearest_rotation(&m));
    let t32: Vector3<f32> = best.translation().into();
    let t_centred: Vector3<f64> = t32.map(f64::from);
    // x = R (X − c) + t'  ⇒  t = t' − R c
    let translation = t_centred - rotation * centroid;
    let pose = Isometry3::from_parts(Translation3::from(translation), rotation);
    if model.iter().any(|p| (pose * p).z <= 0.0) {
        return Err(PnpError::NoSolution(
            "the best SQPnP pose puts points behind the camera",
        ));
    }
    Ok(pose)
}

/// The rotation closest to `m` in the Frobenius norm (SVD, with the determinant fixed to +1).
pub(crate) fn nearest_rotation(m: &Matrix3<f64>) -> Rotation3<f64> {
    let svd = m.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Rotation3::identity();
    };
    let mut d = Matrix3::identity();
    if (u * v_t).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    Rotation3::from_matrix_unchecked(u * d * v_t)
}

/// SQPnP's default tolerances, with FOAM for the nearest rotation (the C++ reference's default):
/// faster than SVD, and its lower accuracy does not matter because refinement follows.
struct InitialParameters;

impl sqpnp::Parameters for InitialParameters {
    const RANK_TOLERANCE: f64 = sqpnp::DefaultParameters::RANK_TOLERANCE;
    const SQP_SQUARED_TOLERANCE: f64 = sqpnp::DefaultParameters::SQP_SQUARED_TOLERANCE;
    const SQP_DET_THRESHOLD: f64 = sqpnp::DefaultParameters::SQP_DET_THRESHOLD;
    const SQP_MAX_ITERATIONS: usize = sqpnp::DefaultParameters::SQP_MAX_ITERATIONS;
    const ORTHOGONALITY_SQUARED_ERROR_THRESHOLD: f64 =
        sqpnp::DefaultParameters::ORTHOGONALITY_SQUARED_ERROR_THRESHOLD;
    const EQUAL_VECTORS_SQUARED_DIFF: f64 = sqpnp::DefaultParameters::EQUAL_VECTORS_SQUARED_DIFF;
    const EQUAL_SQUARED_ERRORS_DIFF: f64 = sqpnp::DefaultParameters::EQUAL_SQUARED_ERRORS_DIFF;
    const POINT_VARIANCE_THRESHOLD: f64 = sqpnp::DefaultParameters::POINT_VARIANCE_THRESHOLD;

    fn nearest_rotation_matrix(m: &sqpnp::NMat3) -> sqpnp::NMat3 {
        sqpnp::nearest_rotation_matrix_foam(m)
    }

    fn eigen_vectors(m: &sqpnp::NMat9) -> (sqpnp::NMat9, sqpnp::NVec9) {
        sqpnp::eigen_vectors_rrqr(m)
    }
}
