//! Stage 5: material-removal simulation of any G-code of the dialect,
//! judged against a relief (DESIGN.md section 7).
//!
//! The stock is a heightfield (top Z per cell). Every straight move sweeps
//! the tool exactly: for each cell within the tool's radius of the move,
//! the lowest point of the swept tool surface above that cell is found in
//! closed form (ball: capsule of the ball centre's path; flat: the disc's
//! interval on the move; V-bit: the stationary point of a convex function;
//! tapered ball: the tip sphere's capsule and the cone's stationary point
//! where the cell is beyond the tip sphere). Min is order-free, so the stock is cut in parallel row bands,
//! each band taking its moves in job order (which keeps the test of rapids
//! against the stock as it was at that moment exact).

use crate::cutter::dropcutter::HeightField;
use crate::cutter::sweep::{cells_between, Sweep};
use crate::gcode::{planner, Kind, Program, Segment};
use crate::grid::Grid;
use crate::machine::Machine;
use crate::relief::Relief;
use crate::tool::Tool;
use glam::DVec3;
use rayon::prelude::*;

pub mod cells;
pub mod engage;
pub mod map;

/// Stretches of a program cut by one tool: (first segment, end, tool).
pub type ToolRuns = Vec<(usize, usize, Tool)>;
/// Per band of rows: rapids into stock, and what each move removed.
type BandCut = (Vec<usize>, Vec<(u32, MoveCut)>);
pub use engage::{Engagement, MoveCut, Over, ToolEngagement};

/// The block of material and its sampling.
#[derive(Clone, Copy, Debug)]
pub struct Stock {
    /// Lower-left corner (mm) and size.
    pub x0: f64,
    pub y0: f64,
    pub width: f64,
    pub height: f64,
    /// Top at Z = 0, bottom at Z = -thickness.
    pub thickness: f64,
    /// Cell size (mm).
    pub pitch: f64,
}

impl Stock {
    pub fn cells(&self) -> (usize, usize) {
        (
            (self.width / self.pitch).round().max(1.0) as usize,
            (self.height / self.pitch).round().max(1.0) as usize,
        )
    }
    /// The stock moved out (or in) by less than a cell on each side so
    /// that its cells are centred on the samples of a relief whose left
    /// edge is at `x` and top edge at `top`: the cut is then compared with
    /// the relief's own samples, not with values interpolated between
    /// them. An edge within a quarter cell of the grid snaps to it (sizes
    /// in a job's header are rounded).
    pub fn aligned_to(self, x: f64, top: f64) -> Stock {
        let p = self.pitch;
        let out = |d: f64| (d / p - 0.25).ceil() * p;
        let x0 = x - out(x - self.x0);
        let x1 = x + out(self.x0 + self.width - x);
        let y1 = top + out(self.y0 + self.height - top);
        let y0 = top - out(top - self.y0);
        Stock {
            x0,
            y0,
            width: x1 - x0,
            height: y1 - y0,
            ..self
        }
    }

    /// Centre of cell (i, j); row 0 is the top edge (largest Y).
    pub fn centre(&self, i: usize, j: usize) -> (f64, f64) {
        (
            self.x0 + (i as f64 + 0.5) * self.pitch,
            self.y0 + self.height - (j as f64 + 0.5) * self.pitch,
        )
    }
}

/// What the simulation found (DESIGN.md section 7 keys).
#[derive(Clone, Debug, serde::Serialize)]
pub struct Report {
    pub max_gouge_mm: f64,
    /// Where the deepest gouge is (job X, Y), if the cells found it...
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_gouge_at_mm: Option<(f64, f64)>,
    /// ...or the line of the move that cuts it, if the exact measure
    /// along the moves (`move_gouge`) found it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_gouge_line: Option<usize>,
    /// Whether every move's gouge was measured exactly along it (ball
    /// and flat end mills); if not, a V or tapered ball's is measured at
    /// the cells.
    pub gouge_exact_per_move: bool,
    pub max_residual_mm: f64,
    pub mean_residual_mm: f64,
    pub removed_mm3: f64,
    pub rapids_in_stock: Vec<usize>,
    pub out_of_travel: Vec<usize>,
    pub time_s: f64,
    /// The estimate by tool, in job order (a tool's runs between changes
    /// to other tools apart).
    pub time_by_tool: Vec<(String, f64)>,
    pub lines: usize,
    /// Per tool: largest axial depth of cut, radial engagement and
    /// slotting depth, with their lines; plunges into material.
    pub engagement: Engagement,
    /// The stock and relief placement read from the job's header.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frame: Option<String>,
    /// Gouge (besides the exact measure) and residual are measured at
    /// the centres of stock cells this far apart, against the relief's
    /// continuous surface...
    pub cell_mm: f64,
    /// ...and a cut's bottom can reach at most this much deeper between
    /// them (the tools' profile half a cell diagonal from the tip; a
    /// flat's rim can cut deeper, which the exact measure sees).
    pub between_cells_mm: f64,
}

