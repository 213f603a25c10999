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

use super::curl;
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
    /// The slopes of the edges to (x + 1, y) and (x, y + 1) and whether
    /// each is an outline. Without geometry: a slope above the threshold.
    fn edges(&self, x: usize, y: usize, threshold: f32) -> RawEdge {
        above(self.slope(x, y), threshold)
    }
}

/// Slopes and which of them exceed the threshold: outlines where no
/// geometry is known.
#[inline]
fn above(g: (f32, f32), threshold: f32) -> RawEdge {
    (g, (g.0.abs() > threshold, g.1.abs() > threshold))
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
    /// A rendered mesh: an edge is an outline where the two samples do not
    /// show one continuous surface (see `Surfaces::outline`), with the
    /// threshold as the largest depth mismatch, in slope units, that still
    /// counts as continuous; a steep surface is not an outline. With smooth
    /// shading, a surface edge's slope is the mean of the two samples'
    /// slopes from interpolated normals instead of their difference.
    fn edges(&self, x: usize, y: usize, threshold: f32) -> RawEdge {
        let mut g = self.slope(x, y);
        let Some(s) = &self.surfaces else {
            return above(g, threshold);
        };
        let n = self.h.w.max(self.h.h) as f64;
        let tol = threshold as f64 / n;
        let sil = (
            x + 1 < self.h.w && s.outline((x, y), (x + 1, y), tol),
            y + 1 < self.h.h && s.outline((x, y), (x, y + 1), tol),
        );
        if let Some(here) = s.smooth_slope(x, y) {
            let mean = |other: Option<[f64; 2]>, k: usize| {
                other.map(|o| (n * (here[k] + o[k]) / 2.0) as f32)
            };
            if x + 1 < self.h.w && !sil.0 {
                g.0 = mean(s.smooth_slope(x + 1, y), 0).unwrap_or(g.0);
            }
            if y + 1 < self.h.h && !sil.1 {
                g.1 = mean(s.smooth_slope(x, y + 1), 1).unwrap_or(g.1);
            }
        }
        (g, sil)
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

/// One source pixel shaped: (gx, gy, step x, step y, silhouette bits:
/// 1 = x edge, 2 = y edge).
#[inline]
fn shape(g: (f32, f32), (sil_x, sil_y): (bool, bool), alpha: f32) -> [f32; 5] {
    let rx = if sil_x { 0.0 } else { g.0 };
    let ry = if sil_y { 0.0 } else { g.1 };
    let m = (rx * rx + ry * ry).sqrt();
    let f = if m > 0.0 && alpha > 0.0 {
        (alpha * m).ln_1p() / (alpha * m)
    } else {
        1.0
    };
    let step = |sil: bool, v: f32| if sil { v.signum() } else { 0.0 };
    let bits = sil_x as u8 | (sil_y as u8) << 1;
    [
        rx * f,
        ry * f,
        step(sil_x, g.0),
        step(sil_y, g.1),
        bits as f32,
    ]
}

/// Silhouette edges of one sign close together across an outline (a
/// surface turning away steeply just before its true edge) are one
/// outline: only the steepest edge within `STEP_GAP` output samples keeps
/// the step, so steps never stack. `near(k)` is the edge k samples along
/// the axis (slope, is an outline), `None` past the buffer.
#[inline]
fn dominated(v: f32, reach: usize, near: impl Fn(isize) -> Option<(f32, bool)>) -> bool {
    let same = |u: (f32, bool)| u.1 && u.0.signum() == v.signum();
    (1..=reach as isize).any(|k| {
        near(-k).is_some_and(|u| same(u) && u.0.abs() > v.abs())
            || near(k).is_some_and(|u| same(u) && u.0.abs() >= v.abs())
    })
}

/// No two steps lie closer than this many output samples.
const STEP_GAP: usize = 3;

/// A source sample's raw slopes and whether its two edges are outlines.
pub type RawEdge = ((f32, f32), (bool, bool));

/// Output rows made per parallel task (source rows shared between
/// neighbouring output rows are shaped once per block).
const BLOCK: usize = 16;

/// One block of output rows, written in place.
struct OutRows<'a> {
    gx: &'a mut [f32],
    gy: &'a mut [f32],
    sx: &'a mut [f32],
    sy: &'a mut [f32],
    barrier: &'a mut [bool],
    mask: &'a mut [bool],
    id: &'a mut [u16],
    depth: &'a mut [f32],
}

/// Shape `src` and bring it down by `factor` (1 or 2). For factor 2 an
/// output slope is the [1 2 1]/4 filter of source slopes along its axis and
/// the mean of the two source rows/columns across it: exactly the slope
/// between neighbouring output samples when each is its 2x2 mean.
pub fn shape_field<S: Source>(src: &S, factor: usize, s: Shaping) -> Field {
    match factor {
        1 => shape_with::<S, 1, 1, 1>(src, s, [1.0], [1.0]),
        2 => shape_with::<S, 2, 3, 2>(src, s, [0.25, 0.5, 0.25], [0.5, 0.5]),
        _ => panic!("supersampling factor must be 1 or 2"),
    }
}

fn shape_with<S: Source, const F: usize, const A: usize, const C: usize>(
    src: &S,
    s: Shaping,
    along: [f32; A],
    across: [f32; C],
) -> Field {
    let (fw, fh) = src.size();
    let (w, h) = (fw / F, fh / F);
    let (alpha, threshold) = (s.alpha as f32, s.threshold as f32);
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
    let n = BLOCK * w;
    let blocks =
        f.gx.data
            .par_chunks_mut(n)
            .zip(f.gy.data.par_chunks_mut(n))
            .zip(f.sx.data.par_chunks_mut(n))
            .zip(f.sy.data.par_chunks_mut(n))
            .zip(f.barrier.data.par_chunks_mut(n))
            .zip(f.mask.data.par_chunks_mut(n))
            .zip(f.id.data.par_chunks_mut(n))
            .zip(f.depth.data.par_chunks_mut(n))
            .enumerate()
            .map(
                |(b, (((((((gx, gy), sx), sy), barrier), mask), id), depth))| {
                    (
                        b,
                        OutRows {
                            gx,
                            gy,
                            sx,
                            sy,
                            barrier,
                            mask,
                            id,
                            depth,
                        },
                    )
                },
            );
    f.silhouette_edges = blocks
        .map_init(
            || (Vec::new(), Vec::new()),
            |(raw, shaped): &mut (Vec<RawEdge>, Vec<[f32; 5]>), (b, out)| {
                let ya = b * BLOCK;
                let yb = ya + out.gx.len() / w;
                // shaped source rows fa .. fb, kept in a per-thread buffer
                let fa = F * ya;
                let fb = (F * (yb - 1) + A).min(fh);
                // raw slopes from the reach of the step test above the
                // shaped rows to its reach below
                let reach = STEP_GAP * F;
                let ra = fa.saturating_sub(1 + reach);
                let rb = (fb + reach).min(fh);
                raw.clear();
                for fy in ra..rb {
                    raw.extend((0..fw).map(|x| src.edges(x, fy, threshold)));
                }
                let rawat = |fy: usize, fx: usize| raw[(fy - ra) * fw + fx];
                let sa = fa.saturating_sub(1);
                shaped.clear();
                for fy in sa..fb {
                    for x in 0..fw {
                        let (g, sil) = rawat(fy, x);
                        let mut p = shape(g, sil, alpha);
                        if p[2] != 0.0 {
                            let near = |k: isize| {
                                let xx = x.checked_add_signed(k).filter(|&xx| xx < fw)?;
                                let e = rawat(fy, xx);
                                Some((e.0 .0, e.1 .0))
                            };
                            if dominated(g.0, reach, near) {
                                p[2] = 0.0;
                            }
                        }
                        if p[3] != 0.0 {
                            let near = |k: isize| {
                                let yy =
                                    fy.checked_add_signed(k).filter(|&yy| yy >= ra && yy < rb)?;
                                let e = rawat(yy, x);
                                Some((e.0 .1, e.1 .1))
                            };
                            if dominated(g.1, reach, near) {
                                p[3] = 0.0;
                            }
                        }
                        shaped.push(p);
                    }
                }
                let at = |fy: usize, fx: usize| -> [f32; 5] {
                    if fy >= sa && fy < fb && fx < fw {
                        shaped[(fy - sa) * fw + fx]
                    } else {
                        [0.0; 5]
                    }
                };
                let mut sil = 0usize;
                for y in ya..yb {
                    let y0 = F * y;
                    for x in 0..w {
                        let x0 = F * x;
                        let (mut gx, mut gy, mut sx, mut sy) = (0.0f32, 0.0, 0.0, 0.0);
                        for (a, wa) in along.iter().enumerate() {
                            for (c, wc) in across.iter().enumerate() {
                                let p = at(y0 + c, x0 + a);
                                gx += wa * wc * p[0];
                                sx += wa * wc * p[2];
                                let q = at(y0 + a, x0 + c);
                                gy += wa * wc * q[1];
                                sy += wa * wc * q[3];
                            }
                        }
                        let (mut fg, mut barrier, mut best, mut id, mut dsum) =
                            (false, false, f32::MIN, 0u16, 0.0f32);
                        for r in 0..F {
                            for c in 0..F {
                                let bits = at(y0 + r, x0 + c)[4] as u8;
                                if bits != 0 {
                                    barrier = true;
                                    sil += (bits & 1) as usize + (bits >> 1) as usize;
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
                        let x_bit = |r: usize| at(y0 + r, x0 - 1)[4] as u8 & 1 != 0;
                        let y_bit = |c: usize| y0 > 0 && at(y0 - 1, x0 + c)[4] as u8 & 2 != 0;
                        if (x0 > 0 && (0..F).any(x_bit)) || (0..F).any(y_bit) {
                            barrier = true;
                        }
                        let k = (y - ya) * w + x;
                        (out.gx[k], out.gy[k], out.sx[k], out.sy[k]) = (gx, gy, sx, sy);
                        (out.barrier[k], out.mask[k], out.id[k]) = (barrier, fg, id);
                        out.depth[k] = dsum / (F * F) as f32;
                    }
                }
                sil
            },
        )
        .sum();
    // the thinned steps' slantwise gaps closed (`curl`)
    curl::pair_off(&mut f.sx, &mut f.sy);
    f
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
            surfaces: None,
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
