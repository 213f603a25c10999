//! Integration: solve lap h = div g on the pixel grid.
//!
//! * Free background (Neumann): exact solve by DCT-II / DCT-III (rustdct);
//!   the 5-point Laplacian with reflecting boundary is diagonal in the DCT
//!   basis, so one forward and one inverse 2D transform solve it exactly.
//! * Flat background (Dirichlet h = 0 on background pixels): conjugate
//!   gradients preconditioned by a geometric multigrid V-cycle on the
//!   masked grid.
//!
//! Gradients are forward differences per pixel: gx(i,j) = h(i+1,j) - h(i,j);
//! the last column of gx and the last row of gy are ignored (no edge there).

use crate::grid::Grid;
use rayon::prelude::*;
use rustdct::DctPlanner;

/// Discrete divergence (backward differences) matching forward-difference
/// gradients, scaled by `scale`.
pub fn divergence(gx: &Grid<f32>, gy: &Grid<f32>, scale: f64) -> Grid<f64> {
    let (w, h) = (gx.w, gx.h);
    let mut d = Grid::new(w, h, 0.0f64);
    d.data.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, out) in row.iter_mut().enumerate() {
            let ex = |x: usize| if x + 1 < w { *gx.get(x, y) as f64 } else { 0.0 };
            let ey = |y: usize| if y + 1 < h { *gy.get(x, y) as f64 } else { 0.0 };
            let mut v = ex(x) + ey(y);
            if x > 0 {
                v -= ex(x - 1);
            }
            if y > 0 {
                v -= ey(y - 1);
            }
            *out = v * scale;
        }
    });
    d
}

fn dct_rows(g: &mut Grid<f64>, inverse: bool) {
    let mut planner = DctPlanner::<f64>::new();
    let plan = planner.plan_dct2(g.w);
    let scratch = plan.get_scratch_len();
    g.data.par_chunks_mut(g.w).for_each_init(
        || vec![0.0; scratch],
        |s, row| {
            if inverse {
                plan.process_dct3_with_scratch(row, s)
            } else {
                plan.process_dct2_with_scratch(row, s)
            }
        },
    );
}

/// Neumann solve: the zero-mean h with lap h = div (div must sum to ~0,
/// which divergence of any field on this grid does).
pub fn solve_neumann(div: &Grid<f64>) -> Grid<f64> {
    let (w, h) = (div.w, div.h);
    let mut f = div.clone();
    dct_rows(&mut f, false);
    let mut t = f.transpose(); // rows are now x-frequency k, columns y
    dct_rows(&mut t, false);
    let lx: Vec<f64> = (0..w)
        .map(|k| 2.0 * (std::f64::consts::PI * k as f64 / w as f64).cos() - 2.0)
        .collect();
    let ly: Vec<f64> = (0..h)
        .map(|l| 2.0 * (std::f64::consts::PI * l as f64 / h as f64).cos() - 2.0)
        .collect();
    let norm = 4.0 / (w as f64 * h as f64);
    t.data.par_chunks_mut(h).enumerate().for_each(|(k, row)| {
        for (l, v) in row.iter_mut().enumerate() {
            let lam = lx[k] + ly[l];
            *v = if k == 0 && l == 0 {
                0.0
            } else {
                *v * norm / lam
            };
        }
    });
    dct_rows(&mut t, true);
    let mut out = t.transpose();
    dct_rows(&mut out, true);
    out
}

/// One grid level of the masked operator A = -lap with h = 0 on
/// non-unknown pixels. The diagonal is not stored (it is the unknown's
/// neighbour count), so a level costs one byte per pixel besides its work
/// vectors.
struct Level {
    w: usize,
    h: usize,
    unknown: Vec<bool>,
}

/// A level's work vectors, allocated once per solve: right-hand side,
/// solution, and the other half of a Jacobi ping-pong.
struct Work {
    r: Vec<f64>,
    x: Vec<f64>,
    t: Vec<f64>,
}

/// Damping of the Jacobi smoother.
const OMEGA: f64 = 0.8;
/// Relative residual at which CG stops. The 16-bit relief then differs
/// from a 1e-12 solve by at most one unit; at 1e-4 it still does, at 1e-3
/// no longer (2048 px: spot, and the demo with steps and bands).
const TOLERANCE: f64 = 1e-6;

impl Level {
    fn coarsen(&self) -> Level {
        let (cw, ch) = (self.w.div_ceil(2), self.h.div_ceil(2));
        // a coarse cell is an unknown when at least 3 of its 4 children
        // are: its Dirichlet neighbours then lie where the fine ones do,
        // not a cell further out (with "any child", the coarse problems
        // grow a border at every level and CG needs 3x the iterations)
        let mut count = vec![(0u8, 0u8); cw * ch];
        for (i, &k) in self.unknown.iter().enumerate() {
            let c = &mut count[(i / self.w / 2) * cw + (i % self.w) / 2];
            c.0 += 1;
            c.1 += k as u8;
        }
        Level {
            w: cw,
            h: ch,
            unknown: count.iter().map(|&(n, k)| k >= n.min(3)).collect(),
        }
    }

