//! G-code in the GRBL 1.1 dialect: the parser shared by the simulator and
//! the sender, and the modal interpreter that turns a program into straight
//! tool moves (arcs become the chords GRBL cuts them into, `arc`).

pub mod emit;
pub mod modal;
pub mod parse;
pub mod planner;

use crate::bail;
use crate::dialect::arc;
use crate::error::Result;
use glam::DVec3;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    Rapid,
    Feed,
}

/// A straight move of the tool tip.
#[derive(Clone, Copy, Debug)]
pub struct Segment {
    /// 1-based line of the job it comes from.
    pub line: usize,
    pub kind: Kind,
    pub a: DVec3,
    pub b: DVec3,
    /// mm/min for feed moves; ignored for rapids.
    pub feed: f64,
    /// The machine comes to a stop before this move (dwell, pause, spindle).
    pub stop_before: bool,
}

/// A program reduced to moves.
#[derive(Debug, Default, Clone)]
pub struct Program {
    pub segments: Vec<Segment>,
    /// Seconds of G4 dwell.
    pub dwell_s: f64,
    /// Each dwell: its 1-based line and seconds (for a time split by
    /// lines).
    pub dwells: Vec<(usize, f64)>,
    /// Lines in the file.
    pub lines: usize,
    /// Tool spec from the first `(tool: SPEC ...)` comment, if any.
    pub tool: Option<String>,
    /// Every `(tool: SPEC ...)` comment: the index of the first segment it
    /// cuts and its spec (a tool change starts a new one).
    pub tools: Vec<(usize, String)>,
    /// The 1-based line of each of those comments.
    pub tool_lines: Vec<usize>,
}

impl Program {
    /// The moves with every Z lowered by `dz`: a job zeroed on the
    /// stock's bottom, seen from its top.
    pub fn lowered(&self, dz: f64) -> Program {
        self.moved(DVec3::new(0.0, 0.0, -dz))
    }

    /// The lowest and highest corners of the box all moves lie in (an
    /// empty program: +inf and -inf).
    pub fn bounds(&self) -> (DVec3, DVec3) {
        self.segments.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), s| (lo.min(s.a).min(s.b), hi.max(s.a).max(s.b)),
        )
    }

    /// The moves shifted by `d`: a job seen from another origin.
    pub fn moved(&self, d: DVec3) -> Program {
        let mut p = self.clone();
        p.shift(d);
        p
    }

    /// `moved` in place.
    pub fn shift(&mut self, d: DVec3) {
        for s in &mut self.segments {
            s.a += d;
            s.b += d;
        }
    }
}

/// Largest arc radius taken, mm: beyond any machine's travel.
pub const MAX_ARC_RADIUS: f64 = 10_000.0;

/// Most straight moves a program may come to (arcs counted in chords):
/// about 2.4 GB as segments, and as many again as the simulator's
/// per-move record.
pub const MAX_SEGMENTS: usize = 30_000_000;

/// Interpret `text`, the tool taken to start at the job's highest Z over
/// work X0 Y0 (where it is not known: nothing is cut on the way to the
/// first move). Errors name the line.
pub fn program(text: &str) -> Result<Program> {
    program_at(text, None)
}

