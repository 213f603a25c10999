//! G-code writer for GRBL 1.1 (DESIGN.md section 6): mm, absolute, modal
//! words only when they change, numbers with at most 4 decimals, every line
//! at most 79 characters.

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
    let s = format!("{:.4}", v);
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" || s.is_empty() {
        "0".into()
    } else {
        s.to_string()
    }
}

/// Comment lines, each cut to fit the line limit; parentheses inside the
/// text would end the comment early, so they become brackets.
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
    let mut line = format!("({clean}");
    line.truncate(MAX_LINE - 1);
    line.push(')');
    out.push_str(&line);
    out.push('\n');
}

/// Writes moves, tracking the modal state so only changes are emitted.
pub struct Emitter {
    pub out: String,
    pos: Option<DVec3>,
    motion: Option<u8>,
    feed: Option<f64>,
}

impl Emitter {
    pub fn new(header: &[String], s: &Settings) -> Emitter {
        let mut e = Emitter {
            out: String::new(),
            pos: None,
            motion: None,
            feed: None,
        };
        for h in header {
            comment(&mut e.out, h);
        }
        e.line("G21 G90 G17 G94".into());
        e.spindle(s);
        e
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
            self.motion = Some(g);
        }
        let prev = self.pos;
        for (k, axis) in ['X', 'Y', 'Z'].into_iter().enumerate() {
            let v = num(p[k]);
            if prev.map(|q| num(q[k]) != v).unwrap_or(true) {
                if !l.is_empty() {
                    l.push(' ');
                }
                write!(l, "{axis}{v}").unwrap();
            }
        }
        if l.is_empty() || l == "G0" || l == "G1" {
            return; // no motion at this resolution
        }
        if !rapid && self.feed != Some(feed) {
            write!(l, " F{}", num(feed.round())).unwrap();
            self.feed = Some(feed);
        }
        self.pos = Some(p);
        self.line(l);
    }

    /// Cut one continuous pass: rise to `clear_z` (a height known to
    /// clear the material) if lower, travel there, plunge, cut.
    pub fn pass(&mut self, pts: &[DVec3], s: &Settings, clear_z: f64) {
        let Some(&first) = pts.first() else { return };
        let z = match self.pos {
            None => {
                let z = clear_z.max(s.safe_z);
                self.line(format!("G0 Z{}", num(z)));
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
        for &p in &pts[1..] {
            self.go(p, false, s.feed);
        }
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
    /// the next tool; `header` (with its `tool: SPEC` line) says which.
    pub fn tool_change(&mut self, header: &[String], s: &Settings) {
        self.retract(s);
        self.line("M5".into());
        for h in header {
            comment(&mut self.out, h);
        }
        comment(
            &mut self.out,
            "change the tool, set Z0 on the stock top again, then resume",
        );
        self.line("M0".into());
        self.spindle(s);
    }

    fn spindle(&mut self, s: &Settings) {
        self.line(format!("M3 S{}", num(s.rpm.round())));
        if s.dwell > 0.0 {
            self.line(format!("G4 P{}", num(s.dwell)));
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

    #[test]
    fn modal_compact_and_short_lines() {
        let s = Settings {
            feed: 1200.0,
            plunge_feed: 300.0,
            rpm: 18000.0,
            safe_z: 5.0,
            dwell: 2.0,
        };
        let mut e = Emitter::new(&["tool: ball:3.175".into(), "x".repeat(200)], &s);
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
}
