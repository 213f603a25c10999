//! Gradients -> silhouettes -> compression -> downsampling, fused in one
//! parallel pass over output rows so that a 2x-supersampled buffer never
//! needs full-size gradient arrays.
//!
//! Units (DESIGN.md section 2): g = N (h(i+1) - h(i)) with N the long side
//! of the buffer in pixels, so a slope is scene depth per image width and
//! flags mean the same at every resolution. A silhouette is an edge between
//! neighbouring samples whose slope exceeds the threshold; it is zeroed,
//! and remembered as a unit step in its original direction so that
//! `--steps` can trace it with a constant height.

use crate::grid::Grid;
use crate::scene::DepthMap;
use rayon::prelude::*;

/// The shaped gradient field at output resolution.
pub struct Field {
    /// Compressed slopes (silhouettes zeroed), slope units.
    pub gx: Grid<f32>,
    pub gy: Grid<f32>,
    /// Unit steps at silhouette edges, downsampled like the slopes.
    pub sx: Grid<f32>,
    pub sy: Grid<f32>,
    /// Output pixels touching a silhouette edge: barriers for diffusion.
    pub barrier: Grid<bool>,
    /// Foreground (not background) output pixels.
    pub mask: Grid<bool>,
    /// Object id per output pixel (0 = background).
    pub id: Grid<u16>,
    /// Depth buffer at output resolution (box average), for `--method linear`.
    pub depth: Grid<f32>,
    /// Long side of the source buffer in pixels (the unit of a step).
    pub n_fine: usize,
    /// Number of silhouette edges found in the source buffer.
    pub silhouette_edges: usize,
}

/// Silhouette threshold and compression.
#[derive(Clone, Copy, Debug)]
pub struct Shaping {
    pub alpha: f64,
    pub threshold: f64,
}

/// What the field is computed from, at source resolution.
pub trait Source: Sync {
    fn size(&self) -> (usize, usize);
    /// Raw forward-difference slope at (x, y); 0 past the last column/row.
    fn slope(&self, x: usize, y: usize) -> (f32, f32);
    fn depth(&self, x: usize, y: usize) -> f32;
    fn id(&self, x: usize, y: usize) -> u16;
}

impl Source for DepthMap {
    fn size(&self) -> (usize, usize) {
        (self.h.w, self.h.h)
    }
    fn slope(&self, x: usize, y: usize) -> (f32, f32) {
        let n = self.h.w.max(self.h.h) as f32;
        let h0 = *self.h.get(x, y);
        let gx = if x + 1 < self.h.w {
            n * (self.h.get(x + 1, y) - h0)
        } else {
            0.0
        };
        let gy = if y + 1 < self.h.h {
            n * (self.h.get(x, y + 1) - h0)
        } else {
            0.0
        };
        (gx, gy)
    }
    fn depth(&self, x: usize, y: usize) -> f32 {
        *self.h.get(x, y)
    }
    fn id(&self, x: usize, y: usize) -> u16 {
        *self.id.get(x, y)
    }
}

/// A slope field given directly (normal-map input).
pub struct SlopeSource {
    pub gx: Grid<f32>,
    pub gy: Grid<f32>,
    pub mask: Grid<bool>,
}

impl Source for SlopeSource {
    fn size(&self) -> (usize, usize) {
        (self.gx.w, self.gx.h)
    }
    fn slope(&self, x: usize, y: usize) -> (f32, f32) {
        (*self.gx.get(x, y), *self.gy.get(x, y))
    }
    fn depth(&self, _: usize, _: usize) -> f32 {
        0.0
    }
    fn id(&self, x: usize, y: usize) -> u16 {
        *self.mask.get(x, y) as u16
    }
}

/// C(x) = ln(1 + a x) / a applied to a magnitude (identity for a = 0).
#[inline]
pub fn compress(x: f64, alpha: f64) -> f64 {
    if alpha > 0.0 {
        (alpha * x).ln_1p() / alpha
    } else {
        x
    }
}

