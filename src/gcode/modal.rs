//! The modal state of a GRBL 1.1 machine and what one line does to it: the
//! one interpreter that `simulate` (through `program`), the simulated GRBL
//! and the sender (its re-entry preamble and its resume safety) fold lines
//! through, so that they cannot disagree about where a line goes. It
//! follows GRBL 1.1h's gc_execute_line (default build) check for check and
//! in its order, so that a line it refuses gets GRBL's own error code.

use super::parse::Line;
use crate::dialect::arc::{self, Arc, Plane};
use glam::DVec3;

/// What GRBL keeps in its EEPROM and so across resets: the six work
/// coordinate systems (G54-G59) and the G28 and G30 positions (machine
/// coordinates, mm).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Stored {
    pub wcs: [DVec3; 6],
    pub g28: DVec3,
    pub g30: DVec3,
}

/// Units, distance mode, motion mode, feed, spindle, offsets, position.
#[derive(Clone, Debug, PartialEq)]
pub struct Modal {
    /// Where the tool is after the lines folded so far (machine
    /// coordinates, mm).
    pub pos: DVec3,
    /// G0, G1, G2, G3, G80 (NO_MOTION) or a probe (PROBE_TOWARD ..).
    pub motion: u8,
    pub absolute: bool,
    pub inches: bool,
    /// G93: F is the inverse of each move's time, given on its line.
    pub inverse_time: bool,
    /// mm/min (G94), or 1/min (G93).
    pub feed: Option<f64>,
    /// M3 or M4 while the spindle is on.
    pub spindle: Option<u8>,
    /// The last S word.
    pub speed: f64,
    /// Mist (M7) and flood (M8) coolant.
    pub coolant: (bool, bool),
    /// The last T word (GRBL only tracks it; a line without T sets 0).
    pub tool: u32,
    /// The arc plane (G17, G18, G19).
    pub plane: Plane,
    /// The work coordinate system in use: 0 = G54 .. 5 = G59.
    pub coord: usize,
    /// The G92 offset, mm.
    pub g92: DVec3,
    /// The tool length offset along Z (G43.1), mm; 0 after G49.
    pub tlo: f64,
    /// G43.1 (rather than G49) in force.
    pub tlo_on: bool,
    pub stored: Stored,
}

/// The motion mode after G80: axis words then have nothing to do.
pub const NO_MOTION: u8 = 80;
/// G38.2 (toward the work, an alarm if nothing touches); G38.3, G38.4
/// (away) and G38.5 follow as GRBL numbers them.
pub const PROBE_TOWARD: u8 = 140;

/// A probing move: toward or away from the work, and whether missing is
/// an alarm (G38.2, G38.4) or not (G38.3, G38.5).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Probe {
    pub away: bool,
    pub must_touch: bool,
}

/// What one line does.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Step {
    pub from: DVec3,
    /// The end of the line's move, when it moves (machine coordinates).
    pub to: Option<DVec3>,
    /// G28/G30 with axis words: the point the move passes on its way.
    pub via: Option<DVec3>,
    /// Motion mode of the move (0 rapid, 1 feed, 2/3 arcs, probes).
    pub motion: u8,
    /// The arc, for G2/G3.
    pub arc: Option<Arc>,
    /// The probe, for G38.x: the move stops where it touches.
    pub probe: Option<Probe>,
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
    /// M2/M30: the program's end (some modes reset, "[MSG:Pgm End]").
    pub end: bool,
    /// A `$J=` jog: it moves, and changes no mode.
    pub jog: bool,
    /// A jog's feed, mm/min.
    pub jog_feed: f64,
}

/// A line GRBL refuses: its `error:N` code and what is wrong.
#[derive(Clone, Debug, PartialEq)]
pub struct Refusal {
    pub code: u32,
    pub what: String,
}

fn refuse<T>(code: u32, what: impl Into<String>) -> Result<T, Refusal> {
    Err(Refusal {
        code,
        what: what.into(),
    })
}

// modal groups, as GRBL's bits
const G_NON_MODAL: u32 = 1 << 0;
const G_MOTION: u32 = 1 << 1;
const G_PLANE: u32 = 1 << 2;
const G_DISTANCE: u32 = 1 << 3;
const G_ARC_DISTANCE: u32 = 1 << 4;
const G_FEED_MODE: u32 = 1 << 5;
const G_UNITS: u32 = 1 << 6;
const G_CUTTER: u32 = 1 << 7;
const G_TOOL_LENGTH: u32 = 1 << 8;
const G_COORD: u32 = 1 << 9;
const G_PATH: u32 = 1 << 10;
const M_FLOW: u32 = 1 << 11;
const M_SPINDLE: u32 = 1 << 12;
const M_COOLANT: u32 = 1 << 13;