    fn work(&self) -> Work {
        let n = self.w * self.h;
        Work {
            r: vec![0.0; n],
            x: vec![0.0; n],
            t: vec![0.0; n],
        }
    }

    /// Rows at least this many to a parallel task (small levels run whole).
    fn min_rows(&self) -> usize {
        (16384 / self.w).max(1)
    }

    /// Neighbours in the grid of pixel (xx, y): the diagonal of A.
    #[inline]
    fn degree(&self, xx: usize, y: usize) -> f64 {
        let edge = |v: usize, n: usize| (v > 0) as u8 + (v + 1 < n) as u8;
        (edge(xx, self.w) + edge(y, self.h)) as f64
    }

    /// For each pixel of row `y`: f(column, (A x)_i, diagonal_i), unknowns only.
    #[inline]
    fn row(&self, x: &[f64], y: usize, mut f: impl FnMut(usize, f64, f64)) {
        let (w, h) = (self.w, self.h);
        let base = y * w;
        for xx in 0..w {
            let i = base + xx;
            if !self.unknown[i] {
                continue;
            }
            let mut s = 0.0;
            if xx > 0 {
                s += x[i - 1];
            }
            if xx + 1 < w {
                s += x[i + 1];
            }
            if y > 0 {
                s += x[i - w];
            }
            if y + 1 < h {
                s += x[i + w];
            }
            let d = self.degree(xx, y);
            f(xx, d * x[i] - s, d);
        }
    }

    /// out = A x (0 at non-unknowns); returns x . A x.
    fn apply_dot(&self, x: &[f64], out: &mut [f64]) -> f64 {
        out.par_chunks_mut(self.w)
            .with_min_len(self.min_rows())
            .enumerate()
            .map(|(y, o)| {
                o.fill(0.0);
                let base = y * self.w;
                let mut s = 0.0;
                self.row(x, y, |c, ax, _| {
                    o[c] = ax;
                    s += x[base + c] * ax;
                });
                s
            })
            .sum()
    }

    /// One damped-Jacobi sweep on A x = r: `w.t` from `w.x`, then swapped.
    fn sweep(&self, w: &mut Work) {
        let (x, r) = (&w.x, &w.r);
        w.t.par_chunks_mut(self.w)
            .with_min_len(self.min_rows())
            .enumerate()
            .for_each(|(y, o)| {
                o.fill(0.0);
                let base = y * self.w;
                self.row(x, y, |c, ax, d| {
                    o[c] = x[base + c] + OMEGA * (r[base + c] - ax) / d;
                });
            });
        std::mem::swap(&mut w.x, &mut w.t);
    }

    /// The first sweep from x = 0: x = OMEGA r / diagonal.
    fn first_sweep(&self, w: &mut Work) {
        let r = &w.r;
        w.x.par_chunks_mut(self.w)
            .with_min_len(self.min_rows())
            .enumerate()
            .for_each(|(y, o)| {
                let base = y * self.w;
                for (xx, v) in o.iter_mut().enumerate() {
                    *v = if self.unknown[base + xx] {
                        OMEGA * r[base + xx] / self.degree(xx, y)
                    } else {
                        0.0
                    };
                }
            });
    }

    /// `w.t` = the residual r - A x.
    fn residual(&self, w: &mut Work) {
        let (x, r) = (&w.x, &w.r);
        w.t.par_chunks_mut(self.w)
            .with_min_len(self.min_rows())
            .enumerate()
            .for_each(|(y, o)| {
                o.fill(0.0);
                let base = y * self.w;
                self.row(x, y, |c, ax, _| o[c] = r[base + c] - ax);
            });
    }
}

/// The two coarse cells a fine cell's centre lies between (cell-centred
/// bilinear interpolation: 3/4 from its own, 1/4 from the next one toward
/// it, the edge cell standing in for a missing one).
#[inline]
fn parents(i: usize, n: usize) -> [(usize, f64); 2] {
    let c = i / 2;
    let other = if i.is_multiple_of(2) {
        c.saturating_sub(1)
    } else {
        (c + 1).min(n - 1)
    };
    [(c.min(n - 1), 0.75), (other, 0.25)]
}

