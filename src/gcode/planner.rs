//! GRBL 1.1h's motion planner (planner.c), shared by the time estimate,
//! the simulated GRBL and the sender's watchdog: each move's top speed and
//! acceleration from the per-axis limits along it ($110-$112,
//! $120-$122), the highest speed a corner with the move before allows
//! (junction deviation, $11), and the look-ahead: a backward pass from a
//! stop after the last move planned, a forward pass from the speed the
//! machine has, and a trapezoid (or triangle) of speed on each move.
//! Speeds in mm/s, accelerations in mm/s².

use glam::DVec3;

/// The limit along direction `u` (a unit vector) of per-axis limits: the
/// axis that reaches its own limit first bounds the move.
pub fn along(u: DVec3, per_axis: DVec3) -> f64 {
    (0..3)
        .filter(|&k| u[k].abs() > 1e-12)
        .map(|k| per_axis[k] / u[k].abs())
        .fold(f64::INFINITY, f64::min)
}

/// The highest speed through the corner from direction `prev` into `next`
/// (unit vectors) by GRBL's junction deviation: the speed at which a
/// circle of deviation `deviation` tangent to both moves is taken at
/// acceleration `accel`. A reversal stops; going straight on is unbound.
pub fn junction_speed(prev: DVec3, next: DVec3, accel: f64, deviation: f64) -> f64 {
    let cos = (-prev.dot(next)).clamp(-1.0, 1.0);
    if cos > 0.999999 {
        return 0.0;
    }
    if cos < -0.999999 {
        return f64::INFINITY;
    }
    let s = (0.5 * (1.0 - cos)).sqrt();
    (accel * deviation * s / (1.0 - s)).sqrt()
}

/// One move as the planner holds it.
#[derive(Clone, Copy, Debug)]
pub struct Move {
    pub len: f64,
    /// Its top speed (feed or rapid, within the axes' rates).
    pub top: f64,
    pub accel: f64,
    /// Before planning, the highest entry speed its corner with the move
    /// before allows (0 after a stop); after, the speed it is entered at.
    pub entry: f64,
}

/// Plan `moves` in place: the machine enters the first at `v_in` (at
/// most its corner's speed) and stops after the last, and no move changes
/// speed faster than its acceleration. A move's exit is the next one's
/// entry (the last one's is 0).
pub fn plan(moves: &mut [Move], v_in: f64) {
    let Some(first) = moves.first_mut() else {
        return;
    };
    first.entry = first.entry.min(v_in);
    // backward: each entry no faster than the move can shed before the
    // next one's entry (the last ends at rest); the first may be entered
    // above its top (an override slowed the move the machine is in: it
    // slows down at its acceleration, as GRBL's stepper does)
    let mut next = 0.0f64;
    for (k, m) in moves.iter_mut().enumerate().rev() {
        let top = if k == 0 { f64::INFINITY } else { m.top };
        m.entry = m
            .entry
            .min(top)
            .min((next * next + 2.0 * m.accel * m.len).sqrt());
        next = m.entry;
    }
    // forward: each entry no faster than the move before can reach
    for k in 1..moves.len() {
        let p = moves[k - 1];
        moves[k].entry = moves[k]
            .entry
            .min((p.entry * p.entry + 2.0 * p.accel * p.len).sqrt());
    }
}

/// Exit speed of move `k` of planned `moves`.
pub fn exit(moves: &[Move], k: usize) -> f64 {
    moves.get(k + 1).map_or(0.0, |m| m.entry)
}

/// Seconds to run a move of `len` entered at `entry`, left at `exit`,
/// cruising at most at `top`, changing speed at `accel`.
pub fn run_time(len: f64, entry: f64, top: f64, exit: f64, accel: f64) -> f64 {
    let a = accel;
    if entry > top {
        let (d1, d3) = slow_down(entry, top, exit, a);
        if d1 + d3 >= len {
            return 2.0 * len / (entry + exit);
        }
        return (entry - top) / a + (len - d1 - d3) / top + (top - exit) / a;
    }
    let peak = top
        .min(((2.0 * a * len + entry * entry + exit * exit) / 2.0).sqrt())
        .max(entry.max(exit));
    let up = (peak * peak - entry * entry) / (2.0 * a);
    let down = (peak * peak - exit * exit) / (2.0 * a);
    let cruise = (len - up - down).max(0.0);
    (peak - entry) / a + (peak - exit) / a + if peak > 0.0 { cruise / peak } else { 0.0 }
}

