//! Physics, stable poses, part CAD authoring, rendering, datasets and the simulated cell.
