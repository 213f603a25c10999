//! Feature scaling (paper section 3.2): the compressed slope field is split
//! into frequency bands by a diffusion that respects silhouettes, and the
//! bands are recombined with gains: l0 = g', l_k = D_k(l_{k-1}),
//! d_k = l_{k-1} - l_k, result = sum a_k d_k + l_n.
//!
//! D_k is an edge-stopping recursive filter (domain-transform style: three
//! alternating horizontal/vertical passes of a first-order recursive filter)
//! whose cost does not grow with the radius. Barrier pixels (silhouettes)
//! neither give nor take: the filter state stops at them and they keep
//! their value.

use crate::grid::Grid;
use rayon::prelude::*;

/// Radius in pixels of band k (0-based) for an image whose long side is `n`:
/// it doubles with each band and is a fixed fraction of the image, so the
/// same gains give the same relief at every resolution.
pub fn band_sigma(k: usize, n: usize) -> f64 {
    (n as f64 / 512.0) * (1 << k) as f64
}

fn filter_rows(v: &mut Grid<f32>, barrier: &Grid<bool>, a: f32) {
    let w = v.w;
    v.data
        .par_chunks_mut(w)
        .zip(barrier.data.par_chunks(w))
        .for_each(|(row, bar)| {
            // forward then backward; the state stops at barrier pixels
            let mut pass = |order: &mut dyn Iterator<Item = usize>| {
                let mut prev: Option<f32> = None;
                for i in order {
                    if bar[i] {
                        prev = None;
                        continue;
                    }
                    if let Some(p) = prev {
                        row[i] += a * (p - row[i]);
                    }
                    prev = Some(row[i]);
                }
            };
            pass(&mut (0..w));
            pass(&mut (0..w).rev());
        });
}

/// Silhouette-respecting smoothing of `v` with radius `sigma` pixels.
pub fn diffuse(
    v: &Grid<f32>,
    barrier: &Grid<bool>,
    barrier_t: &Grid<bool>,
    sigma: f64,
) -> Grid<f32> {
    const ITER: i32 = 3;
    let mut out = v.clone();
    for i in 1..=ITER {
        let s = sigma * 3f64.sqrt() * 2f64.powi(ITER - i) / (4f64.powi(ITER) - 1.0).sqrt();
        let a = (-(2f64.sqrt()) / s.max(1e-6)).exp() as f32;
        filter_rows(&mut out, barrier, a);
        let mut t = out.transpose();
        filter_rows(&mut t, barrier_t, a);
        out = t.transpose();
    }
    out
}

/// Recombine the bands of `v` with `gains` (finest first).
pub fn feature_scale(v: &Grid<f32>, barrier: &Grid<bool>, gains: &[f64]) -> Grid<f32> {
    if gains.is_empty() {
        return v.clone();
    }
    let n = v.w.max(v.h);
    let barrier_t = barrier.transpose();
    let mut out = Grid::new(v.w, v.h, 0.0f32);
    let mut prev = v.clone();
    for (k, &a) in gains.iter().enumerate() {
        let next = diffuse(&prev, barrier, &barrier_t, band_sigma(k, n));
        out.data
            .par_iter_mut()
            .zip(prev.data.par_iter().zip(next.data.par_iter()))
            .for_each(|(o, (p, q))| {
                *o += a as f32 * (p - q);
            });
        prev = next;
    }
    out.data
        .par_iter_mut()
        .zip(prev.data.par_iter())
        .for_each(|(o, l)| *o += l);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unit_gains_reproduce_the_field() {
        let v = Grid::from_vec(20, 10, (0..200).map(|i| ((i * 37) % 11) as f32).collect());
        let b = Grid::new(20, 10, false);
        let r = feature_scale(&v, &b, &[1.0, 1.0, 1.0]);
        for (x, y) in r.data.iter().zip(&v.data) {
            assert!((x - y).abs() < 1e-4);
        }
    }

    #[test]
    fn diffusion_smooths_but_stops_at_barriers() {
        let (w, h) = (40, 8);
        let mut v = Grid::new(w, h, 0.0f32);
        let mut b = Grid::new(w, h, false);
        for y in 0..h {
            b.set(20, y, true);
            for x in 21..w {
                v.set(x, y, if x % 2 == 0 { 1.0 } else { -1.0 });
            }
            v.set(10, y, 5.0);
        }
        let d = diffuse(&v, &b, &b.transpose(), 4.0);
        // the spike spreads to its side of the barrier only
        assert!(*d.get(12, 3) > 0.1 && d.get(10, 3) < &5.0);
        assert!(d.get(19, 3).abs() > 0.0 && d.get(30, 3).abs() < 0.2);
        // total of the left half is preserved nearly (diffusion moves, not makes)
        let left: f32 = (0..20).map(|x| d.get(x, 3)).sum();
        assert!((left - 5.0).abs() < 0.5, "{left}");
        assert_eq!(*d.get(20, 3), 0.0);
    }
}
