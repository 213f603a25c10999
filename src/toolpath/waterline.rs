//! Waterline finishing: closed contours of the CL surface at Z levels. On a
//! steep wall a raster row crosses the wall in one long move and leaves a
//! wide scallop; a waterline runs along it, so the wall is cut at the Z
//! step instead of the row spacing.
//!
//! The CL surface is dropped on a node grid one sample pitch apart that
//! reaches a tool radius past the panel, where nothing is in reach and the
//! CL surface is the floor: every contour above the floor is closed. The
//! contours are traced by marching squares and each crossing is then found
//! on the exact CL surface by bisection along its grid edge.

use super::path::{snap, GRID};
use crate::cutter::dropcutter::HeightField;
use crate::grid::Grid;
use crate::tool::Tool;
use glam::DVec3;
use rayon::prelude::*;

/// How closely a contour point is placed on its level (mm, on the low side).
/// Two micrometres, not a tenth: the moves between crossings then mostly
/// run clear of the CL surface by more than the drop-cutter's cell bounds
/// (the ball's Jensen gap over a cell, 0.58 um at 2048 px), so `refine`'s
/// probes and `clear`'s exact check prune instead of evaluating every
/// contact cell. 2048 px bunny: the check visits 2.53 million cells (3.26
/// at 1 um) and takes 224k of them past their corners (619k); the stage
/// took 10-24% less time at 1 um than at 0.1 um, and 8-13% less again at
/// 2 um; residual mean 0.0035 mm against 0.0033, max 0.061 mm throughout.
const LEVEL_TOL: f64 = 2e-3;

/// The CL surface on a node grid: node (i, j) at (x0 + i p, y0 + j p).
pub struct ClGrid {
    pub z: Grid<f64>,
    /// Lowest and highest CL value of each row.
    row_range: Vec<(f64, f64)>,
    pub x0: f64,
    pub y0: f64,
    pub p: f64,
    pub floor: f64,
}

impl ClGrid {
    /// Drop `tool` on nodes covering [0,w] x [0,h] plus a tool radius and a
    /// node on every side; nodes with no sample in reach take `floor`.
    pub fn new(hf: &HeightField, tool: &Tool, w: f64, h: f64, floor: f64) -> ClGrid {
        let p = node_pitch(hf, tool);
        let m = (tool.radius() / p).ceil() + 2.0;
        let (x0, y0) = (p / 2.0 - m * p, p / 2.0 - m * p);
        let nx = ((w + 2.0 * m * p) / p).round() as usize;
        let ny = ((h + 2.0 * m * p) / p).round() as usize;
        let rows: Vec<Vec<f64>> = (0..ny)
            .into_par_iter()
            .map(|j| {
                let mut stack = Vec::new();
                let mut hint = None;
                (0..nx)
                    .map(|i| {
                        let (x, y) = (x0 + i as f64 * p, y0 + j as f64 * p);
                        match hf.drop_from(tool, x, y, hint, &mut stack) {
                            Some((z, c)) => {
                                hint = Some(c);
                                z.max(floor)
                            }
                            None => floor,
                        }
                    })
                    .collect()
            })
            .collect();
        let row_range = rows
            .iter()
            .map(|r| {
                r.iter()
                    .fold((f64::MAX, f64::MIN), |(l, h), &z| (l.min(z), h.max(z)))
            })
            .collect();
        ClGrid {
            row_range,
            z: Grid::from_vec(nx, ny, rows.concat()),
            x0,
            y0,
            p,
            floor,
        }
    }

    /// Nodes in the grid.
    pub fn nodes(&self) -> usize {
        self.z.w * self.z.h
    }

    fn at(&self, i: usize, j: usize) -> f64 {
        self.z.data[j * self.z.w + i]
    }

    fn pos(&self, i: usize, j: usize) -> (f64, f64) {
        (self.x0 + i as f64 * self.p, self.y0 + j as f64 * self.p)
    }

    /// Steepness of the CL surface at a node (central differences).
    fn slope(&self, i: usize, j: usize) -> f64 {
        let (w, h) = (self.z.w, self.z.h);
        let d = |a: f64, b: f64, n: usize| (b - a) / (n as f64 * self.p);
        let (il, ir) = (i.saturating_sub(1), (i + 1).min(w - 1));
        let (jl, jr) = (j.saturating_sub(1), (j + 1).min(h - 1));
        let gx = d(self.at(il, j), self.at(ir, j), ir - il);
        let gy = d(self.at(i, jl), self.at(i, jr), jr - jl);
        gx.hypot(gy)
    }

