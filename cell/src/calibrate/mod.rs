//! Commissioning a cell: the printable board ([`svg`]); the camera and the table found in the
//! robot base from a tag-board image and pointer touches ([`procedure`]) or from a flange board
//! the arm carries through planned poses ([`hand_eye`]), against the
//! simulated cell ([`sim_world`]) or a real one ([`production`]); the record written into the
//! scenario ([`record`]); and the production pre-flight's check that the camera has not moved
//! since ([`preflight`]).

pub mod commission;
pub mod evidence;
pub mod hand_eye;
pub mod preflight;
pub mod procedure;
pub mod production;
pub mod record;
pub mod sim_world;
pub mod study;
pub mod svg;