/// What claims the block's axis words.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
enum AxisCommand {
    #[default]
    None,
    NonModal,
    Motion,
    ToolLength,
}

/// The value words GRBL reads, by letter.
const VALUE_WORDS: &str = "FIJKLNPRSTXYZ";

/// A float to an integer as GRBL's C does on the host it was recorded on
/// (x86 cvttsd2si): truncated, and out of the int32 range the "integer
/// indefinite" i32::MIN; narrower C types then keep the low bits.
pub fn c_int(x: f64) -> i32 {
    if x.is_nan() || x >= 2_147_483_648.0 || x <= -2_147_483_649.0 {
        i32::MIN
    } else {
        x.trunc() as i32
    }
}

/// How long GRBL dwells for G4 P`p`: whole 50 ms steps, counted in 16
/// bits (delay_sec), so P0.12 waits 0.15 s and P4095 wraps to 818.2 s.
pub fn dwell_seconds(p: f64) -> f64 {
    let steps = c_int(((20.0f32 * p as f32) as f64).ceil()) as u16;
    steps as f64 * 0.05
}

/// A G or M word's number as GRBL splits it: the integer in 8 bits (so
/// G256 reads as G0 with hundredths 25600, and M-3 as M253) and the
/// hundredths of the float's remainder in 16 bits.
fn command_number(value: f64) -> (i64, i64) {
    let int = c_int(value) as u8;
    let rest = 100.0f32 * (value as f32 - int as f32);
    (int as i64, c_int((rest as f64).round()) as u16 as i64)
}

fn bit(c: char) -> u32 {
    1 << (c as u32 - 'A' as u32)
}

const N_COORD_SYSTEMS: f64 = 6.0;
const MAX_LINE_NUMBER: f64 = 10_000_000.0;
const MAX_TOOL_NUMBER: f64 = 255.0;

impl Modal {
    /// GRBL after power-up, with the tool at `pos` and nothing stored.
    pub fn new(pos: DVec3) -> Modal {
        Modal {
            pos,
            motion: 0,
            absolute: true,
            inches: false,
            inverse_time: false,
            feed: None,
            spindle: None,
            speed: 0.0,
            coolant: (false, false),
            tool: 0,
            plane: Plane::Xy,
            coord: 0,
            g92: DVec3::ZERO,
            tlo: 0.0,
            tlo_on: false,
            stored: Stored::default(),
        }
    }

    /// GRBL after a reset with the tool at `pos`: every mode back to its
    /// default, G92 and the tool length offset cleared, what the EEPROM
    /// holds kept.
    pub fn after_reset(&self, pos: DVec3) -> Modal {
        Modal {
            stored: self.stored.clone(),
            ..Modal::new(pos)
        }
    }

    /// The work coordinate offset: machine = work + wco.
    pub fn wco(&self) -> DVec3 {
        self.stored.wcs[self.coord] + self.g92 + DVec3::new(0.0, 0.0, self.tlo)
    }

    /// Fold `l` into the state. A refused line leaves the state as it was.
    pub fn apply(&mut self, l: &Line) -> Result<Step, Refusal> {
        self.apply_as(l, false)
    }

    /// Fold the words of a `$J=` jog line: it moves, modes stay.
    pub fn jog(&mut self, l: &Line) -> Result<Step, Refusal> {
        self.apply_as(l, true)
    }

    fn apply_as(&mut self, l: &Line, jog: bool) -> Result<Step, Refusal> {
        let mut next = self.clone();
        let step = next.fold(l, jog)?;
        if jog {
            self.pos = next.pos;
        } else {
            *self = next;
        }
        Ok(step)
    }

