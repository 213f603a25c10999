//! Arcs in a raster row's vertical plane (G18 for rows along X, G19 along
//! Y): runs of dropped CL points within the tolerance of a circle become
//! one arc, written as the very chords GRBL will cut it into
//! (`gcode::arc`), so the exact move check and the simulator see what the
//! machine runs. The emitter finds those chords again and writes one G2/G3.
//!
//! The band is `merge`'s: the chords pass above every dropped point (no
//! gouge added) and within `tol` of it. Stretches no arc spans are merged
//! into straight moves as before.

use super::merge::merge;
use crate::dialect::arc::{Arc, Plane, GRBL_ARC_TOLERANCE};
use crate::dialect::MAX_RADIUS;
use glam::DVec3;

/// Fewest dropped points an arc spans (fewer: straight moves do as well).
pub(super) const MIN_SPAN: usize = 4;
/// Most dropped points one arc spans (the next arc goes on from there).
const MAX_SPAN: usize = 256;
/// Steepest tangent an arc may have in its plane (rise per run): the
/// chords stay a function along the row.
const MAX_SLOPE: f64 = 8.0;

/// The row's plane and its points as (along, z), if it is a row along X
/// (constant Y: G18) or along Y (constant X: G19).
fn plane_of(points: &[DVec3]) -> Option<(Plane, Vec<(f64, f64)>)> {
    let first = points.first()?;
    if points.iter().all(|p| p.y == first.y) {
        Some((Plane::Zx, points.iter().map(|p| (p.x, p.z)).collect()))
    } else if points.iter().all(|p| p.x == first.x) {
        Some((Plane::Yz, points.iter().map(|p| (p.y, p.z)).collect()))
    } else {
        None
    }
}

/// The row thinned for the machine: arcs where a circle fits, straight
/// merged moves elsewhere.
pub fn fit(points: &[DVec3], tol: f64) -> Vec<DVec3> {
    // GRBL's chords sag up to 2.25 times its $12 (a floor in its count):
    // a band narrower than three times that leaves arcs no room
    let room = tol >= 3.0 * GRBL_ARC_TOLERANCE;
    let Some((plane, uz)) = plane_of(points).filter(|_| room && points.len() > MIN_SPAN) else {
        return merge(points, tol);
    };
    let dir = if uz.last().unwrap().0 >= uz[0].0 {
        1.0
    } else {
        -1.0
    };
    let row = Row {
        plane,
        points,
        uz: &uz,
        dir,
        tol,
    };
    let mut out: Vec<DVec3> = vec![points[0]];
    // start of the stretch not yet covered by an arc
    let mut loose = 0;
    let mut a = 0;
    let n = points.len();
    while a + MIN_SPAN < n {
        // where the arc starts: the pass's end, or the point a
        let start = if a == loose {
            *out.last().unwrap()
        } else {
            points[a]
        };
        // an arc only where it reaches past two straight moves; else on
        // past the first straight move
        let l1 = first_move_end(points, a, tol);
        let Some((e, mut chords)) = row
            .longest(start, a)
            .filter(|(e, _)| *e > first_move_end(points, l1, tol))
        else {
            a = l1;
            continue;
        };
        if loose < a {
            let m = merge_from(*out.last().unwrap(), &points[loose + 1..=a], tol);
            out.extend_from_slice(&m[1..]);
            let end = *out.last().unwrap();
            if end != points[a] {
                // merging lifted the stretch's end: the arc from there,
                // else down onto the point first
                match row.arc(end, a, e) {
                    Some(c) => chords = c,
                    None => out.push(points[a]),
                }
            }
        }
        out.extend(chords);
        a = e;
        loose = e;
    }
    if loose + 1 < n {
        let m = merge_from(*out.last().unwrap(), &points[loose + 1..], tol);
        out.extend_from_slice(&m[1..]);
    }
    out
}

/// The point the first straight merged move from point a reaches.
fn first_move_end(points: &[DVec3], a: usize, tol: f64) -> usize {
    let n = points.len();
    if a + 1 >= n {
        return n - 1;
    }
    let mut w = 16;
    loop {
        let end = (a + w).min(n - 1);
        let m = merge(&points[a..=end], tol);
        if m.len() > 2 || end == n - 1 {
            let q = m[1];
            return (a + 1..=end)
                .find(|&k| points[k].x == q.x && points[k].y == q.y)
                .unwrap_or(end);
        }
        w *= 2;
    }
}

