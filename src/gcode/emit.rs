//! G-code writer for GRBL 1.1 (DESIGN.md section 6): mm (or inch),
//! absolute, modal words only when they change, numbers with at most 4
//! decimals (5 in inches: a 0.25 um grid), every line at most 79
//! characters. Heights are rounded up, never into the material.

use crate::dialect::arc::{self, Arc, Plane};
use crate::dialect::chords::arc_run;
use glam::DVec3;
use std::fmt::Write;

/// Longest line GRBL's 80-byte buffer takes with its newline.
pub const MAX_LINE: usize = 79;

/// Feeds, speeds and heights of a job.
#[derive(Clone, Debug)]
pub struct Settings {
    /// Cutting feed, mm/min.
    pub feed: f64,
    /// Plunge feed, mm/min.
    pub plunge_feed: f64,
    pub rpm: f64,
    /// Clearance height for travels, mm above the stock top.
    pub safe_z: f64,
    /// Spindle spin-up dwell, s.
    pub dwell: f64,
}

/// A number with at most 4 decimals, no trailing zeros, no "-0".
pub fn num(v: f64) -> String {
    num_dec(v, 4)
}

/// A number with at most `dec` decimals, no trailing zeros, no "-0".
pub fn num_dec(v: f64, dec: usize) -> String {
    let s = format!("{:.*}", dec, v);
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" || s.is_empty() {
        "0".into()
    } else {
        s.to_string()
    }
}

/// Comment lines, wrapped at spaces to fit the line limit (a word longer
/// than a line is cut); parentheses inside the text would end the comment
/// early, so they become brackets.
pub fn comment(out: &mut String, text: &str) {
    let clean: String = text
        .chars()
        .map(|c| match c {
            '(' => '[',
            ')' => ']',
            c if c.is_ascii() && !c.is_ascii_control() => c,
            _ => '?',
        })
        .collect();
    let room = MAX_LINE - 2;
    let mut line = String::new();
    let flush = |line: &mut String, out: &mut String| {
        out.push('(');
        out.push_str(line);
        out.push_str(")\n");
        line.clear();
    };
    for word in clean.split(' ') {
        let word = &word[..word.len().min(room)];
        if !line.is_empty() && line.len() + 1 + word.len() > room {
            flush(&mut line, out);
            line.push_str("  ");
        }
        if !line.is_empty() && line.trim() != "" {
            line.push(' ');
        }
        line.push_str(word);
    }
    flush(&mut line, out);
}

/// Writes moves, tracking the modal state so only changes are emitted.
pub struct Emitter {
    pub out: String,
    pos: Option<DVec3>,
    motion: Option<u8>,
    feed: Option<f64>,
    /// Inch output (G20): numbers divided by 25.4, one more decimal.
    inch: bool,
    /// Added to every Z (the stock's thickness when Z0 is its bottom).
    z_shift: f64,
    /// Write runs of GRBL arc chords as G2/G3 (`arc_run`).
    pub arcs: bool,
    /// The arc plane last written.
    plane: Plane,
    /// The machine's steps per mm ($100-$102): a move GRBL would plan as
    /// no step on any axis (it drops it, going from where it stands to
    /// the next target) is not written, so that the job judged is the
    /// path the machine runs.
    pub steps: Option<DVec3>,
}

impl Emitter {
    /// A job in mm (or inches with `inch`), every Z raised by `z_shift`.
    pub fn new(header: &[String], s: &Settings, inch: bool, z_shift: f64) -> Emitter {
        let mut e = Emitter {
            out: String::new(),
            pos: None,
            motion: None,
            feed: None,
            inch,
            z_shift,
            arcs: false,
            plane: Plane::Xy,
            steps: None,
        };
        for h in header {
            comment(&mut e.out, h);
        }
        e.line(
            if inch {
                "G20 G90 G17 G94"
            } else {
                "G21 G90 G17 G94"
            }
            .into(),
        );
        e.spindle(s);
        e
    }

