//! Exact drop-cutter on a sampled heightfield: for a tool axis at (x, y),
//! the lowest tip Z at which the tool touches no sample, i.e.
//! max over samples s within the tool radius of z_s - profile(|s - (x, y)|).
//!
//! Fast for large tools: a max-pyramid of the heights gives, for any block
//! of samples, an upper bound (block max - profile at the block's nearest
//! point) on what it can contribute; blocks that cannot beat the best
//! contribution found so far are skipped whole (branch and bound). Leaves
//! are evaluated with exactly the brute-force formula, so the result equals
//! the brute force bit for bit.

use crate::grid::Grid;
use crate::tool::Tool;

/// Heights (Z frame, mm) of samples at centres x = (i + 0.5) p,
/// y = top - (j + 0.5) p, with a max-pyramid over them.
pub struct HeightField {
    pub pitch: f64,
    /// Y of the top edge (the panel height).
    pub top: f64,
    /// levels[0] = the samples; levels[k] = max over 2^k x 2^k blocks.
    levels: Vec<Grid<f64>>,
    /// Max over runs of ROW_BLOCK samples along each row: lets a swept
    /// move's check skip stretches of a row lying below the tool.
    row_max: Grid<f64>,
}

/// Samples per `row_max` block.
pub const ROW_BLOCK: usize = 16;

impl HeightField {
    pub fn new(z: Grid<f64>, pitch: f64) -> HeightField {
        let top = z.h as f64 * pitch;
        let mut levels = vec![z];
        while let Some(l) = levels.last() {
            if l.w <= 1 && l.h <= 1 {
                break;
            }
            let (w, h) = (l.w.div_ceil(2), l.h.div_ceil(2));
            let mut n = Grid::new(w, h, f64::NEG_INFINITY);
            for y in 0..l.h {
                for x in 0..l.w {
                    let v = n.get(x / 2, y / 2).max(*l.get(x, y));
                    n.set(x / 2, y / 2, v);
                }
            }
            levels.push(n);
        }
        let z = &levels[0];
        let bw = z.w.div_ceil(ROW_BLOCK);
        let row_max = Grid::from_vec(
            bw,
            z.h,
            (0..z.h)
                .flat_map(|j| {
                    let row = &z.data[j * z.w..(j + 1) * z.w];
                    row.chunks(ROW_BLOCK)
                        .map(|c| c.iter().cloned().fold(f64::NEG_INFINITY, f64::max))
                        .collect::<Vec<_>>()
                })
                .collect(),
        );
        HeightField {
            pitch,
            top,
            levels,
            row_max,
        }
    }

    /// Highest sample of row block `b` (samples b*ROW_BLOCK..) of row `j`.
    #[inline]
    pub fn row_block_max(&self, b: usize, j: usize) -> f64 {
        self.row_max.data[j * self.row_max.w + b]
    }

    pub fn samples(&self) -> &Grid<f64> {
        &self.levels[0]
    }

    /// Centre of sample (i, j).
    #[inline]
    pub fn centre(&self, i: usize, j: usize) -> (f64, f64) {
        (
            (i as f64 + 0.5) * self.pitch,
            self.top - (j as f64 + 0.5) * self.pitch,
        )
    }

    /// Distance from (x, y) to the nearest sample centre of block (bx, by)
    /// at `level`.
    #[inline]
    fn block_distance(&self, level: usize, bx: usize, by: usize, x: f64, y: f64) -> f64 {
        let s = 1usize << level;
        let n = self.levels[0].w.max(1);
        let m = self.levels[0].h.max(1);
        let (i0, i1) = (bx * s, ((bx + 1) * s).min(n) - 1);
        let (j0, j1) = (by * s, ((by + 1) * s).min(m) - 1);
        let (x0, y1) = self.centre(i0, j0);
        let (x1, y0) = self.centre(i1, j1);
        let dx = (x0 - x).max(0.0).max(x - x1);
        let dy = (y0 - y).max(0.0).max(y - y1);
        (dx * dx + dy * dy).sqrt()
    }

    /// Exact drop-cutter at (x, y); None when no sample lies within reach.
    pub fn drop(&self, tool: &Tool, x: f64, y: f64) -> Option<f64> {
        self.drop_from(tool, x, y, None, &mut Vec::new())
            .map(|c| c.0)
    }

    /// Contribution of sample (i, j) to the tool at (x, y), if in reach.
    #[inline]
    pub fn contribution(&self, tool: &Tool, i: usize, j: usize, x: f64, y: f64) -> Option<f64> {
        let (sx, sy) = self.centre(i, j);
        let rho = ((sx - x) * (sx - x) + (sy - y) * (sy - y)).sqrt();
        (rho <= tool.radius()).then(|| self.levels[0].get(i, j) - tool.profile(rho))
    }

