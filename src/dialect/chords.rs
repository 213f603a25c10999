//! GRBL's arc chords found again in a run of points: where a fitted arc's
//! chords stand, the emitter writes one G2/G3 for them.

use super::arc::{self, Arc, Plane};
use glam::DVec3;

/// The longest run of `pts` from `i` that is exactly the chords GRBL cuts
/// one arc into (at least two chords, in one plane, equal angles, ends on
/// the circle, the linear axis in equal steps: a helix where they are not
/// nought, as a ramp along a waterline's arc): its last index and the arc.
pub fn arc_run(pts: &[DVec3], i: usize, tol: f64) -> Option<(usize, Arc)> {
    const EPS: f64 = 1e-9;
    if i + 2 >= pts.len() {
        return None;
    }
    let (p0, p1, p2) = (pts[i], pts[i + 1], pts[i + 2]);
    let plane = if p0.y == p1.y && p1.y == p2.y {
        Plane::Zx
    } else if p0.x == p1.x && p1.x == p2.x {
        Plane::Yz
    } else if ((p2.z - p1.z) - (p1.z - p0.z)).abs() < EPS {
        Plane::Xy
    } else {
        return None;
    };
    let (a0, a1, lin) = plane.axes();
    let q = |p: DVec3| (p[a0], p[a1]);
    let ((x0, y0), (x1, y1), (x2, y2)) = (q(p0), q(p1), q(p2));
    // circumcentre of the first three
    let d = 2.0 * (x0 * (y1 - y2) + x1 * (y2 - y0) + x2 * (y0 - y1));
    if d.abs() < 1e-12 {
        return None;
    }
    let s0 = x0 * x0 + y0 * y0;
    let s1 = x1 * x1 + y1 * y1;
    let s2 = x2 * x2 + y2 * y2;
    let cx = (s0 * (y1 - y2) + s1 * (y2 - y0) + s2 * (y0 - y1)) / d;
    let cy = (s0 * (x2 - x1) + s1 * (x0 - x2) + s2 * (x1 - x0)) / d;
    let r = (x0 - cx).hypot(y0 - cy);
    if r > super::MAX_RADIUS {
        return None;
    }
    let chord = (x1 - x0).hypot(y1 - y0);
    let turn = |a: (f64, f64), b: (f64, f64)| (a.0 - cx) * (b.1 - cy) - (a.1 - cy) * (b.0 - cx);
    let cw = turn((x0, y0), (x1, y1)) < 0.0;
    let step = p1[lin] - p0[lin];
    let mut j = i + 1;
    while j + 1 < pts.len() {
        let (a, b) = (pts[j], pts[j + 1]);
        let (pa, pb) = (q(a), q(b));
        let same = ((b[lin] - a[lin]) - step).abs() < EPS
            && ((pb.0 - cx).hypot(pb.1 - cy) - r).abs() < EPS
            && ((pb.0 - pa.0).hypot(pb.1 - pa.1) - chord).abs() < EPS
            && (turn(pa, pb) < 0.0) == cw;
        if !same {
            break;
        }
        j += 1;
    }
    let arc = Arc {
        plane,
        clockwise: cw,
        centre: (cx, cy),
        radius: r,
    };
    // GRBL's count for the arc to j; a run of two arcs on one circle
    // is cut at the first's end
    while j >= i + 2 {
        if arc.chords(arc.travel(p0, pts[j]), tol) == j - i {
            return Some((j, arc));
        }
        j -= 1;
    }
    None
}

/// Every maximal run of GRBL arc chords in `pts` (`arc_run`), as the
/// indices (i, j) of its first and last point.
pub fn arc_runs(pts: &[DVec3]) -> Vec<(usize, usize)> {
    let mut runs = Vec::new();
    let mut i = 0;
    while i + 1 < pts.len() {
        match arc_run(pts, i, arc::GRBL_ARC_TOLERANCE) {
            Some((j, _)) => {
                runs.push((i, j));
                i = j;
            }
            None => i += 1,
        }
    }
    runs
}