    /// The foot of every node: the CL height of the gentle ground (slope
    /// under GENTLEST) reached from it by always stepping to its lowest
    /// neighbour; a node on gentle ground is its own foot.
    pub fn feet(&self) -> Grid<f64> {
        let (w, h) = (self.z.w, self.z.h);
        let n = w * h;
        // nodes from the lowest up: a node's lowest neighbour is settled
        // before it (ties broken by index, the same order both ways)
        let mut order: Vec<u32> = (0..n as u32).collect();
        order.par_sort_unstable_by(|&a, &b| {
            self.z.data[a as usize]
                .total_cmp(&self.z.data[b as usize])
                .then(a.cmp(&b))
        });
        let gentle: Vec<bool> = (0..n)
            .into_par_iter()
            .map(|k| self.slope(k % w, k / w) < GENTLEST)
            .collect();
        let mut foot = vec![0.0f64; n];
        for &k in &order {
            let k = k as usize;
            let (i, j) = (k % w, k / w);
            let z = self.z.data[k];
            let lowest = [(-1, 0), (1, 0), (0, -1), (0, 1)]
                .into_iter()
                .filter_map(|(di, dj): (isize, isize)| {
                    let (a, b) = (i as isize + di, j as isize + dj);
                    (a >= 0 && b >= 0 && (a as usize) < w && (b as usize) < h)
                        .then(|| b as usize * w + a as usize)
                })
                .filter(|&q| (self.z.data[q], q) < (z, k))
                .min_by(|&a, &b| self.z.data[a].total_cmp(&self.z.data[b]).then(a.cmp(&b)));
            foot[k] = match lowest {
                Some(q) if !gentle[k] => foot[q],
                _ => z,
            };
        }
        Grid::from_vec(w, h, foot)
    }

    /// The node nearest (x, y), within the grid.
    pub fn nearest(&self, x: f64, y: f64) -> (usize, usize) {
        let at = |v: f64, v0: f64, n: usize| {
            ((v - v0) / self.p).round().clamp(0.0, (n - 1) as f64) as usize
        };
        (at(x, self.x0, self.z.w), at(y, self.y0, self.z.h))
    }
}

/// The node spacing: the sample pitch, or a whole multiple of it up to an
/// eighth of the tool's radius. The CL surface of a tool is no finer than
/// the tool (a ball's rounds every step to its radius), the crossings are
/// placed on the exact surface, and `refine` splits wherever a move
/// between them would cut; a 2048 px relief under a 3.175 mm ball takes a
/// sixteenth of the drops.
pub fn node_pitch(hf: &HeightField, tool: &Tool) -> f64 {
    hf.pitch * (tool.radius() / (8.0 * hf.pitch)).floor().max(1.0)
}

/// Where a contour point's exact crossing is still to be found: the grid
/// edge's low and high ends and the CL heights there.
#[derive(Clone, Copy, Debug)]
pub struct Crossing {
    lo: (f64, f64),
    hi: (f64, f64),
    /// The CL heights the grid holds at `lo` and `hi`.
    z: (f64, f64),
}

/// A grid edge: from node (i, j) one step in +x (`vertical` false) or +y.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
struct Edge {
    i: usize,
    j: usize,
    vertical: bool,
}

impl Edge {
    fn nodes(self) -> ((usize, usize), (usize, usize)) {
        let b = if self.vertical {
            (self.i, self.j + 1)
        } else {
            (self.i + 1, self.j)
        };
        ((self.i, self.j), b)
    }
}

/// One contour: points at Z = level, the material (CL above the level) on
/// the left of the direction of travel; `closed` loops end where they
/// start. `slope` is the CL surface's steepness at each point.
#[derive(Clone, Debug)]
pub struct Contour {
    pub pts: Vec<DVec3>,
    pub slope: Vec<f64>,
    pub closed: bool,
    /// Points still at the grid's linear guess (`place` finds them on
    /// the exact surface); empty once placed.
    pub pending: Vec<Option<Crossing>>,
}

/// Beside a raster, waterlines run where the CL surface slopes by at least
/// this much, levels `stepover * GENTLEST` apart, so that they lie at most
/// a stepover apart there. Rows running along a slope or a concave crease
/// leave scallops well over the flat scallop of their stepover (up to 4x
/// on the test models); the waterlines bring them back within 0.01 mm of it.
/// With outlines from the geometry, the creases where surfaces meet stay in
/// the relief: at 0.1 the demo kept 0.0103 mm, at 0.08 0.0073 mm (21% more
/// waterline lines).
pub const GENTLEST: f64 = 0.08;

/// Beside a raster, which levels (every m-th, levels `stepover * GENTLEST`
/// apart) a waterline takes on CL ground of this slope; None where it is
/// gentler than GENTLEST. Passes lie at most 0.8 stepover apart along the
/// surface (m * GENTLEST <= 0.8 sin(angle of the slope)), a margin for the
/// contours' own departures from the grid's slope; m is a power of
/// two, so a contour crossing from one steepness to the next stays whole
/// on every level both keep. A wall takes an eighth of the levels.
pub fn every_nth(slope: f64) -> Option<i64> {
    if slope < GENTLEST {
        return None;
    }
    let sin = slope / (1.0 + slope * slope).sqrt();
    let mut m = 1;
    while (2 * m) as f64 * GENTLEST <= 0.8 * sin {
        m *= 2;
    }
    Some(m)
}