    /// GRBL's gc_execute_line on a copy of the state (`self`): the words
    /// read (step 2), the block checked (step 3), then executed (step 4).
    fn fold(&mut self, l: &Line, jog: bool) -> Result<Step, Refusal> {
        let old = self.clone();
        let mut step = Step {
            from: old.pos,
            ..Step::default()
        };
        if jog {
            self.motion = 1;
            self.inverse_time = false;
        }
        let mut b = Block::default();
        for &(c, value) in &l.words {
            self.word(&mut b, c, value)?;
        }
        if let Some(code) = l.bad {
            return refuse(
                code,
                match code {
                    11 => "the line is longer than GRBL's 80-character line buffer",
                    1 => "expected a word's letter",
                    _ => "a word without a valid number",
                },
            );
        }
        // step 3: check the block
        b.unused = b.seen;
        b.present = ['X', 'Y', 'Z'].map(|c| b.has(c));
        b.axis_words = b.present.iter().any(|&p| p);
        if b.axis_words && b.axis_command == AxisCommand::None {
            b.axis_command = AxisCommand::Motion;
        }
        if b.has('N') && b.v('N') > MAX_LINE_NUMBER {
            return refuse(27, format!("line number N{} too large", b.v('N')));
        }
        let scale = if self.inches { 25.4 } else { 1.0 };
        let f = self.feed_rate(&old, &b, jog, scale)?;
        let speed = if b.has('S') { b.v('S') } else { old.speed };
        if b.non_modal == Some(4) {
            if !b.has('P') {
                return refuse(28, "G4 needs a P word (seconds)");
            }
            b.unused &= !bit('P');
        }
        if b.axis_command == AxisCommand::ToolLength
            && b.tool_length == Some(true)
            && b.present != [false, false, true]
        {
            return refuse(37, "G43.1 takes a Z word only");
        }
        let to = self.targets(&old, &mut b, scale)?;
        self.check_motion(&old, &mut b, &mut step, f, to.target, scale)?;
        b.check_unused(jog)?;
        if jog {
            if b.groups & !(G_DISTANCE | G_UNITS | G_NON_MODAL) != 0
                || !matches!(b.non_modal, None | Some(53))
            {
                return refuse(16, "a jog takes only G20/G21, G90/G91 and G53");
            }
            step.jog = true;
            step.jog_feed = f;
            if b.axis_command != AxisCommand::None {
                step.motion = 1;
                step.to = Some(to.target);
                self.pos = to.target;
            }
            return Ok(step);
        }
        self.execute(&old, &b, &to, (f, speed), &mut step);
        Ok(step)
    }

    /// One word of the block (step 2), by its letter: a G or M command
    /// sets its modal group's mode, a value word is kept.
    fn word(&mut self, b: &mut Block, c: char, value: f64) -> Result<(), Refusal> {
        let (int, mantissa) = command_number(value);
        match c {
            'G' => {
                let group = self.g_command(b, int, mantissa, value)?;
                if b.groups & group != 0 {
                    return refuse(21, format!("G{value}: two commands of one modal group"));
                }
                b.groups |= group;
            }
            'M' => {
                if mantissa > 0 {
                    return refuse(23, format!("M{value} needs an integer"));
                }
                let group = self.m_command(b, int, value)?;
                if b.groups & group != 0 {
                    return refuse(21, format!("M{value}: two commands of one modal group"));
                }
                b.groups |= group;
            }
            c if VALUE_WORDS.contains(c) => {
                if c == 'T' && value > MAX_TOOL_NUMBER {
                    return refuse(38, format!("tool number T{value} exceeds 255"));
                }
                if b.seen & bit(c) != 0 {
                    return refuse(25, format!("word {c} repeated"));
                }
                if "FNPTS".contains(c) && value < 0.0 {
                    return refuse(4, format!("negative value {c}{value}"));
                }
                b.seen |= bit(c);
                b.val[c as usize - 'A' as usize] = match c {
                    'L' | 'T' => int as f64,
                    'N' => c_int(value) as f64,
                    _ => value,
                };
            }
            _ => return refuse(20, format!("unsupported word {c}{value}")),
        }
        Ok(())
    }

