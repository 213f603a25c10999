//! Thinning a pass: runs of CL points become single moves within the
//! tolerance, never below a dropped point.

use glam::DVec3;

/// Replace runs of points by single moves where every dropped point lies
/// within `tol` of the move. A move never passes below a dropped point:
/// merging adds no gouge, only up to `tol` of material left. A straight
/// row (a raster row: a move above every dropped point is above the whole
/// dropped polyline) takes the fewest moves (`fewest::row`); other paths
/// fix each move's end as they go (`merge_fixed`).
pub fn merge(points: &[DVec3], tol: f64) -> Vec<DVec3> {
    if points.len() < 3 {
        return points.to_vec();
    }
    super::fewest::row(points, tol).unwrap_or_else(|| merge_fixed(points, tol))
}

/// Merging that fixes each move's end as it goes: where a move would pass
/// below a dropped point, its end is lifted (by at most `tol`) until it
/// clears them all.
pub(crate) fn merge_fixed(points: &[DVec3], tol: f64) -> Vec<DVec3> {
    merge_with(points, tol, true)
}

/// `merge`, with `fast` the O(1) test per point along straight rows
/// (`Run`), else each candidate move checked against every point it
/// replaces (a long straight run costs its length squared).
fn merge_with(points: &[DVec3], tol: f64, fast: bool) -> Vec<DVec3> {
    if points.len() < 3 {
        return points.to_vec();
    }
    // the lift the end of a -> e needs to clear the points between
    let lift = |a: DVec3, e: DVec3, mid: &[DVec3]| -> Option<f64> {
        let d = e - a;
        let dxy = d.truncate().length_squared();
        let mut need = 0.0f64;
        for &p in mid {
            if dxy == 0.0 {
                return None;
            }
            let s = (p - a).truncate().dot(d.truncate()) / dxy;
            if s <= 0.0 || s > 1.0 {
                return None;
            }
            need = need.max((p.z - a.z) / s - d.z);
        }
        let e = DVec3::new(e.x, e.y, e.z + need);
        let d = e - a;
        let (dd, tol2) = (d.length_squared(), tol * tol);
        let near = mid.iter().all(|&p| {
            let t = ((p - a).dot(d) / dd).clamp(0.0, 1.0);
            (p - (a + d * t)).length_squared() <= tol2
        });
        (need <= tol && near).then_some(need)
    };
    let mut out = vec![points[0]];
    let mut anchor = points[0];
    let mut start = 0; // index of the anchor's original point
    let mut k = 2;
    let mut pending = points[1];
    let mut run = Run::new(anchor, points[1], tol);
    while k < points.len() {
        let e = points[k];
        let fast_verdict = if fast { run.test(e) } else { None };
        let l = fast_verdict.unwrap_or_else(|| lift(anchor, e, &points[start + 1..k]));
        match l {
            Some(l) => {
                pending = DVec3::new(e.x, e.y, e.z + l);
                run.add(e);
                k += 1;
            }
            None => {
                out.push(pending);
                anchor = pending;
                start = k - 1;
                pending = e;
                run = Run::new(anchor, e, tol);
                k += 1;
            }
        }
    }
    out.push(pending);
    out
}

/// The points a merged move from `a` replaces, while they lie on one
/// straight line in XY moving away from `a` (a raster row): in the
/// vertical plane of that line, at distance u from `a` and height h over
/// it, the move lifted over them all rises at the steepest of their
/// slopes h / u, which only grows as the move reaches on, and the farthest
/// of them below it lies max(s u - h) / sqrt(1 + s^2) from it: the upper
/// envelope of lines in s, kept as a hull whose best line moves forward.
struct Run {
    a: DVec3,
    /// Unit direction of the line in XY.
    dir: glam::DVec2,
    tol: f64,
    /// Every point so far on the line, each beyond the one before.
    straight: bool,
    /// Distance of the last point from `a`.
    last_u: f64,
    /// Steepest slope h / u so far.
    steepest: f64,
    /// Least u and least h so far (a check that each point's foot on the
    /// move lies past `a`).
    least_u: f64,
    least_h: f64,
    /// The hull of the lines s -> u s - h (u growing), and the index of
    /// the best one at the last slope asked.
    hull: Vec<(f64, f64)>,
    best: usize,
}

