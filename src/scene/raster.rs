//! Software z-buffer. Vertices are snapped to 1/256 pixel and edges are
//! evaluated in exact integer arithmetic with the top-left fill rule, so
//! triangles sharing an edge cover every pixel centre exactly once: no
//! cracks, no double hits.
//!
//! The work is bounded by what the picture shows, not by triangles times
//! their area: triangles are drawn nearest first into tiles, and a tile
//! skips a triangle whose plane lies behind everything the tile already
//! holds (a coarse depth test), so a pile of large overlapping triangles
//! costs about as much as its front layers. Rows of tiles are drawn in
//! parallel; each triangle is binned to the rows its bounds touch.

use crate::grid::Grid;
use rayon::prelude::*;

const SUB: i64 = 256;
/// Side of a tile (pixels): rows of tiles are the parallel tasks; a tile
/// keeps the farthest depth it holds for the coarse test.
const TILE: usize = 32;
/// Pixel tests a render may take before it stops (about 15 s on two
/// cores). A real scan takes two or three per pixel, a million random
/// triangles each a tenth of the picture a few hundred.
pub const MAX_PIXEL_TESTS: u64 = 6_000_000_000;

/// Depth buffer of a scene: h in [0,1] (1 = near), object id (0 = background).
#[derive(Clone, Debug)]
pub struct DepthMap {
    pub h: Grid<f32>,
    pub id: Grid<u16>,
    /// Object names; id k > 0 is `objects[k - 1]`.
    pub objects: Vec<String>,
    /// Which triangle each sample shows, when the scene is a mesh: outlines
    /// then come from the geometry instead of a slope threshold.
    pub surfaces: Option<Surfaces>,
}

/// The surface behind every sample of a rendered mesh.
#[derive(Clone, Debug)]
pub struct Surfaces {
    /// 1 + index into `tris` per sample; 0 = background.
    pub tri: Grid<u32>,
    tris: Vec<Setup>,
    /// Whether the triangles carry slopes from smooth normals.
    smooth: bool,
}

/// Depth slopes (h per pixel in x and y) of a triangle's tangent planes at
/// its three corners, from smooth vertex normals.
pub type CornerSlopes = [[f32; 2]; 3];

/// One triangle ready to scan: vertices in fixed point, counter-oriented so
/// that the inside has positive edge values.
#[derive(Clone, Debug)]
struct Setup {
    v: [[i64; 2]; 3],
    h: [f64; 3],
    area: i64,
    /// 0 for a top-left edge, 1 otherwise (edge k is opposite vertex k).
    bias: [i64; 3],
    x0: usize,
    x1: usize,
    y0: usize,
    y1: usize,
    id: u16,
    /// No sample of the triangle is nearer than this (its nearest corner,
    /// rounded up past f32 rounding).
    top: f32,
    /// The plane h = a x + b y + c in fixed-point pixel coordinates.
    plane: [f64; 3],
    /// The smooth slopes in x and y interpolated across the triangle from
    /// its corners, as planes like `plane` (zero without smooth shading).
    slope: [[f64; 3]; 2],
}