impl Report {
    pub fn summary(&self) -> String {
        let list = |v: &[usize]| {
            if v.is_empty() {
                "none".to_string()
            } else {
                let shown: Vec<String> = v.iter().take(10).map(|n| n.to_string()).collect();
                format!(
                    "{} (lines {}{})",
                    v.len(),
                    shown.join(", "),
                    if v.len() > 10 { ", ..." } else { "" }
                )
            }
        };
        let measured = if self.gouge_exact_per_move {
            format!(
                "gouge exact along every move, residual at cell centres {:.4} mm apart, \
                 against the relief's surface",
                self.cell_mm
            )
        } else {
            format!(
                "against the relief's surface at cell centres {:.4} mm apart (ball and flat \
                 moves also exactly along them); a cut's bottom between them is at most \
                 {:.4} mm deeper",
                self.cell_mm, self.between_cells_mm
            )
        };
        let at = match (self.max_gouge_line, self.max_gouge_at_mm) {
            _ if self.max_gouge_mm < 5e-4 => String::new(),
            (Some(n), _) => format!(" on line {n}"),
            (None, Some((x, y))) => format!(" at X{x:.2} Y{y:.2}"),
            _ => String::new(),
        };
        format!(
            "max gouge {:.4} mm{at}, residual max {:.4} / mean {:.4} mm, removed {:.1} mm3\n\
             ({measured})\n\
             rapids in stock: {}\nout of travel: {}\nestimated time {} ({} lines)",
            self.max_gouge_mm,
            self.max_residual_mm,
            self.mean_residual_mm,
            self.removed_mm3,
            list(&self.rapids_in_stock),
            list(&self.out_of_travel),
            hms(self.time_s),
            self.lines
        ) + &if self.time_by_tool.len() > 1 {
            format!(": {}", shares_text(&self.time_by_tool))
        } else {
            String::new()
        } + "\n"
            + &self.engagement.summary()
    }
}

/// 1h 02m 03s style.
pub fn hms(s: f64) -> String {
    let t = s.round() as u64;
    if t >= 3600 {
        format!("{}h {:02}m {:02}s", t / 3600, t / 60 % 60, t % 60)
    } else {
        format!("{}m {:02}s", t / 60, t % 60)
    }
}

/// A time split: "roughing flat:3.175 1h 02m 10s, finishing ball:3.175
/// 58m 03s".
pub fn shares_text(shares: &[(String, f64)]) -> String {
    shares
        .iter()
        .map(|(name, s)| format!("{name} {}", hms(*s)))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Rows per parallel band.
const BAND: usize = 16;
/// A rapid "touches" stock when it would cut deeper than this (mm).
const TOUCH: f64 = 1e-4;

/// Cell index range [i0, i1] of the row whose centres lie in [xl, xh].
#[inline]
fn cells_in(stock: &Stock, w: usize, span: Option<(f64, f64)>) -> Option<(usize, usize)> {
    let (xl, xh) = span?;
    cells_between(xl - stock.x0, xh - stock.x0, stock.pitch, w)
}

/// Ball end on a feed move, the hot path: the end sphere (and the start
/// sphere unless the previous move ended there and so already cut it) in a
/// branch-free f32 loop, the capsule's side only on the band where its
/// lowest points can lie.
#[allow(clippy::too_many_arguments)]
fn ball_rows<const STATS: bool>(
    stock: &Stock,
    rows: &mut [f32],
    ja: usize,
    w: usize,
    sw: &Sweep,
    continues: bool,
    floor: f32,
    mc: &mut MoveCut,
) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
        // SAFETY: the CPU has the features this copy is compiled for.
        unsafe { ball_rows_avx2::<STATS>(stock, rows, ja, w, sw, continues, floor, mc) };
        return;
    }
    ball_rows_body::<STATS>(stock, rows, ja, w, sw, continues, floor, mc)
}

