//! Cutting passes: polylines of tool-tip (CL) points, refined where the
//! straight move between two CL points would dip into the CL surface,
//! and checked against the relief (thinned by `merge`).

use super::merge::merge;
use crate::cutter::along::Bottom;
use crate::cutter::dropcutter::HeightField;
use crate::tool::Tool;
use glam::DVec3;

/// How far a straight move may dip below the CL surface between two CL
/// points before the gap is split (mm): the gouge budget of a pass.
pub const DIP: f64 = 2e-4;
/// How far it may pass above it (mm): left-over material, not a gouge.
pub const RISE: f64 = 5e-3;
/// How far a merged chord may pass below a dropped point (mm). With DIP
/// this keeps every gouge of a finishing pass under 1 micrometre.
pub const MERGE_DIP: f64 = 7e-4;

/// Ramp entry angle into the material.
pub const RAMP_DEG: f64 = 5.0;
/// Most back-and-forth legs of one ramp.
pub const RAMP_LEGS: usize = 64;

pub use crate::dialect::{snap, snap_up, GRID};

/// How `drop_along` refines the gaps between dropped points.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refine {
    /// One CL point per XY point.
    None,
    /// Split a gap where the two end points' contact samples say so, at
    /// no query: the CL surface is at least the higher of the two
    /// samples' caps, so it bulges more than DIP above the chord where
    /// those caps do (a convex stretch, where a chord one sample long
    /// already dips 0.8 um at 1024 px over 100 mm), and it can sag more
    /// than RISE below it only where the contacts differ and the caps
    /// allow. A third sample rising between is left to the exact check.
    Bounds,
    /// Probe the middle and quarter points of every gap with the
    /// drop-cutter, splitting where the chord leaves the CL surface by
    /// more than DIP below or RISE above.
    Full,
}

/// Drop the tool along the XY polyline `xy` (points at most about one
/// sample apart), refining gaps as `refine` says. Points with no sample in
/// reach sit at `floor`.
pub fn drop_along(
    hf: &HeightField,
    tool: &Tool,
    xy: &[(f64, f64)],
    floor: f64,
    refine: Refine,
) -> Vec<DVec3> {
    type Contact = Option<(usize, usize)>;
    let mut stack = Vec::new();
    let mut hint = None;
    let mut at = |x: f64, y: f64| -> (DVec3, Contact) {
        // snap to the G-code's 0.1 um grid so the moves written are the
        // moves checked: at a flat tool's rim 0.1 um sideways can mean a
        // whole step up or down
        let (x, y) = (snap(x), snap(y));
        match hf.drop_from(tool, x, y, hint, &mut stack) {
            Some((z, c)) if z >= floor => {
                hint = Some(c);
                (DVec3::new(x, y, z), Some(c))
            }
            Some((_, c)) => {
                hint = Some(c);
                (DVec3::new(x, y, floor), None)
            }
            None => (DVec3::new(x, y, floor), None),
        }
    };
    // the CL surface at q is at least this (the caps of both contacts)
    let caps = |q: DVec3, ca: Contact, cb: Contact| -> f64 {
        [ca, cb]
            .into_iter()
            .flatten()
            .filter_map(|(i, j)| hf.contribution(tool, i, j, q.x, q.y))
            .fold(floor, f64::max)
    };
    let mut out: Vec<DVec3> = Vec::with_capacity(xy.len());
    let mut last: Contact = None;
    // below this the snapped midpoint would not split the gap
    let min_gap = (hf.pitch / 4096.0).max(3.0 * GRID);
    for &(x, y) in xy {
        let (p, cp) = at(x, y);
        let Some(&prev) = out.last() else {
            out.push(p);
            last = cp;
            continue;
        };
        if refine == Refine::None {
            out.push(p);
            continue;
        }
        // refine the gap prev -> p (depth-first, in order)
        let mut todo = vec![((prev, last), (p, cp))];
        while let Some(((a, ca), (b, cb))) = todo.pop() {
            let gap = (b - a).truncate().length();
            if gap > min_gap {
                let (mx, my) = ((a.x + b.x) / 2.0, (a.y + b.y) / 2.0);
                let split = match refine {
                    Refine::Bounds => [0.5, 0.25, 0.75]
                        .iter()
                        .any(|&f| {
                            let m = a + (b - a) * f;
                            let c = caps(m, ca, cb);
                            // sags below the chord (only where the
                            // contacts differ), or bulges above it
                            (ca != cb && m.z - c > RISE) || c - m.z > DIP
                        })
                        .then(|| at(mx, my)),
                    _ => {
                        // the CL surface bends at sub-sample scale (the
                        // contact hops between samples): test the quarter
                        // points too
                        let mut split = None;
                        for f in [0.5, 0.25, 0.75] {
                            let m = a + (b - a) * f;
                            let c = at(m.x, m.y);
                            if c.0.z - m.z > DIP || m.z - c.0.z > RISE {
                                split = Some(if f == 0.5 { c } else { at(mx, my) });
                                break;
                            }
                        }
                        split
                    }
                };
                if let Some(c) = split {
                    todo.push((c, (b, cb)));
                    todo.push(((a, ca), c));
                    continue;
                }
            } else if refine == Refine::Full && (b.z - a.z).abs() > DIP {
                // still steep at the finest gap: a jump in the CL
                // surface (a flat or V tool's rim meeting a sample).
                // Step over it on the higher side: up first, or
                // across first and down last; never diagonally.
                let corner = if b.z > a.z {
                    DVec3::new(a.x, a.y, b.z)
                } else {
                    DVec3::new(b.x, b.y, a.z)
                };
                out.push(corner);
            }
            out.push(b);
        }
        last = cp;
    }
    out
}

