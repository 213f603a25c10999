//! Arcs along a waterline (G17): runs of a contour's points that a circle
//! fits within `simplify`'s band become one arc in the XY plane, written
//! as the very chords GRBL cuts it into (`gcode::arc`), so that `clear`'s
//! exact check, the simulator and the time estimate see what the machine
//! runs; the emitter finds those chords again and writes one G2/G3.
//! Stretches no arc spans are thinned into straight moves as before.
//!
//! The band, for the chords as for a straight move: at most `tol` off a
//! point on its free side (the right of travel), and on its material side
//! only as far as keeps the CL rise there under tol / 2 (`chord_fits`).

use super::arcs::{bulge, furthest, grbl_chords, MIN_SPAN};
use super::waterline::{chord_fits, material_allowance, simplify_points};
use crate::dialect::arc::{Arc, Plane, GRBL_ARC_TOLERANCE};
use crate::dialect::MAX_RADIUS;
use glam::{DVec2, DVec3};

/// A contour's points (all at its level) thinned for the machine: arcs
/// where a circle fits, straight moves elsewhere. `slope` is the CL
/// surface's steepness at each point.
pub fn fit(pts: &[DVec3], slope: &[f64], tol: f64) -> Vec<DVec3> {
    let n = pts.len();
    // a band no wider than GRBL's $12 leaves its chords no room; unlike a
    // raster row's (one-sided, above the points), a contour's band on
    // gentle ground reaches `tol` either side, so arcs fit from the
    // default tolerance on
    if tol <= GRBL_ARC_TOLERANCE || n <= MIN_SPAN {
        return simplify_points(pts, slope, tol);
    }
    let band = Band { pts, slope, tol };
    let mut out = vec![pts[0]];
    // the stretch loose..=a is left to straight moves
    let mut loose = 0;
    let mut a = 0;
    // where the straight move from a ends, when known
    let mut next: Option<usize> = None;
    while a + MIN_SPAN < n {
        // an arc only where it reaches past two straight moves; else on
        // past the first straight move
        let l1 = next.take().unwrap_or_else(|| band.straight_end(a));
        let l2 = band.straight_end(l1);
        let Some((e, chords)) = band.longest(a).filter(|(e, _)| *e > l2) else {
            (a, next) = (l1, Some(l2));
            continue;
        };
        if loose < a {
            let m = simplify_points(&pts[loose..=a], &slope[loose..=a], tol);
            out.extend_from_slice(&m[1..]);
        }
        out.extend(chords);
        a = e;
        loose = e;
    }
    if loose + 1 < n {
        let m = simplify_points(&pts[loose..], &slope[loose..], tol);
        out.extend_from_slice(&m[1..]);
    }
    out
}

/// A contour and its band.
struct Band<'a> {
    pts: &'a [DVec3],
    slope: &'a [f64],
    tol: f64,
}