/// The closed contours of the CL surface at `level`, each point on the
/// exact CL surface within LEVEL_TOL below the level.
pub fn contours(g: &ClGrid, level: f64) -> Vec<Contour> {
    let (w, h) = (g.z.w, g.z.h);
    let cells: Vec<Vec<(Edge, Edge)>> = (0..h - 1)
        .into_par_iter()
        .map(|j| row_segments(g, level, j))
        .collect();
    // every crossing edge and the one its segment leads to, in scan order
    // (row, column, horizontal first), found again by binary search
    let id = |e: &Edge| (((e.j * w + e.i) as u64) << 1) | e.vertical as u64;
    let mut next: Vec<(Edge, Edge)> = cells.into_iter().flatten().collect();
    next.sort_unstable_by_key(|(e, _)| id(e));
    let index = |e: &Edge| {
        next.binary_search_by_key(&id(e), |(a, _)| id(a))
            .expect("every crossing edge leads on")
    };
    // each crossing on the exact CL surface, low side
    let points: Vec<(DVec3, f64, Crossing)> = next
        .par_iter()
        .map(|&(e, _)| grid_crossing(g, level, e))
        .collect();
    let mut seen = vec![false; next.len()];
    let mut out = Vec::new();
    for first in 0..next.len() {
        if seen[first] {
            continue;
        }
        let mut pts = Vec::new();
        let mut slope = Vec::new();
        let mut pending = Vec::new();
        let mut k = first;
        loop {
            seen[k] = true;
            let (p, s, c) = points[k];
            pts.push(p);
            slope.push(s);
            pending.push(Some(c));
            k = index(&next[k].1);
            if k == first {
                break;
            }
        }
        pts.push(pts[0]);
        slope.push(slope[0]);
        pending.push(pending[0]);
        out.push(Contour {
            pts,
            slope,
            closed: true,
            pending,
        });
    }
    out
}

/// Row `j`'s contour segments at `level`, from a crossing edge to the next,
/// cell by cell: walking a cell's edges counter-clockwise, a segment runs
/// from an edge that goes above -> below to one that goes below -> above,
/// which keeps the material on its left.
fn row_segments(g: &ClGrid, level: f64, j: usize) -> Vec<(Edge, Edge)> {
    let w = g.z.w;
    let above = |i: usize, j: usize| g.at(i, j) >= level;
    let mut segs = Vec::new();
    // rows wholly below or above the level hold no contour
    let (lo, hi) = (
        g.row_range[j].0.min(g.row_range[j + 1].0),
        g.row_range[j].1.max(g.row_range[j + 1].1),
    );
    if level > hi || level <= lo {
        return segs;
    }
    for i in 0..w - 1 {
        let c = [(i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)];
        let up = c.map(|(a, b)| above(a, b));
        if up.iter().all(|&u| u) || up.iter().all(|&u| !u) {
            continue;
        }
        let edges = [
            Edge {
                i,
                j,
                vertical: false,
            },
            Edge {
                i: i + 1,
                j,
                vertical: true,
            },
            Edge {
                i,
                j: j + 1,
                vertical: false,
            },
            Edge {
                i,
                j,
                vertical: true,
            },
        ];
        // crossing edges in counter-clockwise order, true = down
        let cross: Vec<(Edge, bool)> = (0..4)
            .filter(|&k| up[k] != up[(k + 1) % 4])
            .map(|k| (edges[k], up[k]))
            .collect();
        let centre_up = c.iter().map(|&(a, b)| g.at(a, b)).sum::<f64>() / 4.0 >= level;
        let n = cross.len();
        for k in 0..n {
            if !cross[k].1 {
                continue;
            }
            // saddle: the above corners join through an above centre
            let to = if n == 2 || centre_up {
                (k + 1) % n
            } else {
                (k + n - 1) % n
            };
            segs.push((cross[k].0, cross[to].0));
        }
    }
    segs
}

/// Where the level crosses edge `e`: on the grid's straight line between
/// its nodes (to be placed on the exact CL surface later), the steeper
/// node's slope, and the crossing's low and high sides.
fn grid_crossing(g: &ClGrid, level: f64, e: Edge) -> (DVec3, f64, Crossing) {
    let above = |i: usize, j: usize| g.at(i, j) >= level;
    let ((ai, aj), (bi, bj)) = e.nodes();
    let (pa, pb) = (g.pos(ai, aj), g.pos(bi, bj));
    let (lo, hi) = if above(ai, aj) { (pb, pa) } else { (pa, pb) };
    let slope = g.slope(ai, aj).max(g.slope(bi, bj));
    // where the grid's straight line between the nodes crosses
    let (zl, zh) = if above(ai, aj) {
        (g.at(bi, bj), g.at(ai, aj))
    } else {
        (g.at(ai, aj), g.at(bi, bj))
    };
    let guess = ((level - zl) / (zh - zl)).clamp(0.0, 1.0);
    let at = DVec3::new(
        lo.0 + (hi.0 - lo.0) * guess,
        lo.1 + (hi.1 - lo.1) * guess,
        level,
    );
    let z = (zl, zh);
    (at, slope, Crossing { lo, hi, z })
}

