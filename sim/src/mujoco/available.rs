//! Whether MuJoCo can be used: the version the bindings are generated for, and the check that
//! this build has the engine and the library the loader found is that version.

use super::error::MujocoError;

/// The MuJoCo version the bindings are generated for and the provisioning pins.
pub const VERSION: &str = "3.17.0";

/// Checks that MuJoCo can be used: this build has the `mujoco` feature and the library the
/// loader found is MuJoCo 3.17.0.
pub fn ensure_available() -> Result<(), MujocoError> {
    #[cfg(feature = "mujoco")]
    {
        check_version()
    }
    #[cfg(not(feature = "mujoco"))]
    {
        Err(MujocoError::Unavailable(format!(
            "this build of sim has no MuJoCo: its `mujoco` feature (on by default) was turned \
             off; rebuild without --no-default-features, or with --features sim/mujoco (MuJoCo \
             {VERSION} is then provisioned automatically)"
        )))
    }
}

/// Checks that the loaded library is MuJoCo 3.17.0 (the bindings assert it and would panic).
#[cfg(feature = "mujoco")]
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
