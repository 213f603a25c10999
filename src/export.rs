//! The relief as a watertight solid (binary STL) in the shared frame of
//! DESIGN.md section 6: sample (i, j) at X = (i + 0.5) * pitch,
//! Y = height - (j + 0.5) * pitch, Z = h - depth (top of the relief at 0),
//! the top carried flat to the panel's edges, side walls and a flat
//! bottom at Z = -depth - base.

use crate::relief::Relief;
use stl_io::{Normal, Triangle, Vertex};

/// Vertex positions and outward-facing triangles of the solid: the top
/// is the continuous surface the toolpaths cut (`surface::Lattice`), the
/// samples joined by two triangles per cell and carried flat to the
/// panel's edges.
pub fn solid(r: &Relief, base_mm: f64) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let l = crate::cutter::surface::Lattice::of(r);
    let (w, h) = (l.w + 2, l.h + 2);
    let bottom = (-r.depth_mm - base_mm) as f32;
    let xy = |i: usize, j: usize| [l.vx(i) as f32, l.vy(j) as f32];
    let mut v: Vec<[f32; 3]> = Vec::with_capacity(w * h + 2 * (w + h) + 1);
    for j in 0..h {
        for i in 0..w {
            let [x, y] = xy(i, j);
            let (si, sj) = l.sample(i, j);
            v.push([x, y, *r.heights.get(si, sj) - r.depth_mm as f32]);
        }
    }
    let mut t = Vec::with_capacity(2 * w * h + 8 * (w + h));
    for j in 0..h - 1 {
        for i in 0..w - 1 {
            let a = (j * w + i) as u32;
            let (b, c, d) = (a + 1, a + w as u32, a + w as u32 + 1);
            t.push([a, c, b]);
            t.push([b, c, d]);
        }
    }
    // perimeter, counter-clockwise seen from above
    let mut ring: Vec<(usize, usize)> = Vec::new();
    ring.extend((0..w).map(|i| (i, h - 1)));
    ring.extend((0..h - 1).rev().map(|j| (w - 1, j)));
    ring.extend((0..w - 1).rev().map(|i| (i, 0)));
    ring.extend((1..h - 1).map(|j| (0, j)));
    ring.dedup();
    let first_bottom = v.len() as u32;
    for &(i, j) in &ring {
        let [x, y] = xy(i, j);
        v.push([x, y, bottom]);
    }
    let centre = v.len() as u32;
    v.push([
        (r.width_mm / 2.0) as f32,
        (r.height_mm / 2.0) as f32,
        bottom,
    ]);
    let n = ring.len();
    for k in 0..n {
        let (p, q) = (ring[k], ring[(k + 1) % n]);
        let (tp, tq) = ((p.1 * w + p.0) as u32, (q.1 * w + q.0) as u32);
        let (bp, bq) = (first_bottom + k as u32, first_bottom + ((k + 1) % n) as u32);
        t.push([tp, bp, tq]);
        t.push([tq, bp, bq]);
        t.push([centre, bq, bp]);
    }
    (v, t)
}

/// Binary STL bytes of the solid.
pub fn stl_bytes(r: &Relief, base_mm: f64) -> Vec<u8> {
    let mut out = Vec::new();
    write_stl(r, base_mm, &mut out).expect("writing STL into memory cannot fail");
    out
}

/// The solid as binary STL, streamed to `out`.
pub fn write_stl(r: &Relief, base_mm: f64, out: &mut dyn std::io::Write) -> std::io::Result<()> {
    let (v, t) = solid(r, base_mm);
    let tris = t.iter().map(|f| {
        let [a, b, c] = f.map(|i| glam::Vec3::from(v[i as usize]));
        let n = (b - a).cross(c - a).normalize_or_zero();
        Triangle {
            normal: Normal::new(n.into()),
            vertices: [a, b, c].map(|p| Vertex::new(p.into())),
        }
    });
    stl_io::write_stl(&mut { out }, tris)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::Grid;
    use std::collections::HashMap;

    #[test]
    fn solid_is_watertight_and_outward() {
        let heights = Grid::from_vec(5, 4, (0..20).map(|k| (k % 7) as f32 * 0.3).collect());
        let r = Relief {
            heights,
            width_mm: 10.0,
            height_mm: 8.0,
            depth_mm: 2.0,
        };
        let (v, t) = solid(&r, 1.0);
        let mut edges: HashMap<(u32, u32), i32> = HashMap::new();
        let mut volume = 0.0f64;
        for f in &t {
            for k in 0..3 {
                let (a, b) = (f[k], f[(k + 1) % 3]);
                *edges.entry((a.min(b), a.max(b))).or_default() += if a < b { 1 } else { -1 };
            }
            let [a, b, c] = f.map(|i| glam::DVec3::from(v[i as usize].map(|x| x as f64)));
            volume += a.dot(b.cross(c)) / 6.0;
        }
        // every edge used once in each direction: closed and consistently wound
        assert!(edges.values().all(|&c| c == 0));
        assert!(volume > 0.0, "outward normals give a positive volume");
        // volume = base slab + the relief above the bottom of the depth
        assert!(volume > 10.0 * 8.0 * 1.0);
        // the whole panel, to its edges
        let (lo, hi) = v
            .iter()
            .fold(([f32::MAX; 2], [f32::MIN; 2]), |(lo, hi), p| {
                (
                    [lo[0].min(p[0]), lo[1].min(p[1])],
                    [hi[0].max(p[0]), hi[1].max(p[1])],
                )
            });
        assert_eq!((lo, hi), ([0.0, 0.0], [10.0, 8.0]));
    }
}