/// The contour with every pending point found on the exact CL surface
/// (`crossing`): done after `parts`, so that stretches left to the raster
/// cost no search.
pub fn place(hf: &HeightField, tool: &Tool, floor: f64, c: &Contour) -> Contour {
    // in runs along the contour, so that one long contour (the outline at
    // a low level) is not left to one thread
    let pts = c
        .pts
        .par_iter()
        .zip(&c.pending)
        .with_min_len(RUN)
        .map_init(Near::default, |near, (p, cr)| match cr {
            Some(cr) => crossing(hf, tool, floor, p.z, (cr.lo, cr.z.0), (cr.hi, cr.z.1), near),
            None => *p,
        })
        .collect();
    Contour {
        pts,
        slope: c.slope.clone(),
        closed: c.closed,
        pending: Vec::new(),
    }
}

/// The point between `lo` (CL below the level) and `hi` (at or above it),
/// given with the CL heights expected there, where the exact CL surface
/// crosses `level`: regula falsi (Illinois) over points on the G-code grid
/// (at a jump of the CL surface 0.1 um sideways matters), aimed a little
/// below the level and always keeping a bracket, so it ends on the low
/// side within LEVEL_TOL in a few drops where the surface is smooth and
/// no worse than bisection where it jumps.
fn crossing(
    hf: &HeightField,
    tool: &Tool,
    floor: f64,
    level: f64,
    (lo, zlo): ((f64, f64), f64),
    (hi, zhi): ((f64, f64), f64),
    near: &mut Near,
) -> DVec3 {
    let mut cl = |x: f64, y: f64| match hf.drop_from(tool, x, y, near.hint, &mut near.stack) {
        Some((z, c)) => {
            near.hint = Some(c);
            z.max(floor)
        }
        None => floor,
    };
    let at = |t: f64| {
        (
            snap(lo.0 + (hi.0 - lo.0) * t),
            snap(lo.1 + (hi.1 - lo.1) * t),
        )
    };
    let len = (hi.0 - lo.0).hypot(hi.1 - lo.1);
    // the bracket [a, b] in t, with the heights over the aim there
    let aim = level - 0.5 * LEVEL_TOL;
    let (mut a, mut fa) = (0.0, zlo.min(level) - aim);
    let (mut b, mut fb) = (1.0, zhi.max(level) - aim);
    let mut best = None;
    let mut kept = 0i8; // which end the last two steps kept (Illinois)
                        // a step that would hug an end gains next to nothing
    let margin = 0.5 * GRID / len;
    for k in 0..64 {
        if (b - a) * len <= GRID {
            break;
        }
        let m = if fa < 0.0 && fb > 0.0 && k % 8 != 7 {
            a + (b - a) * (-fa / (fb - fa))
        } else {
            0.5 * (a + b)
        }
        .clamp(a + margin, b - margin);
        let q = at(m);
        let z = cl(q.0, q.1);
        if z >= level {
            (b, fb) = (m, z - aim);
            if kept == 1 {
                fa *= 0.5;
            }
            kept = 1;
        } else {
            (a, fa) = (m, z - aim);
            best = Some(q);
            if level - z <= LEVEL_TOL {
                break;
            }
            if kept == -1 {
                fb *= 0.5;
            }
            kept = -1;
        }
    }
    let best = best.unwrap_or_else(|| {
        // no probe fell below the level: the low node itself, or, where
        // snapping puts it on the material side, a step back from it
        let q = at(0.0);
        if cl(q.0, q.1) < level {
            q
        } else {
            (
                snap(lo.0 - (hi.0 - lo.0) * 1e-3),
                snap(lo.1 - (hi.1 - lo.1) * 1e-3),
            )
        }
    });
    DVec3::new(best.0, best.1, level)
}

/// The drop-cutter's work space carried from one crossing to the next
/// along a contour: the last contact is usually next to the new one.
#[derive(Default)]
pub struct Near {
    hint: Option<(usize, usize)>,
    stack: crate::cutter::dropcutter::Stack,
}

/// Where the straight move between neighbouring contour points cuts the
/// material (a convex corner of the CL surface between grid edges), put
/// the crossing found out from its highest point, on its free side (the
/// right), between them, until every move cuts less than REFINE_DIP or
/// is shorter than a micrometre. Keeps `clear`'s lifts, and so a
/// waterline's departures from its level, in the micrometres.
pub fn refine(hf: &HeightField, tool: &Tool, floor: f64, c: &Contour) -> Contour {
    let level = c.pts[0].z;
    let cl = |x: f64, y: f64| hf.drop(tool, x, y).unwrap_or(floor).max(floor);
    // each move on its own, in runs (as `place`)
    let split: Vec<(Vec<DVec3>, Vec<f64>)> = (1..c.pts.len())
        .into_par_iter()
        .with_min_len(RUN)
        .map(|k| refine_move(hf, tool, floor, level, &cl, c, k))
        .collect();
    let mut pts = vec![c.pts[0]];
    let mut slope = vec![c.slope[0]];
    for (p, s) in split {
        pts.extend(p);
        slope.extend(s);
    }
    Contour {
        pts,
        slope,
        closed: c.closed,
        pending: Vec::new(),
    }
}