/// Where a move planned as for `run_time` is `t` seconds after it began:
/// the distance covered and the speed then.
pub fn at_time(len: f64, entry: f64, top: f64, exit: f64, accel: f64, t: f64) -> (f64, f64) {
    let a = accel;
    let t = t.max(0.0);
    if entry > top {
        let (d1, d3) = slow_down(entry, top, exit, a);
        if d1 + d3 >= len {
            // one even deceleration from entry to exit over the move
            let dec = (entry * entry - exit * exit) / (2.0 * len);
            let t = t.min((entry - exit) / dec.max(1e-12));
            return ((entry * t - 0.5 * dec * t * t).min(len), entry - dec * t);
        }
        let (t1, tc) = ((entry - top) / a, (len - d1 - d3) / top);
        if t <= t1 {
            return (entry * t - 0.5 * a * t * t, entry - a * t);
        }
        if t <= t1 + tc {
            return (d1 + top * (t - t1), top);
        }
        let t = (t - t1 - tc).min((top - exit) / a);
        return ((len - d3 + top * t - 0.5 * a * t * t).min(len), top - a * t);
    }
    let peak = top
        .min(((2.0 * a * len + entry * entry + exit * exit) / 2.0).sqrt())
        .max(entry.max(exit));
    let (t_up, up) = (
        (peak - entry) / a,
        (peak * peak - entry * entry) / (2.0 * a),
    );
    let down = (peak * peak - exit * exit) / (2.0 * a);
    let cruise = (len - up - down).max(0.0);
    let t_cruise = if peak > 0.0 { cruise / peak } else { 0.0 };
    if t <= t_up {
        let t = t.max(0.0);
        return (entry * t + 0.5 * a * t * t, entry + a * t);
    }
    if t <= t_up + t_cruise {
        return (up + peak * (t - t_up), peak);
    }
    let t = (t - t_up - t_cruise).min((peak - exit) / a);
    (
        (up + cruise + peak * t - 0.5 * a * t * t).min(len),
        peak - a * t,
    )
}

/// A move entered above its top: the distances to slow down to the top,
/// and from the top to its exit.
fn slow_down(entry: f64, top: f64, exit: f64, a: f64) -> (f64, f64) {
    (
        (entry * entry - top * top) / (2.0 * a),
        (top * top - exit.min(top) * exit.min(top)) / (2.0 * a),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Entered above its top (an override slowed it), a move slows down
    /// at its acceleration, cruises, and stops; where it is agrees with
    /// how long it takes.
    #[test]
    fn a_move_entered_too_fast_slows_down() {
        // 10 mm/s into a 5 mm/s move of 20 mm, 10 mm/s²: 3.75 mm in 0.5 s
        // down to 5, 1.25 mm to stop in 0.5 s, 15 mm at 5 in 3 s
        let t = run_time(20.0, 10.0, 5.0, 0.0, 10.0);
        assert!((t - 4.0).abs() < 1e-12, "{t}");
        let (s, v) = at_time(20.0, 10.0, 5.0, 0.0, 10.0, 0.5);
        assert!((s - 3.75).abs() < 1e-12 && (v - 5.0).abs() < 1e-12);
        let (s, v) = at_time(20.0, 10.0, 5.0, 0.0, 10.0, 4.0);
        assert!((s - 20.0).abs() < 1e-9 && v.abs() < 1e-12, "{s} {v}");
        // too short to reach the top: one even deceleration
        let t = run_time(4.0, 10.0, 5.0, 0.0, 12.5);
        assert!((t - 0.8).abs() < 1e-12, "{t}");
        let (s, _) = at_time(4.0, 10.0, 5.0, 0.0, 12.5, 0.8);
        assert!((s - 4.0).abs() < 1e-9, "{s}");
    }

    #[test]
    fn a_lone_move_is_a_trapezoid() {
        // 100 mm at 10 mm/s, 10 mm/s^2: 1 s up (5 mm), 9 s at speed, 1 s down
        let t = run_time(100.0, 0.0, 10.0, 0.0, 10.0);
        assert!((t - 11.0).abs() < 1e-12, "{t}");
        // too short to reach speed: a triangle, 2 sqrt(d / a)
        let t = run_time(1.0, 0.0, 10.0, 0.0, 10.0);
        assert!((t - 2.0 * 0.1f64.sqrt()).abs() < 1e-12, "{t}");
    }

    #[test]
    fn a_move_is_where_its_speed_put_it() {
        // 100 mm at 10 mm/s, 10 mm/s^2: 5 mm up in 1 s, 9 s at speed
        assert_eq!(at_time(100.0, 0.0, 10.0, 0.0, 10.0, 0.5), (1.25, 5.0));
        assert_eq!(at_time(100.0, 0.0, 10.0, 0.0, 10.0, 3.0), (25.0, 10.0));
        let (s, v) = at_time(100.0, 0.0, 10.0, 0.0, 10.0, 10.5);
        assert!(
            (s - 98.75).abs() < 1e-9 && (v - 5.0).abs() < 1e-9,
            "{s} {v}"
        );
        assert_eq!(at_time(100.0, 0.0, 10.0, 0.0, 10.0, 20.0), (100.0, 0.0));
    }

    #[test]
    fn look_ahead_carries_speed_through_straight_moves() {
        let m = Move {
            len: 1.0,
            top: 10.0,
            accel: 10.0,
            entry: f64::INFINITY,
        };
        // ten 1 mm moves in a line run as one 10 mm move
        let mut p = [m; 10];
        plan(&mut p, 0.0);
        let t: f64 = (0..10)
            .map(|k| run_time(1.0, p[k].entry, 10.0, exit(&p, k), 10.0))
            .sum();
        assert!(
            (t - run_time(10.0, 0.0, 10.0, 0.0, 10.0)).abs() < 1e-9,
            "{t}"
        );
        assert_eq!(p[0].entry, 0.0);
        // a right angle at 0.01 mm deviation: sqrt(a d s / (1 - s))
        let v = junction_speed(DVec3::X, DVec3::Y, 10.0, 0.01);
        let s = 0.5f64.sqrt();
        assert!((v - (10.0 * 0.01 * s / (1.0 - s)).sqrt()).abs() < 1e-12);
        assert_eq!(junction_speed(DVec3::X, -DVec3::X, 10.0, 0.01), 0.0);
    }
}
