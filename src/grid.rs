//! `Grid<T>`: the row-major 2D array every stage shares. Row 0 is the top
//! edge of the image, as in PNG.

#[derive(Clone, Debug, PartialEq)]
pub struct Grid<T> {
    pub w: usize,
    pub h: usize,
    pub data: Vec<T>,
}

impl<T: Clone + Send + Sync> Grid<T> {
    pub fn new(w: usize, h: usize, fill: T) -> Self {
        Grid {
            w,
            h,
            data: vec![fill; w * h],
        }
    }

    pub fn from_vec(w: usize, h: usize, data: Vec<T>) -> Self {
        assert_eq!(data.len(), w * h, "grid data does not match its size");
        Grid { w, h, data }
    }

    #[inline]
    pub fn idx(&self, x: usize, y: usize) -> usize {
        y * self.w + x
    }

    #[inline]
    pub fn get(&self, x: usize, y: usize) -> &T {
        &self.data[y * self.w + x]
    }

    #[inline]
    pub fn set(&mut self, x: usize, y: usize, v: T) {
        let i = y * self.w + x;
        self.data[i] = v;
    }

    pub fn map<U: Clone + Send + Sync>(&self, f: impl Fn(&T) -> U + Sync + Send) -> Grid<U> {
        use rayon::prelude::*;
        Grid {
            w: self.w,
            h: self.h,
            data: self.data.par_iter().map(f).collect(),
        }
    }

    /// Mirror left to right.
    pub fn flip_x(&mut self) {
        for y in 0..self.h {
            self.data[y * self.w..(y + 1) * self.w].reverse();
        }
    }
}

impl<T: Copy + Default + Send + Sync> Grid<T> {
    /// Transpose (columns become rows), blocked and parallel.
    pub fn transpose(&self) -> Grid<T> {
        use rayon::prelude::*;
        const B: usize = 32;
        let (w, h) = (self.w, self.h);
        let mut out = vec![T::default(); w * h];
        // Output row x holds input column x; fill B output rows per task.
        out.par_chunks_mut(h * B)
            .enumerate()
            .for_each(|(bx, chunk)| {
                let x0 = bx * B;
                let nx = chunk.len() / h.max(1);
                for y0 in (0..h).step_by(B) {
                    for x in x0..x0 + nx {
                        for y in y0..(y0 + B).min(h) {
                            chunk[(x - x0) * h + y] = self.data[y * w + x];
                        }
                    }
                }
            });
        Grid {
            w: h,
            h: w,
            data: out,
        }
    }
}

impl Grid<bool> {
    /// `g` grown by a disc of `k` cells: each row of the result ORs the rows
    /// within k, each widened by the disc's half-width at that offset
    /// (running counts along the row).
    pub fn grown(&self, k: usize) -> Grid<bool> {
        use rayon::prelude::*;
        let g = self;
        let (w, h) = (g.w, g.h);
        // per row, the count of set cells before each index
        let prefix: Vec<Vec<u32>> = (0..h)
            .into_par_iter()
            .map(|j| {
                let mut p = Vec::with_capacity(w + 1);
                let mut n = 0;
                p.push(0);
                for i in 0..w {
                    n += *g.get(i, j) as u32;
                    p.push(n);
                }
                p
            })
            .collect();
        let mut out = Grid::new(w, h, false);
        let k = k as isize;
        out.data.par_chunks_mut(w).enumerate().for_each(|(j, row)| {
            for dj in -k..=k {
                let jj = j as isize + dj;
                if jj < 0 || jj >= h as isize {
                    continue;
                }
                let p = &prefix[jj as usize];
                if p[w] == 0 {
                    continue;
                }
                let span = ((k * k - dj * dj) as f64).sqrt().floor() as usize;
                for (i, c) in row.iter_mut().enumerate() {
                    if !*c {
                        let (a, b) = (i.saturating_sub(span), (i + span + 1).min(w));
                        *c = p[b] > p[a];
                    }
                }
            }
        });
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn growing_takes_a_disc() {
        let mut g = Grid::new(9, 9, false);
        g.set(4, 4, true);
        let o = g.grown(2);
        let n = o.data.iter().filter(|&&c| c).count();
        // the cells within 2 of the centre: 1 + 4 * 2 (axes) + 4 (diagonal 1,1) = 13
        assert_eq!(n, 13);
        assert!(*o.get(4, 2) && *o.get(6, 4) && *o.get(5, 5));
        assert!(!*o.get(6, 6) && !*o.get(6, 5));
    }
}