fn setup(p: [[f64; 3]; 3], id: u16, corner: CornerSlopes, w: usize, h: usize) -> Option<Setup> {
    let mut corner = corner;
    let mut v = p.map(|q| {
        [
            (q[0] * SUB as f64).round() as i64,
            (q[1] * SUB as f64).round() as i64,
        ]
    });
    let mut hh = p.map(|q| q[2]);
    let e = |a: [i64; 2], b: [i64; 2], c: [i64; 2]| {
        (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
    };
    let mut area = e(v[0], v[1], v[2]);
    if area == 0 {
        return None;
    }
    if area < 0 {
        v.swap(1, 2);
        hh.swap(1, 2);
        corner.swap(1, 2);
        area = -area;
    }
    let bias = [0, 1, 2].map(|k| {
        let (a, b) = (v[(k + 1) % 3], v[(k + 2) % 3]);
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        if (dy == 0 && dx > 0) || dy < 0 {
            0
        } else {
            1
        }
    });
    let minx = v.iter().map(|q| q[0]).min().unwrap();
    let maxx = v.iter().map(|q| q[0]).max().unwrap();
    let miny = v.iter().map(|q| q[1]).min().unwrap();
    let maxy = v.iter().map(|q| q[1]).max().unwrap();
    // Pixel x covers centre x*SUB + SUB/2.
    let lo = |m: i64| (m - SUB / 2 + SUB - 1).div_euclid(SUB).max(0);
    let hi = |m: i64, n: usize| (m - SUB / 2).div_euclid(SUB).min(n as i64 - 1);
    let (x0, x1, y0, y1) = (lo(minx), hi(maxx, w), lo(miny), hi(maxy, h));
    if x0 > x1 || y0 > y1 {
        return None;
    }
    // h is affine in the edge values, which are affine in (x, y); so are
    // the interpolated slopes
    let plane_of = |f: [f64; 3]| {
        let at =
            |p: [f64; 2]| (0..3).map(|k| edge_value(&v, k, p) * f[k]).sum::<f64>() / area as f64;
        let c = at([0.0, 0.0]);
        [at([1.0, 0.0]) - c, at([0.0, 1.0]) - c, c]
    };
    let plane = plane_of(hh);
    let slope = [0, 1].map(|a| plane_of(corner.map(|c| c[a] as f64)));
    Some(Setup {
        v,
        h: hh,
        area,
        bias,
        plane,
        slope,
        x0: x0 as usize,
        x1: x1 as usize,
        y0: y0 as usize,
        y1: y1 as usize,
        id,
        top: f32_above(hh.iter().fold(f64::MIN, |a, &b| a.max(b))),
    })
}

/// The least f32 above `h` and above any f32 that an interpolation of
/// values up to `h` rounds to.
fn f32_above(h: f64) -> f32 {
    let f = (h + 1e-9 * h.abs().max(1.0)) as f32;
    f32::from_bits(if f >= 0.0 {
        f.to_bits() + 1
    } else {
        f.to_bits() - 1
    })
}

/// Call `f(x, y, h)` for every pixel centre inside `t` within rows
/// `ya..yb` and columns `xa..xb`; returns how many centres it tested.
#[inline]
fn scan(
    t: &Setup,
    (ya, yb): (usize, usize),
    (xa, xb): (usize, usize),
    mut f: impl FnMut(usize, usize, f64),
) -> u64 {
    let inv = 1.0 / t.area as f64;
    let edges = [0, 1, 2].map(|k| (t.v[(k + 1) % 3], t.v[(k + 2) % 3]));
    let (x0, x1) = (t.x0.max(xa), t.x1.min(xb - 1));
    let (y0, y1) = (t.y0.max(ya), t.y1.min(yb - 1));
    if x0 > x1 || y0 > y1 {
        return 0;
    }
    for y in y0..=y1 {
        let py = y as i64 * SUB + SUB / 2;
        let px = x0 as i64 * SUB + SUB / 2;
        let mut e = edges.map(|(a, b)| (b[0] - a[0]) * (py - a[1]) - (b[1] - a[1]) * (px - a[0]));
        let step = edges.map(|(a, b)| -(b[1] - a[1]) * SUB);
        for x in x0..=x1 {
            if e[0] >= t.bias[0] && e[1] >= t.bias[1] && e[2] >= t.bias[2] {
                let h = (e[0] as f64 * t.h[0] + e[1] as f64 * t.h[1] + e[2] as f64 * t.h[2]) * inv;
                f(x, y, h);
            }
            for k in 0..3 {
                e[k] += step[k];
            }
        }
    }
    ((x1 - x0 + 1) * (y1 - y0 + 1)) as u64
}

/// How many times its area the triangles' bounds may cover before a
/// picture counts as deep: only then are they drawn nearest first with the
/// coarse depth test, which costs a real scan (two or three deep) more than
/// it saves, as it takes triangles out of their file's spatial order.
const DEEP: u64 = 16;

/// The triangles ready to scan, per row of tiles the ones whose bounds touch
/// it, and whether the picture is deep. A deep picture's triangles come
/// nearest first (ties in file order, so the result is the same as drawing
/// them in file order with the first of equals winning).
fn prepare(
    points: &[[f64; 3]],
    tris: &[[u32; 3]],
    ids: &[u16],
    slopes: Option<&[CornerSlopes]>,
    w: usize,
    h: usize,
) -> (Vec<Setup>, Vec<Vec<u32>>, bool) {
    let setups: Vec<Setup> = tris
        .par_iter()
        .zip(ids.par_iter())
        .enumerate()
        .filter_map(|(k, (t, &id))| {
            let corner = slopes.map_or([[0.0; 2]; 3], |s| s[k]);
            setup(t.map(|i| points[i as usize]), id, corner, w, h)
        })
        .collect();
    let covered: u64 = setups
        .par_iter()
        .map(|t| ((t.x1 - t.x0 + 1) * (t.y1 - t.y0 + 1)) as u64)
        .sum();
    let deep = covered > DEEP * (w * h) as u64;
    let mut order: Vec<u32> = (0..setups.len() as u32).collect();
    if deep {
        order.par_sort_unstable_by(|&a, &b| {
            let (ta, tb) = (&setups[a as usize], &setups[b as usize]);
            tb.top.total_cmp(&ta.top).then(a.cmp(&b))
        });
    }
    let mut bins = vec![Vec::new(); h.div_ceil(TILE)];
    for &k in &order {
        let s = &setups[k as usize];
        for b in bins.iter_mut().take(s.y1 / TILE + 1).skip(s.y0 / TILE) {
            b.push(k);
        }
    }
    (setups, bins, deep)
}

/// The render took more pixel tests than `MAX_PIXEL_TESTS`: the triangles
/// are many, large and stacked deep.
#[derive(Debug)]
pub struct TooDeep {
    pub triangles: usize,
}

/// One row of tiles being drawn: its depth, id and triangle rows.
struct Band<'a> {
    depth: &'a mut [f32],
    id: &'a mut [u16],
    tri: &'a mut [u32],
    w: usize,
    /// First image row of the band, and one past its last.
    rows: (usize, usize),
    /// Per tile: the farthest depth it holds (-inf while any of its samples
    /// shows the background), and the tests made since that was taken.
    far: Vec<f32>,
    since: Vec<u64>,
    /// The tiles still open, in order: a tile closes for good once it holds
    /// nothing farther than the next triangle's nearest, as every later
    /// triangle is farther still.
    open: Vec<usize>,
    /// The columns and rows any triangle reaches: samples outside stay
    /// background whatever is drawn, so the coarse test leaves them out.
    reach: ((usize, usize), (usize, usize)),
}