/// The same loops compiled for 8-lane AVX2 vectors. (Its signature is
/// `ball_rows`' and `ball_rows_body`'s again, deliberately: one dispatches,
/// one is compiled for AVX2, one holds the loops.)
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[allow(clippy::too_many_arguments)]
unsafe fn ball_rows_avx2<const STATS: bool>(
    stock: &Stock,
    rows: &mut [f32],
    ja: usize,
    w: usize,
    sw: &Sweep,
    continues: bool,
    floor: f32,
    mc: &mut MoveCut,
) {
    ball_rows_body::<STATS>(stock, rows, ja, w, sw, continues, floor, mc)
}

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn ball_rows_body<const STATS: bool>(
    stock: &Stock,
    rows: &mut [f32],
    ja: usize,
    w: usize,
    sw: &Sweep,
    continues: bool,
    floor: f32,
    mc: &mut MoveCut,
) {
    let (nx, ny) = engage::across(sw);
    let (nxf, nyf) = (nx as f32, ny as f32);
    let core2 = engage::core_radius2(sw.r) as f32;
    let p = stock.pitch;
    let len = sw.d.length();
    let uz = if len > 0.0 { sw.d.z / len } else { 0.0 };
    // the side's lowest points lie behind the band of the move by at most
    // r |u_z| at its higher end (behind the start going down, past the end
    // going up)
    let ext = sw.r * uz.abs();
    let (before, after) = if uz < 0.0 { (ext, 0.0) } else { (0.0, ext) };
    let aa = (1.0 - uz * uz) as f32;
    // a vertical move has no side: its lowest points are on the end spheres
    let side = len > 0.0 && aa > 1e-6;
    let (ux, uy, uzf) = if len > 0.0 {
        ((sw.d.x / len) as f32, (sw.d.y / len) as f32, uz as f32)
    } else {
        (0.0, 0.0, 0.0)
    };
    let inv_aa = if side { 1.0 / aa } else { 0.0 };
    let inv_len = if len > 0.0 { (1.0 / len) as f32 } else { 0.0 };
    let base = (sw.a.z + sw.r) as f32;
    let r2 = (sw.r * sw.r) as f32;
    let rf = sw.r as f32;
    let shave2 = (engage::SIDE_SHAVE * rf).powi(2);
    for (jj, row) in rows.chunks_mut(w).enumerate() {
        let (_, y) = stock.centre(0, ja + jj);
        for t in [1.0, 0.0] {
            if t == 0.0 && continues {
                continue;
            }
            let Some((i0, i1)) = cells_in(stock, w, sw.disc_span(y, t, sw.r)) else {
                continue;
            };
            let (cx, cy) = (sw.a.x + t * sw.d.x, sw.a.y + t * sw.d.y);
            let top = (sw.a.z + t * sw.d.z + sw.r) as f32;
            let dy2 = ((y - cy) * (y - cy)) as f32;
            let x0 = (stock.x0 + (i0 as f64 + 0.5) * p - cx) as f32;
            let pf = p as f32;
            let oc = ((cx - sw.a.x) * nx + (y - sw.a.y) * ny) as f32;
            for (k, cell) in row[i0..=i1].iter_mut().enumerate() {
                let dx = x0 + (k as i32) as f32 * pf;
                let q = dx * dx + dy2;
                let s = r2 - q;
                let z = if s >= 0.0 {
                    top - s.sqrt()
                } else {
                    f32::INFINITY
                };
                // plain compares (not f32::min) so this loop vectorizes
                let old = *cell;
                let v = if z < old { z } else { old };
                let new = if v > floor { v } else { floor };
                *cell = new;
                if STATS {
                    // (the disc's rim: its front plows a wall as thinly)
                    mc.add(old - new, dx * nxf + oc, t == 1.0 && q <= core2, q > shave2);
                }
            }
        }
        if !side {
            continue;
        }
        if let Some((i0, i1)) = cells_in(stock, w, sw.strip_span(y, before, after, sw.r)) {
            // the cylinder formula of `Sweep::cylinder`, in f32 relative to
            // the move's start and branch-free so that it vectorizes
            let wy = (y - sw.a.y) as f32;
            let x0 = (stock.x0 + (i0 as f64 + 0.5) * p - sw.a.x) as f32;
            let pf = p as f32;
            for (k, cell) in row[i0..=i1].iter_mut().enumerate() {
                let wx = x0 + (k as i32) as f32 * pf;
                let wu = wx * ux + wy * uy;
                let bb = -uzf * wu;
                let cc = wx * wx + wy * wy - wu * wu - r2;
                let disc = bb * bb - aa * cc;
                let root = if disc > 0.0 { disc } else { 0.0 }.sqrt();
                let zp = (-bb - root) * inv_aa;
                let t = (wu + zp * uzf) * inv_len;
                let ok = disc >= 0.0 && (0.0..=1.0).contains(&t);
                let z = if ok { base + zp } else { f32::INFINITY };
                let old = *cell;
                let v = if z < old { z } else { old };
                let new = if v > floor { v } else { floor };
                *cell = new;
                if STATS {
                    let across = wx * nxf + wy * nyf;
                    mc.add(old - new, across, false, engage::shaved(across, rf));
                }
            }
        }
    }
}

/// Cut `stock` by every move of `prog`, each stretch with the tool its
/// `(tool: SPEC)` comment names (a tool change starts a stretch), or with
/// `tool` throughout. Returns the lines of rapids into stock and the last
/// tool.
pub fn cut_program(
    stock: &Stock,
    heights: &mut Grid<f32>,
    prog: &Program,
    tool: Option<Tool>,
) -> crate::Result<(Vec<usize>, Tool)> {
    let runs = tool_runs(prog, tool)?;
    let mut hits = Vec::new();
    for (from, to, tool) in &runs {
        hits.extend(cut(stock, heights, &prog.segments[*from..*to], *tool));
    }
    Ok((hits, runs[runs.len() - 1].2))
}

/// As `cut_program`, also measuring what every move removed (one entry
/// per segment of `prog`), with the tool of each stretch.
pub fn cut_program_measured(
    stock: &Stock,
    heights: &mut Grid<f32>,
    prog: &Program,
    tool: Option<Tool>,
) -> crate::Result<(Vec<usize>, Vec<MoveCut>, ToolRuns)> {
    let runs = tool_runs(prog, tool)?;
    let mut hits = Vec::new();
    let mut moves = Vec::with_capacity(prog.segments.len());
    for (from, to, tool) in &runs {
        let (h, m) = cut_impl::<true>(stock, heights, &prog.segments[*from..*to], *tool);
        hits.extend(h);
        moves.extend(m);
    }
    Ok((hits, moves, runs))
}

/// The stretches of `prog` cut by one tool: (first segment, end, tool).
pub fn tool_runs(prog: &Program, tool: Option<Tool>) -> crate::Result<ToolRuns> {
    let mut runs: Vec<(usize, Tool)> = match tool {
        Some(t) => vec![(0, t)],
        None => prog
            .tools
            .iter()
            .map(|(k, s)| Tool::parse(s).map(|t| (*k, t)))
            .collect::<crate::Result<_>>()?,
    };
    if runs.is_empty() {
        crate::bail!("no tool given: use --tool or a (tool: SPEC) comment in the job");
    }
    runs[0].0 = 0;
    let n = prog.segments.len();
    Ok((0..runs.len())
        .map(|k| {
            let to = runs.get(k + 1).map_or(n, |t| t.0);
            (runs[k].0.min(to), to, runs[k].1)
        })
        .collect())
}

/// Cut `stock` (top heights, row 0 = top) by the moves `segs` with
/// `tool`. Returns the job lines of rapids that cut into stock.
pub fn cut(stock: &Stock, heights: &mut Grid<f32>, segs: &[Segment], tool: Tool) -> Vec<usize> {
    cut_impl::<false>(stock, heights, segs, tool).0
}

