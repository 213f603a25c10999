//! Shaded preview of a relief: a headlight plus one raking light from the
//! upper left, as a carving is seen on a wall.

use crate::grid::Grid;
use crate::relief::Relief;
use rayon::prelude::*;

/// Unit surface normal at sample (i, j), from central differences
/// (one-sided at the edges); rows run toward -Y.
fn normal(r: &Relief, i: usize, j: usize) -> glam::DVec3 {
    let (w, h) = (r.heights.w, r.heights.h);
    let (px, py) = (r.width_mm / w as f64, r.height_mm / h as f64);
    let z = |i: usize, j: usize| *r.heights.get(i, j) as f64;
    let (i0, i1) = (i.saturating_sub(1), (i + 1).min(w - 1));
    let (j0, j1) = (j.saturating_sub(1), (j + 1).min(h - 1));
    let dzdx = (z(i1, j) - z(i0, j)) / (((i1 - i0).max(1)) as f64 * px);
    let dzdy = -(z(i, j1) - z(i, j0)) / (((j1 - j0).max(1)) as f64 * py);
    glam::DVec3::new(-dzdx, -dzdy, 1.0).normalize()
}

pub fn shade(r: &Relief) -> Grid<u8> {
    let (w, h) = (r.heights.w, r.heights.h);
    let rake = glam::DVec3::new(-1.0, 1.0, 0.7).normalize();
    let mut out = Grid::new(w, h, 0u8);
    out.data.par_chunks_mut(w).enumerate().for_each(|(j, row)| {
        for (i, o) in row.iter_mut().enumerate() {
            let n = normal(r, i, j);
            let l = 0.08 + 0.42 * n.z + 0.6 * n.dot(rake).max(0.0);
            *o = (l.clamp(0.0, 1.0) * 255.0).round() as u8;
        }
    });
    out
}

/// Shaded with one light from `light` (azimuth clockwise from +Y, i.e.
/// from the panel's top edge, and elevation, degrees; default 315, 35: the
/// upper left) plus a little ambient, the contrast stretched so that the
/// 1st and 99th percentiles of the shades span black to white.
pub fn shade_lit(r: &Relief, light: Option<(f64, f64)>) -> Grid<u8> {
    let (w, h) = (r.heights.w, r.heights.h);
    let (az, el) = light.unwrap_or((315.0, 35.0));
    let (az, el) = (az.to_radians(), el.to_radians());
    let l = glam::DVec3::new(az.sin() * el.cos(), az.cos() * el.cos(), el.sin());
    let mut v = vec![0.0f32; w * h];
    v.par_chunks_mut(w).enumerate().for_each(|(j, row)| {
        for (i, o) in row.iter_mut().enumerate() {
            let n = normal(r, i, j);
            *o = (0.15 + 0.85 * n.dot(l).max(0.0)) as f32;
        }
    });
    let mut sorted = v.clone();
    sorted.sort_unstable_by(f32::total_cmp);
    let q = |f: f64| sorted[((sorted.len() - 1) as f64 * f) as usize];
    let (lo, hi) = (q(0.01), q(0.99));
    let span = (hi - lo).max(1e-6);
    Grid {
        w,
        h,
        data: v
            .iter()
            .map(|x| (((x - lo) / span).clamp(0.0, 1.0) * 255.0).round() as u8)
            .collect(),
    }
}