/// Straight moves merged from `start` (an arc's lifted end, or the pass's
/// start) through `rest`.
fn merge_from(start: DVec3, rest: &[DVec3], tol: f64) -> Vec<DVec3> {
    let mut v = Vec::with_capacity(rest.len() + 1);
    v.push(start);
    v.extend_from_slice(rest);
    merge(&v, tol)
}

/// A row's dropped points in its vertical plane.
struct Row<'a> {
    plane: Plane,
    points: &'a [DVec3],
    /// (along, z) of each point.
    uz: &'a [(f64, f64)],
    /// +1 where `along` grows through the row, else -1.
    dir: f64,
    tol: f64,
}

impl Row<'_> {
    /// The furthest point an arc from `start` (over point a) reaches, and
    /// its chords.
    fn longest(&self, start: DVec3, a: usize) -> Option<(usize, Vec<DVec3>)> {
        furthest(a, self.points.len(), |e| self.arc(start, a, e))
    }

    /// An arc from `start` (over point a) to point e, its end lifted by
    /// part of the tolerance (a cap's chords lie under the arc, so an arc
    /// pinned to the points would cut below them next to its ends).
    fn arc(&self, start: DVec3, a: usize, e: usize) -> Option<Vec<DVec3>> {
        [0.5, 0.2, 0.8, 0.0].into_iter().find_map(|f| {
            let end = self.points[e] + DVec3::Z * (f * self.tol);
            self.arc_to(start, end, a, e)
        })
    }

    /// The arc from `start` to `end` whose GRBL chords pass above every
    /// dropped point after a and before e, within `tol` of it.
    fn arc_to(&self, start: DVec3, end: DVec3, a: usize, e: usize) -> Option<Vec<DVec3>> {
        let (plane, dir, tol) = (self.plane, self.dir, self.tol);
        let inner = &self.uz[a + 1..e];
        // strictly along the row (a step straight up or down breaks arcs)
        if self.uz[a..=e]
            .windows(2)
            .any(|w| (w[1].0 - w[0].0) * dir <= 0.0)
        {
            return None;
        }
        let along = |p: DVec3| if plane == Plane::Zx { p.x } else { p.y };
        let (pa, pe) = ((along(start), start.z), (along(end), end.z));
        let (mu, mz) = (0.5 * (pa.0 + pe.0), 0.5 * (pa.1 + pe.1));
        let (du, dz) = (pe.0 - pa.0, pe.1 - pa.1);
        let half = 0.5 * du.hypot(dz);
        // chord frame: t along start -> end, n its normal with n.z > 0
        let (tu, tz) = (du / (2.0 * half), dz / (2.0 * half));
        let (nu, nz) = if tu > 0.0 { (-tz, tu) } else { (tz, -tu) };
        // the bulge (signed height of the arc's middle over the chord,
        // along n) of the circle through start, end and (u, z)
        let bulge = |u: f64, z: f64| {
            let (x, y) = ((u - mu) * tu + (z - mz) * tz, (u - mu) * nu + (z - mz) * nz);
            bulge(half, x, y)
        };
        // what GRBL's chords cost on either side, found as we go
        let (mut below, mut above) = (0.0f64, 0.0f64);
        for _ in 0..3 {
            let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
            for &(u, z) in inner {
                lo = lo.max(bulge(u, z + below));
                hi = hi.min(bulge(u, z + tol - above));
                if lo > hi {
                    return None;
                }
            }
            let b = 0.5 * (lo + hi);
            if b.abs() > 0.5 * half {
                return None;
            }
            let chords = chords_of(plane, start, end, (mu, mz), (tu, tz), (nu, nz), half, b)?;
            match band_error(&chords, start, &self.uz[a..=e], plane, dir, tol) {
                Ok(()) => return Some(chords),
                Err((dip, over)) => {
                    below += dip;
                    above += over;
                }
            }
        }
        None
    }
}