    /// An axis value as written: X and Y rounded, Z rounded up.
    fn coord(&self, v: f64, axis: usize) -> String {
        let (mut v, dec) = if axis == 2 {
            (v + self.z_shift, 4)
        } else {
            (v, 4)
        };
        // a Z exactly half a step between two steps is rounded either
        // way by GRBL's float arithmetic once the work offset is added:
        // a tenth of a micrometre higher it is one step for certain
        if let (2, Some(steps), false) = (axis, self.steps, self.inch) {
            let at = (v * 1e4).round() / 1e4 * steps.z;
            if (at - at.floor() - 0.5).abs() < 1e-6 {
                v = (v * 1e4).round() / 1e4 + 1e-4;
            }
        }
        if self.inch {
            let u = v / 25.4;
            let u = if axis == 2 {
                (u * 1e5 - 1e-6).ceil() / 1e5
            } else {
                u
            };
            num_dec(u, 5)
        } else {
            num_dec(v, dec)
        }
    }

    fn line(&mut self, l: String) {
        debug_assert!(l.len() <= MAX_LINE);
        self.out.push_str(&l);
        self.out.push('\n');
    }

    /// Move to `p` with G0 (rapid) or G1 at `feed`.
    pub fn go(&mut self, p: DVec3, rapid: bool, feed: f64) {
        let mut l = String::new();
        let g = if rapid { 0 } else { 1 };
        if self.motion != Some(g) {
            write!(l, "G{g}").unwrap();
        }
        let prev = self.pos;
        for (k, axis) in ['X', 'Y', 'Z'].into_iter().enumerate() {
            let v = self.coord(p[k], k);
            if prev.map(|q| self.coord(q[k], k) != v).unwrap_or(true) {
                if !l.is_empty() {
                    l.push(' ');
                }
                write!(l, "{axis}{v}").unwrap();
            }
        }
        if l.is_empty() || l == "G0" || l == "G1" {
            return; // no motion at this resolution
        }
        if let (Some(q), Some(steps)) = (prev, self.steps) {
            let step = |v: f64, k: usize| (self.written(v, k) * steps[k]).round();
            if !q.is_nan() && (0..3).all(|k| step(q[k], k) == step(p[k], k)) {
                // not a step on any axis: GRBL would drop it and go on
                // from where it stands. A descent or a level move is left
                // out (what follows from here passes no lower); a rise is
                // written a whole step up, so that it runs
                if self.written(p.z, 2) <= self.written(q.z, 2) {
                    return;
                }
                let up = self.written(q.z, 2) - self.z_shift + 1.0 / steps.z;
                return self.go(DVec3::new(p.x, p.y, up + 1e-9), rapid, feed);
            }
        }
        self.motion = Some(g);
        if !rapid {
            self.feed_word(&mut l, feed);
        }
        self.pos = Some(p);
        self.line(l);
    }

    /// Cut one continuous pass: rise to `clear_z` (a height known to
    /// clear the material) if lower, travel there, plunge, cut.
    /// The points go on the G-code grid (XY rounded, Z rounded up); runs
    /// of exact GRBL arc chords among them become G2/G3 when `arcs`.
    pub fn pass(&mut self, pts: &[DVec3], s: &Settings, clear_z: f64) {
        use crate::dialect::{snap, snap_up};
        let grid = |p: DVec3| DVec3::new(snap(p.x), snap(p.y), snap_up(p.z));
        let Some(&first) = pts.first() else { return };
        let first = grid(first);
        let z = match self.pos {
            None => {
                let z = clear_z.max(s.safe_z);
                let zs = self.coord(z, 2);
                self.line(format!("G0 Z{zs}"));
                self.motion = Some(0);
                self.pos = Some(DVec3::new(f64::NAN, f64::NAN, z));
                z
            }
            Some(p) if p.z < clear_z => {
                self.go(DVec3::new(p.x, p.y, clear_z), true, 0.0);
                clear_z
            }
            Some(p) => p.z,
        };
        self.go(DVec3::new(first.x, first.y, z), true, 0.0);
        if z > clear_z && clear_z > first.z {
            self.go(DVec3::new(first.x, first.y, clear_z), true, 0.0);
        }
        self.go(first, false, s.plunge_feed);
        let mut i = 0;
        while i + 1 < pts.len() {
            if self.arcs {
                if let Some((j, a)) = arc_run(pts, i, arc::GRBL_ARC_TOLERANCE) {
                    if self.arc(a, grid(pts[j]), j - i, s.feed) {
                        i = j;
                        continue;
                    }
                }
            }
            i += 1;
            self.go(grid(pts[i]), false, s.feed);
        }
    }