    /// Drop-cutter that starts from a `hint` sample (the previous point's
    /// contact, usually close to this one's) and reuses `stack`; returns
    /// the CL height and the contact sample.
    pub fn drop_from(
        &self,
        tool: &Tool,
        x: f64,
        y: f64,
        hint: Option<(usize, usize)>,
        stack: &mut Vec<(f64, usize, usize, usize)>,
    ) -> Option<(f64, (usize, usize))> {
        let r = tool.radius();
        let mut best = f64::NEG_INFINITY;
        let mut contact = (0, 0);
        if let Some((i, j)) = hint {
            if let Some(z) = self.contribution(tool, i, j, x, y) {
                (best, contact) = (z, (i, j));
            }
        }
        // start at the level whose blocks are about the footprint's size,
        // with the (few) blocks the footprint's bounding box touches
        let reach = (2.0 * r / self.pitch).max(1.0);
        let start = (reach.log2().ceil() as usize).min(self.levels.len() - 1);
        let s = (1usize << start) as f64 * self.pitch;
        let base = &self.levels[start];
        let bx0 = (((x - r) / s).floor().max(0.0) as usize).min(base.w - 1);
        let bx1 = (((x + r) / s).floor().max(0.0) as usize).min(base.w - 1);
        let by0 = ((((self.top - y) - r) / s).floor().max(0.0) as usize).min(base.h - 1);
        let by1 = ((((self.top - y) + r) / s).floor().max(0.0) as usize).min(base.h - 1);
        stack.clear();
        for by in by0..=by1 {
            for bx in bx0..=bx1 {
                let d = self.block_distance(start, bx, by, x, y);
                if d <= r {
                    stack.push((base.get(bx, by) - tool.profile(d), start, bx, by));
                }
            }
        }
        stack.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        while let Some((bound, level, bx, by)) = stack.pop() {
            if bound <= best {
                continue;
            }
            if level == 0 {
                // the bound of a single sample is its contribution
                (best, contact) = (bound, (bx, by));
                continue;
            }
            // children, most promising last so they are searched first
            let child = &self.levels[level - 1];
            let mut kids = [(0.0f64, 0usize, 0usize, 0usize); 4];
            let mut nk = 0;
            for (cx, cy) in [
                (2 * bx, 2 * by),
                (2 * bx + 1, 2 * by),
                (2 * bx, 2 * by + 1),
                (2 * bx + 1, 2 * by + 1),
            ] {
                if cx >= child.w || cy >= child.h {
                    continue;
                }
                let d = self.block_distance(level - 1, cx, cy, x, y);
                if d > r {
                    continue;
                }
                let b = child.get(cx, cy) - tool.profile(d);
                if b > best {
                    kids[nk] = (b, level - 1, cx, cy);
                    nk += 1;
                }
            }
            kids[..nk].sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
            stack.extend_from_slice(&kids[..nk]);
        }
        best.is_finite().then_some((best, contact))
    }

    /// Brute force over every sample in reach (the reference).
    pub fn drop_brute(&self, tool: &Tool, x: f64, y: f64) -> Option<f64> {
        let z = &self.levels[0];
        let mut best = f64::NEG_INFINITY;
        for j in 0..z.h {
            for i in 0..z.w {
                let (sx, sy) = self.centre(i, j);
                let rho = ((sx - x) * (sx - x) + (sy - y) * (sy - y)).sqrt();
                if rho <= tool.radius() {
                    best = best.max(z.get(i, j) - tool.profile(rho));
                }
            }
        }
        best.is_finite().then_some(best)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn random_field(w: usize, h: usize, seed: u64, rough: bool) -> HeightField {
        let mut s = seed;
        let mut rnd = move || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let z: Vec<f64> = (0..w * h)
            .map(|k| {
                let (x, y) = ((k % w) as f64, (k / w) as f64);
                let smooth = -2.0 + 0.8 * (x / 7.0).sin() * (y / 5.0).cos();
                if rough {
                    smooth + 0.6 * rnd()
                } else {
                    smooth + 0.01 * rnd()
                }
            })
            .collect();
        HeightField::new(Grid::from_vec(w, h, z), 0.1)
    }

    #[test]
    fn every_tool_matches_brute_force() {
        let tools = [
            "ball:1.5",
            "ball:6",
            "flat:0.8",
            "flat:3.3",
            "taperball:0.2:8:2.4",
            "vbit:60:2",
            "vbit:90:5",
        ];
        for (seed, rough) in [(1, true), (2, false)] {
            let hf = random_field(53, 41, seed, rough);
            let mut s = seed * 77;
            let mut rnd = move || {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (s >> 11) as f64 / (1u64 << 53) as f64
            };
            for spec in tools {
                let tool = Tool::parse(spec).unwrap();
                for _ in 0..150 {
                    let (x, y) = (-0.5 + 6.3 * rnd(), -0.5 + 5.1 * rnd());
                    let (a, b) = (hf.drop(&tool, x, y), hf.drop_brute(&tool, x, y));
                    // a hint (right or wrong) never changes the answer
                    let hinted = hf
                        .drop_from(&tool, x, y, Some((7, 9)), &mut Vec::new())
                        .map(|c| c.0);
                    assert_eq!(a, hinted);
                    match (a, b) {
                        (Some(a), Some(b)) => {
                            assert!((a - b).abs() <= 1e-9, "{spec} at ({x},{y}): {a} vs {b}")
                        }
                        (a, b) => assert_eq!(a, b, "{spec} at ({x},{y})"),
                    }
                }
            }
        }
    }
}