/// One source pixel shaped: (gx, gy, step x, step y).
#[inline]
fn shape(g: (f32, f32), s: Shaping) -> [f32; 4] {
    let sil_x = (g.0.abs() as f64) > s.threshold;
    let sil_y = (g.1.abs() as f64) > s.threshold;
    let rx = if sil_x { 0.0 } else { g.0 as f64 };
    let ry = if sil_y { 0.0 } else { g.1 as f64 };
    let m = (rx * rx + ry * ry).sqrt();
    let f = if m > 0.0 {
        compress(m, s.alpha) / m
    } else {
        0.0
    };
    let step = |sil: bool, v: f32| if sil { v.signum() } else { 0.0 };
    [
        (rx * f) as f32,
        (ry * f) as f32,
        step(sil_x, g.0),
        step(sil_y, g.1),
    ]
}

/// Shape `src` and bring it down by `factor` (1 or 2). For factor 2 an
/// output slope is the [1 2 1]/4 filter of source slopes along its axis and
/// the mean of the two source rows/columns across it: exactly the slope
/// between neighbouring output samples when each is its 2x2 mean.
pub fn shape_field(src: &dyn Source, factor: usize, s: Shaping) -> Field {
    assert!(factor == 1 || factor == 2);
    let (fw, fh) = src.size();
    let (w, h) = (fw / factor, fh / factor);
    let along: &[f32] = if factor == 1 {
        &[1.0]
    } else {
        &[0.25, 0.5, 0.25]
    };
    let across: &[f32] = if factor == 1 { &[1.0] } else { &[0.5, 0.5] };
    let rows: Vec<_> = (0..h)
        .into_par_iter()
        .map(|y| {
            // shaped source rows factor*y .. factor*y + along.len()
            let y0 = factor * y;
            let nrows = along.len().min(fh - y0);
            let shaped: Vec<Vec<[f32; 4]>> = (0..nrows)
                .map(|r| (0..fw).map(|x| shape(src.slope(x, y0 + r), s)).collect())
                .collect();
            let mut out = RowOut::new(w);
            let mut sil = 0usize;
            for x in 0..w {
                let x0 = factor * x;
                let (mut gx, mut gy, mut sx, mut sy) = (0.0f32, 0.0, 0.0, 0.0);
                for (a, wa) in along.iter().enumerate() {
                    for (c, wc) in across.iter().enumerate() {
                        if let Some(p) = shaped.get(c).and_then(|r| r.get(x0 + a)) {
                            gx += wa * wc * p[0];
                            sx += wa * wc * p[2];
                        }
                        if let Some(p) = shaped.get(a).and_then(|r| r.get(x0 + c)) {
                            gy += wa * wc * p[1];
                            sy += wa * wc * p[3];
                        }
                    }
                }
                let (mut fg, mut barrier, mut best, mut id, mut dsum) =
                    (false, false, f32::MIN, 0u16, 0.0f32);
                for (r, row) in shaped.iter().enumerate().take(factor) {
                    for c in 0..factor {
                        let p = row[x0 + c];
                        if p[2] != 0.0 || p[3] != 0.0 {
                            barrier = true;
                            sil += (p[2] != 0.0) as usize + (p[3] != 0.0) as usize;
                        }
                        let (d, i) = (src.depth(x0 + c, y0 + r), src.id(x0 + c, y0 + r));
                        dsum += d;
                        if i != 0 && d > best {
                            best = d;
                            id = i;
                            fg = true;
                        }
                    }
                }
                // a silhouette edge also bars the pixel on its far side
                if x0 > 0 && shaped.iter().take(factor).any(|r| r[x0 - 1][2] != 0.0) {
                    barrier = true;
                }
                out.set(
                    x,
                    [gx, gy, sx, sy],
                    barrier,
                    fg,
                    id,
                    dsum / (factor * factor) as f32,
                );
            }
            (out, sil)
        })
        .collect();
    // a vertical silhouette edge bars the pixel below it too
    let mut f = Field {
        gx: Grid::new(w, h, 0.0),
        gy: Grid::new(w, h, 0.0),
        sx: Grid::new(w, h, 0.0),
        sy: Grid::new(w, h, 0.0),
        barrier: Grid::new(w, h, false),
        mask: Grid::new(w, h, false),
        id: Grid::new(w, h, 0),
        depth: Grid::new(w, h, 0.0),
        n_fine: fw.max(fh),
        silhouette_edges: 0,
    };
    for (y, (r, sil)) in rows.into_iter().enumerate() {
        let o = y * w;
        f.gx.data[o..o + w].copy_from_slice(&r.g[0]);
        f.gy.data[o..o + w].copy_from_slice(&r.g[1]);
        f.sx.data[o..o + w].copy_from_slice(&r.g[2]);
        f.sy.data[o..o + w].copy_from_slice(&r.g[3]);
        f.barrier.data[o..o + w].copy_from_slice(&r.barrier);
        f.mask.data[o..o + w].copy_from_slice(&r.fg);
        f.id.data[o..o + w].copy_from_slice(&r.id);
        f.depth.data[o..o + w].copy_from_slice(&r.depth);
        f.silhouette_edges += sil;
    }
    for y in (1..h).rev() {
        for x in 0..w {
            if *f.sy.get(x, y - 1) != 0.0 {
                f.barrier.set(x, y, true);
            }
        }
    }
    f
}