/// Cut a single move may make below any sample before the final check
/// raises it (mm).
pub const CHECK: f64 = 2e-4;

/// How deep the straight move a -> b would cut into the relief's surface
/// (<= 0 when it cuts none). A ball's or flat's is exact: the highest the
/// CL surface rises over the move (`HeightField::rise_along`; rises under
/// CHECK / 2 count as none). Other tools: the exact swept tool against
/// every sample it passes, then the drop-cutter at probes between them
/// (`probe_gouge`).
///
/// `ends_on_cl`: a and b are drop-cutter points (or above them), where
/// the tool touches no sample, which spares the sweep behind the lower
/// end (`sample_gouge`).
pub fn move_gouge(hf: &HeightField, tool: &Tool, a: DVec3, b: DVec3, ends_on_cl: bool) -> f64 {
    if let Some(bottom) = Bottom::of(tool) {
        return hf.rise_along(bottom, a, b, 0.5 * CHECK).unwrap_or(0.0);
    }
    let at_samples = sample_gouge(hf, tool, a, b, ends_on_cl);
    at_samples.max(probe_gouge(hf, tool, a, b, at_samples.max(0.5 * CHECK)))
}

/// `move_gouge` for a ball's move that passes over `drops`, the CL points
/// dropped along it (in order, the first straight below a, the last
/// below b). They are probes already made, with their clearance under
/// the move known. Between two of them g apart the CL surface, held by
/// the ball, bends down along the row at most as a sphere of radius R
/// does at the surface's slope there (the bound `probe_spacing` takes on
/// level ground), and so rises over the move at most as far as that bend
/// lifts a parabola through their clearances. Only gaps where that
/// reaches CHECK / 2 are probed, as `probe_gouge` would. The slope across
/// the row steepens the bend too (a sphere sloping at q across bends
/// sqrt(1 + p^2 + q^2) / sqrt(1 + p^2) times as much along the row): on a
/// random relief a move from a point lifted by the tolerance to one on
/// the CL surface was cut 0.33 um where the bend at the chord's slope
/// alone saw none. The 2048 px bunny raster's check takes no longer.
fn dropped_move_gouge(hf: &HeightField, tool: &Tool, a: DVec3, b: DVec3, drops: &[DVec3]) -> f64 {
    let r = tool.radius();
    let at_samples = sample_gouge(hf, tool, a, b, true);
    let floor = at_samples.max(0.5 * CHECK);
    let d = b - a;
    let len2 = d.truncate().length_squared();
    // the move's height straight above q
    let above = |q: DVec3| {
        let t = if len2 > 0.0 {
            ((q - a).truncate().dot(d.truncate()) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        a.z + d.z * t
    };
    let spacing = probe_spacing(hf, tool);
    let mut stack = Vec::new();
    let mut hint = None;
    let mut worst = at_samples;
    let mut clear0 = above(drops[0]) - drops[0].z;
    for w in drops.windows(2) {
        let clear1 = above(w[1]) - w[1].z;
        worst = worst.max(-clear0).max(-clear1);
        let g = (w[1] - w[0]).truncate().length();
        // a sphere of radius R sloping at p along the row and q across
        // it bends along the row at (1 + p^2) sqrt(1 + p^2 + q^2) / R
        // (the CL surface is such spheres, cylinders and planes); the
        // rise over the move at t of the gap is then at most
        // -(1 - t) c0 - t c1 + k t (1 - t), k = bend g^2 / 2. p: the
        // chord's slope turned by the most a radius R bends over the gap;
        // q is not known along a row: taken as up to sqrt(3 (1 + p^2)),
        // twice the bend level across
        let s = if g > 0.0 { (w[1].z - w[0].z) / g } else { 0.0 };
        let turn = g * (1.0 + s * s).sqrt() / r;
        let s = (s.abs().atan() + turn).min(1.5).tan();
        let k = (1.0 + s * s) * (1.0 + s * s).sqrt() / r * g * g;
        let t = if k > 0.0 {
            ((k + clear0 - clear1) / (2.0 * k)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let rise = -(1.0 - t) * clear0 - t * clear1 + k * t * (1.0 - t);
        if rise > 0.5 * CHECK {
            let n = (g / spacing).ceil() as usize;
            for m in 1..n.min(1 << 20) {
                let q = w[0] + (w[1] - w[0]) * (m as f64 / n as f64);
                let z = above(q);
                if let Some((c, at)) = hf.drop_above(tool, q.x, q.y, z + floor, hint, &mut stack) {
                    hint = Some(at);
                    worst = worst.max(c - z);
                }
            }
        }
        clear0 = clear1;
    }
    worst
}

/// How far apart `probe_gouge` probes a move. Between creases the CL
/// surface is smooth, bent at most as the tip is: probes this far apart
/// miss at most CHECK / 2 of a bulge. A ball's CL surface is the ball's
/// centre surface and on level ground bends as the ball (for a 3.175 mm
/// ball 0.036 mm, wider than half a sample at 2048 px); a tapered ball's
/// flank makes peaks over vertices, so its probes stay at least two a
/// sample.
fn probe_spacing(hf: &HeightField, tool: &Tool) -> f64 {
    match tool.tip_radius() {
        Some(r) if tool.is_ball() => (4.0 * CHECK * r).sqrt(),
        Some(r) => (4.0 * CHECK * r).sqrt().min(0.5 * hf.pitch),
        None => 0.5 * hf.pitch,
    }
}

/// For each move of `pts`, the stretch of `drops` (the pass's dropped CL
/// points, in order) it passes over: merging keeps a subsequence of them,
/// lifted but never moved in XY. None where `pts` is not such a
/// subsequence (arcs' chords end between dropped points).
fn stretches(pts: &[DVec3], drops: &[DVec3]) -> Option<Vec<(usize, usize)>> {
    let mut at = Vec::with_capacity(pts.len());
    let mut j = 0;
    for p in pts {
        while j < drops.len() && drops[j].truncate() != p.truncate() {
            j += 1;
        }
        if j == drops.len() {
            return None;
        }
        at.push(j);
    }
    Some(at.windows(2).map(|w| (w[0], w[1])).collect())
}

/// The highest the CL surface rises above the move a -> b at probes where
/// the surface between samples can hold the tool higher than the samples
/// do: where the move's path crosses the lattice's cell edges and
/// diagonals (where a pointed tool's CL surface has its creases), and
/// midway between crossings more than half a sample apart. Only rises
/// above `floor` count (the drop-cutter then prunes nearly everything).
pub fn probe_gouge(hf: &HeightField, tool: &Tool, a: DVec3, b: DVec3, floor: f64) -> f64 {
    let p = hf.pitch;
    let (d, top) = (b - a, hf.top);
    // every t in (0, 1) where a family of lines k p + offset is crossed by
    // the linear function f(t) = f0 + t df
    let mut ts: Vec<f64> = vec![0.0, 1.0];
    let mut cross = |f0: f64, df: f64, offset: f64| {
        if df.abs() < 1e-12 {
            return;
        }
        let (lo, hi) = (f0.min(f0 + df), f0.max(f0 + df));
        let k0 = ((lo - offset) / p).ceil() as i64;
        let k1 = ((hi - offset) / p).floor() as i64;
        for k in k0..=k1.min(k0 + 1_000_000) {
            let t = (k as f64 * p + offset - f0) / df;
            if t > 0.0 && t < 1.0 {
                ts.push(t);
            }
        }
    };
    // a ball's or tapered tip's CL surface has no creases (each triangle
    // holds it on a smooth surface): the curvature spacing alone will do
    if tool.is_vbit() {
        cross(a.x, d.x, 0.5 * p);
        cross(top - a.y, -d.y, 0.5 * p);
        cross(a.x + top - a.y, d.x - d.y, 0.0);
    }
    ts.sort_unstable_by(f64::total_cmp);
    let spacing = probe_spacing(hf, tool);
    let len = d.truncate().length();
    let mut probes: Vec<f64> = Vec::with_capacity(2 * ts.len());
    for w in ts.windows(2) {
        if w[0] > 0.0 {
            probes.push(w[0]);
        }
        let n = ((w[1] - w[0]) * len / spacing).ceil() as usize;
        for k in 1..n.min(1 << 20) {
            probes.push(w[0] + (w[1] - w[0]) * k as f64 / n as f64);
        }
    }
    let mut stack = Vec::new();
    let mut hint = None;
    let mut worst = f64::NEG_INFINITY;
    for t in probes {
        let q = a + d * t;
        if let Some((z, c)) = hf.drop_above(tool, q.x, q.y, q.z + floor, hint, &mut stack) {
            hint = Some(c);
            worst = worst.max(z - q.z);
        }
    }
    worst
}

/// How deep the straight move a -> b would cut below the samples it passes
/// over (<= 0 when it cuts none), with the exact swept tool.
///
/// With `ends_on_cl` (neither end's tool touches a sample), the samples
/// behind the lower end (or behind both, on a level move) are left out:
/// over them the swept tool is lowest at that end, which comes nearer and
/// lower at once, and there it touches nothing. On a short move that is
/// most of what the tool passes over.
fn sample_gouge(hf: &HeightField, tool: &Tool, a: DVec3, b: DVec3, ends_on_cl: bool) -> f64 {
    use crate::cutter::sweep::{cells_between, Sweep};
    let sw = Sweep::new(a, b, *tool);
    // a level move with its ends on the CL surface sweeps only its side
    // (`Slab`), where the ball is lowest straight across
    let ball = tool
        .is_ball()
        .then(|| BallSweep::new(a, b, sw.r, ends_on_cl && a.z == b.z));
    let z = hf.samples();
    let p = hf.pitch;
    let r = tool.radius();
    let (ylo, yhi) = (a.y.min(b.y) - r, a.y.max(b.y) + r);
    let mut worst = f64::NEG_INFINITY;
    let Some((j0, j1)) = cells_between(hf.top - yhi, hf.top - ylo, p, z.h) else {
        return worst;
    };
    use crate::cutter::dropcutter::ROW_BLOCK;
    let low_tip = a.z.min(b.z);
    let slab = Slab::new(a, b, ends_on_cl);
    for j in j0..=j1 {
        let (_, y) = hf.centre(0, j);
        let Some((i0, i1)) = sw
            .row_span(y, sw.r)
            .and_then(|(xl, xh)| slab.clip(xl, xh, y))
            .and_then(|(xl, xh)| cells_between(xl, xh, p, z.w))
        else {
            continue;
        };
        // no point of the tool over this row is lower than `floor_j`: the
        // tip, plus for a ball its rise at the row's distance from the path
        let rho = if y < a.y.min(b.y) || y > a.y.max(b.y) {
            (y - a.y).abs().min((y - b.y).abs())
        } else {
            0.0
        };
        let floor_j = low_tip + tool.profile(rho.min(r));
        let wy = y - a.y;
        for blk in i0 / ROW_BLOCK..=i1 / ROW_BLOCK {
            if hf.row_block_max(blk, j) <= floor_j {
                continue; // every sample here lies below the tool
            }
            let (c0, c1) = (
                (blk * ROW_BLOCK).max(i0),
                ((blk + 1) * ROW_BLOCK - 1).min(i1),
            );
            let row = &z.data[j * z.w + c0..=j * z.w + c1];
            let x0 = (c0 as f64 + 0.5) * p - a.x;
            worst = worst.max(match &ball {
                Some(bs) => bs.row_gouge(row, x0, p, wy),
                None => row
                    .iter()
                    .enumerate()
                    .map(|(k, zs)| zs - sw.lowest(x0 + k as f64 * p, wy))
                    .fold(f64::NEG_INFINITY, f64::max),
            });
        }
    }
    worst
}

/// The part of the plane, across a move's XY line, that its sample sweep
/// must cover: between the perpendiculars at its ends, or beyond the one
/// at its higher end (`sample_gouge`).
struct Slab {
    a: glam::DVec2,
    /// Unit direction of the move in XY (zero: no slab).
    u: glam::DVec2,
    /// The along-move range kept (from a).
    lo: f64,
    hi: f64,
}

impl Slab {
    fn new(a: DVec3, b: DVec3, ends_on_cl: bool) -> Slab {
        let d = (b - a).truncate();
        let len = d.length();
        let on = ends_on_cl && len > 1e-9;
        // a sample on a perpendicular is kept: the margin is for rounding
        let m = 1e-9;
        Slab {
            a: a.truncate(),
            u: if on { d / len } else { glam::DVec2::ZERO },
            lo: if on && b.z >= a.z {
                -m
            } else {
                f64::NEG_INFINITY
            },
            hi: if on && b.z <= a.z {
                len + m
            } else {
                f64::INFINITY
            },
        }
    }

    /// [xl, xh] on the row at `y`, cut to the slab; None when empty.
    fn clip(&self, xl: f64, xh: f64, y: f64) -> Option<(f64, f64)> {
        if self.u == glam::DVec2::ZERO {
            return Some((xl, xh));
        }
        // along(x) = (x - a.x) u.x + (y - a.y) u.y
        let base = (y - self.a.y) * self.u.y;
        if self.u.x.abs() < 1e-12 {
            return (self.lo..=self.hi).contains(&base).then_some((xl, xh));
        }
        let (p, q) = (
            self.a.x + (self.lo - base) / self.u.x,
            self.a.x + (self.hi - base) / self.u.x,
        );
        let (lo, hi) = (xl.max(p.min(q)), xh.min(p.max(q)));
        (lo <= hi).then_some((lo, hi))
    }
}

/// The ball's swept surface with everything per move computed once, in a
/// branch-free form the compiler vectorises: the exact check of a 2048 px
/// raster sweeps ~40 million samples.
struct BallSweep {
    /// Only the side to sweep (a level move between CL points).
    side_only: bool,
    d: DVec3,
    az: f64,
    r: f64,
    r2: f64,
    u: DVec3,
    len: f64,
    aa: f64,
}

impl BallSweep {
    /// `level_on_cl`: a level move between CL points (`side_only`).
    fn new(a: DVec3, b: DVec3, r: f64, level_on_cl: bool) -> BallSweep {
        let d = b - a;
        let len = d.length();
        let u = if len > 0.0 { d / len } else { DVec3::ZERO };
        BallSweep {
            side_only: level_on_cl && len > 1e-9,
            d,
            az: a.z,
            r,
            r2: r * r,
            u,
            len,
            aa: 1.0 - u.z * u.z,
        }
    }

    /// max(z - lowest) over the samples `row`, the first at x offset `x0`
    /// from the move's start, `p` apart, at y offset `wy`.
    fn row_gouge(&self, row: &[f64], x0: f64, p: f64, wy: f64) -> f64 {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            // SAFETY: the CPU has the features the wrapper is compiled for
            return unsafe { self.row_gouge_avx2(row, x0, p, wy) };
        }
        self.row_gouge_body(row, x0, p, wy)
    }

    /// The same loop compiled for AVX2 (4 lanes of f64).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn row_gouge_avx2(&self, row: &[f64], x0: f64, p: f64, wy: f64) -> f64 {
        self.row_gouge_body(row, x0, p, wy)
    }

    #[inline(always)]
    fn row_gouge_body(&self, row: &[f64], x0: f64, p: f64, wy: f64) -> f64 {
        if self.side_only {
            return self.side_gouge(row, x0, p, wy);
        }
        let (d, r, r2, u) = (self.d, self.r, self.r2, self.u);
        let inf = f64::INFINITY;
        // the side exists only for a move that is not vertical
        let side = self.aa > 1e-12 && self.len > 0.0;
        let inv_aa = if side { 1.0 / self.aa } else { 0.0 };
        // four running maxima, so the loop vectorises without reordering a
        // floating-point reduction
        let mut worst = [f64::NEG_INFINITY; 4];
        for (k, &zs) in row.iter().enumerate() {
            let wx = x0 + k as f64 * p;
            let q0 = wx * wx + wy * wy;
            let s0 = self.az + r - (r2 - q0).max(0.0).sqrt();
            let s0 = if q0 <= r2 { s0 } else { inf };
            let (x1, y1) = (wx - d.x, wy - d.y);
            let q1 = x1 * x1 + y1 * y1;
            let s1 = self.az + d.z + r - (r2 - q1).max(0.0).sqrt();
            let s1 = if q1 <= r2 { s1 } else { inf };
            let wu = wx * u.x + wy * u.y;
            let bb = -u.z * wu;
            let cc = q0 - wu * wu - r2;
            let disc = bb * bb - self.aa * cc;
            let zp = (-bb - disc.max(0.0).sqrt()) * inv_aa;
            let s = (wu + zp * u.z) / self.len;
            let c = self.az + r + zp;
            let c = if side && disc >= 0.0 && (0.0..=1.0).contains(&s) {
                c
            } else {
                inf
            };
            let g = zs - s0.min(s1).min(c);
            let lane = &mut worst[k % 4];
            *lane = if g > *lane { g } else { *lane };
        }
        worst[0].max(worst[1]).max(worst[2].max(worst[3]))
    }

    /// `row_gouge_body` for a level move's side: over a sample at w from
    /// the move's line the ball is lowest at r - sqrt(r^2 - w^2) above
    /// the tip, one square root instead of three.
    #[inline(always)]
    fn side_gouge(&self, row: &[f64], x0: f64, p: f64, wy: f64) -> f64 {
        let (r, r2, u) = (self.r, self.r2, self.u);
        let top = self.az + r;
        let mut worst = [f64::NEG_INFINITY; 4];
        for (k, &zs) in row.iter().enumerate() {
            let wx = x0 + k as f64 * p;
            let across = wx * u.y - wy * u.x;
            let q = r2 - across * across;
            let low = if q >= 0.0 {
                top - q.sqrt()
            } else {
                f64::INFINITY
            };
            let g = zs - low;
            let lane = &mut worst[k % 4];
            *lane = if g > *lane { g } else { *lane };
        }
        worst[0].max(worst[1]).max(worst[2].max(worst[3]))
    }
}

/// A pass dropped without refinement, merged, then checked exactly: the
/// few moves that would cut deeper than CHECK (where the CL surface bends
/// between points, over convex detail) are dropped again with refinement,
/// merged and checked again. Refining only there keeps the drop-cutter to
/// about one query per point instead of four.
///
/// `drops`: the CL points `pts` was merged from, in order, which a ball's
/// check takes for probes (`dropped_move_gouge`).
pub fn check_and_refine(
    hf: &HeightField,
    tool: &Tool,
    pts: &[DVec3],
    floor: f64,
    tol: f64,
    drops: Option<&[DVec3]>,
) -> Vec<DVec3> {
    use rayon::prelude::*;
    if pts.len() < 2 {
        return pts.to_vec();
    }
    let over = match drops {
        Some(drops) if tool.is_ball() => stretches(pts, drops).map(|s| (drops, s)),
        _ => None,
    };
    let fixes: Vec<Option<Vec<DVec3>>> = pts
        .par_windows(2)
        .enumerate()
        .map(|(k, w)| {
            let (a, b) = (w[0], w[1]);
            let g = match &over {
                Some((drops, s)) => {
                    let (i, j) = s[k];
                    dropped_move_gouge(hf, tool, a, b, &drops[i..=j])
                }
                None => move_gouge(hf, tool, a, b, false),
            };
            if g <= CHECK {
                return None;
            }
            let n = ((b - a).truncate().length() / hf.pitch).ceil().max(1.0) as usize;
            let xy: Vec<(f64, f64)> = (0..=n)
                .map(|i| {
                    let t = i as f64 / n as f64;
                    (a.x + (b.x - a.x) * t, a.y + (b.y - a.y) * t)
                })
                .collect();
            let cl = drop_along(hf, tool, &xy, floor, Refine::Full);
            let m = merge(&cl, tol);
            // a ball's moves over the points just dropped: those are its
            // probes, as for the row
            Some(match stretches(&m, &cl).filter(|_| tool.is_ball()) {
                Some(s) => {
                    let g = m
                        .windows(2)
                        .zip(&s)
                        .map(|(w, &(i, j))| dropped_move_gouge(hf, tool, w[0], w[1], &cl[i..=j]))
                        .collect();
                    lift_cuts(&m, g)
                }
                _ => verify(hf, tool, &m, true),
            })
        })
        .collect();
    let mut out = vec![pts[0]];
    for (w, fix) in pts.windows(2).zip(fixes) {
        // a and b may sit above the CL (lifted by merging): the new
        // stretch starts and ends straight below them
        if let Some(f) = fix {
            out.extend(f.into_iter().filter(|&q| q != w[0] && q != w[1]));
        }
        out.push(w[1]);
    }
    out
}

/// The final check: every move is swept exactly over the samples it
/// passes; one that would cut deeper than CHECK is raised by what it would
/// cut (up at its start, across, down onto its end), which leaves a little
/// material but never gouges. Catches what refinement between CL points
/// cannot see, such as a sample meeting a flat tool's rim between checks.
///
/// `ends_on_cl`: every point of `pts` is a drop-cutter point or above one
/// (`move_gouge`).
pub fn verify(hf: &HeightField, tool: &Tool, pts: &[DVec3], ends_on_cl: bool) -> Vec<DVec3> {
    use rayon::prelude::*;
    if pts.len() < 2 {
        return pts.to_vec();
    }
    let gouges: Vec<f64> = pts
        .par_windows(2)
        .map(|w| move_gouge(hf, tool, w[0], w[1], ends_on_cl))
        .collect();
    lift_cuts(pts, gouges)
}

/// `pts` with every move whose gouge (one per move) passes CHECK raised
/// by it: up at its start, across, down onto its end.
fn lift_cuts(pts: &[DVec3], gouges: Vec<f64>) -> Vec<DVec3> {
    let mut out = vec![pts[0]];
    for (w, &g) in pts.windows(2).zip(&gouges) {
        if g > CHECK {
            let up = DVec3::new(0.0, 0.0, snap_up(g + GRID));
            out.push(w[0] + up);
            out.push(w[1] + up);
        }
        out.push(w[1]);
    }
    out
}

/// Whether the way from `low` up to `high` is 45 degrees or steeper (a
/// G-code unit of margin: the simulator judges the written numbers) and
/// more than a hair tall: gone down, it is a plunge.
pub fn steep(low: DVec3, high: DVec3) -> bool {
    let rise = high.z - low.z;
    rise > 0.05 && rise > (high - low).truncate().length() - GRID
}

/// Whether the move from `pts[i]` rises steeply (`steep`): run backwards,
/// as a ramp's return legs run, it would be a plunge.
pub fn rises_steeply(pts: &[DVec3], i: usize) -> bool {
    steep(pts[i], pts[i + 1])
}

/// Enter the pass at `top` (the material's top there) by ramping back and
/// forth along its first stretch at RAMP_DEG instead of plunging, never
/// below the pass itself. The stretch ends before the pass first rises
/// steeply, which the return legs would run down. A short first stretch
/// takes more legs (at most RAMP_LEGS, steeper beyond that); only a pass
/// whose stretch is shorter than a quarter of the radius plunges.
pub fn ramp(pts: &[DVec3], top: f64, r: f64) -> Vec<DVec3> {
    // where the pass steps straight up or down (a corner over a sample, or
    // a move raised by the check), the ramp keeps to the higher side:
    // run backwards, a step up would be a plunge
    let corner_top = |i: usize| {
        let same = |j: usize| pts.get(j).filter(|q| q.truncate() == pts[i].truncate());
        [i.checked_sub(1).and_then(same), same(i + 1)]
            .into_iter()
            .flatten()
            .fold(pts[i].z, |z, q| z.max(q.z))
    };
    let depth = top - pts[0].z;
    let mut len = 0.0;
    let mut m = 0;
    while m + 1 < pts.len() && len < 4.0 * r && !rises_steeply(pts, m) {
        len += (pts[m + 1] - pts[m]).truncate().length();
        m += 1;
    }
    if depth <= 1e-3 || len < 0.25 * r {
        return pts.to_vec();
    }
    let per_leg = len * RAMP_DEG.to_radians().tan();
    let legs = ((depth / per_leg).ceil() as usize).clamp(1, RAMP_LEGS);
    let legs = legs + legs % 2; // end back at the start
    let slope = depth / (legs as f64 * len);
    let mut out = vec![DVec3::new(pts[0].x, pts[0].y, top)];
    let mut dist = 0.0;
    for leg in 0..legs {
        let idx: Vec<usize> = if leg % 2 == 0 {
            (1..=m).collect()
        } else {
            (0..m).rev().collect()
        };
        for i in idx {
            let prev = *out.last().unwrap();
            dist += (pts[i] - prev).truncate().length();
            let z = (top - dist * slope).max(corner_top(i));
            out.push(DVec3::new(pts[i].x, pts[i].y, z));
        }
    }
    out.pop(); // the start again, at its own depth:
    out.extend_from_slice(pts);
    out
}

#[cfg(test)]
mod check_tests {
    use super::*;
    use crate::grid::Grid;

    /// Waves, a little noise and a raised disc whose rim is a step one
    /// sample wide, `w` samples square, 0.05 mm apart.
    fn field(w: usize, seed: u64) -> HeightField {
        let mut s = seed;
        let mut rnd = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let z = (0..w * w)
            .map(|k| {
                let (x, y) = ((k % w) as f64, (k / w) as f64);
                let (cx, cy) = (x - w as f64 * 0.6, y - w as f64 * 0.4);
                let disc = if cx * cx + cy * cy < (w as f64 * 0.2).powi(2) {
                    0.3
                } else {
                    0.0
                };
                -2.0 + 0.5 * (x / 9.0).sin() * (y / 7.0).cos() + disc + 0.002 * rnd()
            })
            .collect();
        HeightField::new(Grid::from_vec(w, w, z), 0.05)
    }

    /// Leaving out the sweep behind a move's lower end (both ends drop-
    /// cutter points, or lifted above them) finds every cut the whole
    /// sweep finds, within 1e-12 mm: for a ball, a flat and a V tool, level,
    /// rising and falling moves of 0.05-3 mm in every direction.
    #[test]
    fn the_sweep_behind_the_lower_end_finds_nothing_more() {
        let hf = field(96, 3);
        let mut rnd = crate::testing::rng(99);
        let mut cutting = 0;
        for spec in ["ball:1", "flat:0.8", "vbit:90:1.2"] {
            let tool = Tool::parse(spec).unwrap();
            for _ in 0..400 {
                let (x, y) = (0.5 + 3.8 * rnd(), 0.5 + 3.8 * rnd());
                let (len, ang) = (0.05 + 3.0 * rnd(), std::f64::consts::TAU * rnd());
                let (x2, y2) = (x + len * ang.cos(), y + len * ang.sin());
                let (Some(za), Some(zb)) = (hf.drop(&tool, x, y), hf.drop(&tool, x2, y2)) else {
                    continue;
                };
                // ends on the CL surface, or one lifted by up to 0.1 mm, or
                // both level at the higher
                let pick = rnd();
                let (za, zb) = if pick < 0.3 {
                    (za.max(zb), za.max(zb))
                } else if pick < 0.65 {
                    (za, zb + 0.1 * rnd())
                } else {
                    (za, zb)
                };
                let (a, b) = (DVec3::new(x, y, za), DVec3::new(x2, y2, zb));
                let whole = sample_gouge(&hf, &tool, a, b, false);
                let part = sample_gouge(&hf, &tool, a, b, true);
                if whole > 0.0 {
                    cutting += 1;
                }
                // (a touch at an end itself is rounding: 2e-16 mm)
                assert!(
                    (whole.max(1e-9) - part.max(1e-9)).abs() <= 1e-12,
                    "{spec}: {a} -> {b} cuts {whole} with the whole sweep, {part} without the lower end's"
                );
            }
        }
        assert!(cutting > 100, "only {cutting} moves cut");
    }

    /// A ball's merged rows (points up to 2.4 samples apart) checked with
    /// their dropped points as probes
    /// flag every move a dense scan of the CL surface finds cutting more
    /// than CHECK and a half (the probes' own allowance), and the moves
    /// the probes of `move_gouge` flag, but for the few right at CHECK.
    #[test]
    fn dropped_points_probe_as_well_as_probes() {
        let hf = field(128, 5);
        let tool = Tool::parse("ball:1.5").unwrap();
        let (mut moves, mut dense_flags, mut differ) = (0, 0, 0);
        for row in 0..24 {
            let y = 0.6 + row as f64 * 0.21;
            // points up to 2.4 samples apart, unrefined: the CL surface
            // bulges between them
            let step = 0.05 * (1.0 + 0.07 * row as f64);
            let xy: Vec<(f64, f64)> = (0..=(5.4 / step) as usize)
                .map(|i| (0.5 + i as f64 * step, y))
                .collect();
            let drops = drop_along(&hf, &tool, &xy, -10.0, Refine::None);
            for tol in [0.005, 0.02] {
                let pts = merge(&drops, tol);
                let s = stretches(&pts, &drops).expect("a merged row is a subsequence");
                for (k, w) in pts.windows(2).enumerate() {
                    let (a, b) = (w[0], w[1]);
                    let (i, j) = s[k];
                    let by_drops = dropped_move_gouge(&hf, &tool, a, b, &drops[i..=j]);
                    let by_probes = move_gouge(&hf, &tool, a, b, true);
                    let n = ((b - a).truncate().length() / 0.002).ceil() as usize + 1;
                    let dense = (0..=n)
                        .map(|t| {
                            let q = a + (b - a) * (t as f64 / n as f64);
                            hf.drop(&tool, q.x, q.y).unwrap() - q.z
                        })
                        .fold(f64::NEG_INFINITY, f64::max);
                    moves += 1;
                    if dense > 1.5 * CHECK {
                        dense_flags += 1;
                        assert!(
                            by_drops > CHECK,
                            "{a} -> {b}: cuts {dense}, the dropped points say {by_drops}"
                        );
                    }
                    if (by_drops > CHECK) != (by_probes > CHECK) {
                        differ += 1;
                        assert!(
                            by_drops.max(by_probes) < 2.0 * CHECK,
                            "{a} -> {b}: {by_drops} by the dropped points, {by_probes} by probes"
                        );
                    }
                }
            }
        }
        eprintln!("{moves} moves, {dense_flags} cut by more than 1.5 CHECK, {differ} flagged by one check only");
        assert!(dense_flags > 0 && differ * 50 <= moves);
    }
}