/// Contour points a thread takes at once in `place` and `refine`.
const RUN: usize = 64;

/// `refine` on the move into point k: the points it ends up as, in order
/// (the last is point k), with their slopes.
fn refine_move(
    hf: &HeightField,
    tool: &Tool,
    floor: f64,
    level: f64,
    cl: &(dyn Fn(f64, f64) -> f64 + Sync),
    c: &Contour,
    k: usize,
) -> (Vec<DVec3>, Vec<f64>) {
    let (mut pts, mut slope) = (Vec::new(), Vec::new());
    let mut todo = vec![(c.pts[k - 1], c.pts[k], 0)];
    while let Some((a, b, depth)) = todo.pop() {
        let d = (b - a).truncate();
        let len = d.length();
        // the drop-cutter's probes alone decide a split (the exact
        // sweep over the samples is `clear`'s, once thinned): the
        // highest CL point along the chord, if it rises past the dip
        let peak = if depth < 12 && len > 1e-3 {
            peak(hf, tool, cl, a, b)
        } else {
            None
        };
        if let Some((top, at)) = peak {
            let right = glam::DVec2::new(d.y, -d.x) / len;
            let out = [1.0, 0.5, 0.25, 0.125]
                .map(|f| at.truncate() + right * len * f)
                .into_iter()
                .map(|o| (o, cl(o.x, o.y)))
                .find(|o| o.1 < level);
            if let Some((out, zo)) = out {
                let q = crossing(
                    hf,
                    tool,
                    floor,
                    level,
                    ((out.x, out.y), zo),
                    ((at.x, at.y), top),
                    &mut Near::default(),
                );
                todo.push((q, b, depth + 1));
                todo.push((a, q, depth + 1));
                continue;
            }
        }
        pts.push(b);
        slope.push(c.slope[k]);
    }
    (pts, slope)
}

/// The highest point of the CL surface along the move a -> b between two
/// neighbouring contour points, if it rises more than REFINE_DIP above
/// the move. A ball's or tapered tip's CL surface is smooth and the move
/// short (a node pitch): its rise peaks near the middle, and three probes
/// find it (`clear` checks the thinned moves exactly). A flat or V tool's
/// CL surface has creases: whether it rises (exactly for a flat,
/// `rise_along`; a V at every probe `probe_gouge` makes), then the
/// highest of a dense scan.
fn peak(
    hf: &HeightField,
    tool: &Tool,
    cl: &dyn Fn(f64, f64) -> f64,
    a: DVec3,
    b: DVec3,
) -> Option<(f64, DVec3)> {
    use super::path::probe_gouge;
    use crate::cutter::along::Bottom;
    if tool.tip_radius().is_some() {
        let mut stack = Vec::new();
        let mut hint = None;
        let mut top: Option<(f64, DVec3)> = None;
        for f in [0.5, 0.25, 0.75] {
            let q = a + (b - a) * f;
            // a rise that is concave along the move and nothing at its
            // ends is at the quarters at most 1.5 times what it is in the
            // middle: where the middle rises less than REFINE_DIP / 1.5,
            // neither quarter needs a probe
            let floor = if f == 0.5 {
                REFINE_DIP / 1.5
            } else {
                REFINE_DIP
            };
            match hf.drop_above(tool, q.x, q.y, q.z + floor, hint, &mut stack) {
                Some((z, c)) => {
                    hint = Some(c);
                    if z > q.z + REFINE_DIP && top.is_none_or(|t| z > t.0) {
                        top = Some((z, q));
                    }
                }
                None if f == 0.5 => return None,
                None => {}
            }
        }
        return top;
    }
    let rises = match Bottom::of(tool) {
        Some(bottom) => hf.rise_along(bottom, a, b, REFINE_DIP).is_some(),
        None => probe_gouge(hf, tool, a, b, REFINE_DIP) > REFINE_DIP,
    };
    if !rises {
        return None;
    }
    let n = ((b - a).truncate().length() / (hf.pitch / 4.0))
        .ceil()
        .max(2.0) as usize;
    let (mut top, mut at) = (f64::MIN, a);
    for i in 1..n {
        let q = a + (b - a) * (i as f64 / n as f64);
        let z = cl(q.x, q.y);
        if z > top {
            (top, at) = (z, q);
        }
    }
    (top > a.z.max(b.z)).then_some((top, at))
}