struct RowOut {
    g: [Vec<f32>; 4],
    barrier: Vec<bool>,
    fg: Vec<bool>,
    id: Vec<u16>,
    depth: Vec<f32>,
}

impl RowOut {
    fn new(w: usize) -> Self {
        RowOut {
            g: std::array::from_fn(|_| vec![0.0; w]),
            barrier: vec![false; w],
            fg: vec![false; w],
            id: vec![0; w],
            depth: vec![0.0; w],
        }
    }
    fn set(&mut self, x: usize, g: [f32; 4], barrier: bool, fg: bool, id: u16, depth: f32) {
        for (dst, v) in self.g.iter_mut().zip(g) {
            dst[x] = v;
        }
        self.barrier[x] = barrier;
        self.fg[x] = fg;
        self.id[x] = id;
        self.depth[x] = depth;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn depth_map(w: usize, h: usize, f: impl Fn(usize, usize) -> f32) -> DepthMap {
        let mut d = Grid::new(w, h, 0.0);
        for y in 0..h {
            for x in 0..w {
                d.set(x, y, f(x, y));
            }
        }
        let id = d.map(|v| (*v > 0.0) as u16);
        DepthMap {
            h: d,
            id,
            objects: vec!["a".into()],
        }
    }

    #[test]
    fn a_ramp_downsamples_to_the_same_slope() {
        // h = 0.5 + 0.2 * x / N: slope 0.2 at every resolution
        let dm = depth_map(64, 32, |x, _| 0.5 + 0.2 * x as f32 / 64.0);
        let s = Shaping {
            alpha: 0.0,
            threshold: 10.0,
        };
        let f = shape_field(&dm, 2, s);
        assert_eq!((f.gx.w, f.gx.h), (32, 16));
        assert!((f.gx.get(10, 5) - 0.2).abs() < 1e-5);
        assert!(f.gy.get(10, 5).abs() < 1e-6);
        assert_eq!(f.silhouette_edges, 0);
    }

    #[test]
    fn a_jump_is_a_silhouette_with_a_unit_step() {
        let dm = depth_map(16, 8, |x, _| if x < 8 { 0.2 } else { 0.8 });
        let f = shape_field(
            &dm,
            1,
            Shaping {
                alpha: 1.0,
                threshold: 5.0,
            },
        );
        assert_eq!(*f.gx.get(7, 3), 0.0);
        assert_eq!(*f.sx.get(7, 3), 1.0);
        assert!(*f.barrier.get(7, 3) && *f.barrier.get(8, 3) && !*f.barrier.get(5, 3));
        assert_eq!(f.silhouette_edges, 8);
    }

    #[test]
    fn compression_is_log() {
        assert!((compress(2.0, 3.0) - (7.0f64).ln() / 3.0).abs() < 1e-12);
        assert_eq!(compress(2.0, 0.0), 2.0);
    }
}