impl Band<'_> {
    /// The farthest depth tile `c` holds where a triangle can reach, or
    /// -inf if it shows background there.
    fn farthest(&self, c: usize) -> f32 {
        let ((rx0, rx1), (ry0, ry1)) = self.reach;
        let (xa, xb) = ((c * TILE).max(rx0), ((c + 1) * TILE).min(self.w).min(rx1));
        let (ya, yb) = (self.rows.0.max(ry0), self.rows.1.min(ry1));
        let mut far = f32::INFINITY;
        for y in ya.saturating_sub(self.rows.0)..yb.saturating_sub(self.rows.0) {
            for x in xa..xb {
                let i = y * self.w + x;
                if self.tri[i] == 0 {
                    return f32::NEG_INFINITY;
                }
                far = far.min(self.depth[i]);
            }
        }
        far
    }

    /// Draw triangle `k` into tile `c`, unless the coarse test shows it
    /// behind; returns the pixel tests made.
    fn draw(&mut self, t: &Setup, k: u32, c: usize) -> u64 {
        let (ya, yb) = self.rows;
        let (xa, xb) = (c * TILE, ((c + 1) * TILE).min(self.w));
        if !t.meets((xa, xb), (ya, yb))
            || (self.far[c] > f32::NEG_INFINITY && t.nearest_in((xa, xb), (ya, yb)) < self.far[c])
        {
            return 0;
        }
        let n = self.scan(t, k, (xa, xb));
        self.since[c] += n;
        if self.since[c] >= (TILE * TILE) as u64 {
            self.since[c] = 0;
            self.far[c] = self.farthest(c);
        }
        n
    }

    /// Draw triangle `k` within columns `xa..xb` of the band; returns the
    /// pixel tests made.
    fn scan(&mut self, t: &Setup, k: u32, (xa, xb): (usize, usize)) -> u64 {
        let (ya, yb) = self.rows;
        let w = self.w;
        let (dz, di, dt) = (&mut *self.depth, &mut *self.id, &mut *self.tri);
        scan(t, (ya, yb), (xa, xb), |x, y, hv| {
            let i = (y - ya) * w + x;
            let hv = hv as f32;
            // the first of equals in file order wins, as drawn in that order
            if di[i] == 0 || hv > dz[i] || (hv == dz[i] && k + 1 < dt[i]) {
                dz[i] = hv;
                di[i] = t.id;
                dt[i] = k + 1;
            }
        })
    }
}

