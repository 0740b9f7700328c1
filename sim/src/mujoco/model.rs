//! Compiling generated MJCF with the MuJoCo library, after checking the library is the one the
//! bindings are generated for.

use mujoco_rs::prelude::MjModel;

use super::mjcf::Mjcf;
use super::{MujocoError, VERSION};

/// A compiled model with the document it came from (for error messages and debugging).
#[derive(Debug)]
pub struct Compiled {
    /// The model.
    pub model: MjModel,
    /// The MJCF it was compiled from.
    pub xml: String,
}

/// Checks that the loaded library is MuJoCo 3.17.0 (the bindings assert it and would panic).
pub(super) fn check_version() -> Result<(), MujocoError> {
    // SAFETY: mj_version only returns a constant of the loaded library; it takes no arguments
    // and touches no state.
    #[allow(unsafe_code)]
    let loaded = unsafe { mujoco_rs::mujoco_c::mj_version() };
    if i64::from(loaded) == i64::from(mujoco_rs::mujoco_c::mjVERSION_HEADER) {
        return Ok(());
    }
    Err(MujocoError::Unavailable(format!(
        "the MuJoCo library loaded is version {}.{}.{}, expected {VERSION} (the version \
         mujoco-rs 7 is generated for): unset MUJOCO_DYNAMIC_LINK_DIR to let the build provision \
         {VERSION} from its PyPI wheel, or point it at a MuJoCo {VERSION} lib folder (loaded \
         from the build's {})",
        loaded / 1_000_000,
        loaded / 1000 % 1000,
        loaded % 1000,
        mujoco_provision::LIB_DIR
    )))
}

/// Compiles `xml` (generated from `mjcf`); an error that names one of the meshes is reported
/// as that part's piece.
pub fn compile(mjcf: &Mjcf, xml: String) -> Result<Compiled, MujocoError> {
    check_version()?;
    match MjModel::from_xml_string(&xml) {
        Ok(model) => Ok(Compiled { model, xml }),
        Err(e) => {
            let reason = e.to_string();
            Err(match mjcf.piece_named_in(&reason) {
                Some((part, piece)) => MujocoError::Piece {
                    part: part.to_string(),
                    piece,
                    reason: format!("MuJoCo rejects it: {reason}"),
                },
                None => MujocoError::Compile(reason),
            })
        }
    }
}
