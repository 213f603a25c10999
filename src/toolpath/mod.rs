//! Stage 3: toolpaths on a relief: the exact drop-cutter (cutter-location
//! surface) for every tool shape, raster and waterline finishing,
//! roughing, pass refinement and merging.

pub mod arcs;
pub mod contour_arcs;
pub mod fewest;
pub mod merge;
pub mod path;
pub mod pencil;
pub mod raster;
pub mod rough;
pub mod waterline;

/// One cutting pass and the height to travel to its start at.
#[derive(Clone, Debug)]
pub struct Pass {
    pub pts: Vec<glam::DVec3>,
    /// Z for the travel to the pass's start, mm: clears the material.
    pub clear_z: f64,
}
