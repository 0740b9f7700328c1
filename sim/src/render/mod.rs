//! The simulated camera: a ray tracer over the scene's triangle meshes (parry BVHs), rendering RGB
//! with physically based shading and shadows, depth, and per-instance masks through perception's
//! camera model, for a full frame, a downscaled overview or a crop window.
//! [`IncrementalRenderer`] renders a scene again only where its parts changed, and [`CentreRays`]
//! lets the renders of one camera window share its lens inversion.

#![allow(non_snake_case)]

mod aabb;
mod appearance;
mod capture;
mod environment;
mod geometry;
mod incremental;
mod instance_grid;
mod kernels;
mod light;
mod output;
mod renderer;
mod sensor;
mod shading;
mod shadow_grid;
mod tag_board;
mod texture;

pub use appearance::Appearance;
pub use capture::{Capture, capture, window_covering};
pub use environment::{CameraMount, CeilingPanel, Environment, Room};
pub use geometry::{Hit, Instance, RenderMesh, RenderScene, SurfaceKind, Table};
pub use incremental::IncrementalRenderer;
pub use light::{AreaLight, PointLight};
pub use output::{InstanceMask, RenderOutput, Window};
pub use renderer::{CentreRays, RenderSettings, instance_mask, render, render_with_rays};
pub use sensor::{SensorError, SensorModel};
pub use tag_board::{BoardMark, TagBoard};
pub use texture::{TableTexture, TexturePattern};
