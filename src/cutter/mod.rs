//! The cutter's geometry, below every strategy: the relief as a lattice of
//! facets (`surface`), a tool swept along a move (`sweep`), the lowest a
//! tool may stand over a point (`dropcutter`, with the height field it
//! drops onto), and how far a tool may go along a move without gouging
//! (`along`). Strategies, the simulator and the CAM stages ask these; the
//! tool's shape is matched in `tool.rs` and here, where its geometry is.

pub mod along;
pub mod dropcutter;
pub mod surface;
pub mod sweep;

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
