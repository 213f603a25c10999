//! Clean shoulders beside stepped outlines. With `--steps` an outline is
//! carved as one rise of the given height. A form that rolls over into
//! its outline (the bunny's back at 512 px) keeps rising across the last
//! samples before it, so the step is blurred into a ramp and reads up to
//! a tenth of a millimetre taller than asked within two samples of it,
//! unevenly along the outline. Within three samples of an outline, the
//! part of the slope across it that goes the step's way is faded out
//! (gone within one, half at two), so the step alone makes the rise
//! there; the slope along the outline stays,
//! and so does a slope against the step (a wall falling away from its top
//! edge), which leaves the step's edges sharp and a receding wall whole.

use super::gradient::Field;
use crate::grid::Grid;
use rayon::prelude::*;

/// Within this distance (output samples) of an outline's barrier samples
/// the slope across the outline going the step's way is gone ...
const FLAT: f32 = 1.0;
/// ... and from here out it is whole (a smooth ramp between). Faded up
/// to 2 samples out instead, half the slope between one and two samples
/// stayed and put 0.03-0.1 mm onto the step two samples either side on
/// 52 of the bunny's 3,008 outline samples at 512 px.
const WHOLE: f32 = 3.0;

/// Fade the slopes' component across the nearest outline (its normal,
/// from the step field spread over a few samples) by the distance to it,
/// where it goes the step's way.
pub fn flatten(gx: &mut Grid<f32>, gy: &mut Grid<f32>, field: &Field) {
    let (w, h) = (gx.w, gx.h);
    let dist = distance(&field.barrier, WHOLE);
    // the step field's direction: a Gaussian of 1.5 samples over 4 around
    const R: isize = 4;
    let kernel: Vec<(isize, isize, f32)> = (-R..=R)
        .flat_map(|dy| (-R..=R).map(move |dx| (dx, dy)))
        .map(|(dx, dy)| (dx, dy, (-((dx * dx + dy * dy) as f32) / 4.5).exp()))
        .collect();
    let normal = |x: usize, y: usize| {
        let (mut ax, mut ay) = (0.0f32, 0.0f32);
        for &(dx, dy, k) in &kernel {
            let (xx, yy) = (x as isize + dx, y as isize + dy);
            if xx >= 0 && yy >= 0 && (xx as usize) < w && (yy as usize) < h {
                let i = yy as usize * w + xx as usize;
                ax += k * field.sx.data[i];
                ay += k * field.sy.data[i];
            }
        }
        (ax, ay)
    };
    gx.data
        .par_chunks_mut(w)
        .zip(gy.data.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, (rx, ry))| {
            for x in 0..w {
                let d = dist[y * w + x];
                if d >= WHOLE {
                    continue;
                }
                let (ax, ay) = normal(x, y);
                let m = ax.hypot(ay);
                if m < 1e-4 {
                    continue;
                }
                let (ux, uy) = (ax / m, ay / m);
                // only a slope that goes on rising the way the step rises
                // (a rim rolling over into it, a cove at its foot) blurs
                // the step into a ramp; one against it leaves the step's
                // edges sharp
                let a = rx[x] * ux + ry[x] * uy;
                if a <= 0.0 {
                    continue;
                }
                let t = ((d - FLAT) / (WHOLE - FLAT)).clamp(0.0, 1.0);
                let across = a * (1.0 - t * t * (3.0 - 2.0 * t));
                rx[x] -= across * ux;
                ry[x] -= across * uy;
            }
        });
}

/// Euclidean distance (samples) from each sample to the nearest set one
/// where that is under `reach`, `f32::MAX` elsewhere: each set sample
/// stamps the disc around it (outlines are thin, so this is cheap).
fn distance(set: &Grid<bool>, reach: f32) -> Vec<f32> {
    let (w, h) = (set.w as isize, set.h as isize);
    let r = reach.ceil() as isize;
    let disc: Vec<(isize, isize, f32)> = (-r..=r)
        .flat_map(|dy| (-r..=r).map(move |dx| (dx, dy)))
        .map(|(dx, dy)| (dx, dy, ((dx * dx + dy * dy) as f32).sqrt()))
        .filter(|d| d.2 < reach)
        .collect();
    let mut out = vec![f32::MAX; set.data.len()];
    for (i, _) in set.data.iter().enumerate().filter(|s| *s.1) {
        let (x, y) = (i as isize % w, i as isize / w);
        for &(dx, dy, d) in &disc {
            let (xx, yy) = (x + dx, y + dy);
            if xx >= 0 && yy >= 0 && xx < w && yy < h {
                let o = &mut out[(yy * w + xx) as usize];
                *o = o.min(d);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A straight outline between columns 9 and 10 stepping up toward +x,
    /// on a field sloping (gx, 0.3) everywhere.
    fn flattened(gx: f32) -> (Grid<f32>, Grid<f32>) {
        let (w, h) = (20, 12);
        let mut f = Field {
            gx: Grid::new(w, h, gx),
            gy: Grid::new(w, h, 0.3),
            sx: Grid::new(w, h, 0.0),
            sy: Grid::new(w, h, 0.0),
            barrier: Grid::new(w, h, false),
            mask: Grid::new(w, h, true),
            id: Grid::new(w, h, 1),
            depth: Grid::new(w, h, 0.0),
            n_fine: 2 * w,
            silhouette_edges: h,
        };
        for y in 0..h {
            f.sx.set(9, y, 0.5);
            f.gx.set(9, y, 0.0);
            f.barrier.set(9, y, true);
            f.barrier.set(10, y, true);
        }
        let (mut gx, mut gy) = (f.gx.clone(), f.gy.clone());
        flatten(&mut gx, &mut gy, &f);
        (gx, gy)
    }

    #[test]
    fn a_slope_going_the_step_s_way_fades_beside_it() {
        let (gx, gy) = flattened(0.5);
        let y = 6;
        // barrier samples and their neighbours: gone; two out: half;
        // three out: whole
        for x in [8, 10, 11] {
            assert!(gx.get(x, y).abs() < 1e-6, "x {x}: {}", gx.get(x, y));
        }
        for x in [7, 12] {
            assert!(
                (gx.get(x, y) - 0.25).abs() < 1e-6,
                "x {x}: {}",
                gx.get(x, y)
            );
        }
        for x in [5, 6, 13, 14, 19] {
            assert!((gx.get(x, y) - 0.5).abs() < 1e-6, "x {x}: {}", gx.get(x, y));
        }
        // the slope along the outline stays
        assert!(gy.data.iter().all(|v| (v - 0.3).abs() < 1e-6));
    }

    #[test]
    fn a_slope_against_the_step_stays() {
        let (gx, _) = flattened(-0.5);
        for x in (0..20).filter(|&x| x != 9) {
            assert_eq!(*gx.get(x, 6), -0.5);
        }
    }
}
