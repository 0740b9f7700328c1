//! Compiling generated MJCF with the MuJoCo library, after checking the library is the one the
//! bindings are generated for.

use mujoco_rs::prelude::MjModel;

use super::available::check_version;
use super::error::MujocoError;
use super::mjcf::Mjcf;

/// A compiled model with the document it came from (for error messages and debugging).
#[derive(Debug)]
pub struct Compiled {
    /// The model.
    pub model: MjModel,
    /// The MJCF it was compiled from.
    pub xml: String,
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