    /// The value GRBL reads back from `coord(v, axis)`, in mm.
    fn written(&self, v: f64, axis: usize) -> f64 {
        let w: f64 = self.coord(v, axis).parse().unwrap_or(f64::NAN);
        if self.inch {
            w * 25.4
        } else {
            w
        }
    }

    /// Write the arc `a` from the current position to `to` as one G2/G3,
    /// if GRBL, reading the rounded numbers, cuts it into the same
    /// `chords` chords the pass was checked with; else write nothing.
    fn arc(&mut self, a: Arc, to: DVec3, chords: usize, feed: f64) -> bool {
        let Some(from) = self.pos else { return false };
        let (a0, a1, _) = a.plane.axes();
        let start = DVec3::from_array([0, 1, 2].map(|k| self.written(from[k], k)));
        let end = DVec3::from_array([0, 1, 2].map(|k| self.written(to[k], k)));
        // the centre as offsets from where the machine is (Z offsets are
        // not shifted with the heights)
        let scale = if self.inch { 25.4 } else { 1.0 };
        let off = |c: f64, s: f64, k: usize| {
            let raw = if k == 2 { c + self.z_shift - s } else { c - s };
            let w: f64 = num_dec(raw / scale, if self.inch { 5 } else { 4 })
                .parse()
                .unwrap_or(f64::NAN);
            w * scale
        };
        let mut ijk = [None; 3];
        ijk[a0] = Some(off(a.centre.0, start[a0], a0));
        ijk[a1] = Some(off(a.centre.1, start[a1], a1));
        let read = arc::setup(a.plane, a.clockwise, start, end, ijk, None, true);
        let Ok(b) = read else { return false };
        if b.chords(b.travel(start, end), arc::GRBL_ARC_TOLERANCE) != chords {
            return false;
        }
        let mut l = String::new();
        if self.plane != a.plane {
            write!(l, "G{} ", a.plane.code()).unwrap();
            self.plane = a.plane;
        }
        write!(l, "G{}", if a.clockwise { 2 } else { 3 }).unwrap();
        self.motion = Some(if a.clockwise { 2 } else { 3 });
        for (k, axis) in ['X', 'Y', 'Z'].into_iter().enumerate() {
            let v = self.coord(to[k], k);
            if self.coord(from[k], k) != v {
                write!(l, " {axis}{v}").unwrap();
            }
        }
        for k in [a0, a1] {
            let v = ijk[k].unwrap() / scale;
            write!(
                l,
                " {}{}",
                ['I', 'J', 'K'][k],
                num_dec(v, if self.inch { 5 } else { 4 })
            )
            .unwrap();
        }
        self.feed_word(&mut l, feed);
        self.pos = Some(to);
        self.line(l);
        true
    }

    /// Up to safe Z.
    pub fn retract(&mut self, s: &Settings) {
        if let Some(p) = self.pos {
            if p.z < s.safe_z {
                self.go(DVec3::new(p.x, p.y, s.safe_z), true, 0.0);
            }
        }
    }

    /// Retract, stop the spindle and pause (M0) for the operator to fit
    /// the next tool; `header` (with its `tool: SPEC` line) says which and
    /// `zero` where to set Z0 again. After the pause, safe Z again before
    /// the spindle starts and anything moves sideways.
    pub fn tool_change(&mut self, header: &[String], s: &Settings, zero: &str) {
        self.put_away(s);
        self.fit(header, s, zero);
    }