/// How deep a move between contour points may cut before it is split.
const REFINE_DIP: f64 = 5e-4;

/// Z levels for waterlines `dz` apart, from the floor up to the top of the
/// CL surface (the floor itself is left to the raster).
pub fn levels(g: &ClGrid, dz: f64) -> Vec<f64> {
    let top = g.z.data.iter().cloned().fold(g.floor, f64::max);
    let n = ((top - g.floor) / dz).floor() as usize;
    (1..=n)
        .rev()
        .map(|k| g.floor + k as f64 * dz)
        .filter(|&l| l < top)
        .collect()
}

/// Keep the stretches of a contour where `keep(point, slope)` holds: on
/// the panel, and for raster+waterline on steep ground only (the raster
/// finishes gentle slopes). A loop kept whole stays closed; a stretch
/// reaches one point past each end.
pub fn parts(c: &Contour, keep: impl Fn(DVec3, f64) -> bool) -> Vec<Contour> {
    let steep = |k: usize| keep(c.pts[k], c.slope[k]);
    let n = c.pts.len() - 1; // closed: last = first
    let Some(start) = (0..n).find(|&k| !steep(k)) else {
        return vec![c.clone()];
    };
    let mut out = Vec::new();
    let mut run: Vec<usize> = Vec::new();
    for s in 1..=n {
        let k = (start + s) % n;
        if steep(k) {
            run.push(k);
        } else if !run.is_empty() {
            let mut idx = vec![(run[0] + n - 1) % n];
            idx.append(&mut run);
            idx.push(k);
            if idx.len() >= 3 {
                out.push(Contour {
                    pts: idx.iter().map(|&i| c.pts[i]).collect(),
                    slope: idx.iter().map(|&i| c.slope[i]).collect(),
                    closed: false,
                    pending: idx
                        .iter()
                        .map(|&i| c.pending.get(i).copied().flatten())
                        .collect(),
                });
            }
        }
    }
    out
}

/// Thin a contour where points are collinear within `tol`. A chord may
/// cut into the material side (the right of a point, as on a convex
/// island) only as far as keeps the CL rise there, penetration times
/// slope, under `tol / 2`; `clear` then lifts what is left.
pub fn simplify(c: &Contour, tol: f64) -> Vec<DVec3> {
    simplify_points(&c.pts, &c.slope, tol)
}

/// `simplify` over points and their CL slopes.
pub fn simplify_points(pts: &[DVec3], slope: &[f64], tol: f64) -> Vec<DVec3> {
    if pts.len() < 3 {
        return pts.to_vec();
    }
    let fits = |a: usize, e: usize| chord_fits(pts, slope, a, e, tol);
    let mut out = vec![pts[0]];
    let mut start = 0;
    let mut k = 2;
    while k < pts.len() {
        if !fits(start, k) {
            out.push(pts[k - 1]);
            start = k - 1;
        }
        k += 1;
    }
    out.push(*pts.last().unwrap());
    out
}

/// Whether the straight move from point a to point e keeps within the
/// band of every point between (`simplify`'s): at most `tol` off it on
/// its free side (the right), and on its material side only as far as
/// keeps the CL rise there, penetration times slope, under tol / 2.
pub fn chord_fits(pts: &[DVec3], slope: &[f64], a: usize, e: usize, tol: f64) -> bool {
    let d = (pts[e] - pts[a]).truncate();
    let len = d.length();
    if len == 0.0 {
        return false;
    }
    (a + 1..e).all(|k| {
        let v = (pts[k] - pts[a]).truncate();
        let side = d.perp_dot(v) / len; // > 0: left of the chord
        let t = v.dot(d) / (len * len);
        side <= tol && side >= -material_allowance(slope[k], tol) && (0.0..=1.0).contains(&t)
    })
}

/// How far a move may pass a contour point on its material side: as far
/// as keeps the CL rise there, penetration times slope, under tol / 2,
/// and never more than `tol`.
pub fn material_allowance(slope: f64, tol: f64) -> f64 {
    if slope > 0.5 {
        tol / (2.0 * slope)
    } else {
        tol
    }
}

