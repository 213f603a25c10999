//! How fine the simulated stock's cells are: what a cut may hide between
//! their centres, and the fewest cells per relief pixel that keep it under
//! a micrometre.

use crate::tool::Tool;

/// What a cut's bottom may hide between stock cells by default (mm).
pub const BETWEEN_CELLS: f64 = 1e-3;
/// Most stock cells per relief pixel along each axis.
pub const MAX_OVERSAMPLE: usize = 15;
/// Most stock cells taken (two grids of f32 besides the job: 1 GiB).
pub const MAX_CELLS: usize = 1 << 27;
/// Most stock cells an automatic choice makes.
const AUTO_CELLS: usize = 1 << 25;

/// How far below the cell centres a tool's cut can reach between them:
/// its profile half a cell diagonal from the tip (where a ball's groove
/// bottom may run between rows of centres). A V-bit's point is sharp, so
/// its bound is linear in the cell size.
pub fn between_cells(tools: &[Tool], cell: f64) -> f64 {
    let half_diagonal = cell / std::f64::consts::SQRT_2;
    tools
        .iter()
        .map(|t| t.profile(half_diagonal.min(t.radius())))
        .fold(0.0, f64::max)
}

/// The smallest odd number of stock cells per relief pixel (odd, so that
/// cells stay centred on the samples) that keeps `between_cells` within
/// BETWEEN_CELLS, as far as MAX_OVERSAMPLE and AUTO_CELLS allow.
pub fn oversample_for(tools: &[Tool], pitch: f64, samples: usize) -> usize {
    let mut k = 1;
    while between_cells(tools, pitch / k as f64) > BETWEEN_CELLS
        && k + 2 <= MAX_OVERSAMPLE
        && samples * (k + 2) * (k + 2) <= AUTO_CELLS
    {
        k += 2;
    }
    k
}
