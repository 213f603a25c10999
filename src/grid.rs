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