/// The cut, and with STATS what each move removed.
fn cut_impl<const STATS: bool>(
    stock: &Stock,
    heights: &mut Grid<f32>,
    segs: &[Segment],
    tool: Tool,
) -> (Vec<usize>, Vec<MoveCut>) {
    let (w, h) = (heights.w, heights.h);
    let p = stock.pitch;
    let r = tool.radius();
    let top = stock.y0 + stock.height;
    let nb = h.div_ceil(BAND);
    let mut bins: Vec<Vec<u32>> = vec![Vec::new(); nb];
    for (k, s) in segs.iter().enumerate() {
        let (ylo, yhi) = (s.a.y.min(s.b.y) - r, s.a.y.max(s.b.y) + r);
        let Some((j0, j1)) = cells_between(top - yhi, top - ylo, p, h) else {
            continue;
        };
        for bin in bins.iter_mut().take(j1 / BAND + 1).skip(j0 / BAND) {
            bin.push(k as u32);
        }
    }
    let floor = -stock.thickness as f32;
    let core2 = engage::core_radius2(r);
    let per_band: Vec<BandCut> = heights
        .data
        .par_chunks_mut(w * BAND)
        .zip(bins.par_iter())
        .enumerate()
        .map(|(band, (rows, bin))| {
            let mut hits = Vec::new();
            let mut stats = Vec::new();
            let ja = band * BAND;
            let jb = ja + rows.len() / w;
            // cells only come down: nothing in a row stands higher than
            // it did when the band's first swept move came, so a move
            // reaches only where its tool's profile is lower than that (a
            // tapered ball's or V's flank soon stands above all the stock)
            let mut tops: Option<(Vec<f64>, f64)> = None;
            for &k in bin {
                let seg = &segs[k as usize];
                let sw = Sweep::new(seg.a, seg.b, tool);
                let rapid = seg.kind == Kind::Rapid;
                let mut mc = MoveCut::NONE;
                if !rapid && tool.is_ball() {
                    let continues = k > 0 && segs[k as usize - 1].b == seg.a;
                    ball_rows::<STATS>(stock, rows, ja, w, &sw, continues, floor, &mut mc);
                    if STATS && mc.axial > 0.0 {
                        stats.push((k, mc));
                    }
                    continue;
                }
                let low = seg.a.z.min(seg.b.z);
                let (row_top, band_top) = tops.get_or_insert_with(|| {
                    let r: Vec<f64> = rows
                        .chunks(w)
                        .map(|r| r.iter().fold(floor, |m, &z| m.max(z)) as f64)
                        .collect();
                    let top = r.iter().fold(floor as f64, |m, &z| m.max(z));
                    (r, top)
                });
                if *band_top < low {
                    continue;
                }
                let hit = sweep_rows::<STATS>(
                    stock,
                    (rows, ja, jb, w),
                    (row_top, low),
                    (seg, &sw, tool),
                    floor,
                    core2,
                    &mut mc,
                );
                if hit {
                    hits.push(seg.line);
                }
                if STATS && mc.axial > 0.0 {
                    stats.push((k, mc));
                }
            }
            (hits, stats)
        })
        .collect();
    let mut touched = Vec::new();
    let mut moves = if STATS {
        vec![MoveCut::NONE; segs.len()]
    } else {
        Vec::new()
    };
    for (hits, stats) in per_band {
        touched.extend(hits);
        for (k, mc) in stats {
            moves[k as usize].merge(&mc);
        }
    }
    touched.sort_unstable();
    touched.dedup();
    (touched, moves)
}

/// One move (not a ball's cut, which `ball_rows` takes) swept over a band's
/// rows `ja..jb`: each cell lowered to the tool's lowest point over it,
/// where the row's highest cell (`row_top`) stands above the move's lowest
/// point (`low`). True when a rapid went through material.
#[allow(clippy::too_many_arguments)]
#[inline]
fn sweep_rows<const STATS: bool>(
    stock: &Stock,
    (rows, ja, jb, w): (&mut [f32], usize, usize, usize),
    (row_top, low): (&[f64], f64),
    (seg, sw, tool): (&Segment, &Sweep, Tool),
    floor: f32,
    core2: f64,
    mc: &mut MoveCut,
) -> bool {
    let (p, r) = (stock.pitch, tool.radius());
    let rapid = seg.kind == Kind::Rapid;
    let (nx, ny) = engage::across(sw);
    let mut hit = false;
    for j in ja..jb {
        let (_, y) = stock.centre(0, j);
        let Some(reach) = tool.reach(row_top[j - ja] - low) else {
            continue;
        };
        let Some((i0, i1)) = cells_in(stock, w, sw.row_span(y, reach)) else {
            continue;
        };
        let row = &mut rows[(j - ja) * w..(j - ja + 1) * w];
        let wy = y - sw.a.y;
        for (i, cell) in row.iter_mut().enumerate().take(i1 + 1).skip(i0) {
            let x = stock.x0 + (i as f64 + 0.5) * p;
            let z = sw.lowest(x - sw.a.x, wy);
            if z < *cell as f64 {
                if rapid && z < *cell as f64 - TOUCH && *cell > floor {
                    hit = true;
                }
                let new = (z as f32).max(floor);
                if STATS {
                    let (ex, ey) = (x - seg.b.x, y - seg.b.y);
                    let wx = x - sw.a.x;
                    mc.add(
                        *cell - new,
                        (wx * nx + wy * ny) as f32,
                        ex * ex + ey * ey <= core2,
                        engage::shaved(sw.axis_distance(wx, wy) as f32, r as f32),
                    );
                }
                *cell = new;
            }
        }
    }
    hit
}

