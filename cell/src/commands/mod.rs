//! One module per subcommand: argument parsing and human output only; the work lives in the
//! library crates.

pub mod ablate;
pub mod check;
pub mod dataset;
pub mod merge;
pub mod parts;
pub mod regress;
pub mod run;
pub mod scorers;
pub mod virtual_ur;