/// Rasterize triangles (pixel-space points with depth) into a `w x h`
/// depth buffer; the nearest surface (largest h) wins. `ids[k]` is the
/// object id (> 0) of triangle k; `slopes[k]`, if given, its smooth
/// corner slopes. `progress` is told the share of rows drawn. Past
/// `max_tests` pixel tests the render stops.
pub fn rasterize(
    points: &[[f64; 3]],
    tris: &[[u32; 3]],
    ids: &[u16],
    slopes: Option<&[CornerSlopes]>,
    (w, h): (usize, usize),
    (progress, max_tests): (&(dyn Fn(f64) + Sync), u64),
) -> Result<(Grid<f32>, Grid<u16>, Surfaces), TooDeep> {
    use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering::Relaxed};
    let (setups, bins, deep) = prepare(points, tris, ids, slopes, w, h);
    let mut depth = Grid::new(w, h, 0.0f32);
    let mut idg = Grid::new(w, h, 0u16);
    let mut tri = Grid::new(w, h, 0u32);
    let (tests, over, done) = (
        AtomicU64::new(0),
        AtomicBool::new(false),
        AtomicUsize::new(0),
    );
    let cols = w.div_ceil(TILE);
    // (only the coarse test of a deep picture asks)
    let reach = setups
        .iter()
        .filter(|_| deep)
        .fold(((w, 0), (h, 0)), |((x0, x1), (y0, y1)), t| {
            (
                (x0.min(t.x0), x1.max(t.x1 + 1)),
                (y0.min(t.y0), y1.max(t.y1 + 1)),
            )
        });
    depth
        .data
        .par_chunks_mut(w * TILE)
        .zip(idg.data.par_chunks_mut(w * TILE))
        .zip(tri.data.par_chunks_mut(w * TILE))
        .zip(bins.par_iter())
        .enumerate()
        .for_each(|(s, (((depth, id), tri), bin))| {
            let ya = s * TILE;
            let mut band = Band {
                reach,
                depth,
                id,
                tri,
                w,
                rows: (ya, (ya + TILE).min(h)),
                far: vec![f32::NEG_INFINITY; cols],
                since: vec![0; cols],
                open: Vec::with_capacity(cols),
            };
            // tiles no triangle reaches hold nothing to be behind
            if deep {
                for c in 0..cols {
                    band.far[c] = band.farthest(c);
                    if band.far[c] < f32::INFINITY {
                        band.open.push(c);
                    }
                }
            }
            let mut made = 0u64;
            let flush = (max_tests / 16).clamp(1, 1 << 24);
            for &k in bin {
                let t = &setups[k as usize];
                if !deep {
                    made += band.scan(t, k, (0, w));
                    continue;
                }
                let (c0, c1) = (t.x0 / TILE, t.x1 / TILE);
                let mut i = band.open.partition_point(|&c| c < c0);
                while i < band.open.len() && band.open[i] <= c1 {
                    let c = band.open[i];
                    if t.top < band.far[c] {
                        band.open.remove(i);
                    } else {
                        made += band.draw(t, k, c);
                        i += 1;
                    }
                }
                if band.open.is_empty() {
                    break;
                }
                if made > flush {
                    let all = tests.fetch_add(made, Relaxed) + made;
                    made = 0;
                    if all > max_tests {
                        over.store(true, Relaxed);
                    }
                    if over.load(Relaxed) {
                        return;
                    }
                }
            }
            tests.fetch_add(made, Relaxed);
            let d = done.fetch_add(1, Relaxed) + 1;
            progress(d as f64 / bins.len().max(1) as f64);
        });
    if over.load(Relaxed) {
        return Err(TooDeep {
            triangles: tris.len(),
        });
    }
    let surfaces = Surfaces {
        tri,
        tris: setups,
        smooth: slopes.is_some(),
    };
    Ok((depth, idg, surfaces))
}

