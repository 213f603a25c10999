//! The simulated GRBL's `$` system commands, as GRBL 1.1h's
//! system_execute_line reads them: the line as its buffer holds it
//! (upper-cased, no spaces), each command's state rules and error codes.

use super::settings::grbl_float;
use super::{SimGrbl, PLANNER_BLOCKS};
use crate::gcode::modal::PROBE_TOWARD;
use crate::gcode::parse::{parse_line, read_number};
use crate::grbl::state::State;
use glam::DVec3;

/// GRBL's own constant (nuts_bolts.h), not 1/25.4.
const INCH_PER_MM: f64 = 0.0393701;

const HELP: &str = "[HLP:$$ $# $G $I $N $x=val $Nx=line $J=line $SLP $C $X $H ~ ! ? ctrl-x]";

/// GRBL's read_float on a `$` line from byte `at`: the value and where it
/// ends.
fn number(line: &str, at: usize) -> Option<(f32, usize)> {
    read_number(line.as_bytes(), at).map(|(v, end)| (v as f32, end))
}

impl SimGrbl {
    /// A `$` line (`line` starts with '$'): answered, or refused with
    /// GRBL's code.
    pub(super) fn system(&mut self, line: &str) {
        match self.system_line(line) {
            Ok(true) => self.say("ok"),
            Ok(false) => {}
            Err(code) => self.error(code),
        }
    }

    /// Ok(false): answered already (a command that resets after its ok).
    fn system_line(&mut self, line: &str) -> Result<bool, u32> {
        let b = line.as_bytes();
        let at = |k: usize| b.get(k).copied().unwrap_or(0);
        let state = self.state();
        match at(1) {
            0 => self.say(HELP),
            b'J' => {
                if !matches!(state, State::Idle | State::Jog) {
                    return Err(8);
                }
                if at(2) != b'=' {
                    return Err(3);
                }
                return self.jog(&line[3..]).map(|_| true);
            }
            c @ (b'$' | b'G' | b'C' | b'X') => {
                if at(2) != 0 {
                    return Err(3);
                }
                match c {
                    b'$' => {
                        if matches!(state, State::Run | State::Hold(_)) {
                            return Err(8);
                        }
                        for l in self.settings.report() {
                            self.say(&l);
                        }
                    }
                    b'G' => {
                        let l = self.parser_state();
                        self.say(&l);
                    }
                    b'C' => {
                        if state == State::Check {
                            // GRBL resets when check mode ends
                            self.say("[MSG:Disabled]");
                            self.say("ok");
                            self.reset();
                            return Ok(false);
                        }
                        if state != State::Idle {
                            return Err(8);
                        }
                        self.check = true;
                        self.say("[MSG:Enabled]");
                    }
                    _ => {
                        if self.alarm.take().is_some() {
                            self.say("[MSG:Caution: Unlocked]");
                        }
                    }
                }
            }
            c => {
                if !matches!(state, State::Idle | State::Alarm) {
                    return Err(8);
                }
                return self.system_idle(line, c);
            }
        }
        Ok(true)
    }

    /// The `$` commands GRBL takes only when idle or in alarm.
    fn system_idle(&mut self, line: &str, c: u8) -> Result<bool, u32> {
        let b = line.as_bytes();
        let at = |k: usize| b.get(k).copied().unwrap_or(0);
        match c {
            b'#' => {
                if at(2) != 0 {
                    return Err(3);
                }
                for l in self.parameters() {
                    self.say(&l);
                }
            }
            b'H' => {
                if !self.settings.homing() {
                    return Err(5);
                }
                if at(2) != 0 {
                    return Err(3);
                }
                self.alarm = None;
                self.done = DVec3::ZERO;
                self.modal.pos = DVec3::ZERO;
            }
            b'S' => {
                if &line[1..] != "SLP" {
                    return Err(3);
                }
                self.sleep();
                return Ok(false);
            }
            b'I' if at(2) == 0 => {
                let mut v = b"[VER:1.1h.20190830:".to_vec();
                v.extend_from_slice(&self.build_info);
                v.push(b']');
                self.say_bytes(&v);
                self.say(&format!("[OPT:V,{PLANNER_BLOCKS},{}]", self.rx_size));
            }
            b'I' => {
                if at(2) != b'=' {
                    return Err(3);
                }
                self.build_info = line.chars().skip(3).map(|c| c as u8).collect();
            }
            b'R' => {
                if !line.starts_with("$RST=") || line.len() != 6 {
                    return Err(3);
                }
                match at(5) {
                    b'$' => self.settings = super::settings::Settings::of(&self.machine),
                    b'#' => self.modal.stored = Default::default(),
                    b'*' => {
                        self.settings = super::settings::Settings::of(&self.machine);
                        self.modal.stored = Default::default();
                        self.startup = Default::default();
                        self.build_info.clear();
                    }
                    _ => return Err(3),
                }
                self.say("[MSG:Restoring defaults]");
                self.say("ok");
                self.reset();
                return Ok(false);
            }
            b'N' if at(2) == 0 => {
                for k in 0..2 {
                    let l = format!("$N{k}={}", self.startup[k]);
                    self.say(&l);
                }
            }
            b'N' => {
                if self.state() != State::Idle {
                    return Err(8);
                }
                let (n, end) = number(line, 2).ok_or(2u32)?;
                if at(end) != b'=' {
                    return Err(3);
                }
                let block = &line[end + 1..];
                // GRBL runs the line to check it, then keeps it
                let step = self
                    .modal
                    .apply(&parse_line(block, 0))
                    .map_err(|r| r.code)?;
                if let Some(to) = step.to.filter(|_| !self.check) {
                    self.queue(step.from, to, String::new());
                }
                if step.end {
                    self.say("[MSG:Pgm End]");
                }
                let k = super::c_int(n as f64) as u8 as usize;
                if k < 2 {
                    self.startup[k] = block.to_string();
                }
            }
            _ => {
                let (n, end) = number(line, 1).ok_or(2u32)?;
                if at(end) != b'=' {
                    return Err(3);
                }
                let (value, stop) = number(line, end + 1).ok_or(2u32)?;
                if stop != line.len() || n > 255.0 {
                    return Err(3);
                }
                let k = super::c_int(n as f64) as u8;
                self.settings.store(k, value)?;
            }
        }
        Ok(true)
    }

