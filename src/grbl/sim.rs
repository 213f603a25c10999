//! A simulated GRBL 1.1 machine, driven by bytes and simulated time: the
//! 128-byte receive buffer (overflow is counted as a failure, never
//! hidden), a 15-block planner executing moves at their feed, `ok` /
//! `error:N` replies, status reports, realtime commands, `$` commands,
//! check mode, alarms, and injectable faults. It has no clock of its own:
//! the port that carries its bytes says what time it is.

use super::{SOFT_RESET, WELCOME};
use crate::gcode::parse::{parse_line, strip};
use crate::machine::Machine;
use glam::DVec3;
use std::collections::VecDeque;

/// Planner blocks GRBL 1.1 holds on an Uno.
pub const PLANNER_BLOCKS: usize = 15;
/// GRBL's line buffer: longer lines are refused with error:11.
const LINE_MAX: usize = 80;

/// Faults to inject. Lines count the G-code lines the machine received
/// (not `$` commands or blank lines), from 1.
#[derive(Clone, Debug, Default)]
pub struct Faults {
    /// Reply `error:CODE` to line N instead of executing it.
    pub error_at: Option<(usize, u32)>,
    /// Raise `ALARM:CODE` at line N (before its `ok`), stopping motion.
    pub alarm_at: Option<(usize, u32)>,
    /// Drop the link after this many bytes received: later bytes are lost,
    /// what was already received is still executed and answered.
    pub disconnect_after: Option<usize>,
    /// Probability that a reply line gets noise bytes (non-ASCII, as a
    /// noisy USB-serial adapter produces) spliced into it.
    pub garble: f64,
}

#[derive(Clone, Copy, Debug)]
struct Block {
    duration: f64,
    end: DVec3,
}

pub struct SimGrbl {
    now: f64,
    rx: VecDeque<u8>,
    rx_size: usize,
    /// Bytes that arrived with the receive buffer full (lost): a failure.
    pub overflow: usize,
    planner: VecDeque<Block>,
    /// When the head block completes (while not held).
    block_end: f64,
    /// Time left of the head block while held.
    held_left: Option<f64>,
    alarm: Option<u32>,
    check: bool,
    out: Vec<u8>,
    /// Position after the planned moves, and after the completed ones.
    planned: DVec3,
    done: DVec3,
    absolute: bool,
    inches: bool,
    feed: Option<f64>,
    motion: u8,
    spindle: f64,
    /// Every G-code line executed (accepted into the planner or run), in
    /// order, as GRBL's line buffer held it.
    pub log: Vec<String>,
    /// Lines refused with an error, as (line count, code).
    pub errors: Vec<(usize, u32)>,
    gcode_lines: usize,
    bytes_in: usize,
    pub faults: Faults,
    pub disconnected: bool,
    travel: DVec3,
    max_rate: DVec3,
    /// mm/s^2 per axis, and GRBL's junction deviation ($11), mm.
    accel: DVec3,
    junction: f64,
    /// Direction and exit speed (mm/s) of the last queued move.
    last_dir: Option<DVec3>,
    last_exit: f64,
    rng: u64,
}

impl SimGrbl {
    /// A machine with `m`'s travel, rates and receive buffer, just
    /// powered up (its welcome is waiting to be read).
    pub fn new(m: &Machine) -> SimGrbl {
        let mut s = SimGrbl {
            now: 0.0,
            rx: VecDeque::new(),
            rx_size: m.rx_buffer,
            overflow: 0,
            planner: VecDeque::new(),
            block_end: 0.0,
            held_left: None,
            alarm: None,
            check: false,
            out: Vec::new(),
            planned: DVec3::ZERO,
            done: DVec3::ZERO,
            absolute: true,
            inches: false,
            feed: None,
            motion: 0,
            spindle: 0.0,
            log: Vec::new(),
            errors: Vec::new(),
            gcode_lines: 0,
            bytes_in: 0,
            faults: Faults::default(),
            disconnected: false,
            travel: DVec3::new(m.travel.x, m.travel.y, m.travel.z),
            max_rate: DVec3::new(m.max_rate.x, m.max_rate.y, m.max_rate.z),
            accel: DVec3::new(m.acceleration.x, m.acceleration.y, m.acceleration.z),
            junction: m.junction_deviation,
            last_dir: None,
            last_exit: 0.0,
            rng: 0x9e3779b97f4a7c15,
        };
        s.say(&format!("\r\n{WELCOME}"));
        s
    }

    /// The spindle's speed now (0 = stopped).
    pub fn spindle_rpm(&self) -> f64 {
        self.spindle
    }

    /// Bytes the machine has sent since the last call.
    pub fn take_output(&mut self) -> Vec<u8> {
        std::mem::take(&mut self.out)
    }

