//! The fewest straight moves along a straight row of dropped points.
//!
//! A move from height `a` at distance `ua` along the row, rising at slope
//! `s`, keeps a point (u, z) when it clears it and passes within the
//! tolerance above it: z <= a + s (u - ua) <= z + tol sqrt(1 + s^2).
//! Both are linear in (a, s) once sqrt(1 + s^2) is replaced by its tangent
//! at the chord slope to the point (never more, so the band only
//! narrows). The moves a row's start can reach with one move form a
//! convex polygon in (a, s), clipped point by point; a move goes on while
//! the polygon is not empty. Where it ends, the heights its end may take
//! are an interval, not one height (a merge that fixes each end as it goes
//! gives that freedom away), and the next move starts anywhere in it.
//! Greedy reach per move with that interval carried on gives the fewest
//! moves whose corners lie over dropped points (within the linearised
//! band, and with each corner at most the tolerance straight above its
//! point, as a merge fixing each end keeps it: a corner high over a steep
//! move would not be within the tolerance of a flatter next one). The
//! heights are then chosen back from the row's end, each move's end the
//! lowest its polygon allows.
//!
//! The 512 px demo relief's rows (ball 3.175, 10% stepover, 0.005 mm)
//! merge into 13,117 moves (the job 13,404 with links and ramps, against
//! 14,443 fixing each end); no path within the band takes fewer than
//! 12,568 (`bound`).

use glam::DVec3;

/// Slopes past this are a vertical move (a step straight up or down).
const STEEPEST: f64 = 1e6;

/// A half-plane c0 a + c1 s <= c2.
type Half = [f64; 3];

/// A convex polygon in (a, s), counter-clockwise or degenerate.
type Poly = Vec<[f64; 2]>;

/// Clip `p` to the half-plane `h` (Sutherland-Hodgman; a polygon flattened
/// to a segment or a point stays one). Points within `slack` outside
/// count as inside, so that an interval of one height is not lost to
/// rounding.
fn clip(p: &Poly, h: &Half, slack: f64) -> Poly {
    let f = |v: &[f64; 2]| h[0] * v[0] + h[1] * v[1] - h[2];
    let mut out = Vec::with_capacity(p.len() + 2);
    for i in 0..p.len() {
        let (v, w) = (p[i], p[(i + 1) % p.len()]);
        let (fv, fw) = (f(&v), f(&w));
        if fv <= slack {
            out.push(v);
        }
        if (fv <= slack) != (fw <= slack) && (fv - fw).abs() > 0.0 {
            let t = (fv / (fv - fw)).clamp(0.0, 1.0);
            out.push([v[0] + t * (w[0] - v[0]), v[1] + t * (w[1] - v[1])]);
        }
    }
    out
}

/// `p` clipped to every half-plane of `hs` (empty as soon as one empties it).
fn clip_all(p: &Poly, hs: &[Half], slack: f64) -> Poly {
    let mut out = p.clone();
    for h in hs {
        out = clip(&out, h, slack);
        if out.is_empty() {
            break;
        }
    }
    out
}

/// Every move from heights `lo..=hi`, any slope short of vertical.
fn any_move(lo: f64, hi: f64) -> Poly {
    vec![
        [lo, -STEEPEST],
        [hi, -STEEPEST],
        [hi, STEEPEST],
        [lo, STEEPEST],
    ]
}

/// Each point's distance along the line from the first point to the
/// last, and whether they all lie on it, each no nearer the first than
/// the one before.
fn along(points: &[DVec3]) -> (Vec<f64>, bool) {
    let first = points[0];
    let d = (points[points.len() - 1] - first).truncate();
    let len = d.length();
    let dir = if len > 0.0 {
        d / len
    } else {
        glam::DVec2::ZERO
    };
    let mut straight = dir != glam::DVec2::ZERO;
    let mut u: Vec<f64> = Vec::with_capacity(points.len());
    for p in points {
        let v = (*p - first).truncate();
        let d = v.dot(dir);
        straight &= v.perp_dot(dir).abs() <= 1e-6 && u.last().is_none_or(|&l| d >= l);
        u.push(d);
    }
    (u, straight)
}

/// The two half-planes point (du, z) puts on a move starting at `du` = 0.
fn halves(du: f64, z: f64, a0: f64, tol: f64) -> [Half; 2] {
    // tangent of sqrt(1 + s^2) at the chord slope from the lowest start
    let t = if du > 0.0 { (z - a0) / du } else { 0.0 };
    let c = (1.0 + t * t).sqrt();
    [
        // clears: a + s du >= z
        [-1.0, -du, -z],
        // near: a + s du - tol (1 + s t) / c <= z
        [1.0, du - tol * t / c, z + tol / c],
    ]
}