/// Edge k's function (edge k is opposite vertex k) at a point in fixed
/// point, in floating point: positive inside, as `scan` evaluates it.
#[inline]
fn edge_value(v: &[[i64; 2]; 3], k: usize, p: [f64; 2]) -> f64 {
    let (a, b) = (v[(k + 1) % 3], v[(k + 2) % 3]);
    (b[0] - a[0]) as f64 * (p[1] - a[1] as f64) - (b[1] - a[1]) as f64 * (p[0] - a[0] as f64)
}

impl Setup {
    /// Signed distance of a point (fixed point) from each edge line,
    /// positive inside; edge k is opposite vertex k.
    fn distances(&self, p: [f64; 2]) -> [f64; 3] {
        [0, 1, 2].map(|k| {
            let (a, b) = (self.v[(k + 1) % 3], self.v[(k + 2) % 3]);
            edge_value(&self.v, k, p) / ((b[0] - a[0]) as f64).hypot((b[1] - a[1]) as f64)
        })
    }

    /// No sample of the triangle inside columns `xa..xb` and rows `ya..yb`
    /// is nearer than this: its plane's highest over the part of its bounds
    /// there (a corner of that rectangle), past rounding.
    fn nearest_in(&self, (xa, xb): (usize, usize), (ya, yb): (usize, usize)) -> f32 {
        let (x0, x1) = (self.x0.max(xa), self.x1.min(xb - 1));
        let (y0, y1) = (self.y0.max(ya), self.y1.min(yb - 1));
        let c = |i: usize| (i as i64 * SUB + SUB / 2) as f64;
        let [a, b, k] = self.plane;
        let px = if a > 0.0 { c(x1) } else { c(x0) };
        let py = if b > 0.0 { c(y1) } else { c(y0) };
        let h = a * px + b * py + k;
        let err = 1e-12 * ((a * px).abs() + (b * py).abs() + k.abs());
        f32_above(h + err).min(self.top)
    }

    /// Whether the triangle may cover a sample centre in columns `xa..xb`
    /// and rows `ya..yb`: no edge has the whole rectangle outside it.
    fn meets(&self, (xa, xb): (usize, usize), (ya, yb): (usize, usize)) -> bool {
        let c = |i: usize| i as i64 * SUB + SUB / 2;
        let (x0, x1, y0, y1) = (c(xa), c(xb - 1), c(ya), c(yb - 1));
        (0..3).all(|k| {
            let (a, b) = (self.v[(k + 1) % 3], self.v[(k + 2) % 3]);
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            // the corner where the edge function is largest
            let px = if dy < 0 { x1 } else { x0 };
            let py = if dx > 0 { y1 } else { y0 };
            dx * (py - a[1]) - dy * (px - a[0]) >= self.bias[k]
        })
    }

    /// The triangle's plane: depth at any point, inside or not.
    #[inline]
    fn depth_at(&self, p: [f64; 2]) -> f64 {
        self.plane[0] * p[0] + self.plane[1] * p[1] + self.plane[2]
    }
}

/// How far (pixels) a plane crossing may lie outside the two triangles and
/// still count as their common edge: rounding only, since triangles that
/// share an edge share its snapped vertices exactly.
const EDGE_SLACK: f64 = 0.02;

impl Surfaces {
    /// Fixed-point centre of sample (x, y).
    fn centre(x: usize, y: usize) -> [f64; 2] {
        [
            (x as i64 * SUB + SUB / 2) as f64,
            (y as i64 * SUB + SUB / 2) as f64,
        ]
    }

    /// The smooth slope (h per pixel) at sample (x, y): the corner slopes
    /// interpolated across its triangle; `None` without smooth shading or
    /// on the background.
    pub fn smooth_slope(&self, x: usize, y: usize) -> Option<[f64; 2]> {
        if !self.smooth {
            return None;
        }
        let t = *self.tri.get(x, y);
        if t == 0 {
            return None;
        }
        let s = &self.tris[t as usize - 1];
        let [px, py] = Self::centre(x, y);
        Some(s.slope.map(|[a, b, c]| a * px + b * py + c))
    }

