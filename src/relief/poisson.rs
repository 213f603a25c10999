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
/// non-unknown pixels; `scale` = 2^level makes the rediscretised coarse
/// operator approximate the Galerkin product P^T A P.
struct Level {
    w: usize,
    h: usize,
    unknown: Vec<bool>,
    diag: Vec<f64>,
    scale: f64,
}

impl Level {
    fn new(w: usize, h: usize, unknown: Vec<bool>, scale: f64) -> Level {
        let diag = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let n = (x > 0) as u32 + (x + 1 < w) as u32 + (y > 0) as u32 + (y + 1 < h) as u32;
                if unknown[i] {
                    n as f64 * scale
                } else {
                    1.0
                }
            })
            .collect();
        Level {
            w,
            h,
            unknown,
            diag,
            scale,
        }
    }

    fn coarsen(&self) -> Level {
        let (cw, ch) = (self.w.div_ceil(2), self.h.div_ceil(2));
        let mut u = vec![false; cw * ch];
        for (i, &k) in self.unknown.iter().enumerate() {
            if k {
                u[(i / self.w / 2) * cw + (i % self.w) / 2] = true;
            }
        }
        Level::new(cw, ch, u, self.scale * 2.0)
    }

    /// out = A x (0 at non-unknowns).
    fn apply(&self, x: &[f64], out: &mut [f64]) {
        let w = self.w;
        let h = self.h;
        out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            for (xx, o) in row.iter_mut().enumerate() {
                let i = y * w + xx;
                if !self.unknown[i] {
                    *o = 0.0;
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
                *o = self.diag[i] * x[i] - self.scale * s;
            }
        });
    }

    /// `sweeps` damped-Jacobi sweeps on A x = r.
    fn smooth(&self, x: &mut [f64], r: &[f64], sweeps: usize, tmp: &mut [f64]) {
        const OMEGA: f64 = 0.8;
        for _ in 0..sweeps {
            self.apply(x, tmp);
            x.par_iter_mut().enumerate().for_each(|(i, xi)| {
                if self.unknown[i] {
                    *xi += OMEGA * (r[i] - tmp[i]) / self.diag[i];
                }
            });
        }
    }
}

/// Symmetric V-cycle: an SPD approximation of A^-1 for the CG.
fn vcycle(levels: &[Level], r: &[f64]) -> Vec<f64> {
    let l = &levels[0];
    let n = l.w * l.h;
    let mut x = vec![0.0; n];
    let mut tmp = vec![0.0; n];
    if levels.len() == 1 {
        l.smooth(&mut x, r, 40, &mut tmp);
        return x;
    }
    l.smooth(&mut x, r, 2, &mut tmp);
    l.apply(&x, &mut tmp);
    let c = &levels[1];
    let mut rc = vec![0.0; c.w * c.h];
    for i in 0..n {
        if l.unknown[i] {
            rc[(i / l.w / 2) * c.w + (i % l.w) / 2] += r[i] - tmp[i];
        }
    }
    let ec = vcycle(&levels[1..], &rc);
    x.par_iter_mut().enumerate().for_each(|(i, xi)| {
        if l.unknown[i] {
            *xi += ec[(i / l.w / 2) * c.w + (i % l.w) / 2];
        }
    });
    l.smooth(&mut x, r, 2, &mut tmp);
    x
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.par_iter().zip(b.par_iter()).map(|(x, y)| x * y).sum()
}

/// Dirichlet solve: lap h = div on pixels where `unknown` is true, h = 0
/// elsewhere. Background pixels come out exactly 0. Returns the solution
/// and the number of CG iterations.
pub fn solve_masked(div: &Grid<f64>, unknown: &Grid<bool>) -> (Grid<f64>, usize) {
    let (w, h) = (div.w, div.h);
    let mut levels = vec![Level::new(w, h, unknown.data.clone(), 1.0)];
    while levels.last().map(|l| l.w.max(l.h) > 6).unwrap_or(false) {
        let c = levels.last().unwrap().coarsen();
        levels.push(c);
    }
    let l0 = &levels[0];
    let b: Vec<f64> = div
        .data
        .iter()
        .zip(&l0.unknown)
        .map(|(d, &u)| if u { -d } else { 0.0 })
        .collect();
    let bnorm = dot(&b, &b).sqrt();
    let mut x = vec![0.0; w * h];
    if bnorm == 0.0 {
        return (Grid::from_vec(w, h, x), 0);
    }
    let mut r = b;
    let mut z = vcycle(&levels, &r);
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    let mut ap = vec![0.0; w * h];
    let mut it = 0;
    while it < 1000 {
        it += 1;
        l0.apply(&p, &mut ap);
        let alpha = rz / dot(&p, &ap);
        x.par_iter_mut()
            .zip(p.par_iter())
            .for_each(|(xi, pi)| *xi += alpha * pi);
        r.par_iter_mut()
            .zip(ap.par_iter())
            .for_each(|(ri, ai)| *ri -= alpha * ai);
        if dot(&r, &r).sqrt() <= 1e-13 * bnorm {
            break;
        }
        z = vcycle(&levels, &r);
        let rz2 = dot(&r, &z);
        let beta = rz2 / rz;
        rz = rz2;
        p.par_iter_mut()
            .zip(z.par_iter())
            .for_each(|(pi, zi)| *pi = zi + beta * *pi);
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