    /// When the next block completes, if one is running.
    pub fn next_event(&self) -> Option<f64> {
        (self.held_left.is_none() && !self.planner.is_empty()).then_some(self.block_end)
    }

    /// Run the planner up to time `t`.
    pub fn advance(&mut self, t: f64) {
        while let Some(end) = self.next_event() {
            if end > t {
                break;
            }
            self.now = end;
            let b = self.planner.pop_front().unwrap();
            self.done = b.end;
            if let Some(next) = self.planner.front() {
                self.block_end = self.now + next.duration;
            }
            self.pump();
        }
        self.now = self.now.max(t);
    }

    /// One byte from the host at the current time.
    pub fn receive(&mut self, b: u8) {
        if self.disconnected {
            return;
        }
        self.bytes_in += 1;
        if self
            .faults
            .disconnect_after
            .is_some_and(|n| self.bytes_in > n)
        {
            self.disconnected = true;
            return;
        }
        match b {
            b'?' => {
                let r = self.status();
                self.say(&r);
            }
            b'!' => {
                if self.held_left.is_none() && !self.planner.is_empty() {
                    self.held_left = Some((self.block_end - self.now).max(0.0));
                }
            }
            b'~' => {
                if let Some(left) = self.held_left.take() {
                    self.block_end = self.now + left;
                }
            }
            SOFT_RESET => self.reset(),
            super::SPINDLE_STOP => {
                if self.held_left.is_some() {
                    self.spindle = 0.0;
                }
            }
            _ => {
                if self.rx.len() >= self.rx_size {
                    self.overflow += 1;
                } else {
                    self.rx.push_back(b);
                    self.pump();
                }
            }
        }
    }

    /// Soft reset: buffers and planner cleared; a reset in motion raises
    /// ALARM:3 as GRBL does.
    pub fn reset(&mut self) {
        let moving = !self.planner.is_empty();
        self.rx.clear();
        self.planner.clear();
        self.last_dir = None;
        self.held_left = None;
        self.check = false;
        self.planned = self.done;
        self.feed = None;
        self.motion = 0;
        self.absolute = true;
        self.inches = false;
        self.spindle = 0.0;
        if moving {
            self.alarm = Some(3);
            self.say("ALARM:3");
        }
        self.say(&format!("\r\n{WELCOME}"));
        if self.alarm.is_some() {
            self.say("[MSG:'$H'|'$X' to unlock]");
        }
    }

    /// A reconnection: the link is up again and the board has reset (DTR).
    pub fn reconnect(&mut self) {
        self.disconnected = false;
        self.faults.disconnect_after = None;
        self.reset();
    }

    fn status(&self) -> String {
        let state = if self.alarm.is_some() {
            "Alarm"
        } else if self.held_left.is_some() {
            "Hold:0"
        } else if self.check {
            "Check"
        } else if !self.planner.is_empty() {
            "Run"
        } else {
            "Idle"
        };
        let p = self.done;
        format!(
            "<{state}|MPos:{:.3},{:.3},{:.3}|Bf:{},{}|FS:{},{}>",
            p.x,
            p.y,
            p.z,
            PLANNER_BLOCKS - self.planner.len(),
            self.rx_size - self.rx.len(),
            self.feed.unwrap_or(0.0).round(),
            self.spindle.round()
        )
    }

    fn say(&mut self, line: &str) {
        let mut bytes = line.as_bytes().to_vec();
        if self.faults.garble > 0.0 && self.random() < self.faults.garble {
            let at = (self.random() * bytes.len() as f64) as usize;
            let noise = [0x80 | (self.random() * 127.0) as u8, 0xff, 0x00];
            bytes.splice(at..at, noise);
        }
        self.out.extend_from_slice(&bytes);
        self.out.extend_from_slice(b"\r\n");
    }