/// Interpret `text` with the tool starting at `start` (work coordinates,
/// mm; None = the highest Z over X0 Y0, as `program`). Errors name the
/// line. Lines are parsed twice (the first pass finds the highest Z)
/// rather than held, so that memory follows the moves, not the text.
pub fn program_at(text: &str, start: Option<DVec3>) -> Result<Program> {
    let mut max_z = 0.0f64;
    let mut count = 0;
    for (k, l) in text.lines().enumerate() {
        let line = parse::parse_line(l, k + 1);
        for w in line.words.iter().filter(|w| w.0 == 'Z') {
            max_z = max_z.max(w.1);
        }
        count += 1;
    }
    let mut p = Program {
        lines: count,
        ..Default::default()
    };
    let mut modal = modal::Modal::new(start.unwrap_or(DVec3::new(0.0, 0.0, max_z)));
    let mut stop = true;
    for (k, l) in text.lines().enumerate() {
        // '%' marks a program's start and end in a file; senders do not
        // send it
        if parse::strip(l) == "%" {
            continue;
        }
        let l = &parse::parse_line(l, k + 1);
        if p.segments.len() > MAX_SEGMENTS {
            bail!(
                "line {}: the job comes to more than {} million moves (arcs in GRBL's \
                 chords), more than is taken",
                l.number,
                MAX_SEGMENTS / 1_000_000
            );
        }
        for c in &l.comments {
            let lower = c.to_ascii_lowercase();
            if let Some(rest) = lower
                .strip_prefix("tool:")
                .or_else(|| lower.strip_prefix("tool "))
            {
                if let Some(spec) = rest.split_whitespace().next() {
                    p.tool.get_or_insert_with(|| spec.to_string());
                    p.tools.push((p.segments.len(), spec.to_string()));
                    p.tool_lines.push(l.number);
                }
            }
        }
        let n = l.number;
        let step = modal
            .apply(l)
            .map_err(|r| crate::Error(format!("line {n}: GRBL error:{} ({})", r.code, r.what)))?;
        if step.probe.is_some() {
            bail!(
                "line {n}: a probing move (G38.x): where it stops depends on what it touches; \
                 simulate the job from after its touch-off"
            );
        }
        stop |= step.sync;
        if let Some(d) = step.dwell {
            p.dwell_s += d;
            p.dwells.push((n, d));
        }
        let Some(target) = step.to else { continue };
        let (pos, motion) = (step.from, step.motion);
        let kind = if motion == 0 { Kind::Rapid } else { Kind::Feed };
        // the points the move goes through: G28/G30 by the point given,
        // an arc by GRBL's chords
        let mut path = vec![pos];
        if let Some(via) = step.via.filter(|&v| v != pos) {
            path.push(via);
        }
        match step.arc {
            Some(a) => {
                if a.radius > MAX_ARC_RADIUS {
                    bail!(
                        "line {n}: arc radius {:.1} mm is larger than {MAX_ARC_RADIUS} mm",
                        a.radius
                    );
                }
                let from = *path.last().unwrap();
                path.extend(a.points(from, target, arc::GRBL_ARC_TOLERANCE));
            }
            None => path.push(target),
        }
        path.dedup();
        // G93: F is 1/min, a line in 1/F minutes; GRBL's mc_arc plans an
        // arc's chords at F times their count, in mm/min
        let f = match kind {
            Kind::Rapid => 0.0,
            Kind::Feed if modal.inverse_time && step.arc.is_some() => {
                modal.feed.unwrap_or(0.0) * (path.len() - 1) as f64
            }
            Kind::Feed if modal.inverse_time => {
                modal.feed.unwrap_or(0.0) * (path[path.len() - 1] - path[0]).length()
            }
            Kind::Feed => modal.feed.unwrap_or(0.0),
        };
        for w in path.windows(2) {
            p.segments.push(Segment {
                line: n,
                kind,
                a: w[0],
                b: w[1],
                feed: f,
                stop_before: stop,
            });
            stop = false;
        }
    }
    Ok(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// G93: a feed move takes 1/F minutes; an arc's chords go at F times
    /// their count, as GRBL's mc_arc plans them.
    #[test]
    fn inverse_time_feeds_take_one_over_f_minutes() {
        let p = program("G21 G90 G0 X0 Y0 Z0\nG93 G1 X30 F2\nG2 X50 Y0 I10 F6\nG94 G1 X0 F600\n")
            .unwrap();
        let s = &p.segments;
        assert!((s[0].feed - 60.0).abs() < 1e-9, "{}", s[0].feed);
        let arc: Vec<_> = s.iter().filter(|g| g.line == 3).collect();
        let len: f64 = arc.iter().map(|g| (g.b - g.a).length()).sum();
        assert!(arc.len() > 5 && (len - 31.4).abs() < 0.1, "{len}");
        assert!(arc.iter().all(|g| g.feed == 6.0 * arc.len() as f64));
        assert_eq!(s.last().unwrap().feed, 600.0);
    }

    #[test]
    fn modal_state_units_and_increments() {
        let p = program(
            "(tool: ball:3.175 finishing)\nG21 G90\nG0 X1 Z5\nG1 X10 F600\nG91 Y5\nG20 G90 G1 X1\n",
        )
        .unwrap();
        assert_eq!(p.tool.as_deref(), Some("ball:3.175"));
        let s = &p.segments;
        assert_eq!(s[0].kind, Kind::Rapid);
        assert_eq!(s[1].b, DVec3::new(10.0, 0.0, 5.0));
        assert_eq!(s[2].b, DVec3::new(10.0, 5.0, 5.0));
        assert!((s[3].b.x - 25.4).abs() < 1e-12 && s[3].feed == 600.0);
    }

    #[test]
    fn arcs_with_ij_and_r_agree() {
        let ij = program("G0 X10 Y0 Z0\nG2 X0 Y-10 I-10 J0 F100\n").unwrap();
        let r = program("G0 X10 Y0 Z0\nG2 X0 Y-10 R10 F100\n").unwrap();
        for p in [&ij, &r] {
            for s in &p.segments[1..] {
                let m = (s.a + s.b) / 2.0;
                // GRBL's chords: midpoints within its $12 of the circle
                let sag = 10.0 - m.truncate().length();
                assert!((0.0..=arc::GRBL_ARC_TOLERANCE + 1e-4).contains(&sag));
                assert!(
                    s.b.y <= 1e-9 && s.b.x >= -1e-9,
                    "clockwise quarter from +x to -y"
                );
            }
        }
        assert_eq!(ij.segments.len(), r.segments.len());
        // G18: the arc turns in the ZX plane, Y fixed
        let zx = program("G0 X0 Y3 Z0\nG18 G3 X10 I5 K0 F100\n").unwrap();
        assert!(zx.segments[1..].iter().all(|s| s.b.y == 3.0));
        let top = zx.segments.iter().map(|s| s.b.z).fold(f64::MIN, f64::max);
        assert!(
            (top - 5.0).abs() < 0.01,
            "G3 in G18 from X0 to X10 rises to Z5"
        );
        assert!(program("G2 X10 Y0 I1 J0 F100\n")
            .unwrap_err()
            .0
            .contains("line 1"));
        assert!(program("G1 X1\n").unwrap_err().0.contains("feed"));
    }
}