    /// Whether the edge between samples a and b (neighbours) is an outline:
    /// one side is background, or the two sides are not one continuous
    /// surface. Continuous means: the two samples' planes agree at both
    /// samples within `tol` (a smooth surface finely tessellated, or one
    /// plane), or they meet between the samples on an edge both triangles
    /// reach (a crease, however steep either side is).
    #[inline]
    pub fn outline(&self, a: (usize, usize), b: (usize, usize), tol: f64) -> bool {
        let (ta, tb) = (*self.tri.get(a.0, a.1), *self.tri.get(b.0, b.1));
        if ta == tb {
            return false;
        }
        if ta == 0 || tb == 0 {
            return true;
        }
        self.apart(ta, tb, a, b, tol)
    }

    /// `outline` for two different triangles.
    #[inline(never)]
    fn apart(&self, ta: u32, tb: u32, a: (usize, usize), b: (usize, usize), tol: f64) -> bool {
        let (sa, sb) = (&self.tris[ta as usize - 1], &self.tris[tb as usize - 1]);
        let (pa, pb) = (Self::centre(a.0, a.1), Self::centre(b.0, b.1));
        let d0 = sa.depth_at(pa) - sb.depth_at(pa);
        let d1 = sa.depth_at(pb) - sb.depth_at(pb);
        if d0.abs().max(d1.abs()) <= tol {
            return false;
        }
        if d0 * d1 < 0.0 {
            let s = d0 / (d0 - d1);
            let p = [pa[0] + s * (pb[0] - pa[0]), pa[1] + s * (pb[1] - pa[1])];
            let slack = -EDGE_SLACK * SUB as f64;
            let inside = |t: &Setup| t.distances(p).iter().all(|&d| d >= slack);
            if inside(sa) && inside(sb) {
                return false;
            }
        }
        true
    }
}

