//! Raster finishing: parallel rows across the panel at an angle, zigzag,
//! each row and each link between rows dropped onto the CL surface, so the
//! whole raster is one continuous pass.

use super::dropcutter::HeightField;
use super::path::{drop_along, merge};
use crate::tool::Tool;
use glam::DVec3;
use rayon::prelude::*;

/// Rows of XY points across the rectangle [0,w] x [0,h] in direction
/// `angle` (degrees), `stepover` apart, points at most `step` apart.
pub fn rows(w: f64, h: f64, angle: f64, stepover: f64, step: f64) -> Vec<Vec<(f64, f64)>> {
    let (c, s) = (angle.to_radians().cos(), angle.to_radians().sin());
    // along = (c, s), across = (-s, c); cover the rectangle's projection
    let corners = [(0.0, 0.0), (w, 0.0), (0.0, h), (w, h)];
    let across: Vec<f64> = corners.iter().map(|&(x, y)| -s * x + c * y).collect();
    let (lo, hi) = (
        across.iter().cloned().fold(f64::MAX, f64::min),
        across.iter().cloned().fold(f64::MIN, f64::max),
    );
    let n = ((hi - lo) / stepover).ceil().max(0.0) as usize;
    let mut out = Vec::new();
    for k in 0..=n {
        // first and last rows run along the edges
        let v = (lo + k as f64 * stepover).min(hi);
        // clip the line {t (c,s) + v (-s,c)} to the rectangle
        let (mut t0, mut t1) = (f64::MIN, f64::MAX);
        let (ox, oy) = (-s * v, c * v);
        for (o, d, lim) in [(ox, c, w), (oy, s, h)] {
            if d.abs() < 1e-12 {
                if o < -1e-9 || o > lim + 1e-9 {
                    t0 = f64::MAX;
                }
            } else {
                let (a, b) = ((0.0 - o) / d, (lim - o) / d);
                t0 = t0.max(a.min(b));
                t1 = t1.min(a.max(b));
            }
        }
        if t0 > t1 {
            continue;
        }
        let m = ((t1 - t0) / step).ceil().max(1.0) as usize;
        let row: Vec<(f64, f64)> = (0..=m)
            .map(|i| {
                let t = t0 + (t1 - t0) * i as f64 / m as f64;
                ((ox + t * c).clamp(0.0, w), (oy + t * s).clamp(0.0, h))
            })
            .collect();
        out.push(row);
        if v >= hi {
            break;
        }
    }
    out
}

/// The zigzag raster as one continuous CL polyline: rows alternate in
/// direction and each link from a row's end to the next row's start is
/// dropped too. Rows are dropped and merged within `tol` in parallel.
/// Returns the pass and the number of CL points before merging.
pub fn zigzag(
    hf: &HeightField,
    tool: &Tool,
    rows: &[Vec<(f64, f64)>],
    floor: f64,
    refine: bool,
    tol: f64,
) -> (Vec<DVec3>, usize) {
    let step = hf.pitch;
    let passes: Vec<(Vec<DVec3>, usize)> = rows
        .par_iter()
        .enumerate()
        .map(|(k, row)| {
            let mut r = row.clone();
            if k % 2 == 1 {
                r.reverse();
            }
            let cl = drop_along(hf, tool, &r, floor, refine);
            (merge(&cl, tol), cl.len())
        })
        .collect();
    let raw = passes.iter().map(|p| p.1).sum();
    let mut out: Vec<DVec3> = Vec::new();
    for (pass, _) in passes {
        if let (Some(&a), Some(&b)) = (out.last(), pass.first()) {
            let n = ((b - a).truncate().length() / step).ceil().max(1.0) as usize;
            let link: Vec<(f64, f64)> = (0..=n)
                .map(|i| {
                    let t = i as f64 / n as f64;
                    (a.x + (b.x - a.x) * t, a.y + (b.y - a.y) * t)
                })
                .collect();
            // the link, merged, replaces the pass's first point (merging
            // may lift a run's end, never lower it)
            let l = merge(&drop_along(hf, tool, &link, floor, refine), tol);
            out.extend_from_slice(&l[1..]);
            out.extend_from_slice(&pass[1..]);
            continue;
        }
        out.extend(pass);
    }
    (out, raw)
}

/// One-way rows, each its own pass (merged within `tol`), and the number
/// of CL points before merging. Rows follow one another toward the
/// left of their direction, so the uncut side is on the left: climb
/// (material on the right of a clockwise spindle) runs them backwards.
pub fn one_way(
    hf: &HeightField,
    tool: &Tool,
    rows: &[Vec<(f64, f64)>],
    floor: f64,
    climb: bool,
    refine: bool,
    tol: f64,
) -> (Vec<Vec<DVec3>>, usize) {
    let rows: Vec<(Vec<DVec3>, usize)> = rows
        .par_iter()
        .map(|row| {
            let mut r = row.clone();
            if climb {
                r.reverse();
            }
            let cl = drop_along(hf, tool, &r, floor, refine);
            (merge(&cl, tol), cl.len())
        })
        .collect();
    let raw = rows.iter().map(|r| r.1).sum();
    (rows.into_iter().map(|r| r.0).collect(), raw)
}

#[cfg(test)]
mod tests {
    #[test]
    fn rows_cover_the_panel() {
        let r = super::rows(10.0, 4.0, 0.0, 1.0, 0.5);
        assert_eq!(r.len(), 5);
        assert_eq!(r[0].first(), Some(&(0.0, 0.0)));
        assert_eq!(r[4].last(), Some(&(10.0, 4.0)));
        let d = super::rows(10.0, 4.0, 45.0, 1.0, 0.5);
        assert!(d.len() > 9);
        for row in &d {
            for &(x, y) in row {
                assert!((0.0..=10.0).contains(&x) && (0.0..=4.0).contains(&y));
            }
        }
    }
}
