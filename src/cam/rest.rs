//! Rest machining: a smaller finishing tool goes only where the tools
//! before it left more than a threshold on the relief, read from the
//! planned stock (the simulated cut of every pass so far), not guessed
//! from the geometry.

use super::stock::Planned;
use crate::cutter::dropcutter::HeightField;
use crate::error::Result;
use crate::grid::Grid;
use crate::relief::Relief;
use crate::sim::Stock;
use crate::tool::Tool;
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
        let lattice = crate::cutter::surface::Lattice::of(relief);
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

impl super::ToolpathJob {
    /// The rest stage: the rest tool in layers where the planned stock
    /// holds more than it may cut at once, then a raster at its finishing
    /// stepover, then pencil passes along the creases, all only near where
    /// the tools before it left more than the threshold (the rows on
    /// either side of such a place both come in). None (and a note) where
    /// nothing is left, or no rest tool is asked for.
    pub(super) fn rest_stage(&self, w: &mut super::setup::Work) -> Result<Option<super::Op>> {
        use super::{order, Op, Stepover};
        use crate::toolpath::Pass;
        let (Some(r), Some(rt)) = (&self.rest, w.rest_tool) else {
            return Ok(None);
        };
        let mut t = std::mem::take(&mut w.t);
        let op = t.time("rest", || -> Result<Option<Op>> {
            let settings = self.settings(&w.machine, &rt, w.material.as_ref(), &mut w.notes)?;
            let step = w
                .material
                .as_ref()
                .and_then(|mt| mt.cutting_for(rt.working_diameter()))
                .map(|c| Stepover::Percent(c.finish_stepover))
                .or(self.stepover.filter(|s| matches!(s, Stepover::Percent(_))))
                .unwrap_or(Stepover::Percent(10.0))
                .mm(&rt)?;
            let pitch = w.planned.stock.pitch;
            let left = Unfinished::find(&w.planned, &w.relief, r.threshold, step + pitch);
            if left.share() == 0.0 {
                w.notes.push(format!(
                    "--rest {}: nothing left over {} mm; no rest pass",
                    rt.spec(),
                    r.threshold
                ));
                return Ok(None);
            }
            let subject = w.subject.as_ref();
            let keep = |x: f64, y: f64| left.near(x, y) && subject.is_none_or(|s| s.is_near(x, y));
            let (hf, panel, floor) = (&w.hf, w.panel, w.floor);
            let mut passes = Vec::new();
            if let Some((layers, depth)) = self.rest_layers(
                hf,
                &rt,
                &w.planned,
                panel,
                floor,
                w.limits.layer(&rt),
                &settings,
                Some(&keep),
            ) {
                w.raw_points += layers.iter().map(|p| p.pts.len()).sum::<usize>();
                w.notes.push(format!(
                    "{} steps down in layers of {depth:.2} mm where more is left than it may cut",
                    rt.spec()
                ));
                passes.extend(w.planned.ramp_and_cut(layers, rt, false));
            }
            let (rows, raw) = self.raster(hf, &rt, panel, floor, step, Some(&keep));
            w.raw_points += raw;
            let rows = order::tour(rows, None);
            let rows = linked(hf, &rt, rows, floor, self.tolerance, rt.working_diameter());
            let rows = rows
                .into_iter()
                .map(|pts| Pass {
                    pts,
                    clear_z: settings.safe_z,
                })
                .collect();
            passes.extend(w.planned.ramp_and_cut(rows, rt, true));
            // pencil passes last, one clean line along each crease: valleys
            // of the rest tool's CL surface sharper than the finishing tool
            // fits into
            let kappa = 1.0 / (w.tool.radius() - rt.radius()).max(rt.radius());
            let start = passes.last().and_then(|p: &Pass| p.pts.last().copied());
            let (pencil, raw) =
                self.pencil(hf, &rt, panel, floor, kappa, &keep, start, settings.safe_z);
            let n_pencil = pencil.len();
            w.raw_points += raw;
            passes.extend(w.planned.ramp_and_cut(pencil, rt, true));
            let what = format!(
                "rest machining where more than {} mm was left ({:.1}% of the stock), raster, \
                 stepover {step:.4} mm, then {n_pencil} pencil passes along creases",
                r.threshold,
                100.0 * left.share()
            );
            w.notes.push(format!("{}: {what}", rt.spec()));
            Ok(Some(Op {
                title: "rest",
                tool: rt,
                zero: String::new(),
                settings,
                strategy: what,
                passes,
            }))
        });
        w.t = t;
        op
    }
}