/// How many triangles cover each pixel centre (for the fill-rule tests).
pub fn coverage(points: &[[f64; 3]], tris: &[[u32; 3]], w: usize, h: usize) -> Grid<u32> {
    let ids = vec![1u16; tris.len()];
    let (setups, _, _) = prepare(points, tris, &ids, None, w, h);
    let mut g = Grid::new(w, h, 0u32);
    for t in &setups {
        scan(t, (0, h), (0, w), |x, y, _| g.data[y * w + x] += 1);
    }
    g
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A jittered grid mesh, including vertices exactly on pixel centres and
    /// edges through them, must cover every pixel inside exactly once.
    #[test]
    fn shared_edges_leave_no_crack_and_no_overlap() {
        let n = 13;
        let mut pts = Vec::new();
        let mut seed = 12345u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 33) as f64 / (1u64 << 31) as f64) - 0.5
        };
        for j in 0..=n {
            for i in 0..=n {
                let border = i == 0 || j == 0 || i == n || j == n;
                // border vertices and every third one sit exactly on a pixel centre
                let (jx, jy) = if border || (i + j) % 3 == 0 {
                    (0.0, 0.0)
                } else {
                    (rnd() * 1.5, rnd() * 1.5)
                };
                pts.push([
                    2.0 + i as f64 * 4.0 + 0.5 + jx,
                    2.0 + j as f64 * 4.0 + 0.5 + jy,
                    0.5,
                ]);
            }
        }
        let mut tris = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let a = (j * (n + 1) + i) as u32;
                let (b, c, d) = (a + 1, a + n as u32 + 1, a + n as u32 + 2);
                if (i + j) % 2 == 0 {
                    tris.push([a, b, d]);
                    tris.push([a, d, c]);
                } else {
                    tris.push([a, b, c]);
                    tris.push([b, d, c]);
                }
            }
        }
        let size = 4 * n + 6;
        let cov = coverage(&pts, &tris, size, size);
        for y in 0..size {
            for x in 0..size {
                let inside = x >= 2 && x < 2 + 4 * n && y >= 2 && y < 2 + 4 * n;
                assert_eq!(*cov.get(x, y), inside as u32, "pixel ({x},{y})");
            }
        }
    }

    #[test]
    fn nearest_surface_wins_and_depth_is_interpolated() {
        let pts = [
            [0.0, 0.0, 0.2],
            [10.0, 0.0, 0.2],
            [0.0, 10.0, 0.2],
            [0.0, 0.0, 0.9],
            [10.0, 0.0, 0.1],
            [0.0, 10.0, 0.1],
        ];
        let (d, id, _) = rasterize(
            &pts,
            &[[0, 1, 2], [3, 4, 5]],
            &[1, 2],
            None,
            (10, 10),
            (&|_| {}, u64::MAX),
        )
        .unwrap();
        assert_eq!(*id.get(0, 0), 2);
        assert_eq!(*id.get(7, 1), 1);
        assert!((*d.get(7, 1) - 0.2).abs() < 1e-6);
        // h at pixel (0,0) centre (0.5,0.5): 0.9 - 0.8 * (0.5/10 + 0.5/10)
        assert!((*d.get(0, 0) - 0.82).abs() < 1e-5);
        assert_eq!(*id.get(9, 9), 0);
    }

    /// Random triangles of a deep pile (drawn nearest first, with the coarse
    /// test), duplicates among them, give exactly what drawing every one in
    /// file order gives with the first of equals winning.
    #[test]
    fn a_deep_pile_draws_as_file_order_does() {
        let (w, h) = (70, 45);
        let mut rnd = crate::testing::rng(99);
        let mut pts = Vec::new();
        let mut tris = Vec::new();
        for k in 0..3000u32 {
            if k % 7 == 3 {
                // the same triangle again: a tie at every sample
                let t: [u32; 3] = tris[(k as usize) / 2];
                tris.push(t);
                continue;
            }
            for _ in 0..3 {
                pts.push([rnd() * 80.0 - 5.0, rnd() * 55.0 - 5.0, rnd()]);
            }
            let n = pts.len() as u32;
            tris.push([n - 3, n - 2, n - 1]);
        }
        let ids: Vec<u16> = (0..tris.len()).map(|k| (k % 5 + 1) as u16).collect();
        let (setups, _, deep) = prepare(&pts, &tris, &ids, None, w, h);
        assert!(deep, "the pile must take the deep path");
        let (d, id, s) = rasterize(&pts, &tris, &ids, None, (w, h), (&|_| {}, u64::MAX)).unwrap();
        // the reference: every triangle in file order, the first of equals wins
        let mut rd = Grid::new(w, h, 0.0f32);
        let mut rid = Grid::new(w, h, 0u16);
        let mut rt = Grid::new(w, h, 0u32);
        for (k, t) in setups.iter().enumerate() {
            scan(t, (0, h), (0, w), |x, y, hv| {
                let (i, hv) = (y * w + x, hv as f32);
                if rid.data[i] == 0 || hv > rd.data[i] {
                    rd.data[i] = hv;
                    rid.data[i] = t.id;
                    rt.data[i] = k as u32 + 1;
                }
            });
        }
        assert_eq!(d.data, rd.data);
        assert_eq!(id.data, rid.data);
        assert_eq!(s.tri.data, rt.data);
        assert!(
            rt.data.iter().all(|&t| t > 0),
            "the pile covers the picture"
        );
    }

    /// A render past its budget of pixel tests stops and says so.
    #[test]
    fn a_render_past_its_budget_stops() {
        let pts: Vec<[f64; 3]> = (0..300)
            .map(|k| {
                let a = k as f64 * 2.399;
                [
                    50.0 + 60.0 * a.cos(),
                    50.0 + 60.0 * a.sin(),
                    (k % 13) as f64 / 13.0,
                ]
            })
            .collect();
        let tris: Vec<[u32; 3]> = (0..100).map(|k| [3 * k, 3 * k + 1, 3 * k + 2]).collect();
        let ids = vec![1u16; tris.len()];
        let r = rasterize(&pts, &tris, &ids, None, (100, 100), (&|_| {}, 20_000));
        assert_eq!(r.err().map(|e| e.triangles), Some(100));
        assert!(rasterize(&pts, &tris, &ids, None, (100, 100), (&|_| {}, u64::MAX)).is_ok());
    }
}