/// Lines whose moves leave the machine's travel, with the travel box's
/// lower-left corner at `origin` in job coordinates and Z within +-travel.
pub fn out_of_travel(prog: &Program, m: &Machine, origin: (f64, f64)) -> Vec<usize> {
    let inside = |p: DVec3| {
        p.x >= origin.0 - 1e-9
            && p.x <= origin.0 + m.travel.x + 1e-9
            && p.y >= origin.1 - 1e-9
            && p.y <= origin.1 + m.travel.y + 1e-9
            && p.z.abs() <= m.travel.z + 1e-9
    };
    let mut v: Vec<usize> = prog
        .segments
        .iter()
        .filter(|s| !inside(s.a) || !inside(s.b))
        .map(|s| s.line)
        .collect();
    v.dedup();
    v
}

/// Run time with GRBL-style acceleration: per-axis rate and acceleration
/// limits along each move, junction speeds from the junction deviation, a
/// forward and backward pass, trapezoidal speed profiles; plus dwells.
pub fn estimate_time(prog: &Program, m: &Machine) -> f64 {
    timed(prog, m, |_, _| {})
}

/// Seconds of each job line's moves by that estimate: (1-based line,
/// seconds), in job order (dwells not included).
pub fn line_times(prog: &Program, m: &Machine) -> Vec<(usize, f64)> {
    let mut out: Vec<(usize, f64)> = Vec::new();
    timed(prog, m, |k, dt| {
        let line = prog.segments[k].line;
        match out.last_mut() {
            Some(l) if l.0 == line => l.1 += dt,
            _ => out.push((line, dt)),
        }
    });
    out
}

/// The estimate split into parts of the job: part k holds the lines after
/// the first `starts[k]` (starts ascending, the first 0), its moves and
/// its dwells. The parts sum to `estimate_time`.
pub fn time_by_part(prog: &Program, m: &Machine, starts: &[usize]) -> Vec<f64> {
    let part = |line: usize| starts.iter().rposition(|&s| s < line).unwrap_or(0);
    let mut out = vec![0.0; starts.len().max(1)];
    for &(line, s) in &prog.dwells {
        out[part(line)] += s;
    }
    timed(prog, m, |k, dt| out[part(prog.segments[k].line)] += dt);
    out
}

/// The estimate, calling `each(segment, seconds)` for every move of some
/// length.
fn timed(prog: &Program, m: &Machine, mut each: impl FnMut(usize, f64)) -> f64 {
    // moves of some length, by index (4 bytes each: a 30 million move
    // job holds 4 arrays of f64 beside them, not a copy of its moves)
    let segs: Vec<u32> = (0..prog.segments.len() as u32)
        .filter(|&k| {
            let s = &prog.segments[k as usize];
            (s.b - s.a).length() > 1e-9
        })
        .collect();
    let n = segs.len();
    if n == 0 {
        return prog.dwell_s;
    }
    let seg = |k: usize| &prog.segments[segs[k] as usize];
    let unit = |k: usize| (seg(k).b - seg(k).a).normalize();
    let rates = DVec3::new(m.max_rate.x, m.max_rate.y, m.max_rate.z) / 60.0;
    let accels = DVec3::new(m.acceleration.x, m.acceleration.y, m.acceleration.z);
    let mut moves: Vec<planner::Move> = (0..n)
        .map(|k| {
            let (s, u) = (seg(k), unit(k));
            let rate = planner::along(u, rates);
            planner::Move {
                len: (s.b - s.a).length(),
                top: if s.kind == Kind::Rapid {
                    rate
                } else {
                    (s.feed / 60.0).min(rate)
                },
                accel: planner::along(u, accels),
                entry: 0.0,
            }
        })
        .collect();
    // the highest entry each corner allows
    for k in 1..n {
        if seg(k).stop_before {
            continue;
        }
        let a = moves[k].accel.min(moves[k - 1].accel);
        let vj = planner::junction_speed(unit(k - 1), unit(k), a, m.junction_deviation);
        moves[k].entry = vj.min(moves[k - 1].top);
    }
    planner::plan(&mut moves, 0.0);
    let mut t = prog.dwell_s;
    for (k, mv) in moves.iter().enumerate() {
        let exit = planner::exit(&moves, k);
        let dt = planner::run_time(mv.len, mv.entry, mv.top, exit, mv.accel);
        each(segs[k] as usize, dt);
        t += dt;
    }
    t
}

/// Compare the cut with the relief whose lower-left corner lies at `at`,
/// on the continuous surface the toolpaths cut against (`surface`):
/// (max gouge, max residual, mean residual, deviation per cell).
pub fn deviation(
    stock: &Stock,
    cut: &Grid<f32>,
    relief: &Relief,
    at: (f64, f64),
) -> (f64, f64, f64, Grid<f32>) {
    let lattice = crate::cutter::surface::Lattice::of(relief);
    let target = |x: f64, y: f64| {
        lattice
            .height_at(x, y, |i, j| *relief.heights.get(i, j) as f64)
            .map(|z| z - relief.depth_mm)
    };
    let mut dev = Grid::new(cut.w, cut.h, f32::NAN);
    dev.data
        .par_chunks_mut(cut.w)
        .enumerate()
        .for_each(|(j, row)| {
            for (i, d) in row.iter_mut().enumerate() {
                let (x, y) = stock.centre(i, j);
                if let Some(t) = target(x - at.0, y - at.1) {
                    *d = (*cut.get(i, j) as f64 - t) as f32;
                }
            }
        });
    let (mut gouge, mut res, mut sum, mut n) = (0.0f64, 0.0f64, 0.0f64, 0usize);
    for &d in dev.data.iter().filter(|d| !d.is_nan()) {
        let d = d as f64;
        gouge = gouge.max(-d);
        res = res.max(d);
        sum += d.max(0.0);
        n += 1;
    }
    (gouge, res, if n > 0 { sum / n as f64 } else { 0.0 }, dev)
}

