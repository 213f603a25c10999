//! The modal state of a GRBL machine and what one line does to it: the
//! one interpreter that `simulate` (through `program`), the simulated GRBL
//! and the sender (its re-entry preamble and its resume safety) fold lines
//! through, so that they cannot disagree about where a line goes.

use super::arc::{self, Arc, Plane};
use super::parse::Line;
use glam::DVec3;

/// Units, distance mode, motion mode, feed, spindle and position.
#[derive(Clone, Debug, PartialEq)]
pub struct Modal {
    /// Where the tool is after the lines folded so far (mm).
    pub pos: DVec3,
    /// G0, G1, G2 or G3.
    pub motion: u8,
    pub absolute: bool,
    pub inches: bool,
    /// mm/min.
    pub feed: Option<f64>,
    /// M3 or M4 while the spindle is on.
    pub spindle: Option<u8>,
    /// The last S word.
    pub speed: f64,
    /// Mist (M7) and flood (M8) coolant.
    pub coolant: (bool, bool),
    /// The last T word (GRBL only tracks it).
    pub tool: u32,
    /// The arc plane (G17, G18, G19).
    pub plane: Plane,
}

/// The motion mode after G80: axis words then have nothing to do.
pub const NO_MOTION: u8 = 80;

/// What one line does.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Step {
    pub from: DVec3,
    /// The end of the line's move, when it moves.
    pub to: Option<DVec3>,
    /// Motion mode of the move (0 rapid, 1 feed, 2/3 arcs).
    pub motion: u8,
    /// The arc, for G2/G3.
    pub arc: Option<Arc>,
    /// Seconds of G4 dwell.
    pub dwell: Option<f64>,
    /// GRBL finishes every earlier move before it answers this line
    /// (dwell, spindle, coolant, program stop): once it is acknowledged,
    /// everything before it has run.
    pub sync: bool,
    /// Axis words in G91: running the line twice moves the machine twice.
    pub relative: bool,
    /// M0: GRBL holds once the moves before it are done, until cycle start.
    pub pause: bool,
}

/// A line GRBL refuses: its `error:N` code and what is wrong.
#[derive(Clone, Debug, PartialEq)]
pub struct Refusal {
    pub code: u32,
    pub what: String,
}

fn refuse<T>(code: u32, what: String) -> Result<T, Refusal> {
    Err(Refusal { code, what })
}

impl Modal {
    /// GRBL after power-up or a reset, with the tool at `pos`.
    pub fn new(pos: DVec3) -> Modal {
        Modal {
            pos,
            motion: 0,
            absolute: true,
            inches: false,
            feed: None,
            spindle: None,
            speed: 0.0,
            coolant: (false, false),
            tool: 0,
            plane: Plane::Xy,
        }
    }

    fn scale(&self) -> f64 {
        if self.inches {
            25.4
        } else {
            1.0
        }
    }

    /// Fold `l` into the state. A refused line leaves the state as it was.
    pub fn apply(&mut self, l: &Line) -> Result<Step, Refusal> {
        let mut next = self.clone();
        let step = next.fold(l)?;
        *self = next;
        Ok(step)
    }