/// The furthest end e after a (below n, at most MAX_SPAN on) for which
/// `arc(e)` gives an arc, and that arc: gallop from MIN_SPAN, then bisect.
pub(super) fn furthest<T>(
    a: usize,
    n: usize,
    arc: impl Fn(usize) -> Option<T>,
) -> Option<(usize, T)> {
    let mut good: Option<(usize, T)> = None;
    let mut step = MIN_SPAN;
    let mut bad = n.min(a + MAX_SPAN + 1);
    while a + step < bad {
        match arc(a + step) {
            Some(c) => good = Some((a + step, c)),
            None => {
                bad = a + step;
                break;
            }
        }
        step *= 2;
    }
    let (mut lo, mut hi) = (good.as_ref()?.0, bad);
    while hi - lo > 1 {
        let mid = (lo + hi) / 2;
        match arc(mid) {
            Some(c) => {
                good = Some((mid, c));
                lo = mid;
            }
            None => hi = mid,
        }
    }
    good
}

/// The bulge (height of the arc's middle over the chord) of the circle
/// through the chord's ends (-half, 0), (half, 0) and (x, y), in the
/// chord's frame.
pub(super) fn bulge(half: f64, x: f64, y: f64) -> f64 {
    if y.abs() < 1e-15 {
        return 0.0;
    }
    let t = (x * x + y * y - half * half) / (2.0 * y);
    let rho = (half * half + t * t).sqrt();
    if y > 0.0 {
        t + rho
    } else {
        t - rho
    }
}

/// GRBL's chord points (after `from`) of the arc of bulge `b` over the
/// chord from `from` to `to`; None where it would be too steep or GRBL's
/// chord count sits at a rounding edge.
#[allow(clippy::too_many_arguments)]
fn chords_of(
    plane: Plane,
    from: DVec3,
    to: DVec3,
    (mu, mz): (f64, f64),
    (tu, tz): (f64, f64),
    (nu, nz): (f64, f64),
    half: f64,
    b: f64,
) -> Option<Vec<DVec3>> {
    // centre on the normal through the chord's middle
    let t = (b * b - half * half) / (2.0 * b);
    let (cu, cz) = (mu + t * nu, mz + t * nz);
    let radius = (half * half + t * t).sqrt();
    if b.abs() < 1e-12 || radius > MAX_RADIUS {
        return Some(vec![to]); // straight: GRBL would cut one chord
    }
    // tangents at the ends: the chord's slope turned by half the arc
    let turn = 2.0 * (b / half).atan();
    let chord = tz.atan2(tu.abs());
    if (chord.abs() + turn.abs()).tan().abs() > MAX_SLOPE || chord.abs() + turn.abs() >= 1.5 {
        return None;
    }
    let (a0, _, _) = plane.axes();
    let at = |p: DVec3| if a0 == 2 { (p.z, p.x) } else { (p.y, p.z) };
    let centre = if a0 == 2 { (cz, cu) } else { (cu, cz) };
    let (s0, s1) = at(from);
    let (e0, e1) = at(to);
    let cross = (s0 - centre.0) * (e1 - centre.1) - (s1 - centre.1) * (e0 - centre.0);
    let arc = Arc {
        plane,
        clockwise: cross < 0.0,
        centre,
        radius,
    };
    grbl_chords(&arc, from, to)
}

/// The points GRBL cuts `arc` from `from` to `to` into (after `from`);
/// None where its chord count sits at a rounding edge: the emitter rounds
/// the numbers, and the machine must cut the chords that were checked.
pub(super) fn grbl_chords(arc: &Arc, from: DVec3, to: DVec3) -> Option<Vec<DVec3>> {
    let (travel, radius) = (arc.travel(from, to), arc.radius);
    let x = 0.5 * travel.abs() * radius
        / (GRBL_ARC_TOLERANCE * (2.0 * radius - GRBL_ARC_TOLERANCE)).sqrt();
    if (x - x.round()).abs() < 0.02 && x > 0.5 {
        return None;
    }
    Some(arc.points(from, to, GRBL_ARC_TOLERANCE))
}

