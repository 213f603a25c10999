//! Software z-buffer. Vertices are snapped to 1/256 pixel and edges are
//! evaluated in exact integer arithmetic with the top-left fill rule, so
//! triangles sharing an edge cover every pixel centre exactly once: no
//! cracks, no double hits. Rows are split into strips rasterized in
//! parallel; each triangle is binned to the strips its bounds touch.

use crate::grid::Grid;
use rayon::prelude::*;

const SUB: i64 = 256;
const STRIP: usize = 8;

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
    })
}

/// Call `f(x, y, h)` for every pixel centre inside `t` within rows `ya..yb`.
#[inline]
fn scan(t: &Setup, ya: usize, yb: usize, mut f: impl FnMut(usize, usize, f64)) {
    let inv = 1.0 / t.area as f64;
    let edges = [0, 1, 2].map(|k| (t.v[(k + 1) % 3], t.v[(k + 2) % 3]));
    for y in t.y0.max(ya)..=t.y1.min(yb - 1) {
        let py = y as i64 * SUB + SUB / 2;
        let px = t.x0 as i64 * SUB + SUB / 2;
        let mut e = edges.map(|(a, b)| (b[0] - a[0]) * (py - a[1]) - (b[1] - a[1]) * (px - a[0]));
        let step = edges.map(|(a, b)| -(b[1] - a[1]) * SUB);
        for x in t.x0..=t.x1 {
            if e[0] >= t.bias[0] && e[1] >= t.bias[1] && e[2] >= t.bias[2] {
                let h = (e[0] as f64 * t.h[0] + e[1] as f64 * t.h[1] + e[2] as f64 * t.h[2]) * inv;
                f(x, y, h);
            }
            for k in 0..3 {
                e[k] += step[k];
            }
        }
    }
}

fn prepare(
    points: &[[f64; 3]],
    tris: &[[u32; 3]],
    ids: &[u16],
    slopes: Option<&[CornerSlopes]>,
    w: usize,
    h: usize,
) -> (Vec<Setup>, Vec<Vec<u32>>) {
    let setups: Vec<Setup> = tris
        .par_iter()
        .zip(ids.par_iter())
        .enumerate()
        .filter_map(|(k, (t, &id))| {
            let corner = slopes.map_or([[0.0; 2]; 3], |s| s[k]);
            setup(t.map(|i| points[i as usize]), id, corner, w, h)
        })
        .collect();
    let mut bins = vec![Vec::new(); h.div_ceil(STRIP)];
    for (k, s) in setups.iter().enumerate() {
        for b in bins.iter_mut().take(s.y1 / STRIP + 1).skip(s.y0 / STRIP) {
            b.push(k as u32);
        }
    }
    (setups, bins)
}

/// Rasterize triangles (pixel-space points with depth) into a `w x h`
/// depth buffer; the nearest surface (largest h) wins. `ids[k]` is the
/// object id (> 0) of triangle k; `slopes[k]`, if given, its smooth
/// corner slopes.
pub fn rasterize(
    points: &[[f64; 3]],
    tris: &[[u32; 3]],
    ids: &[u16],
    slopes: Option<&[CornerSlopes]>,
    w: usize,
    h: usize,
) -> (Grid<f32>, Grid<u16>, Surfaces) {
    let (setups, bins) = prepare(points, tris, ids, slopes, w, h);
    let mut depth = Grid::new(w, h, 0.0f32);
    let mut idg = Grid::new(w, h, 0u16);
    let mut tri = Grid::new(w, h, 0u32);
    depth
        .data
        .par_chunks_mut(w * STRIP)
        .zip(idg.data.par_chunks_mut(w * STRIP))
        .zip(tri.data.par_chunks_mut(w * STRIP))
        .zip(bins.par_iter())
        .enumerate()
        .for_each(|(s, (((dz, di), dt), bin))| {
            let ya = s * STRIP;
            let yb = (ya + STRIP).min(h);
            for &k in bin {
                let t = &setups[k as usize];
                scan(t, ya, yb, |x, y, hv| {
                    let i = (y - ya) * w + x;
                    let hv = hv as f32;
                    if di[i] == 0 || hv > dz[i] {
                        dz[i] = hv;
                        di[i] = t.id;
                        dt[i] = k + 1;
                    }
                });
            }
        });
    let surfaces = Surfaces {
        tri,
        tris: setups,
        smooth: slopes.is_some(),
    };
    (depth, idg, surfaces)
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
    let (setups, _) = prepare(points, tris, &ids, None, w, h);
    let mut g = Grid::new(w, h, 0u32);
    for t in &setups {
        scan(t, 0, h, |x, y, _| g.data[y * w + x] += 1);
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
        let (d, id, _) = rasterize(&pts, &[[0, 1, 2], [3, 4, 5]], &[1, 2], None, 10, 10);
        assert_eq!(*id.get(0, 0), 2);
        assert_eq!(*id.get(7, 1), 1);
        assert!((*d.get(7, 1) - 0.2).abs() < 1e-6);
        // h at pixel (0,0) centre (0.5,0.5): 0.9 - 0.8 * (0.5/10 + 0.5/10)
        assert!((*d.get(0, 0) - 0.82).abs() < 1e-5);
        assert_eq!(*id.get(9, 9), 0);
    }
}