impl Run {
    fn new(a: DVec3, first: DVec3, tol: f64) -> Run {
        let v = (first - a).truncate();
        let len = v.length();
        let mut r = Run {
            a,
            dir: if len > 0.0 {
                v / len
            } else {
                glam::DVec2::ZERO
            },
            tol,
            straight: len > 0.0,
            last_u: 0.0,
            steepest: f64::NEG_INFINITY,
            least_u: f64::INFINITY,
            least_h: f64::INFINITY,
            hull: Vec::new(),
            best: 0,
        };
        r.add(first);
        r
    }

    /// Where `p` lies on the line: its distance along it, if it is on the
    /// line (within a nanometre) and beyond every point so far.
    fn along(&self, p: DVec3) -> Option<f64> {
        let v = (p - self.a).truncate();
        let u = v.dot(self.dir);
        (self.straight && v.perp_dot(self.dir).abs() <= 1e-6 && u > self.last_u).then_some(u)
    }

    /// A point the move now reaches past.
    fn add(&mut self, p: DVec3) {
        let Some(u) = self.along(p) else {
            self.straight = false;
            return;
        };
        let h = p.z - self.a.z;
        self.last_u = u;
        self.steepest = self.steepest.max(h / u);
        self.least_u = self.least_u.min(u);
        self.least_h = self.least_h.min(h);
        // the line s -> u s - h; slopes u grow, so it goes last, and lines
        // it and the one before leave nowhere best drop out
        let line = (u, -h);
        while self.hull.len() >= 2 {
            let (l1, l2) = (
                self.hull[self.hull.len() - 2],
                self.hull[self.hull.len() - 1],
            );
            // l2 is never strictly best where `line` crosses l1 at or
            // before l2 does
            if (line.1 - l1.1) * (l2.0 - l1.0) >= (l2.1 - l1.1) * (line.0 - l1.0) {
                self.hull.pop();
            } else {
                break;
            }
        }
        self.hull.push(line);
        self.best = self.best.min(self.hull.len() - 1);
    }

    /// The lift a move from `a` to `e` needs over the points so far (as
    /// `merge`'s exact test gives it): Some(Some(lift)) when it is within
    /// the tolerance, Some(None) when not, None when this test cannot
    /// tell (off the line, or a point's foot before `a`); from then on it
    /// leaves the run to the exact test.
    fn test(&mut self, e: DVec3) -> Option<Option<f64>> {
        let Some(u) = self.along(e) else {
            self.straight = false;
            return None;
        };
        let h = e.z - self.a.z;
        let s = self.steepest.max(h / u);
        let need = s * u - h;
        if need > self.tol {
            return Some(None);
        }
        // every point's foot on the lifted move lies past a (past e it
        // cannot: they are all below the move and nearer than e)
        if s > 0.0 && self.least_u + s * self.least_h < 0.0 {
            self.straight = false;
            return None;
        }
        while self.best + 1 < self.hull.len() {
            let (p, q) = (self.hull[self.best], self.hull[self.best + 1]);
            if q.0 * s + q.1 >= p.0 * s + p.1 {
                self.best += 1;
            } else {
                break;
            }
        }
        let (bu, bh) = self.hull[self.best];
        let far = bu * s + bh;
        Some((far <= self.tol * (1.0 + s * s).sqrt()).then_some(need))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn merge_keeps_corners_and_drops_collinear_points() {
        let pts: Vec<DVec3> = (0..=100)
            .map(|i| {
                let x = i as f64 * 0.1;
                DVec3::new(
                    x,
                    0.0,
                    if x < 5.0 {
                        -x * 0.1
                    } else {
                        -0.5 + (x - 5.0) * 0.2
                    },
                )
            })
            .collect();
        let m = merge(&pts, 0.005);
        assert_eq!(m.len(), 3, "{m:?}");
        assert!((m[1].x - 5.0).abs() < 1e-9);
    }
}

#[cfg(test)]
pub(crate) mod merge_tests {
    use super::*;
    use crate::toolpath::path::snap;

    /// Rows of dropped points on the G-code grid: noise, steps (a corner
    /// straight above a point), steep walls, and every fifth bent out of
    /// line.
    pub(crate) fn stepped_rows() -> Vec<Vec<DVec3>> {
        let mut seed = 7u64;
        let mut rnd = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut rows = Vec::new();
        for case in 0..40 {
            let mut pts: Vec<DVec3> = Vec::new();
            for i in 0..600 {
                let x = i as f64 * 0.05;
                let z = -1.0
                    + 0.4 * (x * (0.5 + case as f64 * 0.1)).sin()
                    + 0.002 * rnd()
                    + if (x % 7.0) > 3.5 { 0.8 } else { 0.0 };
                let p = DVec3::new(snap(x), 2.0, snap(z));
                if let Some(&q) = pts.last() {
                    if (p.z - q.z).abs() > 0.5 {
                        // a step: straight up (or across first, then down)
                        pts.push(if p.z > q.z {
                            DVec3::new(q.x, q.y, p.z)
                        } else {
                            DVec3::new(p.x, p.y, q.z)
                        });
                    }
                }
                pts.push(p);
            }
            if case % 5 == 4 {
                // a bend: the rest of the row turns off the line
                for p in pts.iter_mut().skip(400) {
                    p.y += (p.x - 20.0) * 0.3;
                }
            }
            rows.push(pts);
        }
        rows
    }