    /// The first half of a tool change, the last lines of the tool going
    /// out: retract and stop the spindle.
    pub fn put_away(&mut self, s: &Settings) {
        self.retract(s);
        self.line("M5".into());
    }

    /// The second half, the first lines of the tool coming in: its header,
    /// the pause, safe Z and the spindle.
    pub fn fit(&mut self, header: &[String], s: &Settings, zero: &str) {
        for h in header {
            comment(&mut self.out, h);
        }
        comment(
            &mut self.out,
            &format!("change the tool, {zero}, then resume"),
        );
        self.line("M0".into());
        // the operator leaves the new tool wherever Z0 was set, often on
        // the stock or the pad: up to safe Z before any other move
        if let Some(p) = self.pos {
            self.pos = Some(DVec3::new(p.x, p.y, f64::NAN));
            self.go(DVec3::new(p.x, p.y, s.safe_z), true, 0.0);
        }
        self.spindle(s);
    }

    fn spindle(&mut self, s: &Settings) {
        self.line(format!("M3 S{}", num(s.rpm.round())));
        if s.dwell > 0.0 {
            self.line(format!("G4 P{}", num(s.dwell)));
        }
    }

    /// The F word, where the feed changes (modal otherwise).
    fn feed_word(&mut self, l: &mut String, feed: f64) {
        if self.feed != Some(feed) {
            let f = if self.inch {
                num_dec(feed / 25.4, 2)
            } else {
                num(feed.round())
            };
            write!(l, " F{f}").unwrap();
            self.feed = Some(feed);
        }
    }

    /// Retract, spindle off, end of program.
    pub fn finish(mut self, s: &Settings) -> String {
        self.retract(s);
        self.line("M5".into());
        self.line("M30".into());
        self.out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Feeds, speed, safe Z and dwell of a typical finish.
    fn settings() -> Settings {
        Settings {
            feed: 1200.0,
            plunge_feed: 300.0,
            rpm: 18000.0,
            safe_z: 5.0,
            dwell: 2.0,
        }
    }

    #[test]
    fn modal_compact_and_short_lines() {
        let s = settings();
        let mut e = Emitter::new(
            &["tool: ball:3.175".into(), "x".repeat(200)],
            &s,
            false,
            0.0,
        );
        e.pass(
            &[
                DVec3::new(1.0, 2.0, -0.5),
                DVec3::new(1.5, 2.0, -0.25),
                DVec3::new(2.0, 2.0, -0.25),
            ],
            &s,
            s.safe_z,
        );
        let g = e.finish(&s);
        assert!(g.lines().all(|l| l.len() <= MAX_LINE));
        assert!(g.contains("G1 Z-0.5 F300\nX1.5 Z-0.25 F1200\nX2\n"), "{g}");
        assert_eq!(num(-0.00001), "0");
        assert_eq!(num(2.50), "2.5");
        crate::gcode::program(&g).unwrap();
    }

    /// After the M0 of a tool change the tool rises to safe Z before the
    /// spindle starts and before any sideways move: the operator may
    /// leave it touching the stock where Z0 was set.
    #[test]
    fn a_tool_change_rises_before_it_moves() {
        let s = settings();
        let mut e = Emitter::new(&["tool: flat:3.175".into()], &s, false, 0.0);
        let cut = [DVec3::new(1.0, 2.0, -0.5), DVec3::new(3.0, 2.0, -0.5)];
        e.pass(&cut, &s, s.safe_z);
        e.tool_change(&["tool: ball:1".into()], &s, "set Z0 on the stock");
        e.pass(&[DVec3::new(8.0, 9.0, -0.2)], &s, s.safe_z);
        let g = e.finish(&s);
        let after: Vec<&str> = g
            .lines()
            .skip_while(|l| *l != "M0")
            .skip(1)
            .filter(|l| !l.starts_with('('))
            .collect();
        assert_eq!(after[..3], ["Z5", "M3 S18000", "G4 P2"], "{g}");
        assert!(after[3].starts_with("X8 Y9"), "{g}");
        crate::gcode::program(&g).unwrap();
    }
}

#[cfg(test)]
mod inch_tests {
    use super::*;

