//! The G-code dialect's numbers, below both the strategies that make
//! moves and the G-code that writes and reads them: the grid coordinates
//! are written on, the largest arc written, arcs as GRBL takes and cuts
//! them (`arc`), and runs of points that are exactly an arc's chords
//! (`chords`).

pub mod arc;
pub mod chords;

/// The resolution of coordinates in the G-code (mm).
pub const GRID: f64 = 1e-4;

/// Round to the G-code grid.
#[inline]
pub fn snap(v: f64) -> f64 {
    (v / GRID).round() * GRID
}

/// Round a height up to the G-code grid (never into the material).
#[inline]
pub fn snap_up(v: f64) -> f64 {
    (v / GRID - 1e-6).ceil() * GRID
}

/// Largest arc radius written (mm): flatter runs are straight moves.
pub const MAX_RADIUS: f64 = 1000.0;
