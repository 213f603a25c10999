//! Stage 3: toolpaths on a relief: the exact drop-cutter (cutter-location
//! surface) for every tool shape, raster finishing, pass refinement and
//! merging.

pub mod dropcutter;
pub mod path;
pub mod raster;
