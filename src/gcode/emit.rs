//! G-code writer for GRBL 1.1 (DESIGN.md section 6): mm (or inch),
//! absolute, modal words only when they change, numbers with at most 4
//! decimals (5 in inches: a 0.25 um grid), every line at most 79
//! characters. Heights are rounded up, never into the material.

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
        let (v, dec) = if axis == 2 {
            (v + self.z_shift, 4)
        } else {
            (v, 4)
        };
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
            self.motion = Some(g);
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
        if !rapid && self.feed != Some(feed) {
            let f = if self.inch {
                num_dec(feed / 25.4, 2)
            } else {
                num(feed.round())
            };
            write!(l, " F{f}").unwrap();
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
    /// the next tool; `header` (with its `tool: SPEC` line) says which and
    /// `zero` where to set Z0 again.
    pub fn tool_change(&mut self, header: &[String], s: &Settings, zero: &str) {
        self.retract(s);
        self.line("M5".into());
        for h in header {
            comment(&mut self.out, h);
        }
        comment(
            &mut self.out,
            &format!("change the tool, {zero}, then resume"),
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