/// The deepest cut of a job's moves into the relief's continuous surface,
/// measured exactly along each move for a ball or flat end mill
/// (`HeightField::rise_along`, the check the toolpath itself passes):
/// what stock cells alone can miss between their centres, where a flat's
/// rim meets the surface.
#[derive(Clone, Copy, Debug)]
pub struct MoveGouge {
    /// How deep (mm; 0 when none).
    pub mm: f64,
    /// The line of the move that cuts deepest, if any cuts.
    pub line: Option<usize>,
    /// Whether every tool was measured so (a V or tapered ball is not, nor
    /// a ball unless asked).
    pub every_tool: bool,
}

impl MoveGouge {
    /// No move measured yet: none cuts, and every tool so far was exact.
    pub const NONE: MoveGouge = MoveGouge {
        mm: 0.0,
        line: None,
        every_tool: true,
    };

    /// Both measures of one job or a series of jobs.
    pub fn max(self, o: MoveGouge) -> MoveGouge {
        let deeper = if o.mm > self.mm { o } else { self };
        MoveGouge {
            every_tool: self.every_tool && o.every_tool,
            ..deeper
        }
    }
}

/// `MoveGouge` of `prog`'s runs against `hf`, the relief's surface with
/// its lower-left corner at job X, Y `at` and its top at Z 0; a ball's
/// moves only with `balls` (fine enough cells bound what a ball hides
/// between them, and relievo's own jobs passed this very check when they
/// were made, at a second or two for a 2048 px raster). A tool whose side
/// only touches the surface does not cut it: the tool is taken a G-code
/// unit (`GRID`) narrower, so a cut-out's slot, a radius outside the
/// panel, does not read as cutting the panel's side wall. Rises under
/// that unit are the G-code's rounding, and left out.
pub fn move_gouge(
    prog: &Program,
    runs: &ToolRuns,
    hf: &HeightField,
    at: (f64, f64),
    balls: bool,
) -> MoveGouge {
    use crate::cutter::along::Bottom;
    use crate::dialect::GRID;
    let shift = DVec3::new(at.0, at.1, 0.0);
    let mut out = MoveGouge::NONE;
    for (from, to, tool) in runs {
        let bottom = match Bottom::of(tool) {
            Some(Bottom::Ball(r)) if balls => Bottom::Ball(r - GRID),
            Some(Bottom::Flat(r)) => Bottom::Flat(r - GRID),
            _ => {
                out.every_tool = false;
                continue;
            }
        };
        // the deepest found so far (f64 bits: ordered as the numbers are
        // for positive ones) is the floor the next move must reach, which
        // lets the branch and bound prune more (a tie still counts, so
        // the first line of equals is named, whatever the threads' order)
        let best = std::sync::atomic::AtomicU64::new(GRID.max(out.mm).to_bits());
        let worst = prog.segments[*from..*to]
            .par_iter()
            .filter_map(|s| {
                let floor = f64::from_bits(best.load(std::sync::atomic::Ordering::Relaxed));
                let floor = floor.next_down();
                let g = hf.rise_along(bottom, s.a - shift, s.b - shift, floor)?;
                best.fetch_max(g.to_bits(), std::sync::atomic::Ordering::Relaxed);
                Some((g, s.line))
            })
            .reduce_with(|a, b| {
                if b.0 > a.0 || (b.0 == a.0 && b.1 < a.1) {
                    b
                } else {
                    a
                }
            });
        if let Some((g, line)) = worst.filter(|w| w.0 > out.mm) {
            (out.mm, out.line) = (g, Some(line));
        }
    }
    out
}