    fn fold(&mut self, l: &Line) -> Result<Step, Refusal> {
        let get = |c: char| l.words.iter().rev().find(|w| w.0 == c).map(|w| w.1);
        let mut step = Step {
            from: self.pos,
            ..Step::default()
        };
        let mut new_motion = None;
        let mut dwell = false;
        for &(c, v) in &l.words {
            match (c, v as i32) {
                // G91.1: arc centres are incremental, as they always are
                ('G', 91) if v != 91.0 => {}
                ('G', 0..=3) => new_motion = Some(v as u8),
                ('G', 4) => dwell = true,
                ('G', 20) => self.inches = true,
                ('G', 21) => self.inches = false,
                ('G', 17) => self.plane = Plane::Xy,
                ('G', 18) => self.plane = Plane::Zx,
                ('G', 19) => self.plane = Plane::Yz,
                ('G', 90) => self.absolute = true,
                ('G', 91) => self.absolute = false,
                ('M', 3) | ('M', 4) => {
                    self.spindle = Some(v as u8);
                    step.sync = true;
                }
                ('M', 5) => {
                    self.spindle = None;
                    step.sync = true;
                }
                ('M', 0) if v == 0.0 => {
                    step.pause = true;
                    step.sync = true;
                }
                ('M', 7) => {
                    self.coolant.0 = true;
                    step.sync = true;
                }
                ('M', 8) => {
                    self.coolant.1 = true;
                    step.sync = true;
                }
                ('M', 9) => {
                    self.coolant = (false, false);
                    step.sync = true;
                }
                ('G', 80) => self.motion = NO_MOTION,
                ('M', _) => step.sync = true,
                _ => {}
            }
        }
        if let Some(t) = get('T') {
            if t < 0.0 {
                return refuse(4, format!("negative tool number T{t}"));
            }
            if t > 255.0 {
                return refuse(38, format!("tool number T{t} exceeds 255"));
            }
            self.tool = t as u32;
        }
        if let Some(s) = get('S') {
            if s < 0.0 {
                return refuse(4, format!("negative spindle speed S{s}"));
            }
            step.sync |= self.spindle.is_some() && s != self.speed;
            self.speed = s;
        }
        let scale = self.scale();
        if let Some(f) = get('F') {
            if f <= 0.0 {
                return refuse(4, format!("feed rate F{f} must be positive"));
            }
            self.feed = Some(f * scale);
        }
        if dwell {
            let Some(p) = get('P') else {
                return refuse(28, "G4 needs a P word (seconds)".into());
            };
            if p < 0.0 {
                return refuse(4, format!("negative dwell P{p}"));
            }
            step.dwell = Some(p);
            step.sync = true;
            return Ok(step);
        }
        if let Some(m) = new_motion {
            self.motion = m;
        }
        let axes = ['X', 'Y', 'Z'].map(get);
        if axes.iter().all(Option::is_none) {
            if new_motion.is_some_and(|m| (2..=3).contains(&m)) {
                return refuse(26, "arc without an end point".into());
            }
            return Ok(step);
        }
        if self.motion == NO_MOTION {
            return refuse(31, "axis words with no motion mode (after G80)".into());
        }
        if self.motion >= 1 && self.feed.is_none() {
            return refuse(22, "feed move with no feed rate set (F)".into());
        }
        let mut to = self.pos;
        for (k, v) in axes.iter().enumerate() {
            if let Some(v) = v {
                to[k] = if self.absolute {
                    v * scale
                } else {
                    to[k] + v * scale
                };
            }
        }
        step.relative = !self.absolute;
        step.motion = self.motion;
        if self.motion == 2 || self.motion == 3 {
            let ijk = ['I', 'J', 'K'].map(|c| get(c).map(|v| v * scale));
            let r = get('R').map(|v| v * scale);
            if r.is_some() && ijk.iter().any(Option::is_some) {
                return refuse(36, "arc with both I/J/K offsets and R".into());
            }
            let (a0, a1, _) = self.plane.axes();
            let in_plane = axes[a0].is_some() || axes[a1].is_some();
            match arc::setup(self.plane, self.motion == 2, self.pos, to, ijk, r, in_plane) {
                Ok(a) => step.arc = Some(a),
                Err((code, what)) => return refuse(code, what),
            }
        }
        step.to = Some(to);
        self.pos = to;
        Ok(step)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gcode::parse::parse_line;

    fn fold(m: &mut Modal, s: &str) -> Result<Step, Refusal> {
        m.apply(&parse_line(s, 1).unwrap())
    }

    #[test]
    fn units_distance_and_what_a_line_does() {
        let mut m = Modal::new(DVec3::ZERO);
        assert_eq!(fold(&mut m, "G1 X1").unwrap_err().code, 22);
        assert_eq!(m, Modal::new(DVec3::ZERO), "a refused line changes nothing");
        let s = fold(&mut m, "G20 G1 X1 F10").unwrap();
        assert_eq!(s.to, Some(DVec3::new(25.4, 0.0, 0.0)));
        assert_eq!(m.feed, Some(254.0));
        assert!(!s.sync && !s.relative);
        let s = fold(&mut m, "G91 G21 Y2").unwrap();
        assert!(s.relative);
        assert_eq!(m.pos, DVec3::new(25.4, 2.0, 0.0));
        assert!(fold(&mut m, "M3 S1000").unwrap().sync);
        assert!(!fold(&mut m, "S1000").unwrap().sync, "the same speed");
        assert!(fold(&mut m, "S2000").unwrap().sync);
        let d = fold(&mut m, "G4 P0.5").unwrap();
        assert_eq!(d.dwell, Some(0.5));
        assert!(d.sync && d.to.is_none());
        assert_eq!(fold(&mut m, "G4").unwrap_err().code, 28);
        assert_eq!(fold(&mut m, "G2 I1").unwrap_err().code, 26);
        assert_eq!(fold(&mut m, "F-1").unwrap_err().code, 4);
        // what other CAM programs' posts write
        let mut m = Modal::new(DVec3::ZERO);
        assert!(!fold(&mut m, "G90 G91.1 G0 X1").unwrap().relative);
        assert!(fold(&mut m, "M8").unwrap().sync);
        assert_eq!(m.coolant, (false, true));
        assert_eq!(fold(&mut m, "T300").unwrap_err().code, 38);
        assert!(fold(&mut m, "G40 G49 G80 T1").unwrap().to.is_none());
        assert_eq!(fold(&mut m, "X5").unwrap_err().code, 31);
        assert_eq!(
            fold(&mut m, "G0 X5").unwrap().to,
            Some(DVec3::new(5.0, 0.0, 0.0))
        );
    }
}