    /// A G command: its modal group's bit, the mode set.
    fn g_command(
        &mut self,
        b: &mut Block,
        int: i64,
        mut mantissa: i64,
        value: f64,
    ) -> Result<u32, Refusal> {
        let unsupported = || refuse(20, format!("unsupported command G{value}"));
        let group = match int {
            4 | 10 | 28 | 30 | 53 | 92 => {
                if matches!(int, 10 | 28 | 30 | 92) && mantissa == 0 {
                    b.claim(AxisCommand::NonModal)?;
                }
                let mut code = int as u16;
                if matches!(int, 28 | 30 | 92) {
                    if mantissa != 0 && mantissa != 10 {
                        return unsupported();
                    }
                    code += mantissa as u16;
                    mantissa = 0;
                }
                b.non_modal = Some(code);
                G_NON_MODAL
            }
            0..=3 | 38 => {
                b.claim(AxisCommand::Motion)?;
                self.motion = int as u8;
                if int == 38 {
                    if !matches!(mantissa, 20 | 30 | 40 | 50) {
                        return refuse(20, format!("unsupported probe G{value}"));
                    }
                    self.motion = PROBE_TOWARD + (mantissa / 10 - 2) as u8;
                    mantissa = 0;
                }
                G_MOTION
            }
            80 => {
                self.motion = NO_MOTION;
                G_MOTION
            }
            17..=19 => {
                self.plane = [Plane::Xy, Plane::Zx, Plane::Yz][(int - 17) as usize];
                G_PLANE
            }
            90 | 91 if mantissa == 0 => {
                self.absolute = int == 90;
                G_DISTANCE
            }
            90 | 91 => {
                // G91.1 (arc centres incremental, as always)
                if mantissa != 10 || int == 90 {
                    return unsupported();
                }
                mantissa = 0;
                G_ARC_DISTANCE
            }
            93 | 94 => {
                self.inverse_time = int == 93;
                G_FEED_MODE
            }
            20 | 21 => {
                self.inches = int == 20;
                G_UNITS
            }
            40 => G_CUTTER,
            43 | 49 => {
                b.claim(AxisCommand::ToolLength)?;
                if int == 49 {
                    b.tool_length = Some(false);
                } else if mantissa == 10 {
                    b.tool_length = Some(true);
                } else {
                    return unsupported();
                }
                mantissa = 0;
                G_TOOL_LENGTH
            }
            54..=59 => {
                self.coord = (int - 54) as usize;
                G_COORD
            }
            61 => {
                if mantissa != 0 {
                    return unsupported();
                }
                G_PATH
            }
            _ => return unsupported(),
        };
        if mantissa > 0 {
            return refuse(23, format!("G{value} needs an integer"));
        }
        Ok(group)
    }

    /// An M command: its modal group's bit, the mode set.
    fn m_command(&mut self, b: &mut Block, int: i64, value: f64) -> Result<u32, Refusal> {
        Ok(match int {
            0 | 1 | 2 | 30 => {
                // M1, the optional stop, is ignored
                if int != 1 {
                    b.flow = Some(int as u8);
                }
                M_FLOW
            }
            3 | 4 => {
                self.spindle = Some(int as u8);
                M_SPINDLE
            }
            5 => {
                self.spindle = None;
                M_SPINDLE
            }
            // M7 (mist) is not in GRBL's default build
            8 => {
                self.coolant.1 = true;
                M_COOLANT
            }
            9 => {
                self.coolant = (false, false);
                M_COOLANT
            }
            _ => return refuse(20, format!("unsupported command M{value}")),
        })
    }

    /// The block's feed rate, mm/min or 1/min in G93 (0 = undefined).
    fn feed_rate(&self, old: &Modal, b: &Block, jog: bool, scale: f64) -> Result<f64, Refusal> {
        Ok(if jog {
            if !b.has('F') {
                return refuse(22, "a jog needs its F word");
            }
            b.v('F') * scale
        } else if self.inverse_time {
            if b.axis_command == AxisCommand::Motion
                && self.motion != NO_MOTION
                && self.motion != 0
                && !b.has('F')
            {
                return refuse(22, "G93 needs an F word on every feed move");
            }
            b.v('F')
        } else if !old.inverse_time {
            if b.has('F') {
                b.v('F') * scale
            } else {
                old.feed.unwrap_or(0.0)
            }
        } else {
            // (GRBL takes F as given when leaving G93)
            b.v('F')
        })
    }