/// Volume removed from the stock (mm^3).
pub fn removed(stock: &Stock, cut: &Grid<f32>) -> f64 {
    let floor = -stock.thickness;
    cut.data
        .par_iter()
        .map(|&z| -(z as f64).max(floor).min(0.0))
        .sum::<f64>()
        * stock.pitch
        * stock.pitch
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gcode::program;

    #[test]
    fn an_aligned_stock_puts_cell_centres_on_the_relief_samples() {
        let s = Stock {
            x0: -0.3,
            y0: -1.1,
            width: 10.5,
            height: 8.2,
            thickness: 3.0,
            pitch: 0.5,
        }
        .aligned_to(0.0, 6.0);
        // covers the stock, by less than a cell more on each side (an
        // edge within a quarter cell of the grid snaps to it)
        assert!(s.x0 <= -0.3 && s.x0 > -0.8 && s.x0 + s.width >= 10.2 - 0.125);
        assert!(s.y0 <= -1.1 + 0.125 && s.y0 + s.height >= 7.1 - 0.125 && s.y0 + s.height < 7.6);
        let snapped = Stock {
            x0: -1.00004,
            width: 3.00009,
            ..s
        }
        .aligned_to(0.0, 6.0);
        assert!((snapped.x0 + 1.0).abs() < 1e-9 && (snapped.width - 3.0).abs() < 1e-9);
        let (w, h) = s.cells();
        assert_eq!((w as f64 * 0.5, h as f64 * 0.5), (s.width, s.height));
        // a cell centre is a relief sample centre: (i + 0.5) * 0.5 from 0
        for (i, j) in [(0, 0), (3, 5), (w - 1, h - 1)] {
            let (cx, cy) = s.centre(i, j);
            let (u, v) = (cx / 0.5 - 0.5, (6.0 - cy) / 0.5 - 0.5);
            assert!((u - u.round()).abs() < 1e-9 && (v - v.round()).abs() < 1e-9);
        }
    }

    /// A flat's rim passing 0.02 mm beside a sample 0.5 mm high cuts the
    /// surface round it (the triangles there stand 0.49 mm high) where no
    /// stock cell centre lies: the cells see nothing, the exact measure
    /// along the move sees the 0.39 mm and its line. A ball's move 1.6
    /// mm beside it cuts nothing.
    #[test]
    fn a_flat_s_rim_between_cells_is_measured_along_the_move() {
        let mut heights = Grid::new(20, 20, 0.0f32);
        heights.set(10, 10, 0.5);
        let relief = Relief {
            heights,
            width_mm: 20.0,
            height_mm: 20.0,
            depth_mm: 1.0,
        };
        // the sample's centre (10.5, 9.5); Z 0 is the relief's top, the
        // level field at -1.0, the move 0.1 above it
        let (r, z) = (1.0, -0.9);
        let y = 9.5 + r + 0.02;
        let job = format!(
            "(tool: flat:2)\nG21 G90\nG0 X2 Y{y} Z1\nG1 Z{z} F300\nG1 X18 Y{y} Z{z}\nG0 Z1\n"
        );
        let prog = program(&job).unwrap();
        let stock = Stock {
            x0: 0.0,
            y0: 0.0,
            width: 20.0,
            height: 20.0,
            thickness: 3.0,
            pitch: 1.0,
        }
        .aligned_to(0.0, 20.0);
        let (w, h) = stock.cells();
        let mut cut = Grid::new(w, h, 0.0f32);
        let (_, _, runs) = cut_program_measured(&stock, &mut cut, &prog, None).unwrap();
        let (at_cells, _, _, _) = deviation(&stock, &cut, &relief, (0.0, 0.0));
        let surface = HeightField::of_relief(&relief);
        let along = move_gouge(&prog, &runs, &surface, (0.0, 0.0), true);
        assert!(at_cells < 1e-9, "cells {at_cells}");
        // (the tool taken a G-code unit narrower; Y read in single
        // precision, as GRBL reads it: 10.52 is 10.5200005)
        let expected = 0.5 * (1.0 - 0.02 - crate::dialect::GRID) - 0.1;
        assert!((along.mm - expected).abs() < 1e-6, "{along:?}");
        assert_eq!((along.line, along.every_tool), (Some(5), true));
        let clear = format!("{}", 9.5 + 1.6);
        let ball = program(
            &job.replace("flat:2", "ball:2")
                .replace(&format!("Y{y}"), &format!("Y{clear}")),
        )
        .unwrap();
        let runs = tool_runs(&ball, None).unwrap();
        let none = move_gouge(&ball, &runs, &surface, (0.0, 0.0), true);
        assert_eq!((none.mm, none.line), (0.0, None));
    }

    /// A wall left 0.09 mm proud along a pre-cut channel is shaved by the
    /// tool's rim at full height: not an axial depth of cut. A wall 0.59
    /// mm proud is (ball and flat: the two cutting paths).
    #[test]
    fn a_wall_shaved_by_the_rim_is_not_a_depth_of_cut() {
        for tool in [Tool::Ball { d: 3.175 }, Tool::Flat { d: 3.175 }] {
            let axial = |proud: f64| {
                let (s, mut h) = stock(20.0, 0.02);
                // channel 2 mm deep along X at Y 10, the wall at |dy| > edge
                let edge = 1.5875 - proud;
                for j in 0..h.h {
                    let (_, y) = s.centre(0, j);
                    if (y - 10.0).abs() <= edge {
                        for i in 0..h.w {
                            h.set(i, j, -2.0);
                        }
                    }
                }
                let prog = program("G0 X2 Y10 Z1\nG1 Z-2 F100\nG1 X18\n").unwrap();
                let (_, moves, _) = cut_program_measured(&s, &mut h, &prog, Some(tool)).unwrap();
                moves[2].axial
            };
            let (sliver, real) = (axial(0.09), axial(0.59));
            assert!(
                sliver < 0.01,
                "{tool:?}: a 0.09 mm sliver counts {sliver} mm"
            );
            assert!(real > 1.0, "{tool:?}: a 0.59 mm cut counts only {real} mm");
        }
    }

    fn stock(size: f64, pitch: f64) -> (Stock, Grid<f32>) {
        let s = Stock {
            x0: 0.0,
            y0: 0.0,
            width: size,
            height: size,
            thickness: 10.0,
            pitch,
        };
        let (w, h) = s.cells();
        (s, Grid::new(w, h, 0.0))
    }

    /// Brute force: the tool placed at many points along each move.
    fn brute(s: &Stock, prog: &Program, tool: Tool) -> Grid<f32> {
        let (w, h) = s.cells();
        let mut g = Grid::new(w, h, 0.0f32);
        for seg in &prog.segments {
            let n = 4000;
            for k in 0..=n {
                let p = seg.a + (seg.b - seg.a) * (k as f64 / n as f64);
                for j in 0..h {
                    for i in 0..w {
                        let (x, y) = s.centre(i, j);
                        let r = ((x - p.x).powi(2) + (y - p.y).powi(2)).sqrt();
                        let z = p.z + tool.profile(r);
                        let c = g.get(i, j).min(z as f32).max(-10.0);
                        g.set(i, j, c);
                    }
                }
            }
        }
        g
    }

    #[test]
    fn exact_sweeps_match_dense_stamping() {
        let job = "G0 X1 Y1.2 Z1\nG1 Z-0.8 F100\nG1 X4.1 Y2.9 Z-1.3\nG1 X2.2 Y4.0 Z-0.2\nG1 X2.2 Y1.0 Z-0.6\nG1 X2.5 Y1.3 Z-2.5\nG1 X3.5 Y1.1 Z0.5\nG0 X4 Y4 Z-0.3\n";
        let prog = program(job).unwrap();
        for spec in ["ball:2", "flat:1.5", "vbit:60:3", "taperball:0.3:10:2.5"] {
            let tool = Tool::parse(spec).unwrap();
            let (s, mut g) = stock(5.0, 0.1);
            cut(&s, &mut g, &prog.segments, tool);
            let b = brute(&s, &prog, tool);
            // compare away from the rim of the footprint, where a flat or
            // V tool's edge makes the surface jump
            let (w, _) = s.cells();
            let rim = |k: usize| {
                let (x, y) = s.centre(k % w, k / w);
                let d = prog.segments.iter().map(|sg| {
                    let (a, b) = (sg.a.truncate(), sg.b.truncate());
                    let q = glam::DVec2::new(x, y);
                    let t = if a == b {
                        0.0
                    } else {
                        ((q - a).dot(b - a) / (b - a).length_squared()).clamp(0.0, 1.0)
                    };
                    (q - (a + (b - a) * t)).length()
                });
                (d.fold(f64::MAX, f64::min) - tool.radius()).abs() < 0.02
            };
            let diffs = || {
                g.data
                    .iter()
                    .zip(&b.data)
                    .enumerate()
                    .filter(|(k, _)| !rim(*k))
                    .map(|(_, (x, y))| x - y)
            };
            let worst = diffs().fold(f32::MIN, f32::max);
            let under = diffs().map(|d| -d).fold(f32::MIN, f32::max);
            eprintln!("{spec}: exact above stamping by {worst}, below by {under}");
            assert!(
                worst < 2e-3 && under < 2e-3,
                "{spec}: exact above stamping by {worst}, below by {under}"
            );
        }
    }

    /// The ball's fast path (end spheres, side only near the move) equals
    /// the full capsule evaluation on random polylines, steep ones too.
    #[test]
    fn ball_fast_path_equals_full_capsule() {
        let mut rnd = crate::testing::rng(99);
        let tool = Tool::Ball { d: 1.6 };
        for trial in 0..6 {
            let mut job = String::from("G0 X3 Y3 Z0.5\nG1 F500\n");
            for k in 0..40 {
                let steep = if trial % 2 == 0 { 3.0 } else { 0.4 };
                let (x, y) = (0.5 + 5.0 * rnd(), 0.5 + 5.0 * rnd());
                let z = -1.5 + steep * (rnd() - 0.5);
                if k % 7 == 3 {
                    job += &format!("G1 Z{z:.4}\n"); // a plunge or lift
                } else if k % 5 == 1 {
                    job += &format!("G1 X{:.4} Z{z:.4}\n", x); // along X only
                } else {
                    job += &format!("G1 X{x:.4} Y{y:.4} Z{z:.4}\n");
                }
            }
            let prog = program(&job).unwrap();
            let (s, mut g) = stock(6.0, 0.05);
            cut(&s, &mut g, &prog.segments, tool);
            let (w, h) = s.cells();
            let sweeps: Vec<Sweep> = prog
                .segments
                .iter()
                .map(|sg| Sweep::new(sg.a, sg.b, tool))
                .collect();
            let mut worst = 0.0f64;
            for j in 0..h {
                for i in 0..w {
                    let (x, y) = s.centre(i, j);
                    let z = sweeps
                        .iter()
                        .map(|sw| sw.lowest(x - sw.a.x, y - sw.a.y))
                        .fold(0.0f64, f64::min)
                        .max(-10.0);
                    worst = worst.max((z - *g.get(i, j) as f64).abs());
                }
            }
            // f32 arithmetic in the fast path: micrometre-level agreement
            eprintln!("trial {trial}: {worst:.2e} mm");
            assert!(worst < 2e-4, "trial {trial}: fast path off by {worst} mm");
        }
    }

    #[test]
    fn time_of_a_long_straight_move_is_accel_plus_cruise() {
        let m = Machine::load("grbl-generic").unwrap();
        // 100 mm at 300 mm/min = 5 mm/s, accel 10 mm/s^2: 0.5 s up, 0.5 s down
        let prog = program("G1 X100 F300\n").unwrap();
        let t = estimate_time(&prog, &m);
        let want = 0.5 + 0.5 + (100.0 - 2.0 * 1.25) / 5.0;
        assert!((t - want).abs() < 1e-9, "{t} vs {want}");
    }

    #[test]
    fn time_by_part_splits_moves_and_dwells_at_the_lines_given() {
        let m = Machine::load("grbl-generic").unwrap();
        // two 100 mm moves with a full stop and a 2 s dwell between them
        let prog = program("G1 X100 F300\nM5\n(two)\nG4 P2\nG1 X0\n").unwrap();
        let one = 0.5 + 0.5 + (100.0 - 2.0 * 1.25) / 5.0;
        let parts = time_by_part(&prog, &m, &[0, 2]);
        assert!((parts[0] - one).abs() < 1e-9, "{parts:?}");
        assert!((parts[1] - (one + 2.0)).abs() < 1e-9, "{parts:?}");
        let total = estimate_time(&prog, &m);
        assert!((parts.iter().sum::<f64>() - total).abs() < 1e-9);
        // a start past the dwell leaves it to the first part
        let parts = time_by_part(&prog, &m, &[0, 4]);
        assert!((parts[0] - (one + 2.0)).abs() < 1e-9, "{parts:?}");
    }
}