/// Lift the ends of every move that would cut a sample by what it would
/// cut (exact swept tool): a waterline stays one smooth pass, a little
/// above its level where a chord crossed the material side. The chords
/// of one GRBL arc (`arcs`) are lifted together by the most any of them
/// or the moves beside it need, so that they stay one arc at one height.
pub fn clear(hf: &HeightField, tool: &Tool, pts: &[DVec3], arcs: bool) -> Vec<DVec3> {
    use super::path::{move_gouge, snap_up};
    if pts.len() < 2 {
        return pts.to_vec();
    }
    let mut g: Vec<f64> = pts
        .par_windows(2)
        .map(|w| move_gouge(hf, tool, w[0], w[1], true).max(0.0))
        .collect();
    let n = g.len();
    // a closed loop's ends are one point: it takes both neighbours' lift
    let closed = n > 1 && pts[0] == pts[n];
    if arcs {
        // an arc's chords (moves i..j) share the lift of its ends too, which
        // the moves beside it set; neighbouring arcs settle in a few rounds
        let runs = crate::dialect::chords::arc_runs(pts);
        for _ in 0..4 {
            let mut moved = false;
            for &(i, j) in &runs {
                let before = if i > 0 {
                    Some(g[i - 1])
                } else {
                    closed.then(|| g[n - 1])
                };
                let after = if j < n {
                    Some(g[j])
                } else {
                    closed.then(|| g[0])
                };
                let most = g[i..j]
                    .iter()
                    .chain(before.iter())
                    .chain(after.iter())
                    .cloned()
                    .fold(0.0, f64::max);
                if g[i..j].iter().any(|v| *v != most) {
                    g[i..j].iter_mut().for_each(|v| *v = most);
                    moved = true;
                }
            }
            if !moved {
                break;
            }
        }
    }
    let wrap = if closed { g[0].max(g[n - 1]) } else { 0.0 };
    pts.iter()
        .enumerate()
        .map(|(k, p)| {
            let lift = match k {
                _ if closed && (k == 0 || k == n) => wrap,
                0 => g[0],
                _ if k == n => g[n - 1],
                _ => g[k - 1].max(g[k]),
            };
            if lift > 0.0 {
                DVec3::new(p.x, p.y, snap_up(p.z + lift))
            } else {
                *p
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A block standing on a floor that slopes gently: the feet of the
    /// block's sides are the floor's CL height beside them (not the panel's
    /// lowest point, nor the block's top), and the floor is its own foot.
    #[test]
    fn the_foot_of_a_wall_is_the_ground_beside_it() {
        let (n, p) = (80, 0.25);
        let floor = |x: f64| -3.0 + 0.02 * x;
        let z = Grid::from_vec(
            n,
            n,
            (0..n * n)
                .map(|k| {
                    let (x, y) = ((k % n) as f64 * p, (k / n) as f64 * p);
                    let block = (8.0..12.0).contains(&x) && (5.0..15.0).contains(&y);
                    if block {
                        -1.0
                    } else {
                        floor(x)
                    }
                })
                .collect(),
        );
        let hf = HeightField::new(z, p);
        let tool = Tool::parse("ball:2").unwrap();
        let g = ClGrid::new(&hf, &tool, 20.0, 20.0, -3.0);
        let feet = g.feet();
        let foot = |x: f64, y: f64| {
            let (i, j) = g.nearest(x, y);
            *feet.get(i, j)
        };
        // on the floor, well away from the block: its own height
        let cl = |x: f64, y: f64| hf.drop(&tool, x, y).unwrap();
        for (x, y) in [(3.0, 3.0), (17.0, 17.0)] {
            assert!((foot(x, y) - cl(x, y)).abs() < 0.01);
        }
        // on the block's sides (the ball riding up them): the floor beside
        for (x, y, beside) in [(7.6, 10.0, 6.0), (12.4, 10.0, 14.0)] {
            let (h, f) = (cl(x, y), foot(x, y));
            assert!(h > floor(x) + 0.5, "({x}, {y}) is on the wall: {h}");
            assert!(
                (f - cl(beside, 10.0)).abs() < 0.05,
                "foot at ({x}, {y}) {f} against the floor beside {}",
                cl(beside, 10.0)
            );
        }
    }

    /// A dome and a steep-sided block on a floor, with a ball and a V tool:
    /// every contour closes and every point is on the CL surface at its
    /// level (acceptance: within 0.01 mm). On sampled data the CL surface
    /// has vertical faces (a sample meeting the ball's equator), so the
    /// distance is the lesser of the height below the level and the
    /// horizontal distance to where the CL reaches the level.
    #[test]
    fn contours_are_closed_and_on_the_cl_surface() {
        let (n, p) = (80, 0.25);
        let z = Grid::from_vec(
            n,
            n,
            (0..n * n)
                .map(|k| {
                    let (x, y) = ((k % n) as f64 * p, (k / n) as f64 * p);
                    let dome = 25.0 - (x - 7.0).powi(2) - (y - 10.0).powi(2);
                    let block = if (13.0..17.0).contains(&x) && (4.0..15.0).contains(&y) {
                        -1.0
                    } else {
                        -3.0
                    };
                    (dome.max(0.0).sqrt() * 0.5 - 3.0).max(block)
                })
                .collect(),
        );
        let hf = HeightField::new(z, p);
        for spec in ["ball:2", "vbit:90:3"] {
            let tool = Tool::parse(spec).unwrap();
            let g = ClGrid::new(&hf, &tool, 20.0, 20.0, -3.0);
            let lv = levels(&g, 0.3);
            assert!(lv.len() >= 5, "{spec}: {} levels", lv.len());
            let mut worst = 0.0f64;
            let mut count = 0;
            for &l in &lv {
                for c in contours(&g, l) {
                    let c = place(&hf, &tool, -3.0, &c);
                    assert!(c.closed && c.pts.len() > 3);
                    assert_eq!(c.pts.first(), c.pts.last());
                    for q in &c.pts {
                        let cl = |x: f64, y: f64| hf.drop(&tool, x, y).unwrap_or(-3.0).max(-3.0);
                        let below = l - cl(q.x, q.y);
                        assert!(q.z == l && below >= 0.0, "{spec}: above the level");
                        let near = (0..64).any(|k| {
                            let t = k as f64 / 64.0 * std::f64::consts::TAU;
                            cl(q.x + 1e-3 * t.cos(), q.y + 1e-3 * t.sin()) >= l
                        });
                        worst = worst.max(if near { below.min(LEVEL_TOL) } else { below });
                        count += 1;
                    }
                }
            }
            assert!(count > 100, "{spec}: {count} points");
            assert!(worst <= LEVEL_TOL, "{spec}: off by {worst}");
        }
    }

    /// Material on the left: an island's contour runs counter-clockwise.
    #[test]
    fn island_contours_run_counter_clockwise() {
        let n = 40;
        let z = Grid::from_vec(
            n,
            n,
            (0..n * n)
                .map(|k| {
                    let (x, y) = ((k % n) as f64 - 20.0, (k / n) as f64 - 20.0);
                    if x * x + y * y < 64.0 {
                        0.0
                    } else {
                        -2.0
                    }
                })
                .collect(),
        );
        let hf = HeightField::new(z, 1.0);
        let tool = Tool::parse("ball:2").unwrap();
        let g = ClGrid::new(&hf, &tool, 40.0, 40.0, -2.0);
        let cs = contours(&g, -1.0);
        assert_eq!(cs.len(), 1);
        let a: f64 = cs[0]
            .pts
            .windows(2)
            .map(|w| w[0].x * w[1].y - w[1].x * w[0].y)
            .sum();
        assert!(a > 0.0, "signed area {a}");
    }

    /// An arc's chords are lifted as one, by the deepest cut of its own
    /// chords and of the moves beside it, so it stays one arc.
    #[test]
    fn clear_lifts_an_arc_as_one() {
        use crate::dialect::arc::{Arc, Plane, GRBL_ARC_TOLERANCE};
        use crate::dialect::chords::arc_run;
        let hf = HeightField::new(Grid::new(60, 60, 0.0), 0.25);
        let tool = Tool::parse("ball:2").unwrap();
        let arc = Arc {
            plane: Plane::Xy,
            clockwise: false,
            centre: (7.5, 7.5),
            radius: 4.0,
        };
        let (from, to) = (DVec3::new(11.5, 7.5, -0.001), DVec3::new(7.5, 11.5, -0.001));
        // a move cutting 3 um into the arc's start, the arc 1 um deep
        let mut pts = vec![DVec3::new(11.5, 3.5, -0.003), from];
        pts.extend(arc.points(from, to, GRBL_ARC_TOLERANCE));
        assert!(arc_run(&pts, 1, GRBL_ARC_TOLERANCE).is_some_and(|r| r.0 == pts.len() - 1));
        let lifted = clear(&hf, &tool, &pts, true);
        assert!(lifted[1..]
            .iter()
            .all(|p| p.z >= 0.0019 && p.z == lifted[1].z));
        let run = arc_run(&lifted, 1, GRBL_ARC_TOLERANCE);
        assert!(
            run.is_some_and(|r| r.0 == pts.len() - 1),
            "the arc is broken"
        );
        // without arcs each point takes its own moves' lift
        let each = clear(&hf, &tool, &pts, false);
        assert!(each[2].z < each[1].z);
    }

    /// Around a pocket (material outside) chords may stray away from the
    /// material by the tolerance; around an island on a wall of slope 2
    /// they may cut into it by a quarter of it.
    #[test]
    fn simplify_keeps_chords_off_the_material() {
        let circle = |ccw: bool| Contour {
            pts: (0..=400)
                .map(|k| {
                    let t = k as f64 / 400.0 * std::f64::consts::TAU;
                    let t = if ccw { t } else { -t };
                    DVec3::new(5.0 * t.cos(), 5.0 * t.sin(), 0.0)
                })
                .collect(),
            slope: vec![2.0; 401],
            closed: true,
            pending: Vec::new(),
        };
        // (plus the sagitta of the 400-gon itself, 1.5e-4, for the island)
        for (ccw, lim) in [(true, 0.005 / 4.0 + 1.6e-4), (false, 0.005)] {
            let s = simplify(&circle(ccw), 0.005);
            assert!(s.len() * 2 < 401, "{}", s.len());
            for w in s.windows(2) {
                let m = (w[0] + w[1]) / 2.0;
                // island: chords inside by at most lim; pocket: never outside
                let r = m.truncate().length();
                assert!(r >= 5.0 - lim - 1e-9 && r <= 5.0 + 1e-9, "{ccw}: {r}");
            }
        }
    }
}
