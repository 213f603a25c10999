//! The subject's outline: where the relief stands off its background.
//! `--boundary subject` finishes only there (plus a margin) with the
//! finishing tool; roughing cuts the level background to its height (no
//! stock left on it): a ball spends no time on a flat field.

use crate::bail;
use crate::error::Result;
use crate::grid::Grid;
use crate::relief::Relief;

/// Which samples show the subject, and which lie within `margin` mm of it.
pub struct Subject {
    pub pitch: f64,
    pub height_mm: f64,
    /// Samples off the background.
    pub inside: Grid<bool>,
    /// `inside` grown by the margin.
    pub near: Grid<bool>,
    /// The background's height (relief mm, 0 = floor).
    pub level: f64,
}

impl Subject {
    /// The background is the height most of the panel's border shows
    /// (its median); the subject, every sample more than a hundredth of
    /// a millimetre (or 0.2% of the depth) off it. A background that is
    /// not level (a relief made with a free background) has no such
    /// outline: refused, with the figures.
    pub fn find(r: &Relief, margin: f64) -> Result<Subject> {
        let (w, h) = (r.heights.w, r.heights.h);
        let mut border: Vec<f32> = Vec::with_capacity(2 * (w + h));
        for i in 0..w {
            border.push(*r.heights.get(i, 0));
            border.push(*r.heights.get(i, h - 1));
        }
        for j in 0..h {
            border.push(*r.heights.get(0, j));
            border.push(*r.heights.get(w - 1, j));
        }
        border.sort_by(f32::total_cmp);
        let level = border[border.len() / 2] as f64;
        let tol = (0.002 * r.depth_mm).max(0.01);
        // most of the border on the level: a quarter of it may be subject
        let (lo, hi) = (
            border[border.len() / 8] as f64,
            border[border.len() * 5 / 8] as f64,
        );
        if hi - lo > tol {
            bail!(
                "--boundary subject: the relief's background is not level (its border spans \
                 {lo:.3}..{hi:.3} mm); make the relief without --free-background"
            );
        }
        let inside = r.heights.map(|z| (*z as f64 - level).abs() > tol);
        let n = (margin / r.pitch_mm()).ceil().max(0.0) as usize;
        let near = grow(&inside, n);
        Ok(Subject {
            pitch: r.pitch_mm(),
            height_mm: r.height_mm,
            inside,
            near,
            level,
        })
    }

    fn at(&self, g: &Grid<bool>, x: f64, y: f64) -> bool {
        let i = (x / self.pitch).floor().clamp(0.0, (g.w - 1) as f64) as usize;
        let j = ((self.height_mm - y) / self.pitch)
            .floor()
            .clamp(0.0, (g.h - 1) as f64) as usize;
        *g.get(i, j)
    }

    /// Within the margin of the subject (panel mm).
    pub fn is_near(&self, x: f64, y: f64) -> bool {
        self.at(&self.near, x, y)
    }

    /// Share of the panel within the margin of the subject.
    pub fn share(&self) -> f64 {
        self.near.data.iter().filter(|b| **b).count() as f64 / self.near.data.len() as f64
    }
}

/// `g` grown by `n` samples (a disc), by a distance transform.
fn grow(g: &Grid<bool>, n: usize) -> Grid<bool> {
    if n == 0 {
        return g.clone();
    }
    // squared distance to the nearest true sample, rows then columns
    // (two passes of the 1-D lower envelope, exact for Euclidean)
    let (w, h) = (g.w, g.h);
    let far = (w * w + h * h) as f64;
    let mut d = Grid::new(w, h, far);
    for j in 0..h {
        let row: Vec<f64> = (0..w)
            .map(|i| if *g.get(i, j) { 0.0 } else { far })
            .collect();
        for (i, v) in envelope(&row).into_iter().enumerate() {
            d.set(i, j, v);
        }
    }
    for i in 0..w {
        let col: Vec<f64> = (0..h).map(|j| *d.get(i, j)).collect();
        for (j, v) in envelope(&col).into_iter().enumerate() {
            d.set(i, j, v);
        }
    }
    let r2 = (n * n) as f64;
    d.map(|v| *v <= r2)
}

/// The lower envelope of parabolas (k - q)^2 + f[q] (Felzenszwalb and
/// Huttenlocher's 1-D squared distance transform).
fn envelope(f: &[f64]) -> Vec<f64> {
    let n = f.len();
    let mut v = vec![0usize; n];
    let mut z = vec![0.0f64; n + 1];
    let mut k = 0;
    z[0] = f64::NEG_INFINITY;
    z[1] = f64::INFINITY;
    for q in 1..n {
        loop {
            let p = v[k];
            let s = ((f[q] + (q * q) as f64) - (f[p] + (p * p) as f64)) / (2.0 * (q - p) as f64);
            if s <= z[k] && k > 0 {
                k -= 1;
            } else {
                k += 1;
                v[k] = q;
                z[k] = s;
                z[k + 1] = f64::INFINITY;
                break;
            }
        }
    }
    let mut out = vec![0.0; n];
    k = 0;
    for (q, o) in out.iter_mut().enumerate() {
        while z[k + 1] < q as f64 {
            k += 1;
        }
        let p = v[k];
        *o = (q as f64 - p as f64).powi(2) + f[p];
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_raised_disc_on_a_flat_field_is_the_subject_and_grows_round() {
        let mut g = Grid::new(40, 40, 0.5f32);
        for j in 0..40 {
            for i in 0..40 {
                let (x, y) = (i as f64 - 20.0, j as f64 - 20.0);
                if x * x + y * y <= 25.0 {
                    g.set(i, j, 2.0);
                }
            }
        }
        let r = Relief {
            heights: g,
            width_mm: 40.0,
            height_mm: 40.0,
            depth_mm: 2.0,
        };
        let s = Subject::find(&r, 3.0).unwrap();
        assert_eq!(s.level, 0.5);
        // sample (20, 20) is at x 20.5, y 19.5
        assert!(*s.inside.get(20, 20) && !*s.inside.get(27, 20));
        // grown by 3: radius 8 round the centre, not 9
        assert!(s.is_near(28.5, 19.5) && !s.is_near(29.5, 19.5));
        assert!(s.is_near(20.5, 11.5) && !s.is_near(26.5, 13.5));
        assert!(s.share() > 0.12 && s.share() < 0.16);
    }
}
