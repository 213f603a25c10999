//! The strategies' passes over a region: raster rows, waterlines, pencil
//! passes along valleys, a tool's own layers where more is left than it
//! may cut at once, each merged and checked against the exact tool.

use super::{order, stock, tile, Direction, Finish, ToolpathJob};
use crate::cutter::dropcutter::HeightField;
use crate::gcode::emit::Settings;
use crate::relief::Relief;
use crate::tool::Tool;
use crate::toolpath::{contour_arcs, merge, path, pencil, raster, rough, waterline, Pass};
use glam::DVec3;
use rayon::prelude::*;

impl ToolpathJob {
    /// Passes cleaned for the machine: merged within the tolerance, then
    /// every move checked exactly.
    pub(super) fn checked(&self, hf: &HeightField, tool: &Tool, passes: Vec<Pass>) -> Vec<Pass> {
        passes
            .into_iter()
            .map(|p| Pass {
                pts: path::verify(hf, tool, &merge::merge(&p.pts, self.tolerance), false),
                clear_z: p.clear_z,
            })
            .collect()
    }

    /// The finishing tool in layers over `region` wherever the planned
    /// stock holds more above the relief than it may cut at once (`most`);
    /// None where nothing is. Returns the passes and the layer depth.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn rest_layers(
        &self,
        hf: &HeightField,
        tool: &Tool,
        planned: &stock::Planned,
        region: [f64; 4],
        floor: f64,
        most: f64,
        s: &Settings,
        keep: Option<&(dyn Fn(f64, f64) -> bool + Sync)>,
    ) -> Option<(Vec<Pass>, f64)> {
        let left = planned.left_above(hf, region, tool);
        // (sampled a quarter radius apart: keep a fifth in hand)
        if left <= 0.8 * most {
            return None;
        }
        // room for the scallops and terraces the layers leave
        let layer = 0.5 * most.min(left);
        let r = tool.radius();
        // (where the finishing tool does not go, nor do its layers)
        let material = |x: f64, y: f64| {
            if keep.is_none_or(|k| k(x, y)) {
                planned.highest(x, y, r)
            } else {
                f64::NEG_INFINITY
            }
        };
        let params = rough::Params {
            tool: *tool,
            stepover: 0.4 * tool.working_diameter(),
            step_down: layer,
            stock_to_leave: 0.0,
            angle: self.angle,
            region,
            material: Some(&material),
            background: None,
        };
        let passes = rough::passes(hf, floor, &params).ok()?;
        let passes: Vec<Pass> = self
            .checked(hf, tool, passes)
            .into_iter()
            .map(|p| Pass {
                // the first travel comes from wherever the operation
                // before left off: at safe Z (the stock plan sets the rest)
                clear_z: s.safe_z,
                ..p
            })
            .collect();
        (!passes.is_empty()).then_some((passes, layer))
    }

    /// The raster over `region`, only where `keep` holds: zigzag runs of
    /// whole rows (a row cut short by `keep` is a pass of its own), or
    /// one-way rows. Returns the passes and the CL points dropped.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn raster(
        &self,
        hf: &HeightField,
        tool: &Tool,
        region: [f64; 4],
        floor: f64,
        step: f64,
        keep: Option<&(dyn Fn(f64, f64) -> bool + Sync)>,
    ) -> (Vec<Vec<DVec3>>, usize) {
        let rows = raster::rows_in(region, self.angle, step, raster::point_spacing(hf, tool));
        let tol = self.tolerance;
        let climb = self.direction == Some(Direction::Climb);
        // runs of whole rows; pieces of cut rows alone
        // (whole rows?, rows)
        type Group = (bool, Vec<Vec<(f64, f64)>>);
        let mut groups: Vec<Group> = Vec::new();
        for (k, row) in rows.into_iter().enumerate() {
            let pieces = match keep {
                None => vec![row.clone()],
                Some(f) => row
                    .split(|&(x, y)| !f(x, y))
                    .filter(|p| p.len() > 1)
                    .map(|p| p.to_vec())
                    .collect(),
            };
            if pieces.len() == 1 && pieces[0].len() == row.len() {
                match groups.last_mut() {
                    Some((true, g)) => g.push(row),
                    _ => groups.push((true, vec![row])),
                }
            } else {
                // odd rows run right to left: their pieces too, in turn
                let mut pieces = pieces;
                if k % 2 == 1 {
                    pieces.reverse();
                }
                for mut p in pieces {
                    if k % 2 == 1 {
                        p.reverse();
                    }
                    groups.push((false, vec![p]));
                }
            }
        }
        // every group at once: the pieces beside a keep-out are single
        // rows, each too small to keep both cores busy alone
        let done: Vec<(Vec<Vec<DVec3>>, usize)> = groups
            .into_par_iter()
            .map(|(whole, g)| {
                let cl = raster::drop_rows(hf, tool, &g, floor);
                let raw = cl.iter().map(Vec::len).sum::<usize>();
                // (pass, the CL points it was merged from)
                let main: Vec<(Vec<DVec3>, Vec<DVec3>)> = match (self.direction, whole) {
                    (None, true) => vec![raster::zigzag(hf, tool, &cl, floor, tol, self.arcs)],
                    (None, false) => cl
                        .into_iter()
                        .map(|c| (raster::thin(&c, tol, self.arcs), c))
                        .collect(),
                    (Some(_), _) => raster::one_way(&cl, climb, tol, self.arcs),
                };
                let checked = main
                    .iter()
                    .map(|(c, drops)| path::check_and_refine(hf, tool, c, floor, tol, Some(drops)))
                    .collect();
                (checked, raw)
            })
            .collect();
        let raw = done.iter().map(|d| d.1).sum();
        (done.into_iter().flat_map(|d| d.0).collect(), raw)
    }

    /// Pencil passes of `tool` along the valleys of its CL surface over
    /// `region` that bend up by at least `kappa` (1/mm), where `keep`
    /// holds: merged, checked, and toured from `start`. Returns the passes
    /// and the CL points dropped. (Its parameters are `pencil::lines`'
    /// again, deliberately: it passes them through and adds the tour.)
    #[allow(clippy::too_many_arguments)]
    pub(super) fn pencil(
        &self,
        hf: &HeightField,
        tool: &Tool,
        region: [f64; 4],
        floor: f64,
        kappa: f64,
        keep: &(dyn Fn(f64, f64) -> bool + Sync),
        start: Option<DVec3>,
        clear_z: f64,
    ) -> (Vec<Pass>, usize) {
        let lines: Vec<Vec<DVec3>> = pencil::lines(hf, tool, region, floor, kappa, keep)
            .par_iter()
            .map(|l| {
                let m = merge::merge(l, self.tolerance);
                path::check_and_refine(hf, tool, &m, floor, self.tolerance, None)
            })
            .collect();
        let raw = lines.iter().map(Vec::len).sum();
        let passes = order::tour(lines, start)
            .into_iter()
            .map(|pts| Pass { pts, clear_z })
            .collect();
        (passes, raw)
    }

    /// Waterline passes `dz` apart, level by level from the top, nearest
    /// first.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn waterlines(
        &self,
        hf: &HeightField,
        tool: &Tool,
        relief: &Relief,
        floor: f64,
        dz: f64,
        climb: bool,
        keep_also: Option<&(dyn Fn(f64, f64) -> bool + Sync)>,
    ) -> Vec<Vec<DVec3>> {
        let g = waterline::ClGrid::new(hf, tool, relief.width_mm, relief.height_mm, floor);
        let steep_only = self.finish == Finish::RasterWaterline;
        let (w, h) = (relief.width_mm, relief.height_mm);
        // every level's contours, then all of them placed, refined and
        // checked at once: one level may hold a single long contour
        let levels = waterline::levels(&g, dz);
        // steep ground takes every m-th level, and every level within m
        // of its foot: the lowest contour of a wall is what cleans the
        // corner a raster row beside it leaves (rows parallel to a wall's
        // foot ride up on it)
        let feet = steep_only.then(|| g.feet());
        let contours: Vec<(usize, waterline::Contour)> = levels
            .par_iter()
            .enumerate()
            .map(|(n, &level)| {
                // beside a raster, steep ground takes every m-th level only
                let k = ((level - floor) / dz).round() as i64;
                let keep = |p: DVec3, slope: f64| {
                    (0.0..=w).contains(&p.x)
                        && (0.0..=h).contains(&p.y)
                        && (!steep_only
                            || waterline::every_nth(slope).is_some_and(|m| {
                                k % m == 0
                                    || feet.as_ref().is_some_and(|f| {
                                        let (i, j) = g.nearest(p.x, p.y);
                                        level - *f.get(i, j) < m as f64 * dz
                                    })
                            }))
                        && keep_also.is_none_or(|f| f(p.x, p.y))
                };
                waterline::contours(&g, level)
                    .iter()
                    .flat_map(|c| waterline::parts(c, keep))
                    .map(|c| (n, c))
                    .collect::<Vec<_>>()
            })
            .flatten_iter()
            .collect();
        // (closed?, points) of each piece, by level
        type Pieces = Vec<(bool, Vec<DVec3>)>;
        let done: Vec<(usize, Pieces)> = contours
            .par_iter()
            .map(|(n, c)| {
                let c = waterline::place(hf, tool, floor, c);
                let c = waterline::refine(hf, tool, floor, &c);
                let mut pts = if self.arcs {
                    contour_arcs::fit(&c.pts, &c.slope, self.tolerance)
                } else {
                    waterline::simplify(&c, self.tolerance)
                };
                if climb {
                    pts.reverse();
                }
                // within the panel, where the job's travel is checked
                let pts = waterline::clear(hf, tool, &pts, self.arcs);
                let pieces = tile::clip(&pts, [0.0, 0.0, w, h]);
                let whole = pieces.len() == 1 && pieces[0].len() == pts.len();
                let closed = c.closed && whole;
                (*n, pieces.into_iter().map(|p| (closed, p)).collect())
            })
            .collect();
        let mut by_level: Vec<Pieces> = vec![Vec::new(); levels.len()];
        for (n, pieces) in done {
            by_level[n].extend(pieces);
        }
        let mut out: Vec<Vec<DVec3>> = Vec::new();
        for mut loops in by_level {
            // nearest next: closed loops start where they are nearest
            let mut at = out
                .last()
                .and_then(|p| p.last().copied())
                .unwrap_or_default();
            while !loops.is_empty() {
                let d = |p: &DVec3| (*p - at).truncate().length_squared();
                let (k, start) = loops
                    .iter()
                    .enumerate()
                    .map(|(k, (closed, pts))| {
                        let s = if *closed {
                            (0..pts.len() - 1)
                                .min_by(|&a, &b| d(&pts[a]).total_cmp(&d(&pts[b])))
                                .unwrap_or(0)
                        } else {
                            0
                        };
                        (k, s, d(&pts[s]))
                    })
                    .min_by(|a, b| a.2.total_cmp(&b.2))
                    .map(|(k, s, _)| (k, s))
                    .unwrap();
                let (closed, mut pts) = loops.swap_remove(k);
                if closed && start > 0 {
                    pts.pop();
                    pts.rotate_left(start);
                    pts.push(pts[0]);
                }
                at = *pts.last().unwrap();
                out.push(pts);
            }
        }
        out
    }
}
