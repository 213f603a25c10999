//! The stock as the job plans it: a heightfield on the relief's samples
//! (0 = stock top), cut pass by pass as operations are planned, so that
//! later operations know where material is left: where to step down, and
//! from how high each pass must ramp in instead of plunging.

use crate::cutter::dropcutter::HeightField;
use crate::gcode::{Kind, Segment};
use crate::grid::Grid;
use crate::sim::{self, Stock};
use crate::tool::Tool;
use crate::toolpath::{path, Pass};
use glam::DVec3;

/// Height of travels over the highest material on their way, mm.
const TRAVEL_CLEARANCE: f64 = 1.0;

pub struct Planned {
    pub stock: Stock,
    pub top: Grid<f32>,
}

impl Planned {
    /// Untouched stock (in panel coordinates).
    pub fn new(stock: Stock) -> Planned {
        let (cw, ch) = stock.cells();
        Planned {
            stock,
            top: Grid::new(cw, ch, 0.0),
        }
    }

    /// Fold `f(acc, height, distance^2)` over the stock cells within `r`
    /// of (x, y), starting from `init`.
    fn fold_footprint(
        &self,
        (x, y, r): (f64, f64, f64),
        init: f64,
        f: impl Fn(f64, f64, f64) -> f64,
    ) -> f64 {
        let s = &self.stock;
        let (w, h) = (self.top.w, self.top.h);
        let top = s.y0 + s.height;
        let (Some((i0, i1)), Some((j0, j1))) = (
            crate::cutter::sweep::cells_between(x - r - s.x0, x + r - s.x0, s.pitch, w),
            crate::cutter::sweep::cells_between(top - y - r, top - y + r, s.pitch, h),
        ) else {
            return init;
        };
        let mut acc = init;
        for j in j0..=j1 {
            let (_, cy) = s.centre(0, j);
            for i in i0..=i1 {
                let (cx, _) = s.centre(i, 0);
                let d2 = (cx - x).powi(2) + (cy - y).powi(2);
                if d2 <= r * r {
                    acc = f(acc, *self.top.get(i, j) as f64, d2);
                }
            }
        }
        acc
    }

    /// The highest material within `r` of (x, y) (-inf off the stock).
    pub fn highest(&self, x: f64, y: f64, r: f64) -> f64 {
        self.fold_footprint((x, y, r), f64::NEG_INFINITY, |m, z, _| m.max(z))
    }

    /// The highest material of the cells any part of which lies within
    /// `r` of (x, y): a cell's height is its centre's, and at the edge of
    /// a cut a cell whose centre the tool took may be stock top elsewhere
    /// (a hair more than half its diagonal, so that a point on a cell's
    /// corner, the panel's, still finds it).
    fn highest_touching(&self, x: f64, y: f64, r: f64) -> f64 {
        let half_diagonal = self.stock.pitch * (std::f64::consts::FRAC_1_SQRT_2 + 1e-6);
        self.highest(x, y, r + half_diagonal)
    }

    /// The thickest material the tool at tip (x, y, z) would cut: over the
    /// cells under it, how far the stock stands above its surface.
    pub fn would_cut(&self, x: f64, y: f64, z: f64, tool: &Tool) -> f64 {
        // most cells lie below the tip: those need no profile
        self.fold_footprint((x, y, tool.radius()), 0.0, |m, top, d2| {
            if top - z <= m {
                m
            } else {
                m.max(top - (z + tool.profile_sq(d2)))
            }
        })
    }

    /// Cut one pass into the stock.
    pub fn cut(&mut self, pts: &[DVec3], tool: Tool) {
        let segs: Vec<Segment> = pts
            .windows(2)
            .map(|w| Segment {
                line: 0,
                kind: Kind::Feed,
                a: w[0],
                b: w[1],
                feed: 1.0,
                stop_before: false,
            })
            .collect();
        sim::cut(&self.stock, &mut self.top, &segs, tool);
    }