/// Whether the chord polyline from `from` through `chords` stays above
/// the dropped points `dense` (its inner points, and the polyline through
/// them at every chord end) and within `tol` of them; else how far it
/// dips below the worst and rises over the band.
fn band_error(
    chords: &[DVec3],
    from: DVec3,
    dense: &[(f64, f64)],
    plane: Plane,
    dir: f64,
    tol: f64,
) -> Result<(), (f64, f64)> {
    let along = |p: DVec3| if plane == Plane::Zx { p.x } else { p.y };
    let mut k = 0;
    let mut prev = from;
    let (mut dip, mut over) = (0.0f64, 0.0f64);
    let inner = &dense[1..dense.len() - 1];
    for &(u, z) in inner {
        while k < chords.len() && (along(chords[k]) - u) * dir < 0.0 {
            prev = chords[k];
            k += 1;
        }
        let Some(next) = chords.get(k) else {
            return Err((f64::INFINITY, f64::INFINITY));
        };
        let (u0, u1) = (along(prev), along(*next));
        let s = if u1 != u0 { (u - u0) / (u1 - u0) } else { 0.0 };
        let zc = prev.z + (next.z - prev.z) * s;
        dip = dip.max(z - zc);
        over = over.max(zc - z - tol);
    }
    // and every chord end above the dropped polyline (between two dropped
    // points a valley's arc sags below their straight line)
    let mut k = 0;
    for c in &chords[..chords.len() - 1] {
        let u = along(*c);
        while k + 1 < dense.len() && (dense[k + 1].0 - u) * dir < 0.0 {
            k += 1;
        }
        let (p, q) = (dense[k], dense[(k + 1).min(dense.len() - 1)]);
        let s = if q.0 != p.0 {
            (u - p.0) / (q.0 - p.0)
        } else {
            0.0
        };
        dip = dip.max(p.1 + (q.1 - p.1) * s - c.z);
    }
    verdict(dip, over)
}

/// Ok where the chords neither dip below the CL points nor rise over
/// them by more than allowed, else by how much (mm).
pub(super) fn verdict(dip: f64, over: f64) -> Result<(), (f64, f64)> {
    if dip > 0.0 || over > 0.0 {
        Err((dip.max(0.0), over.max(0.0)))
    } else {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A row over a bump and a dip, dense as dropped points.
    fn row(y: f64) -> Vec<DVec3> {
        (0..=400)
            .map(|i| {
                let x = i as f64 * 0.05;
                DVec3::new(x, y, -2.0 + 0.8 * (x * 0.4).sin() + 0.3 * (x * 0.9).cos())
            })
            .collect()
    }

    #[test]
    fn arcs_stay_in_the_band_and_cut_the_moves() {
        let pts = row(3.0);
        for tol in [0.006, 0.01, 0.02] {
            let fitted = fit(&pts, tol);
            // the chords pass above every dropped point and within tol
            // of it
            let mut seg = 0;
            for p in &pts {
                while seg + 2 < fitted.len() && fitted[seg + 1].x < p.x {
                    seg += 1;
                }
                let (a, b) = (fitted[seg], fitted[seg + 1]);
                let s = ((p.x - a.x) / (b.x - a.x)).clamp(0.0, 1.0);
                let z = a.z + (b.z - a.z) * s;
                assert!(z >= p.z - 1e-12, "below the point at x {}", p.x);
                // (merging measures its band square to the move)
                let slope = (b.z - a.z) / (b.x - a.x);
                let band = tol * (1.0 + slope * slope).sqrt();
                assert!(z - p.z <= band + 1e-12, "over the band at x {}", p.x);
            }
            // never more moves than the fewest straight ones; fewer where
            // GRBL's own chords (sagitta up to 4.5 um) leave the band room
            // (at 0.02 mm: 15 against 19, and 20 fixing each move's end)
            let (runs, lines) = (runs_of(&fitted), merge(&pts, tol).len() - 1);
            assert!(runs <= lines, "tol {tol}: {runs} moves vs {lines}");
            if tol >= 0.02 {
                assert!(runs * 5 <= lines * 4, "tol {tol}: {runs} moves vs {lines}");
            }
        }
    }

    /// Moves the emitter would write: maximal runs of GRBL chords count once.
    fn runs_of(pts: &[DVec3]) -> usize {
        let runs = crate::dialect::chords::arc_runs(pts);
        let chords: usize = runs.iter().map(|(i, j)| j - i).sum();
        pts.len() - 1 - chords + runs.len()
    }
}