    #[test]
    fn inch_jobs_round_heights_up_and_convert_feeds() {
        let s = Settings {
            feed: 1270.0,
            plunge_feed: 254.0,
            rpm: 18000.0,
            safe_z: 5.0,
            dwell: 0.0,
        };
        let mut e = Emitter::new(&[], &s, true, 0.0);
        e.pass(
            &[
                DVec3::new(25.4, 2.54, -0.00001),
                DVec3::new(50.8, 2.54, -1.0),
            ],
            &s,
            5.0,
        );
        let g = e.finish(&s);
        assert!(g.starts_with("G20 G90 G17 G94\n"), "{g}");
        assert!(g.contains("G1 Z0 F10\n"), "{g}");
        assert!(g.contains("X2 Z-0.03937 F50\n"), "{g}");
        let p = crate::gcode::program(&g).unwrap();
        let last_cut = p
            .segments
            .iter()
            .rev()
            .find(|s| s.kind == crate::gcode::Kind::Feed)
            .unwrap();
        assert!((last_cut.b.z - -1.0).abs() < 2.6e-4 && last_cut.b.z >= -1.0);
    }
}

#[cfg(test)]
mod arc_tests {
    use super::*;

    /// A finish's feeds and speed, no dwell.
    fn no_dwell() -> Settings {
        Settings {
            feed: 1000.0,
            plunge_feed: 300.0,
            rpm: 18000.0,
            safe_z: 5.0,
            dwell: 0.0,
        }
    }

    /// The ends of a program's feed moves (arcs as their chords).
    fn feeds(g: &str) -> Vec<DVec3> {
        let p = crate::gcode::program(g).unwrap();
        p.segments
            .iter()
            .filter(|s| s.kind == crate::gcode::Kind::Feed)
            .map(|s| s.b)
            .collect()
    }

    /// GRBL's chords of an XY arc, level and descending (a ramp along a
    /// waterline's arc), are written as one G2/G3 each, with Z where it
    /// changes, and read back as those chords; points that only lie on a
    /// circle are not.
    #[test]
    fn level_and_helical_xy_arcs_are_found() {
        let s = no_dwell();
        let arc = Arc {
            plane: Plane::Xy,
            clockwise: false,
            centre: (10.0, 10.0),
            radius: 4.0,
        };
        for dz in [0.0, -0.35] {
            let from = DVec3::new(14.0, 10.0, -1.0);
            let to = DVec3::new(10.0, 14.0, -1.0 + dz);
            let mut pts = vec![from];
            pts.extend(arc.points(from, to, arc::GRBL_ARC_TOLERANCE));
            assert!(pts.len() > 10);
            assert_eq!(
                arc_run(&pts, 0, arc::GRBL_ARC_TOLERANCE).map(|r| r.0),
                Some(pts.len() - 1)
            );
            let mut e = Emitter::new(&[], &s, false, 0.0);
            e.arcs = true;
            e.pass(&pts, &s, 5.0);
            let g = e.finish(&s);
            let arcs: Vec<&str> = g.lines().filter(|l| l.starts_with("G3")).collect();
            assert_eq!(arcs.len(), 1, "{g}");
            assert_eq!(arcs[0].contains('Z'), dz != 0.0, "{g}");
            let cut = feeds(&g);
            // (the feed down onto the first point, then the chords)
            assert_eq!(cut.len(), pts.len());
            for (a, b) in cut.iter().zip(&pts) {
                assert!((*a - *b).length() < 3e-4, "{a} vs {b}");
            }
            // uneven steps down are no helix GRBL cuts
            let mut bent = pts.clone();
            bent[3].z -= 0.01;
            assert!(arc_run(&bent, 0, arc::GRBL_ARC_TOLERANCE).is_none_or(|r| r.0 < 3));
        }
    }
}