impl Band<'_> {
    /// How far a move may pass on the material side of point k.
    fn allowance(&self, k: usize) -> f64 {
        material_allowance(self.slope[k], self.tol)
    }

    /// The furthest point one straight move from point a reaches.
    fn straight_end(&self, a: usize) -> usize {
        let mut e = a + 1;
        while e + 1 < self.pts.len() && chord_fits(self.pts, self.slope, a, e + 1, self.tol) {
            e += 1;
        }
        e
    }

    /// The furthest point an arc from point a reaches, and its chords.
    fn longest(&self, a: usize) -> Option<(usize, Vec<DVec3>)> {
        furthest(a, self.pts.len(), |e| self.arc(a, e))
    }

    /// The arc from point a to point e whose GRBL chords keep within the
    /// band of every point between, and its chords after point a.
    fn arc(&self, a: usize, e: usize) -> Option<Vec<DVec3>> {
        let (s, t) = (self.pts[a], self.pts[e]);
        if self.pts[a..=e].iter().any(|p| p.z != s.z) {
            return None;
        }
        let d = (t - s).truncate();
        let len = d.length();
        if len < 1e-6 {
            return None;
        }
        let half = 0.5 * len;
        // chord frame: x along s -> t from the middle, y to the free side
        let u = d / len;
        let free = DVec2::new(u.y, -u.x);
        let mid = 0.5 * (s.truncate() + t.truncate());
        let inner: Vec<(f64, f64, f64)> = (a + 1..e)
            .map(|k| {
                let p = self.pts[k].truncate() - mid;
                (p.dot(u), p.dot(free), self.allowance(k))
            })
            .collect();
        // the points run along the chord (a contour folding back is no arc)
        if inner.iter().any(|q| q.0.abs() >= half) || inner.windows(2).any(|w| w[1].0 <= w[0].0) {
            return None;
        }
        // what GRBL's chords cost on either side, found as we go
        let (mut dip, mut over) = (0.0f64, 0.0f64);
        for _ in 0..3 {
            let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
            for &(x, y, m) in &inner {
                lo = lo.max(bulge(half, x, y - m + dip));
                hi = hi.min(bulge(half, x, y + self.tol - over));
                if lo > hi {
                    return None;
                }
            }
            let b = 0.5 * (lo + hi);
            if b.abs() > 0.5 * half {
                return None;
            }
            let chords = if b.abs() < 1e-12 {
                vec![t]
            } else {
                // centre on the normal through the chord's middle
                let c = mid + free * ((b * b - half * half) / (2.0 * b));
                let radius = (s.truncate() - c).length();
                if radius > MAX_RADIUS {
                    vec![t]
                } else {
                    let arc = Arc {
                        plane: Plane::Xy,
                        clockwise: (s.truncate() - c).perp_dot(t.truncate() - c) < 0.0,
                        centre: (c.x, c.y),
                        radius,
                    };
                    grbl_chords(&arc, s, t)?
                }
            };
            match self.error(s, &chords, a, e) {
                Ok(()) => return Some(chords),
                Err((d, o)) => {
                    dip += d;
                    over += o;
                }
            }
        }
        None
    }

    /// Whether the chords from `s` keep within the band of the points
    /// a+1..e (each against the chord beside it) and every chord end
    /// within the band of the contour's own polyline; else how far they
    /// stray to the material side and past `tol` on the free side.
    fn error(&self, s: DVec3, chords: &[DVec3], a: usize, e: usize) -> Result<(), (f64, f64)> {
        let q: Vec<DVec2> = std::iter::once(s)
            .chain(chords.iter().copied())
            .map(|p| p.truncate())
            .collect();
        let p: Vec<DVec2> = self.pts[a..=e].iter().map(|p| p.truncate()).collect();
        let (mut dip, mut over) = (0.0f64, 0.0f64);
        // the free side's offset of a point on one polyline from the
        // segment of the other beside it, and the allowance there
        let mut check = |line: &[DVec2], k: usize, at: DVec2, sign: f64, m: f64| {
            let (q0, q1) = (line[k], line[k + 1]);
            let dd = q1 - q0;
            let off = sign * dd.perp_dot(at - q0) / dd.length();
            dip = dip.max(-m - off);
            over = over.max(off - self.tol);
        };
        let beside = |line: &[DVec2], k: &mut usize, at: DVec2| {
            while *k + 2 < line.len() && (at - line[*k + 1]).dot(line[*k + 1] - line[*k]) > 0.0 {
                *k += 1;
            }
        };
        let mut k = 0;
        for (i, &x) in p.iter().enumerate().take(p.len() - 1).skip(1) {
            beside(&q, &mut k, x);
            check(&q, k, x, 1.0, self.allowance(a + i));
        }
        let mut k = 0;
        for &c in &q[1..q.len() - 1] {
            beside(&p, &mut k, c);
            let m = self.allowance(a + k).min(self.allowance(a + k + 1));
            check(&p, k, c, -1.0, m);
        }
        super::arcs::verdict(dip, over)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dialect::chords::arc_runs;

    /// An island's contour (material inside, counter-clockwise) and a
    /// pocket's (clockwise), an ellipse with a wobble, dense as placed.
    fn contour(ccw: bool) -> Vec<DVec3> {
        (0..=720)
            .map(|k| {
                let t = k as f64 / 720.0 * std::f64::consts::TAU;
                let t = if ccw { t } else { -t };
                let r = 1.0 + 0.05 * (3.0 * t).sin();
                DVec3::new(6.0 * r * t.cos(), 4.0 * r * t.sin(), -1.5)
            })
            .collect()
    }

    /// Moves the emitter would write (maximal runs of GRBL chords count
    /// once), and how many are arcs.
    fn moves(pts: &[DVec3]) -> (usize, usize) {
        let runs = arc_runs(pts);
        let chords: usize = runs.iter().map(|(i, j)| j - i).sum();
        (pts.len() - 1 - chords + runs.len(), runs.len())
    }

    #[test]
    fn waterline_arcs_keep_the_band_and_cut_the_moves() {
        for ccw in [true, false] {
            let pts = contour(ccw);
            for (slope, tol) in [(0.3, 0.005), (0.3, 0.01), (3.0, 0.01), (3.0, 0.02)] {
                let sl = vec![slope; pts.len()];
                let fitted = fit(&pts, &sl, tol);
                assert_eq!(fitted.first(), pts.first());
                assert_eq!(fitted.last(), pts.last());
                // every point against the fitted path beside it: within
                // tol on the free side, within the allowance on the other
                let allow = if slope > 0.5 {
                    tol / (2.0 * slope)
                } else {
                    tol
                };
                let mut k = 0;
                for p in &pts[1..pts.len() - 1] {
                    let x = p.truncate();
                    while k + 2 < fitted.len()
                        && (x - fitted[k + 1].truncate())
                            .dot((fitted[k + 1] - fitted[k]).truncate())
                            > 0.0
                    {
                        k += 1;
                    }
                    let (q0, q1) = (fitted[k].truncate(), fitted[k + 1].truncate());
                    let off = (q1 - q0).perp_dot(x - q0) / (q1 - q0).length();
                    assert!(
                        off <= tol + 1e-9 && off >= -allow - 1e-9,
                        "ccw {ccw} slope {slope} tol {tol}: {off} at {x}"
                    );
                }
                let (with, arcs) = moves(&fitted);
                let straight = simplify_points(&pts, &sl, tol).len() - 1;
                assert!(arcs > 0, "ccw {ccw} slope {slope} tol {tol}: no arcs");
                assert!(
                    with * 2 <= straight,
                    "ccw {ccw} slope {slope} tol {tol}: {with} moves with arcs, {straight} without"
                );
            }
            // within GRBL's own $12 no arcs are fitted
            let sl = vec![1.0; pts.len()];
            assert_eq!(fit(&pts, &sl, 0.002), simplify_points(&pts, &sl, 0.002));
        }
    }
}
