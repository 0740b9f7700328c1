//! Commissioning a cell: the printable board ([`svg`]) and the calibration record written into
//! a scenario ([`record`]).

pub mod record;
pub mod svg;