    fn random(&mut self) -> f64 {
        self.rng ^= self.rng << 13;
        self.rng ^= self.rng >> 7;
        self.rng ^= self.rng << 17;
        (self.rng >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Take complete lines from the receive buffer while the planner has
    /// room, as GRBL's main loop does.
    fn pump(&mut self) {
        while self.planner.len() < PLANNER_BLOCKS {
            let Some(end) = self.rx.iter().position(|&b| b == b'\n') else {
                return;
            };
            let raw: Vec<u8> = self.rx.drain(..=end).collect();
            let text = String::from_utf8_lossy(&raw).to_string();
            self.execute(text.trim_end_matches(['\n', '\r']));
        }
    }

    fn execute(&mut self, raw: &str) {
        let line = strip(raw);
        if line.len() > LINE_MAX - 1 {
            return self.error(11);
        }
        if line.is_empty() {
            return self.say("ok");
        }
        if let Some(cmd) = line.strip_prefix('$') {
            return self.system(cmd);
        }
        if self.alarm.is_some() {
            return self.error(9);
        }
        self.gcode_lines += 1;
        let n = self.gcode_lines;
        if self.faults.error_at.is_some_and(|(k, _)| k == n) {
            return self.error(self.faults.error_at.unwrap().1);
        }
        if let Some((k, code)) = self.faults.alarm_at {
            if k == n {
                self.raise(code);
                return self.say("ok");
            }
        }
        match self.interpret(&line) {
            Err(code) => self.error(code),
            Ok(None) => {
                if !self.check {
                    self.log.push(line);
                }
                self.say("ok")
            }
            Ok(Some(target)) => {
                let lim = self.travel;
                if (0..3).any(|k| target[k].abs() > lim[k] + 1e-9) {
                    self.raise(2);
                    return self.say("ok");
                }
                if !self.check {
                    self.queue(target);
                    self.log.push(line);
                }
                self.planned = target;
                self.say("ok")
            }
        }
    }

    fn error(&mut self, code: u32) {
        self.errors.push((self.gcode_lines, code));
        self.say(&format!("error:{code}"));
    }

    /// An alarm stops motion at once and locks G-code out until $X or $H.
    fn raise(&mut self, code: u32) {
        self.planner.clear();
        self.last_dir = None;
        self.held_left = None;
        self.planned = self.done;
        self.alarm = Some(code);
        self.say(&format!("ALARM:{code}"));
    }

    /// Queue a move. Its time follows GRBL's planner in a forward-only
    /// form: it enters at the junction speed its corner with the previous
    /// move allows (junction deviation, as GRBL computes it), never faster
    /// than the previous move got, and accelerates toward its rate.
    fn queue(&mut self, target: DVec3) {
        let d = target - self.planned;
        let dist = d.length();
        if dist <= 0.0 {
            return;
        }
        let u = d / dist;
        // the slowest axis' rate and acceleration along the move
        let along = |lim: DVec3| {
            (0..3)
                .filter(|&k| u[k] != 0.0)
                .map(|k| lim[k] / u[k].abs())
                .fold(f64::INFINITY, f64::min)
        };
        let top = along(self.max_rate) / 60.0;
        let v = if self.motion == 0 {
            top
        } else {
            (self.feed.unwrap_or(1.0) / 60.0).min(top)
        };
        let a = along(self.accel);
        let entry = match (self.planner.is_empty(), self.last_dir) {
            (false, Some(prev)) => {
                let cos = (-prev.dot(u)).clamp(-1.0, 1.0);
                let vj = if cos > 0.999999 {
                    0.0
                } else {
                    let s2 = (0.5 * (1.0 - cos)).sqrt();
                    if s2 > 0.999999 {
                        f64::INFINITY // straight on
                    } else {
                        (a * self.junction * s2 / (1.0 - s2)).sqrt()
                    }
                };
                vj.min(self.last_exit).min(v)
            }
            _ => 0.0,
        };
        let ramp = (v * v - entry * entry) / (2.0 * a);
        let (duration, exit) = if dist >= ramp {
            ((v - entry) / a + (dist - ramp) / v, v)
        } else {
            let ve = (entry * entry + 2.0 * a * dist).sqrt();
            ((ve - entry) / a, ve)
        };
        self.last_dir = Some(u);
        self.last_exit = exit;
        if self.planner.is_empty() {
            self.block_end = self.now + duration;
        }
        self.planner.push_back(Block {
            duration,
            end: target,
        });
    }

    /// Modal state and the target of a motion line; GRBL's error code for
    /// what it refuses.
    fn interpret(&mut self, line: &str) -> Result<Option<DVec3>, u32> {
        let l = match parse_line(line, 0) {
            Ok(l) => l,
            Err(e) if e.0.contains("unsupported") => return Err(20),
            Err(_) => return Err(2),
        };
        let scale = |inches: bool| if inches { 25.4 } else { 1.0 };
        let mut motion = None;
        for &(c, v) in &l.words {
            match (c, v as i32) {
                ('G', 0..=3) => motion = Some(v as u8),
                ('G', 20) => self.inches = true,
                ('G', 21) => self.inches = false,
                ('G', 90) => self.absolute = true,
                ('G', 91) => self.absolute = false,
                ('M', 3) | ('M', 4) => self.spindle = self.spindle.max(1.0),
                ('M', 5) => self.spindle = 0.0,
                ('F', _) => {
                    if v <= 0.0 {
                        return Err(4);
                    }
                    self.feed = Some(v * scale(self.inches));
                }
                ('S', _) => self.spindle = v,
                _ => {}
            }
        }
        if let Some(m) = motion {
            self.motion = m;
        }
        let axes = ['X', 'Y', 'Z'].map(|a| l.words.iter().rev().find(|w| w.0 == a).map(|w| w.1));
        if axes.iter().all(Option::is_none) {
            return Ok(None);
        }
        if self.motion >= 1 && self.feed.is_none() {
            return Err(22);
        }
        let mut t = self.planned;
        for (k, v) in axes.iter().enumerate() {
            if let Some(v) = v {
                let v = v * scale(self.inches);
                t[k] = if self.absolute { v } else { t[k] + v };
            }
        }
        Ok(Some(t))
    }

    fn system(&mut self, cmd: &str) {
        match cmd {
            "C" => {
                if self.check {
                    self.say("[MSG:Disabled]");
                    self.say("ok");
                    self.reset();
                } else {
                    self.check = true;
                    self.say("[MSG:Enabled]");
                    self.say("ok");
                }
            }
            "X" => {
                if self.alarm.take().is_some() {
                    self.say("[MSG:Caution: Unlocked]");
                }
                self.say("ok");
            }
            "H" => {
                if !self.planner.is_empty() {
                    return self.error(8);
                }
                self.alarm = None;
                self.done = DVec3::ZERO;
                self.planned = DVec3::ZERO;
                self.say("ok");
            }
            "$" => {
                let t = self.travel;
                let r = self.max_rate;
                for (k, v) in [
                    (110, r.x),
                    (111, r.y),
                    (112, r.z),
                    (130, t.x),
                    (131, t.y),
                    (132, t.z),
                ] {
                    self.say(&format!("${k}={v:.3}"));
                }
                self.say("ok");
            }
            "G" => {
                let s = format!(
                    "[GC:G{} G54 G17 {} {} G94 M{} M9 T0 F{} S{}]",
                    self.motion,
                    if self.inches { "G20" } else { "G21" },
                    if self.absolute { "G90" } else { "G91" },
                    if self.spindle > 0.0 { 3 } else { 5 },
                    self.feed.unwrap_or(0.0),
                    self.spindle
                );
                self.say(&s);
                self.say("ok");
            }
            "I" => {
                self.say("[VER:1.1h.20190830:relievo simulated machine]");
                self.say(&format!("[OPT:V,{PLANNER_BLOCKS},{}]", self.rx_size));
                self.say("ok");
            }
            _ => self.error(3),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn machine() -> SimGrbl {
        let mut s = SimGrbl::new(&Machine::load("shapeoko").unwrap());
        s.take_output();
        s
    }

    fn send(s: &mut SimGrbl, text: &str) -> String {
        for b in text.bytes() {
            s.receive(b);
        }
        String::from_utf8_lossy(&s.take_output()).to_string()
    }

    #[test]
    fn replies_and_codes() {
        let mut s = machine();
        assert_eq!(send(&mut s, "G21 G90\n"), "ok\r\n");
        assert_eq!(send(&mut s, "G1 X1\n"), "error:22\r\n");
        assert_eq!(send(&mut s, "G38.2 Z-1 F10\n"), "error:20\r\n");
        assert_eq!(send(&mut s, "$Q\n"), "error:3\r\n");
        assert_eq!(
            send(&mut s, &format!("G1X1{}\n", "0".repeat(90))),
            "error:11\r\n"
        );
        assert!(send(&mut s, "G1 X9999 F100\n").starts_with("ALARM:2\r\nok"));
        assert_eq!(send(&mut s, "G1 X1 F100\n"), "error:9\r\n");
        assert!(send(&mut s, "$X\n").ends_with("ok\r\n"));
        assert!(send(&mut s, "?").starts_with("<Idle|MPos:0.000,0.000,0.000|Bf:15,128"));
        assert_eq!(s.log, ["G21G90"]);
    }

    #[test]
    fn planner_runs_in_simulated_time_and_the_buffer_overflows_loudly() {
        let mut s = machine();
        // 10 mm at 600 mm/min from rest (400 mm/s^2): 1.0125 s; the
        // second move goes straight on at full speed: 1 s
        send(&mut s, "G1 X10 F600\nG1 X20\n");
        assert!(send(&mut s, "?").starts_with("<Run"));
        s.advance(1.0);
        assert!(send(&mut s, "?").contains("MPos:0.000"));
        s.advance(1.5);
        assert!(send(&mut s, "?").contains("MPos:10.000"));
        s.advance(2.01);
        assert!(send(&mut s, "?").starts_with("<Run"));
        s.advance(2.02);
        assert!(send(&mut s, "?").starts_with("<Idle|MPos:20.000"));
        // 16 queued moves fill the planner; the 16th waits in the buffer
        let mv: String = (1..=16).map(|k| format!("G1 X{k}\n")).collect();
        send(&mut s, &mv);
        assert!(send(&mut s, "?").contains("Bf:0,"));
        let flood = "G1 X1 Y1 Z-1\n".repeat(20);
        send(&mut s, &flood);
        assert!(s.overflow > 0);
    }
}
