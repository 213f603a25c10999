//! Tiles: a panel larger than the machine's travel cut in pieces that
//! each fit, the stock moved between them. Every tile's job is the one
//! big job's moves clipped to the tile (segments cut exactly where they
//! cross its border, so the cut is the same), its own X0 Y0 at the tile's
//! lower-left corner. Clearing passes reach a little past the border so
//! that the finishing tool, working along it, never meets uncleared
//! stock on the neighbour's side.

use glam::DVec3;

/// The tiles of a `pw` x `ph` panel, `w` x `h` at most, row by row from
/// the lower-left: `[x0, y0, x1, y1]` in panel mm, with (column, row).
pub fn grid(pw: f64, ph: f64, w: f64, h: f64) -> Vec<([f64; 4], (usize, usize))> {
    let nx = ((pw / w) - 1e-9).ceil().max(1.0) as usize;
    let ny = ((ph / h) - 1e-9).ceil().max(1.0) as usize;
    // equal tiles: no sliver at the far edge
    let (tw, th) = (pw / nx as f64, ph / ny as f64);
    let mut out = Vec::with_capacity(nx * ny);
    for j in 0..ny {
        for i in 0..nx {
            let x0 = crate::toolpath::path::snap(i as f64 * tw);
            let y0 = crate::toolpath::path::snap(j as f64 * th);
            let x1 = if i + 1 == nx {
                pw
            } else {
                crate::toolpath::path::snap((i + 1) as f64 * tw)
            };
            let y1 = if j + 1 == ny {
                ph
            } else {
                crate::toolpath::path::snap((j + 1) as f64 * th)
            };
            out.push(([x0, y0, x1, y1], (i + 1, j + 1)));
        }
    }
    out
}

/// The pieces of the polyline `pts` inside `rect` (XY), each segment cut
/// where it crosses the border (Z along the segment).
pub fn clip(pts: &[DVec3], rect: [f64; 4]) -> Vec<Vec<DVec3>> {
    let [x0, y0, x1, y1] = rect;
    let inside = |p: DVec3| p.x >= x0 && p.x <= x1 && p.y >= y0 && p.y <= y1;
    let mut out: Vec<Vec<DVec3>> = Vec::new();
    let mut cur: Vec<DVec3> = Vec::new();
    if pts.len() == 1 && inside(pts[0]) {
        return vec![pts.to_vec()];
    }
    for w in pts.windows(2) {
        let (a, b) = (w[0], w[1]);
        let d = b - a;
        let Some((t0, t1)) = crate::cutter::sweep::clip_to_rect((a.x, a.y), (d.x, d.y), rect)
        else {
            if cur.len() > 1 {
                out.push(std::mem::take(&mut cur));
            }
            cur.clear();
            continue;
        };
        let (pa, pb) = (a + d * t0, a + d * t1);
        if cur.is_empty() || t0 > 0.0 {
            if cur.len() > 1 {
                out.push(std::mem::take(&mut cur));
            }
            cur = vec![pa];
        }
        cur.push(pb);
        if t1 < 1.0 {
            out.push(std::mem::take(&mut cur));
        }
    }
    if cur.len() > 1 {
        out.push(cur);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_cover_the_panel_in_equal_pieces() {
        let g = grid(600.0, 400.0, 280.0, 170.0);
        assert_eq!(g.len(), 9);
        assert_eq!(g[0].0, [0.0, 0.0, 200.0, 133.3333]);
        assert_eq!(g[8].0, [400.0, 266.6667, 600.0, 400.0]);
        assert_eq!(g[5].1, (3, 2));
    }

    #[test]
    fn a_path_is_cut_at_the_border_along_its_segments() {
        let pts = vec![
            DVec3::new(-2.0, 1.0, 0.0),
            DVec3::new(2.0, 1.0, -4.0),
            DVec3::new(4.0, 1.0, -4.0),
            DVec3::new(4.0, 3.0, -2.0),
            DVec3::new(1.0, 3.0, -2.0),
        ];
        let parts = clip(&pts, [0.0, 0.0, 3.0, 5.0]);
        assert_eq!(parts.len(), 2);
        // enters at x = 0 half way down the first segment
        assert_eq!(parts[0][0], DVec3::new(0.0, 1.0, -2.0));
        assert_eq!(parts[0].last().copied(), Some(DVec3::new(3.0, 1.0, -4.0)));
        assert_eq!(
            parts[1],
            vec![DVec3::new(3.0, 3.0, -2.0), DVec3::new(1.0, 3.0, -2.0)]
        );
        // wholly inside: unchanged
        assert_eq!(
            clip(&pts[1..3], [0.0, 0.0, 10.0, 10.0]),
            vec![pts[1..3].to_vec()]
        );
    }
}