    /// The non-modal commands' data (G10, G92, G28/G30) and the block's
    /// target in machine coordinates.
    fn targets(&self, old: &Modal, b: &mut Block, scale: f64) -> Result<Targets, Refusal> {
        let mut xyz = ['X', 'Y', 'Z'].map(|c| b.v(c) * scale);
        let present = b.present;
        let block_coord = self.stored.wcs[self.coord];
        let tlo = DVec3::new(0.0, 0.0, old.tlo);
        let mut to = Targets::default();
        match b.non_modal {
            Some(10) => {
                if !b.axis_words {
                    return refuse(26, "G10 without axis words");
                }
                if !b.has('P') && !b.has('L') {
                    return refuse(28, "G10 needs L and P words");
                }
                // GRBL keeps the system's number in 8 bits
                let p = c_int(b.v('P')) as u8 as f64;
                if p > N_COORD_SYSTEMS {
                    return refuse(29, format!("no coordinate system P{p}"));
                }
                let l20 = b.v('L') == 20.0;
                if !l20 && (b.v('L') != 2.0 || b.has('R')) {
                    return refuse(20, format!("unsupported G10 L{}", b.v('L')));
                }
                b.unused &= !(bit('L') | bit('P'));
                let idx = if p > 0.0 { p as usize - 1 } else { self.coord };
                let mut data = self.stored.wcs[idx];
                for k in (0..3).filter(|&k| present[k]) {
                    data[k] = if l20 {
                        old.pos[k] - old.g92[k] - xyz[k] - tlo[k]
                    } else {
                        xyz[k]
                    };
                }
                to.g10 = Some((idx, data));
            }
            Some(92) => {
                if !b.axis_words {
                    return refuse(26, "G92 without axis words");
                }
                let mut o = old.g92;
                for k in (0..3).filter(|&k| present[k]) {
                    o[k] = old.pos[k] - block_coord[k] - xyz[k] - tlo[k];
                }
                to.g92 = Some(o);
            }
            _ => {
                if b.axis_command != AxisCommand::ToolLength && b.axis_words {
                    for k in 0..3 {
                        xyz[k] = if !present[k] {
                            old.pos[k]
                        } else if b.non_modal == Some(53) {
                            xyz[k]
                        } else if self.absolute {
                            xyz[k] + block_coord[k] + old.g92[k] + tlo[k]
                        } else {
                            xyz[k] + old.pos[k]
                        };
                    }
                }
                match b.non_modal {
                    Some(28) | Some(30) => {
                        let mut h = if b.non_modal == Some(28) {
                            self.stored.g28
                        } else {
                            self.stored.g30
                        };
                        if b.axis_words {
                            for k in (0..3).filter(|&k| !present[k]) {
                                h[k] = old.pos[k];
                            }
                        } else {
                            b.axis_command = AxisCommand::None;
                        }
                        to.home = Some(h);
                    }
                    Some(53) if self.motion != 0 && self.motion != 1 => {
                        return refuse(30, "G53 needs G0 or G1");
                    }
                    _ => {}
                }
            }
        }
        to.xyz = xyz;
        to.target = DVec3::from_array(xyz);
        Ok(to)
    }

    /// The motion mode's checks: a feed for feed moves, an arc's geometry,
    /// a probe's target.
    fn check_motion(
        &self,
        old: &Modal,
        b: &mut Block,
        step: &mut Step,
        f: f64,
        target: DVec3,
        scale: f64,
    ) -> Result<(), Refusal> {
        if self.motion == NO_MOTION {
            if b.axis_words {
                return refuse(31, "axis words with no motion mode (after G80)");
            }
            return Ok(());
        }
        if b.axis_command != AxisCommand::Motion {
            return Ok(());
        }
        if self.motion == 0 {
            if !b.axis_words {
                b.axis_command = AxisCommand::None;
            }
            return Ok(());
        }
        if f == 0.0 {
            return refuse(22, "feed move with no feed rate set (F)");
        }
        match self.motion {
            1 if !b.axis_words => b.axis_command = AxisCommand::None,
            2 | 3 => {
                if !b.axis_words {
                    return refuse(26, "arc without an end point");
                }
                let r = b.has('R').then(|| b.v('R') * scale);
                let ijk = if r.is_some() {
                    b.unused &= !bit('R');
                    [None; 3]
                } else {
                    b.unused &= !(bit('I') | bit('J') | bit('K'));
                    ['I', 'J', 'K'].map(|c| b.has(c).then(|| b.v(c) * scale))
                };
                let (a0, a1, _) = self.plane.axes();
                let in_plane = b.present[a0] || b.present[a1];
                let cw = self.motion == 2;
                match arc::setup(self.plane, cw, old.pos, target, ijk, r, in_plane) {
                    Ok(a) => step.arc = Some(a),
                    Err((code, what)) => return refuse(code, what),
                }
            }
            m if m >= PROBE_TOWARD => {
                if !b.axis_words {
                    return refuse(26, "a probe without axis words");
                }
                if target == old.pos {
                    return refuse(33, "a probe to where the tool is");
                }
                let k = m - PROBE_TOWARD;
                step.probe = Some(Probe {
                    away: k >= 2,
                    must_touch: k.is_multiple_of(2),
                });
                // GRBL runs a probe alone, after the moves before it, and
                // answers when it has ended
                step.sync = true;
            }
            _ => {}
        }
        Ok(())
    }

