//! Rest machining: a smaller finishing tool goes only where the tools
//! before it left more than a threshold on the relief, read from the
//! planned stock (the simulated cut of every pass so far), not guessed
//! from the geometry.

use super::stock::Planned;
use crate::grid::Grid;
use crate::relief::Relief;
use crate::sim::Stock;
use crate::tool::Tool;
use crate::toolpath::dropcutter::HeightField;
use crate::toolpath::path;
use glam::DVec3;
use rayon::prelude::*;

/// A rest pass asked for.
#[derive(Clone, Debug)]
pub struct Rest {
    /// Tool spec or tool-table name; smaller than the finishing tool.
    pub tool: String,
    /// Material left above the relief (mm) that calls for the rest tool.
    pub threshold: f64,
}

/// The default threshold, mm: over a 3.175 mm ball's scallop at a 10%
/// stepover on a 45 degree slope across its rows (0.016 mm), under what
/// shows on a carved surface under raking light.
pub const THRESHOLD: f64 = 0.03;

/// Where the stock stands more than a threshold above the relief, on the
/// planned stock's cells, grown by a distance so that the rows of the
/// rest pass on either side of an unfinished cell both come in.
pub struct Unfinished {
    stock: Stock,
    /// Unfinished cells, as found.
    left: Grid<bool>,
    /// The same, grown.
    near: Grid<bool>,
}

impl Unfinished {
    /// The cells of `planned` standing more than `threshold` above the
    /// relief's continuous surface (panel coordinates), grown by `grow` mm.
    pub fn find(planned: &Planned, relief: &Relief, threshold: f64, grow: f64) -> Unfinished {
        let stock = planned.stock;
        let lattice = crate::surface::Lattice::of(relief);
        let (w, h) = (planned.top.w, planned.top.h);
        let mut left = Grid::new(w, h, false);
        left.data
            .par_chunks_mut(w)
            .enumerate()
            .for_each(|(j, row)| {
                for (i, c) in row.iter_mut().enumerate() {
                    let (x, y) = stock.centre(i, j);
                    let t = lattice
                        .height_at(x, y, |a, b| *relief.heights.get(a, b) as f64)
                        .map(|z| z - relief.depth_mm);
                    *c = t.is_some_and(|t| *planned.top.get(i, j) as f64 - t > threshold);
                }
            });
        let near = left.grown((grow / stock.pitch).ceil() as usize);
        Unfinished { stock, left, near }
    }

    /// Share of the stock's cells left unfinished.
    pub fn share(&self) -> f64 {
        self.left.data.iter().filter(|&&c| c).count() as f64 / self.left.data.len().max(1) as f64
    }

    /// Whether (x, y) (panel mm) lies within the grown region.
    pub fn near(&self, x: f64, y: f64) -> bool {
        let s = &self.stock;
        let i = ((x - s.x0) / s.pitch).floor();
        let j = ((s.y0 + s.height - y) / s.pitch).floor();
        if i < 0.0 || j < 0.0 || i >= self.near.w as f64 || j >= self.near.h as f64 {
            return false;
        }
        *self.near.get(i as usize, j as usize)
    }
}

/// Passes in turn joined where the next starts within `gap` (XY) of
/// where the last ended: the tool stays down along a link that follows
/// the relief (dropped and checked like any pass) instead of lifting,
/// travelling and ramping in again between the short pieces a rest
/// raster is made of.
pub fn linked(
    hf: &HeightField,
    tool: &Tool,
    passes: Vec<Vec<DVec3>>,
    floor: f64,
    tol: f64,
    gap: f64,
) -> Vec<Vec<DVec3>> {
    let mut out: Vec<Vec<DVec3>> = Vec::with_capacity(passes.len());
    for p in passes {
        if let Some(last) = out.last_mut() {
            let (a, b) = (last[last.len() - 1], p[0]);
            if (b - a).truncate().length() <= gap {
                let link = path::check_and_refine(hf, tool, &[a, b], floor, tol, None);
                last.extend_from_slice(&link[1..link.len() - 1]);
                last.extend_from_slice(&p);
                continue;
            }
        }
        out.push(p);
    }
    out
}
