//! The toolpath job: a relief in, a GRBL job out. Its pipeline of named
//! stages (setup, roughing, finishing, rest, cutout, delivery) lives in
//! `cam`, one file per stage; this is its place among the jobs.

pub use crate::cam::{CamSummary, ToolpathJob};