    /// The O(1) test along straight rows merges as checking every point
    /// does, at three tolerances.
    #[test]
    fn the_fast_row_test_merges_as_the_exact_one() {
        for (case, pts) in stepped_rows().iter().enumerate() {
            for tol in [0.001, 0.005, 0.05] {
                let (f, e) = (merge_with(pts, tol, true), merge_with(pts, tol, false));
                // the same moves but where rounding tips a lift right at
                // the tolerance one way or the other (from there on the
                // moves differ), and every point within it
                assert!(
                    f.len().abs_diff(e.len()) <= 1 + e.len() / 50,
                    "case {case}, tol {tol}: {} moves against {}",
                    f.len(),
                    e.len()
                );
                within_and_above(pts, &f, tol);
            }
        }
    }

    /// Every point of the row lies within `tol` of the merged path `m`
    /// and not above it (points in order along x; a vertical step's
    /// corner is passed through by `m`).
    pub(crate) fn within_and_above(pts: &[DVec3], m: &[DVec3], tol: f64) {
        let mut seg = 0;
        for p in pts {
            while seg + 2 < m.len()
                && (m[seg + 1].x < p.x
                    || (m[seg + 1].x == p.x && m[seg + 1].z < p.z - 1e-12 && m[seg + 2].x == p.x))
            {
                seg += 1;
            }
            let (a, b) = (m[seg], m[seg + 1]);
            let d = b - a;
            let t = ((*p - a).dot(d) / d.length_squared()).clamp(0.0, 1.0);
            let near = (*p - (a + d * t)).length();
            // the nearest of this and the next move
            let next = m.get(seg + 2).map_or(f64::MAX, |&c| {
                let d = c - b;
                let t = ((*p - b).dot(d) / d.length_squared()).clamp(0.0, 1.0);
                (*p - (b + d * t)).length()
            });
            assert!(
                near.min(next) <= tol * (1.0 + 1e-9),
                "{p} is {near} from {a} -> {b}"
            );
            if b.x > a.x && a.y == p.y && b.y == p.y {
                let z = a.z + d.z * ((p.x - a.x) / d.x).clamp(0.0, 1.0);
                assert!(
                    z >= p.z - 1e-9 || p.x == a.x || p.x == b.x,
                    "{p} above {a} -> {b}"
                );
            }
        }
    }

    /// On a wavy row: every original point lies within tol of the merged
    /// path, and the merged path is never below the original one.
    #[test]
    fn merged_path_stays_within_tolerance_and_above() {
        let pts: Vec<DVec3> = (0..2000)
            .map(|i| {
                let x = i as f64 * 0.01;
                DVec3::new(
                    x,
                    3.0,
                    -1.0 + 0.3 * (x * 1.7).sin()
                        + 0.05 * (x * 9.0).cos()
                        + if x > 10.0 { 0.2 } else { 0.0 },
                )
            })
            .collect();
        for tol in [0.001, 0.005, 0.05] {
            let m = merge(&pts, tol);
            assert!(
                m.len() * 5 < pts.len(),
                "tol {tol}: {} of {}",
                m.len(),
                pts.len()
            );
            let mut seg = 0;
            for p in &pts {
                while seg + 1 < m.len() - 1 && m[seg + 1].x < p.x {
                    seg += 1;
                }
                let (a, b) = (m[seg], m[seg + 1]);
                let s = ((p.x - a.x) / (b.x - a.x)).clamp(0.0, 1.0);
                let z = a.z + (b.z - a.z) * s;
                assert!(
                    z >= p.z - 1e-12,
                    "merged path below the original at x {}",
                    p.x
                );
                let d = b - a;
                let t = ((*p - a).dot(d) / d.length_squared()).clamp(0.0, 1.0);
                assert!(
                    (*p - (a + d * t)).length() <= tol + 1e-12,
                    "tol {tol}: {p} is {} from {a} -> {b}",
                    (*p - (a + d * t)).length()
                );
            }
        }
    }
}
