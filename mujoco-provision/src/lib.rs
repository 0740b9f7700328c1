//! The MuJoCo shared library for mujoco-rs: its build script finds or downloads MuJoCo 3.17.0
//! (see `build.rs`) and puts it on the link path of every crate that depends on this one.

/// The MuJoCo version the bindings are generated for, and the one provisioned.
pub const VERSION: &str = "3.17.0";

/// The folder the build linked `libmujoco.so` from (the loader finds it there through
/// `cargo run`/`cargo test`, which put OUT_DIR folders on the library path).
pub const LIB_DIR: &str = env!("MUJOCO_PROVISIONED_DIR");
