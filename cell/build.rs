//! With MuJoCo, the `cell` binary records where mujoco-provision put `libmujoco.so` as its rpath,
//! so `target/release/cell` runs outside `cargo run` (which sets the library path itself).

fn main() {
    println!("cargo::rerun-if-env-changed=DEP_MUJOCO_PROVISION_LIB_DIR");
    if let Ok(dir) = std::env::var("DEP_MUJOCO_PROVISION_LIB_DIR") {
        println!("cargo::rustc-link-arg-bins=-Wl,-rpath,{dir}");
    }
}