/// The range of a + s len over `p`.
fn reach(p: &Poly, len: f64) -> (f64, f64) {
    p.iter()
        .map(|v| v[0] + v[1] * len)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), e| {
            (l.min(e), h.max(e))
        })
}

/// The point of `p` on a + s len = target with the lowest a (the nearest
/// vertex when rounding leaves the line just outside `p`).
fn lowest_on(p: &Poly, len: f64, target: f64) -> [f64; 2] {
    let f = |v: &[f64; 2]| v[0] + v[1] * len - target;
    let mut best: Option<[f64; 2]> = None;
    let mut keep = |q: [f64; 2]| {
        if best.is_none_or(|b| q[0] < b[0]) {
            best = Some(q);
        }
    };
    for i in 0..p.len() {
        let (v, w) = (p[i], p[(i + 1) % p.len()]);
        let (fv, fw) = (f(&v), f(&w));
        if fv == 0.0 {
            keep(v);
        }
        if (fv < 0.0) != (fw < 0.0) && fv != 0.0 && fw != 0.0 {
            let t = fv / (fv - fw);
            keep([v[0] + t * (w[0] - v[0]), v[1] + t * (w[1] - v[1])]);
        }
    }
    best.unwrap_or_else(|| {
        *p.iter()
            .min_by(|x, y| f(x).abs().total_cmp(&f(y).abs()))
            .expect("a move's polygon is never empty")
    })
}

/// One move of the greedy pass: from point `from` to point `to`, any
/// (start height, slope) in `poly`. A move with an empty polygon is a
/// vertical one, between two points at one distance.
struct Move {
    from: usize,
    to: usize,
    poly: Poly,
}

/// `points` (a straight row in XY, each no nearer the first than the one
/// before) as the fewest moves within `tol` above them, as `merge` keeps
/// them: the row's first and last points' XY, each corner over a dropped
/// point, no move below a dropped point. None when the points are not
/// such a row.
pub fn row(points: &[DVec3], tol: f64) -> Option<Vec<DVec3>> {
    let first = *points.first()?;
    let (u, straight) = along(points);
    if !straight {
        return None;
    }
    let slack = 1e-12 * (1.0 + tol);
    let z = |i: usize| points[i].z;
    // the greedy pass; `seen[i]` is the move's polygon up to point
    // from + 1 + i
    let mut moves: Vec<Move> = Vec::new();
    let (mut from, mut lo, mut hi) = (0usize, z(0), z(0));
    let mut seen: Vec<Poly> = Vec::new();
    let mut k = 1;
    loop {
        if k < points.len() {
            let last = seen.last().cloned().unwrap_or_else(|| any_move(lo, hi));
            let next = clip_all(&last, &halves(u[k] - u[from], z(k), lo, tol), slack);
            if !next.is_empty() {
                seen.push(next);
                k += 1;
                continue;
            }
        }
        if seen.is_empty() {
            if k == points.len() {
                break;
            }
            // not even the next point: it lies straight above or below
            // (a step); the move to it is vertical
            moves.push(Move {
                from,
                to: k,
                poly: Vec::new(),
            });
            (from, lo, hi) = (k, z(k), z(k));
            k += 1;
            continue;
        }
        // the move ends at the farthest point it reaches within the
        // tolerance straight above it (a corner high over a steep move
        // would not be within it of the next, flatter one; a picometre
        // under it, for rounding), if any
        let cap = |i: usize| {
            let e = from + 1 + i;
            clip(&seen[i], &[1.0, u[e] - u[from], z(e) + tol - 1e-9], slack)
        };
        let (i, poly) = (0..seen.len())
            .rev()
            .map(|i| (i, cap(i)))
            .find(|(_, p)| !p.is_empty())
            .unwrap_or_else(|| (seen.len() - 1, seen.last().unwrap().clone()));
        let to = from + 1 + i;
        // the next move starts anywhere this one can end
        let (l, h) = reach(&poly, u[to] - u[from]);
        moves.push(Move { from, to, poly });
        (from, lo, hi) = (to, l, h);
        seen.clear();
        k = to + 1;
        if to + 1 == points.len() {
            break;
        }
    }
    // heights back from the end: each move's end is its successor's start
    let mut h = vec![f64::NAN; moves.len() + 1];
    let mut end: Option<f64> = None;
    for (j, m) in moves.iter().enumerate().rev() {
        let l = u[m.to] - u[m.from];
        if m.poly.is_empty() {
            // a vertical move: its end is its point, its start free
            h[j + 1] = end.unwrap_or(z(m.to));
            end = None;
            continue;
        }
        let target = end.unwrap_or_else(|| reach(&m.poly, l).0);
        let v = lowest_on(&m.poly, l, target);
        h[j + 1] = target;
        h[j] = v[0];
        end = Some(v[0]);
    }
    if h[0].is_nan() {
        // the row starts with a vertical move
        h[0] = z(0);
    }
    // rounding: lift each move over every point it passes by what it
    // lacks (nanometres at most), both ends
    let mut out: Vec<DVec3> = Vec::with_capacity(moves.len() + 1);
    out.push(DVec3::new(first.x, first.y, h[0]));
    for (j, m) in moves.iter().enumerate() {
        let (a, b) = (h[j].max(out[j].z), h[j + 1]);
        let l = u[m.to] - u[m.from];
        let mut lack = 0.0f64;
        if l > 0.0 {
            for i in m.from..=m.to {
                let at = a + (b - a) * (u[i] - u[m.from]) / l;
                lack = lack.max(z(i) - at);
            }
        }
        out[j].z = a + lack;
        let p = points[m.to];
        out.push(DVec3::new(p.x, p.y, b + lack));
    }
    Some(out)
}

