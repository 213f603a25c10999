//! Stage 3: toolpaths on a relief: the exact drop-cutter (cutter-location
//! surface) for every tool shape, raster and waterline finishing,
//! roughing, pass refinement and merging.

pub mod along;
pub mod arcs;
pub mod contour_arcs;
pub mod dropcutter;
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

/// Golden-section search for the maximum of a unimodal function on
/// [lo, hi]: the middle of the bracket after `steps` narrowings (each by
/// the golden ratio).
pub fn golden_max(lo: f64, hi: f64, steps: usize, f: impl Fn(f64) -> f64) -> f64 {
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut a, mut b) = (lo, hi);
    let (mut c, mut d) = (b - g * (b - a), a + g * (b - a));
    let (mut fc, mut fd) = (f(c), f(d));
    for _ in 0..steps {
        if fc >= fd {
            b = d;
            (d, fd) = (c, fc);
            c = b - g * (b - a);
            fc = f(c);
        } else {
            a = c;
            (c, fc) = (d, fd);
            d = a + g * (b - a);
            fd = f(d);
        }
    }
    0.5 * (a + b)
}
