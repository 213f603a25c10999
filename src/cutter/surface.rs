//! The relief as the continuous surface a user sees, prints and exports:
//! the samples joined by two triangles per cell (diagonal from a cell's
//! top-right to its bottom-left corner, as the STL writes them), carried
//! flat to the panel's edges. The drop-cutter cuts against it and the
//! simulator judges against it, so both mean the same surface.
//!
//! Vertices form a padded lattice of (w + 2) x (h + 2): vertex (I, J) sits
//! at X = clamp((I - 0.5) px, 0, width), Y = height - clamp((J - 0.5) py,
//! 0, height) with the height of sample (clamp(I - 1), clamp(J - 1)). The
//! outer ring lies on the panel's edges, so the cells along them are half
//! a sample wide and flat across.

/// Geometry of the vertex lattice of a relief of w x h samples.
#[derive(Clone, Copy, Debug)]
pub struct Lattice {
    pub w: usize,
    pub h: usize,
    pub px: f64,
    pub py: f64,
    pub width: f64,
    pub height: f64,
}

impl Lattice {
    /// Square samples of `pitch` filling a w x h panel.
    pub fn square(w: usize, h: usize, pitch: f64) -> Lattice {
        Lattice {
            w,
            h,
            px: pitch,
            py: pitch,
            width: w as f64 * pitch,
            height: h as f64 * pitch,
        }
    }

    /// The lattice of a relief's samples.
    pub fn of(r: &crate::relief::Relief) -> Lattice {
        let (w, h) = (r.heights.w, r.heights.h);
        Lattice {
            w,
            h,
            px: r.width_mm / w as f64,
            py: r.height_mm / h as f64,
            width: r.width_mm,
            height: r.height_mm,
        }
    }

    /// X of vertex column I (0..=w+1).
    #[inline]
    pub fn vx(&self, i: usize) -> f64 {
        ((i as f64 - 0.5) * self.px).clamp(0.0, self.width)
    }

    /// Y of vertex row J (0..=h+1); row 0 is the top edge.
    #[inline]
    pub fn vy(&self, j: usize) -> f64 {
        self.height - ((j as f64 - 0.5) * self.py).clamp(0.0, self.height)
    }

    /// The sample whose height vertex (I, J) carries.
    #[inline]
    pub fn sample(&self, i: usize, j: usize) -> (usize, usize) {
        (i.clamp(1, self.w) - 1, j.clamp(1, self.h) - 1)
    }

    /// Cells per row and per column: (w + 1, h + 1).
    #[inline]
    pub fn cells(&self) -> (usize, usize) {
        (self.w + 1, self.h + 1)
    }

    /// The cell column holding X (clamped to the lattice).
    #[inline]
    pub fn cell_x(&self, x: f64) -> usize {
        ((x / self.px + 0.5).floor().max(0.0) as usize).min(self.w)
    }

    /// The cell row holding Y (clamped to the lattice).
    #[inline]
    pub fn cell_y(&self, y: f64) -> usize {
        (((self.height - y) / self.py + 0.5).floor().max(0.0) as usize).min(self.h)
    }

    /// Height of the surface at (x, y), `z` giving the sample heights;
    /// None off the panel.
    pub fn height_at(&self, x: f64, y: f64, z: impl Fn(usize, usize) -> f64) -> Option<f64> {
        if !(x >= 0.0 && y >= 0.0 && x <= self.width && y <= self.height) {
            return None;
        }
        let (i, j) = (self.cell_x(x), self.cell_y(y));
        let (x0, x1, yt, yb) = (self.vx(i), self.vx(i + 1), self.vy(j), self.vy(j + 1));
        let at = |i: usize, j: usize| {
            let (a, b) = self.sample(i, j);
            z(a, b)
        };
        let (za, zb, zc, zd) = (at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1));
        let u = if x1 > x0 { (x - x0) / (x1 - x0) } else { 0.0 };
        let v = if yt > yb { (yt - y) / (yt - yb) } else { 0.0 };
        Some(if u + v <= 1.0 {
            za + u * (zb - za) + v * (zc - za)
        } else {
            zd + (1.0 - u) * (zc - zd) + (1.0 - v) * (zb - zd)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_surface_passes_through_the_samples_and_is_flat_at_the_edges() {
        let l = Lattice::square(4, 3, 0.5);
        let z = |i: usize, j: usize| (i * 10 + j) as f64;
        for j in 0..3 {
            for i in 0..4 {
                let (x, y) = ((i as f64 + 0.5) * 0.5, 1.5 - (j as f64 + 0.5) * 0.5);
                assert_eq!(l.height_at(x, y, z), Some(z(i, j)));
            }
        }
        // flat to the panel's edge, and bilinear nowhere: on the diagonal
        // of cell (1, 1) (from sample (1, 0) to sample (0, 1)) the height
        // is the mean of those two, not of all four corners
        assert_eq!(l.height_at(0.0, 1.5, z), Some(0.0));
        assert_eq!(l.height_at(2.0, 0.0, z), Some(32.0));
        assert_eq!(l.height_at(0.5, 1.0, z), Some(5.5));
        assert_eq!(l.height_at(-0.01, 1.0, z), None);
    }
}