    /// Each pass in order: split where it would drop steeply into
    /// material (the rest becomes a pass of its own), ramped in from the
    /// material's top wherever it starts in material, and cut into the
    /// stock, so that no move plunges. A sliver between two steep drops
    /// too short to ramp along is left out of clearing passes (`surface`
    /// false: later passes take its material) and kept in surface passes.
    pub fn ramp_and_cut(&mut self, passes: Vec<Pass>, tool: Tool, surface: bool) -> Vec<Pass> {
        let r = tool.radius();
        let mut out: Vec<Pass> = Vec::with_capacity(passes.len());
        for p in passes {
            let mut from = 0;
            let clear_z = p.clear_z;
            let pass_start = out.len();
            while from < p.pts.len() {
                let split = self.steep_drop(&p.pts[from..], r).map(|i| from + i);
                let to = split.unwrap_or(p.pts.len());
                let mut piece = p.pts[from..to].to_vec();
                // a sharp tip (a V-bit's) between the cells' centres meets
                // the material of the cell it is in
                let in_material = |q: DVec3| {
                    self.would_cut(q.x, q.y, q.z, &tool) > 0.005
                        || self.highest_touching(q.x, q.y, 0.0) - q.z > 0.005
                };
                // a surface piece between two steep drops too short to ramp
                // along would be entered straight down from above: the drop
                // that leads to it is the gentler way in, so it stays
                let xy_len = |pts: &[DVec3]| -> f64 {
                    pts.windows(2)
                        .map(|w| (w[1] - w[0]).truncate().length())
                        .sum()
                };
                if surface
                    && from > 0
                    && out.len() > pass_start
                    && xy_len(&piece) < 0.25 * r
                    && in_material(piece[0])
                {
                    let prev = out.last_mut().unwrap();
                    let mut way = vec![*prev.pts.last().unwrap()];
                    way.extend_from_slice(&piece);
                    self.cut(&way, tool);
                    prev.pts.extend(piece);
                    from = to;
                    continue;
                }
                // a clearing piece that starts in material at the foot of a
                // steep rise can be entered only by going down the rise:
                // its foot is left to later passes
                if !surface {
                    let foot = (0..piece.len() - 1)
                        .take_while(|&i| path::rises_steeply(&piece, i) && in_material(piece[i]))
                        .count();
                    piece.drain(..foot);
                    if piece.len() < 2 {
                        from = to;
                        continue;
                    }
                }
                let first = piece[0];
                if in_material(first) {
                    let top = self.highest(first.x, first.y, r);
                    // start a hair above the material
                    let start = path::snap_up(top + 0.05).min(clear_z.max(top + 0.05));
                    piece = path::ramp(&piece, start, r);
                    if piece[0].z < start - 1e-9 && !surface {
                        from = to;
                        continue;
                    }
                }
                // travel from the last pass as high as the material under
                // the way (and a millimetre) needs: the pass's own
                // clearance was reckoned for the way from where its
                // operation left off, which a split, a dropped foot or a
                // skipped piece before it changes (and over material that
                // only this plan knows is still there)
                let travel = match out.last().and_then(|q| q.pts.last()) {
                    Some(&end) => self.over_the_way(end, piece[0], r) + TRAVEL_CLEARANCE,
                    None => clear_z,
                };
                self.cut(&piece, tool);
                out.push(Pass {
                    pts: piece,
                    clear_z: travel,
                });
                // the rest of the pass starts from the pass's own
                // clearance height, which clears everything
                from = to;
            }
        }
        out
    }

    /// The highest material within `r` of the straight way from `a` to
    /// `b` (XY), at least both ends' Z: sampled at most half a radius
    /// apart, each sample over r sqrt(1 + 1/16), which covers every point
    /// within r of the way, in every cell any part of which lies there
    /// (the finish of Suzanne at 400 px with the field held flat hopped
    /// 1 mm over the cut beside an uncut row that stood 0.93 mm higher,
    /// within the tool's reach, whose cell's centre had been cut).
    fn over_the_way(&self, a: DVec3, b: DVec3, r: f64) -> f64 {
        let len = (b - a).truncate().length();
        let n = (len / (0.5 * r)).ceil() as usize + 1;
        let reach = r * (1.0f64 + 1.0 / 16.0).sqrt();
        (0..=n)
            .map(|k| {
                let p = a + (b - a) * (k as f64 / n as f64);
                self.highest_touching(p.x, p.y, reach)
            })
            .fold(a.z.max(b.z), f64::max)
    }

    /// The first point of `pts` reached by a steep drop (`path::steep`)
    /// that ends in material (more than a scallop under the tool's axis,
    /// within a quarter radius as the simulator judges it, and a cell
    /// more: the rim of a neighbouring row's cut can fall between these
    /// cells and not between the simulator's finer ones).
    fn steep_drop(&self, pts: &[DVec3], r: f64) -> Option<usize> {
        let near = r / 4.0 + self.stock.pitch;
        (1..pts.len()).find(|&i| {
            let (a, b) = (pts[i - 1], pts[i]);
            path::steep(b, a)
                && self.highest(b.x, b.y, near) - b.z > crate::sim::engage::PLUNGE_SKIN as f64
        })
    }