/// A lower bound on the straight moves any path over a row's points
/// needs within the band [z, z + tol sqrt(1 + s^2)], s the CL surface's
/// own slope at the point (central differences): the fewest runs of
/// consecutive points each of which one straight line passes within the
/// band, runs sharing their end points, each line free of the others
/// (so not one continuous path). Greedy longest-run-first finds that
/// fewest exactly, since every part of a run that fits fits too. What a
/// merge is judged against (`bench/line_bound.py` counts the same).
pub fn bound(points: &[DVec3], tol: f64) -> usize {
    let n = points.len();
    if n < 2 {
        return 0;
    }
    let u = along(points).0;
    let z = |i: usize| points[i].z;
    let band = |i: usize| {
        let (a, b) = (i.saturating_sub(1), (i + 1).min(n - 1));
        let du = u[b] - u[a];
        let s = if du > 0.0 { (z(b) - z(a)) / du } else { 0.0 };
        tol * (1.0 + s * s).sqrt()
    };
    let (mut from, mut count) = (0usize, 0usize);
    while from < n - 1 {
        // lines by their height over the run's first point and slope
        let mut poly = any_move(z(from), z(from) + band(from));
        let mut end = from + 1;
        for e in from + 1..n {
            let du = u[e] - u[from];
            let next = clip_all(
                &poly,
                &[[-1.0, -du, -z(e)], [1.0, du, z(e) + band(e)]],
                1e-12,
            );
            if next.is_empty() {
                break;
            }
            (poly, end) = (next, e);
        }
        count += 1;
        from = end;
    }
    count
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::toolpath::merge::{merge, merge_fixed, merge_tests};

    /// Every move clears every point it passes and stays within the
    /// tolerance of it; and straight rows take fewer moves than fixing
    /// each end as the row goes (`merge`'s other path).
    #[test]
    fn fewest_moves_keep_the_band() {
        for tol in [0.001, 0.005, 0.05] {
            let (mut ours, mut fixed, mut least) = (0, 0, 0);
            for pts in merge_tests::stepped_rows() {
                let m = merge(&pts, tol);
                merge_tests::within_and_above(&pts, &m, tol);
                if row(&pts, tol).is_some() {
                    ours += m.len() - 1;
                    fixed += merge_fixed(&pts, tol).len() - 1;
                    least += bound(&pts, tol);
                }
            }
            assert!(
                ours < fixed,
                "tolerance {tol}: {ours} moves, {fixed} fixing each end"
            );
            assert!(
                least <= ours && least * 5 >= ours * 4,
                "tolerance {tol}: {ours} moves, bound {least}"
            );
            eprintln!("tolerance {tol}: {ours} moves against {fixed}, at least {least}");
        }
    }

    #[test]
    fn a_straight_row_is_one_move_and_a_step_goes_straight_up() {
        let line: Vec<DVec3> = (0..100)
            .map(|i| DVec3::new(i as f64 * 0.1, 0.0, 0.01 * i as f64))
            .collect();
        assert_eq!(row(&line, 0.005).unwrap().len(), 2);
        assert_eq!(bound(&line, 0.005), 1);
        let mut step = line[..50].to_vec();
        step.push(DVec3::new(step[49].x, 0.0, 3.0));
        step.extend((50..100).map(|i| DVec3::new(i as f64 * 0.1, 0.0, 3.0)));
        let m = row(&step, 0.005).unwrap();
        assert_eq!(m.len(), 4, "{m:?}");
        assert_eq!(m[1].x, m[2].x);
        assert!(m[2].z >= 3.0 && m[1].z < 0.5);
        // not a row: a bend out of line, or a point back toward the start
        let mut bent = line.clone();
        bent[50].y = 0.1;
        assert!(row(&bent, 0.005).is_none());
        let mut back = line.clone();
        back[50].x = 0.0;
        assert!(row(&back, 0.005).is_none());
    }
}