/// For each coarse cell along an axis, the fine cells that interpolate
/// from it and with what weight: the transpose of `parents`.
fn children(fine: usize, n: usize) -> Vec<Vec<(usize, f64)>> {
    let mut out = vec![Vec::with_capacity(4); n];
    for i in 0..fine {
        for (c, w) in parents(i, n) {
            match out[c].iter_mut().find(|e: &&mut (usize, f64)| e.0 == i) {
                Some(e) => e.1 += w,
                None => out[c].push((i, w)),
            }
        }
    }
    out
}

/// Symmetric V-cycle from level `k` (its right-hand side in `work[k].r`,
/// the result left in `work[k].x`): an SPD approximation of A^-1 for CG.
/// Two damped-Jacobi sweeps before and after; the residual goes down by
/// the transpose of bilinear interpolation and the correction comes back
/// up by it, which with the coarse operator rediscretised on the coarse
/// mask makes the coarse problem the fine one seen at half resolution.
fn vcycle(levels: &[Level], work: &mut [Work], k: usize) {
    let l = &levels[k];
    let (fine, coarse) = work.split_at_mut(k + 1);
    let wk = &mut fine[k];
    l.first_sweep(wk);
    if k + 1 == levels.len() {
        for _ in 0..39 {
            l.sweep(wk);
        }
        return;
    }
    l.sweep(wk);
    l.residual(wk);
    let c = &levels[k + 1];
    let rows = children(l.h, c.h);
    let cols = children(l.w, c.w);
    let t = &wk.t;
    coarse[0]
        .r
        .par_chunks_mut(c.w)
        .with_min_len(c.min_rows())
        .enumerate()
        .for_each(|(cy, rc)| {
            for (cx, out) in rc.iter_mut().enumerate() {
                let mut s = 0.0;
                if c.unknown[cy * c.w + cx] {
                    for &(y, wy) in &rows[cy] {
                        let base = y * l.w;
                        for &(xx, wx) in &cols[cx] {
                            s += wy * wx * t[base + xx];
                        }
                    }
                }
                *out = s;
            }
        });
    vcycle(levels, work, k + 1);
    let (fine, coarse) = work.split_at_mut(k + 1);
    let (wk, ec) = (&mut fine[k], &coarse[0].x);
    wk.x.par_chunks_mut(l.w)
        .with_min_len(l.min_rows())
        .enumerate()
        .for_each(|(y, row)| {
            let py = parents(y, c.h);
            for (xx, v) in row.iter_mut().enumerate() {
                if l.unknown[y * l.w + xx] {
                    let px = parents(xx, c.w);
                    let mut e = 0.0;
                    for (cy, wy) in py {
                        for (cx, wx) in px {
                            e += wy * wx * ec[cy * c.w + cx];
                        }
                    }
                    *v += e;
                }
            }
        });
    l.sweep(wk);
    l.sweep(wk);
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.par_iter().zip(b.par_iter()).map(|(x, y)| x * y).sum()
}