    /// Step 4: the checked block executed in GRBL's order.
    fn execute(
        &mut self,
        old: &Modal,
        b: &Block,
        to: &Targets,
        (f, speed): (f64, f64),
        step: &mut Step,
    ) {
        self.feed = (f > 0.0).then_some(f);
        if speed != old.speed {
            step.sync |= old.spindle.is_some();
            self.speed = speed;
        }
        self.tool = if b.has('T') { b.v('T') as u32 } else { 0 };
        step.sync |= self.spindle != old.spindle || self.coolant != old.coolant;
        if b.non_modal == Some(4) {
            step.dwell = Some(dwell_seconds(b.v('P')));
            step.sync = true;
        }
        if let Some(on) = b.tool_length {
            self.tlo_on = on;
            self.tlo = if on { to.xyz[2] } else { 0.0 };
        }
        if let Some((idx, data)) = to.g10 {
            self.stored.wcs[idx] = data;
        }
        match b.non_modal {
            Some(28) | Some(30) => {
                let h = to.home.unwrap_or(old.pos);
                if b.axis_command != AxisCommand::None {
                    step.via = Some(to.target);
                }
                step.motion = 0;
                step.to = Some(h);
                self.pos = h;
            }
            Some(38) => self.stored.g28 = old.pos,
            Some(40) => self.stored.g30 = old.pos,
            Some(92) => self.g92 = to.g92.unwrap_or(old.g92),
            Some(102) => self.g92 = DVec3::ZERO,
            _ => {}
        }
        if self.motion != NO_MOTION && b.axis_command == AxisCommand::Motion {
            step.motion = self.motion;
            step.to = Some(to.target);
            step.relative = !self.absolute;
            self.pos = to.target;
        }
        match b.flow {
            Some(0) => {
                step.pause = true;
                step.sync = true;
            }
            Some(_) => {
                // M2/M30: these modes go back to their defaults
                step.end = true;
                step.sync = true;
                self.motion = 1;
                self.plane = Plane::Xy;
                self.absolute = true;
                self.inverse_time = false;
                self.coord = 0;
                self.spindle = None;
                self.coolant = (false, false);
            }
            None => {}
        }
    }
}

/// A block's words as GRBL's parser reads them, and what its checks find.
#[derive(Default)]
struct Block {
    /// Modal groups met, as GRBL's bits.
    groups: u32,
    /// Value words met, by letter bit; `unused` those nothing took.
    seen: u32,
    unused: u32,
    val: [f64; 26],
    axis_command: AxisCommand,
    non_modal: Option<u16>,
    flow: Option<u8>,
    tool_length: Option<bool>,
    /// X, Y, Z given.
    present: [bool; 3],
    axis_words: bool,
}

impl Block {
    fn has(&self, c: char) -> bool {
        self.seen & bit(c) != 0
    }

    fn v(&self, c: char) -> f64 {
        self.val[c as usize - 'A' as usize]
    }

    /// The axis words go to one command only.
    fn claim(&mut self, to: AxisCommand) -> Result<(), Refusal> {
        if self.axis_command != AxisCommand::None {
            return refuse(24, "two commands in the block use the axis words");
        }
        self.axis_command = to;
        Ok(())
    }

    /// A value word that nothing took is an error.
    fn check_unused(&mut self, jog: bool) -> Result<(), Refusal> {
        self.unused &= !(bit('N') | bit('F'));
        if !jog {
            self.unused &= !(bit('S') | bit('T'));
        }
        if self.axis_command != AxisCommand::None {
            self.unused &= !(bit('X') | bit('Y') | bit('Z'));
        }
        if self.unused != 0 {
            let words: String = VALUE_WORDS
                .chars()
                .filter(|&c| self.unused & bit(c) != 0)
                .collect();
            return refuse(36, format!("words {words} unused"));
        }
        Ok(())
    }
}

/// Where a block goes and what its non-modal command stores.
#[derive(Default)]
struct Targets {
    /// The axis words made machine coordinates (for G43.1, Z as given).
    xyz: [f64; 3],
    target: DVec3,
    g10: Option<(usize, DVec3)>,
    g92: Option<DVec3>,
    home: Option<DVec3>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gcode::parse::parse_line;

    fn fold(m: &mut Modal, s: &str) -> Result<Step, Refusal> {
        m.apply(&parse_line(s, 1))
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