    /// Thickest material left above the CL surface of `tool` over the
    /// region's sample points (x0, y0, x1, y1, panel mm) at which the tool
    /// would meet it: what a finishing pass there would cut at once.
    pub fn left_above(&self, hf: &HeightField, region: [f64; 4], tool: &Tool) -> f64 {
        use rayon::prelude::*;
        // a quarter radius apart (however coarse the relief's samples):
        // what is left lies in terraces and corners wider than that; at
        // most about 4 million points
        let area = (region[2] - region[0]).max(0.0) * (region[3] - region[1]).max(0.0);
        let step = (tool.radius() / 4.0).max((area / 4e6).sqrt());
        let nx = ((region[2] - region[0]) / step).ceil() as usize + 1;
        let ny = ((region[3] - region[1]) / step).ceil() as usize + 1;
        (0..ny)
            .into_par_iter()
            .map(|j| {
                let y = (region[1] + j as f64 * step).min(region[3]);
                let mut most = 0.0f64;
                for i in 0..nx {
                    let x = (region[0] + i as f64 * step).min(region[2]);
                    if let Some(z) = hf.drop(tool, x, y) {
                        most = most.max(self.would_cut(x, y, z, tool));
                    }
                }
                most
            })
            .reduce(|| 0.0, f64::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn planned() -> Planned {
        Planned::new(Stock {
            x0: -2.0,
            y0: 0.0,
            width: 14.0,
            height: 10.0,
            thickness: 6.0,
            pitch: 0.05,
        })
    }

    /// The steepest descent of a pass: drop over horizontal run.
    fn steepest_descent(p: &Pass) -> f64 {
        p.pts
            .windows(2)
            .map(|w| (w[0].z - w[1].z) / (w[1] - w[0]).truncate().length().max(1e-9))
            .fold(f64::NEG_INFINITY, f64::max)
    }

    /// A pass's own clearance height is reckoned by its operation for the
    /// way from where that operation left off; the travel the plan makes
    /// can run elsewhere (here over stock no pass has cut, between two
    /// channels), and must clear what the plan knows is there.
    #[test]
    fn travels_clear_the_planned_stock_not_the_pass_s_own_height() {
        let tool = Tool::parse("flat:3.175").unwrap();
        let row = |y: f64, rev: bool| {
            let mut pts: Vec<DVec3> = (0..=40)
                .map(|i| DVec3::new(0.25 * i as f64, y, -1.0))
                .collect();
            if rev {
                pts.reverse();
            }
            pts
        };
        let passes = vec![
            Pass {
                pts: row(2.0, false),
                clear_z: 5.0,
            },
            // as low as a layer's travel over its own cleared level
            Pass {
                pts: row(8.0, true),
                clear_z: -0.5,
            },
        ];
        let out = planned().ramp_and_cut(passes, tool, false);
        assert_eq!(out.len(), 2);
        // the stock top (0) stands between the channels
        assert!(
            out[1].clear_z >= TRAVEL_CLEARANCE - 1e-9,
            "travels at {}",
            out[1].clear_z
        );
    }

    /// A clearing pass that starts in material at the foot of a steep rise
    /// (the CL drop at a panel edge): the ramp's return legs would run down
    /// the rise, so the foot is left out and the ramp keeps to the gentle
    /// stretch after it.
    #[test]
    fn a_clearing_pass_is_not_entered_down_a_steep_rise() {
        let tool = Tool::parse("flat:3.175").unwrap();
        let y = 5.0;
        let mut pts = vec![DVec3::new(0.0, y, -2.1), DVec3::new(0.2, y, -1.9)];
        pts.extend((1..=40).map(|i| DVec3::new(0.2 + 0.25 * i as f64, y, -1.9)));
        let out = planned().ramp_and_cut(vec![Pass { pts, clear_z: 5.0 }], tool, false);
        assert_eq!(out.len(), 1);
        assert!(out[0].pts.iter().all(|p| p.x > 0.1), "the foot was cut");
        let s = steepest_descent(&out[0]);
        assert!(
            s <= path::RAMP_DEG.to_radians().tan() * 1.01,
            "descends at {s}"
        );
    }

    /// A surface pass down a wall in steps just over 45 degrees: each step
    /// is a steep drop into material, and the piece after each is too short
    /// to ramp along. The pass keeps to the wall instead of being cut into
    /// one-point pieces entered straight down from above.
    #[test]
    fn a_surface_pass_down_a_wall_is_not_cut_into_plunges() {
        let tool = Tool::parse("ball:3.175").unwrap();
        let y = 5.0;
        let mut pts: Vec<DVec3> = (0..=20)
            .map(|i| DVec3::new(0.25 * i as f64, y, -0.5))
            .collect();
        pts.extend((1..=8).map(|i| DVec3::new(5.0 + 0.1 * i as f64, y, -0.5 - 0.11 * i as f64)));
        pts.extend((1..=20).map(|i| DVec3::new(5.8 + 0.25 * i as f64, y, -1.38)));
        let out = planned().ramp_and_cut(vec![Pass { pts, clear_z: 5.0 }], tool, true);
        for p in &out {
            for w in p.pts.windows(2) {
                let vertical = (w[1] - w[0]).truncate().length() < 1e-9 && w[1].z < w[0].z;
                assert!(
                    !vertical || p.pts[0] == w[0],
                    "a plunge inside a pass at {}",
                    w[1]
                );
            }
            // a piece is entered by a ramp, never by a plunge to a lone point
            assert!(p.pts.len() > 2, "a one-point piece at {}", p.pts[0]);
        }
        assert!(out.len() <= 2, "{} pieces", out.len());
        assert!(steepest_descent(&out[0]) <= 1.2);
    }
}
