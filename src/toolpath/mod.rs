//! Stage 3: toolpaths on a relief. Built so far: the exact drop-cutter
//! (cutter-location surface) for every tool shape.

pub mod dropcutter;