/// Dirichlet solve: lap h = div on pixels where `unknown` is true, h = 0
/// elsewhere. Background pixels come out exactly 0. Returns the solution
/// and the number of CG iterations.
pub fn solve_masked(div: &Grid<f64>, unknown: &Grid<bool>) -> (Grid<f64>, usize) {
    let (w, h) = (div.w, div.h);
    let mut levels = vec![Level {
        w,
        h,
        unknown: unknown.data.clone(),
    }];
    while levels.last().map(|l| l.w.max(l.h) > 6).unwrap_or(false) {
        let c = levels.last().unwrap().coarsen();
        levels.push(c);
    }
    let mut work: Vec<Work> = levels.iter().map(Level::work).collect();
    let l0 = &levels[0];
    // CG's residual is the finest level's right-hand side: the V-cycle
    // reads it there without a copy
    work[0]
        .r
        .par_iter_mut()
        .zip(div.data.par_iter().zip(l0.unknown.par_iter()))
        .for_each(|(r, (d, &u))| *r = if u { -d } else { 0.0 });
    let bnorm = dot(&work[0].r, &work[0].r).sqrt();
    let mut x = vec![0.0; w * h];
    if bnorm == 0.0 {
        return (Grid::from_vec(w, h, x), 0);
    }
    let mut z = vec![0.0; w * h];
    let mut p = vec![0.0; w * h];
    let mut ap = vec![0.0; w * h];
    let mut rz = 0.0;
    let mut it = 0;
    while it < 1000 {
        // z = M^-1 r by the V-cycle; p = z + beta p
        vcycle(&levels, &mut work, 0);
        std::mem::swap(&mut z, &mut work[0].x);
        let rz2 = dot(&work[0].r, &z);
        let beta = if it == 0 { 0.0 } else { rz2 / rz };
        rz = rz2;
        p.par_iter_mut()
            .zip(z.par_iter())
            .for_each(|(pi, zi)| *pi = zi + beta * *pi);
        it += 1;
        let alpha = rz / l0.apply_dot(&p, &mut ap);
        let rr: f64 = x
            .par_iter_mut()
            .zip(work[0].r.par_iter_mut())
            .zip(p.par_iter().zip(ap.par_iter()))
            .map(|((xi, ri), (pi, ai))| {
                *xi += alpha * pi;
                *ri -= alpha * ai;
                *ri * *ri
            })
            .sum();
        if rr.sqrt() <= TOLERANCE * bnorm {
            break;
        }
    }
    (Grid::from_vec(w, h, x), it)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field(w: usize, h: usize, f: impl Fn(f64, f64) -> f64) -> Grid<f64> {
        let mut g = Grid::new(w, h, 0.0);
        for y in 0..h {
            for x in 0..w {
                g.set(x, y, f(x as f64 / w as f64, y as f64 / h as f64));
            }
        }
        g
    }

    fn grad(f: &Grid<f64>) -> (Grid<f32>, Grid<f32>, Grid<f64>, Grid<f64>) {
        let (w, h) = (f.w, f.h);
        let mut gx = Grid::new(w, h, 0.0f64);
        let mut gy = Grid::new(w, h, 0.0f64);
        for y in 0..h {
            for x in 0..w {
                if x + 1 < w {
                    gx.set(x, y, f.get(x + 1, y) - f.get(x, y));
                }
                if y + 1 < h {
                    gy.set(x, y, f.get(x, y + 1) - f.get(x, y));
                }
            }
        }
        (gx.map(|v| *v as f32), gy.map(|v| *v as f32), gx, gy)
    }

    /// Divergence in full f64 precision (the f32 path is for production).
    fn div64(gx: &Grid<f64>, gy: &Grid<f64>) -> Grid<f64> {
        let (w, h) = (gx.w, gx.h);
        let mut d = Grid::new(w, h, 0.0);
        for y in 0..h {
            for x in 0..w {
                let mut v = gx.get(x, y) + gy.get(x, y);
                if x > 0 {
                    v -= gx.get(x - 1, y);
                }
                if y > 0 {
                    v -= gy.get(x, y - 1);
                }
                d.set(x, y, v);
            }
        }
        d
    }

    fn max_err(a: &Grid<f64>, b: &Grid<f64>, shift: bool) -> f64 {
        let n = a.data.len() as f64;
        let off = if shift {
            (a.data.iter().sum::<f64>() - b.data.iter().sum::<f64>()) / n
        } else {
            0.0
        };
        a.data
            .iter()
            .zip(&b.data)
            .map(|(x, y)| (x - y - off).abs())
            .fold(0.0, f64::max)
    }

    #[test]
    fn neumann_recovers_a_smooth_field() {
        for (w, h) in [(96, 64), (75, 101)] {
            let f = field(w, h, |x, y| {
                (3.0 * x).sin() * (2.0 * y).cos() + x * x - 0.5 * y
            });
            let (_, _, gx, gy) = grad(&f);
            let sol = solve_neumann(&div64(&gx, &gy));
            let (lo, hi) = f
                .data
                .iter()
                .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
            let e = max_err(&sol, &f, true);
            assert!(e < 1e-6 * (hi - lo), "{w}x{h}: error {e}");
        }
    }

    #[test]
    fn masked_recovers_field_and_keeps_background_zero() {
        let (w, h) = (90, 70);
        // a smooth bump on a disc, exactly 0 outside it
        let f = field(w, h, |x, y| {
            let r2 = ((x - 0.5) * 1.3).powi(2) + (y - 0.5).powi(2);
            if r2 < 0.16 {
                (0.16 - r2).powi(2) * 50.0 + 0.3 * x
            } else {
                0.0
            }
        });
        let unknown = f.map(|v| *v != 0.0);
        let (_, _, gx, gy) = grad(&f);
        let (sol, iters) = solve_masked(&div64(&gx, &gy), &unknown);
        let (lo, hi) = f
            .data
            .iter()
            .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
        let e = max_err(&sol, &f, false);
        assert!(e < 1e-6 * (hi - lo), "error {e} after {iters} iterations");
        assert!(iters < 60, "{iters} iterations");
        for (s, u) in sol.data.iter().zip(&unknown.data) {
            if !u {
                assert_eq!(*s, 0.0);
            }
        }
    }

    #[test]
    fn transpose_round_trips() {
        let g = Grid::from_vec(37, 5, (0..185).map(|v| v as f64).collect());
        let t = g.transpose();
        assert_eq!((t.w, t.h), (5, 37));
        assert_eq!(*t.get(3, 20), *g.get(20, 3));
        assert_eq!(t.transpose(), g);
    }
}