    /// The `$N0`/`$N1` lines GRBL runs after its welcome (not in an
    /// alarm), each answered `>line:ok` or `>line:error:N`.
    pub(super) fn run_startup(&mut self) {
        for k in 0..2 {
            let line = self.startup[k].clone();
            if line.is_empty() {
                continue;
            }
            let mark = self.out.len();
            self.run(line.clone());
            let now = self.now;
            self.advance(now); // a G4 P0 answers at once
                               // its answer, the last line it printed, goes after the line
            let said: Vec<u8> = self.out.split_off(mark);
            let text = String::from_utf8_lossy(&said).to_string();
            let mut lines: Vec<&str> = text.split("\r\n").filter(|l| !l.is_empty()).collect();
            let answer = lines
                .last()
                .copied()
                .filter(|a| *a == "ok" || a.starts_with("error:"));
            if answer.is_some() {
                lines.pop();
            }
            for l in &lines {
                self.say(l);
            }
            if let Some(a) = answer {
                self.say(&format!(">{line}:{a}"));
            }
        }
    }

    /// `$G`: the parser's modes as GRBL reports them.
    fn parser_state(&self) -> String {
        let m = &self.modal;
        let motion = match m.motion {
            p if p >= PROBE_TOWARD => format!("38.{}", p - PROBE_TOWARD + 2),
            p => p.to_string(),
        };
        let coolant = match m.coolant {
            (false, false) => "M9".to_string(),
            (mist, flood) => [(mist, "M7"), (flood, "M8")]
                .iter()
                .filter(|c| c.0)
                .map(|c| c.1)
                .collect::<Vec<_>>()
                .join(" "),
        };
        format!(
            "[GC:G{motion} G{} G{} {} {} {} M{} {coolant} T{} F{} S{}]",
            54 + m.coord,
            m.plane.code(),
            if m.inches { "G20" } else { "G21" },
            if m.absolute { "G90" } else { "G91" },
            if m.inverse_time { "G93" } else { "G94" },
            m.spindle.unwrap_or(5),
            m.tool,
            self.rate(m.feed.unwrap_or(0.0)),
            grbl_float(m.speed as f32, 0)
        )
    }

    /// `$#`: the stored offsets, G92, the tool length offset, the probe.
    fn parameters(&self) -> Vec<String> {
        let m = &self.modal;
        let mut lines: Vec<String> = (0..6)
            .map(|k| format!("[G{}:{}]", 54 + k, self.coords(m.stored.wcs[k])))
            .collect();
        lines.push(format!("[G28:{}]", self.coords(m.stored.g28)));
        lines.push(format!("[G30:{}]", self.coords(m.stored.g30)));
        lines.push(format!("[G92:{}]", self.coords(m.g92)));
        lines.push(format!("[TLO:{}]", self.coord(m.tlo)));
        lines.push(format!(
            "[PRB:{}:{}]",
            self.coords(self.probed.0),
            u8::from(self.probed.1)
        ));
        lines
    }

    /// A coordinate as GRBL prints it: mm to 3 places, or inches to 4
    /// with `$13=1`.
    pub(super) fn coord(&self, v: f64) -> String {
        if self.settings.report_inches() {
            grbl_float((v as f32 as f64 * INCH_PER_MM) as f32, 4)
        } else {
            grbl_float(v as f32, 3)
        }
    }

    pub(super) fn coords(&self, p: DVec3) -> String {
        format!(
            "{},{},{}",
            self.coord(p.x),
            self.coord(p.y),
            self.coord(p.z)
        )
    }

    /// A feed as GRBL prints it: mm/min whole, or inch/min to 1 place.
    pub(super) fn rate(&self, v: f64) -> String {
        if self.settings.report_inches() {
            grbl_float((v as f32 as f64 * INCH_PER_MM) as f32, 1)
        } else {
            grbl_float(v as f32, 0)
        }
    }
}
