//! A simulated GRBL 1.1 machine, driven by bytes and simulated time: the
//! 128-byte receive buffer (overflow is counted as a failure, never
//! hidden), a 15-block planner executing moves at their feed, `ok` /
//! `error:N` replies, status reports, realtime commands, `$` commands,
//! check mode, alarms, and injectable faults. It has no clock of its own:
//! the port that carries its bytes says what time it is.

use super::state::State;
use super::{JOG_CANCEL, SOFT_RESET, WELCOME};
use crate::gcode::modal::{c_int, Modal, Step};
use crate::gcode::parse::{parse_line, LineFilter};
use crate::gcode::planner;
use crate::machine::Machine;
use glam::DVec3;
use std::collections::VecDeque;

mod hold;
mod probe;
mod report;
mod settings;
mod system;
pub use probe::Plate;
use probe::Probing;

/// Planner blocks GRBL 1.1 holds on an Uno.
pub const PLANNER_BLOCKS: usize = 15;

/// Faults to inject. Lines count the G-code lines the machine received
/// (not `$` commands or blank lines), from 1.
#[derive(Clone, Debug, Default)]
pub struct Faults {
    /// Reply `error:CODE` to line N instead of executing it.
    pub error_at: Option<(usize, u32)>,
    /// Raise `ALARM:CODE` at line N (before its `ok`), stopping motion.
    pub alarm_at: Option<(usize, u32)>,
    /// Cut the link after this many bytes received, as a pulled cable
    /// does: later bytes and every reply from then on are lost, while the
    /// machine goes on executing what it had received.
    pub disconnect_after: Option<usize>,
    /// At line N the machine goes into a feed hold that cycle start does
    /// not release (a hold button stuck, a door left open), until a reset.
    pub hold_at: Option<usize>,
    /// At line N the machine freezes: it still answers status polls (as
    /// Run) but neither moves nor takes another line, until a reset.
    pub freeze_at: Option<usize>,
    /// After its welcome the machine answers nothing and only prints
    /// `[MSG:...]` lines, ten a second (a confused or foreign firmware).
    pub chatty: bool,
    /// Probability that a reply line gets noise bytes (non-ASCII, as a
    /// noisy USB-serial adapter produces) spliced into it.
    pub garble: f64,
    /// After line N, the first status report taken while moves run says
    /// Idle, as GRBL's does when the report and the cycle start are due
    /// in the same pass of its realtime loop (the report prints first).
    pub stale_idle_after: Option<usize>,
}

/// The speed a queued move asks for, mm/min.
#[derive(Clone, Copy, Debug)]
enum Feed {
    /// The modal F (a rapid: the axes' rates).
    Modal,
    /// Its line's own: G93's F in 1/min made a speed.
    Line(f64),
    /// A `$J=` jog's (no override acts on it).
    Jog(f64),
}

/// A completed move as the tool's tip went: machine coordinates less the
/// length of the tool in the spindle (the `tool`-th, from 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TipMove {
    pub from: DVec3,
    pub to: DVec3,
    pub rapid: bool,
    pub tool: usize,
}

/// How a block moves: its length, its programmed and top speeds (mm/s),
/// acceleration (mm/s^2) and entry speed; the overrides scale it when it
/// runs.
#[derive(Clone, Debug)]
struct Block {
    dist: f64,
    v: f64,
    top: f64,
    a: f64,
    /// The highest entry its corner with the move before allows (0 after
    /// a stop), then, once planned, its entry and exit speeds.
    max_entry: f64,
    entry: f64,
    exit: f64,
    /// A `$J=` jog (no feed override acts on it).
    jog: bool,
    /// The braking of a feed hold: its own speeds, no override.
    brake: bool,
    start: DVec3,
    rapid: bool,
    end: DVec3,
    /// Its line, and the lines without motion that GRBL took after it:
    /// they count as executed when the move completes.
    lines: Vec<String>,
}

pub struct SimGrbl {
    now: f64,
    rx: VecDeque<u8>,
    rx_size: usize,
    /// The line GRBL's main loop is reading from the receive buffer.
    reader: LineFilter,
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
    /// Modal state after the lines taken (position: after the planned
    /// moves), and the position after the completed moves.
    modal: Modal,
    done: DVec3,
    spindle: f64,
    /// A line that waits for the planner to empty (GRBL synchronises
    /// before a dwell, spindle or program stop), then runs.
    waiting: Option<String>,
    /// The end of a dwell, and its line, answered then.
    dwell: Option<(f64, String)>,
    /// A feed hold that cycle start does not release (fault).
    stuck: bool,
    /// Frozen by the `freeze_at` fault: no motion, no new line.
    frozen: bool,
    /// Held by an M0 until cycle start: its line, answered then (GRBL's
    /// main loop waits in the hold, taking no further line).
    paused: Option<String>,
    next_chatter: f64,
    /// Every G-code line executed, in order, as GRBL's line buffer held
    /// it: a move when it completes, a line without motion when GRBL has
    /// acted on it. Moves lost in the planner at a reset or an alarm never
    /// appear.
    pub log: Vec<String>,
    /// Lines refused with an error, as (line count, code).
    pub errors: Vec<(usize, u32)>,
    gcode_lines: usize,
    bytes_in: usize,
    pub faults: Faults,
    pub disconnected: bool,
    /// Direction of the last queued move.
    last_dir: Option<DVec3>,
    /// When the head block started, and the speed the last completed
    /// block left at (the next one's entry; 0 after a stop).
    head_start: f64,
    exit_speed: f64,
    rng: u64,
    /// The machine file it was made from ($RST= goes back to it), its
    /// `$` settings, `$I=` text and `$N0=`/`$N1=` startup lines.
    machine: Machine,
    settings: settings::Settings,
    build_info: Vec<u8>,
    startup: [String; 2],
    /// `$SLP`: asleep until a reset.
    asleep: bool,
    /// Decelerating into a feed hold (Hold:1).
    braking: bool,
    /// The touch plate, if one lies on the work.
    pub plate: Option<Plate>,
    /// Length of each tool in turn (mm; the tip is this far below where a
    /// tool of length 0 would be): the next one goes in at each M0.
    pub tool_lengths: Vec<f64>,
    tool: usize,
    probing: Option<Probing>,
    /// The last probe's trigger point (machine) and whether it touched.
    probed: (DVec3, bool),
    /// Every completed move as the tool's tip went.
    pub tips: Vec<TipMove>,
    /// When status reports give the work offset and the overrides.
    counters: report::Counters,
    /// Feed, rapid and spindle overrides, percent.
    ov: (u32, u32, u32),
    /// The spindle's pins: its direction (3 or 4) when on; the flood
    /// coolant's.
    spindle_dir: Option<u8>,
    flood: bool,
    /// The spindle stopped by its override in a hold (0x9E).
    spindle_stopped: bool,
    /// A safety door (0x84) holds the machine rather than a feed hold;
    /// cycle start restores the spindle first, until this time (Door:3).
    door: bool,
    restore_at: Option<f64>,
    /// The braking of a jog cancel: the jog's blocks go at its end.
    jog_cancel: bool,
    /// A dwell a hold stopped: its time left and its line.
    dwell_held: Option<(f64, String)>,
    /// An arc's chords not yet planned, where the next starts, its line
    /// and its feed.
    arc_left: Option<(VecDeque<DVec3>, DVec3, String, Feed)>,
}

impl SimGrbl {
    /// A machine with `m`'s travel, rates and receive buffer, just
    /// powered up (its welcome is waiting to be read).
    pub fn new(m: &Machine) -> SimGrbl {
        let mut s = SimGrbl {
            now: 0.0,
            rx: VecDeque::new(),
            rx_size: m.rx_buffer,
            reader: LineFilter::default(),
            overflow: 0,
            planner: VecDeque::new(),
            block_end: 0.0,
            held_left: None,
            alarm: None,
            check: false,
            out: Vec::new(),
            modal: Modal::new(DVec3::ZERO),
            done: DVec3::ZERO,
            spindle: 0.0,
            waiting: None,
            dwell: None,
            stuck: false,
            frozen: false,
            paused: None,
            next_chatter: 0.0,
            log: Vec::new(),
            errors: Vec::new(),
            gcode_lines: 0,
            bytes_in: 0,
            faults: Faults::default(),
            disconnected: false,
            last_dir: None,
            head_start: 0.0,
            exit_speed: 0.0,
            rng: 0x9e3779b97f4a7c15,
            machine: m.clone(),
            settings: settings::Settings::of(m),
            build_info: Vec::new(),
            startup: Default::default(),
            asleep: false,
            braking: false,
            plate: None,
            tool_lengths: Vec::new(),
            tool: 0,
            probing: None,
            probed: (DVec3::ZERO, false),
            tips: Vec::new(),
            counters: Default::default(),
            ov: (100, 100, 100),
            spindle_dir: None,
            flood: false,
            spindle_stopped: false,
            door: false,
            restore_at: None,
            jog_cancel: false,
            dwell_held: None,
            arc_left: None,
        };
        s.say(&format!("\r\n{WELCOME}"));
        s
    }

    /// The operator fitted the next tool (a change the machine does not
    /// see, as at a tool change the page steers).
    pub fn fit_next_tool(&mut self) {
        if self.tool + 1 < self.tool_lengths.len() {
            self.tool += 1;
        }
    }

    /// The spindle's speed now (0 = stopped).
    pub fn spindle_rpm(&self) -> f64 {
        self.spindle
    }

    /// Bytes the machine has sent since the last call.
    pub fn take_output(&mut self) -> Vec<u8> {
        std::mem::take(&mut self.out)
    }

    /// When the running block completes, if one runs.
    fn block_due(&self) -> Option<f64> {
        (self.held_left.is_none()
            && self.paused.is_none()
            && !self.frozen
            && !self.planner.is_empty())
        .then_some(self.block_end)
    }

    /// Whether a move is planned or running.
    pub fn moving(&self) -> bool {
        !self.planner.is_empty()
    }

    /// When something happens next: a block completes, a dwell ends, or
    /// a chatty machine talks.
    pub fn next_event(&self) -> Option<f64> {
        [
            self.block_due(),
            self.dwell.as_ref().map(|d| d.0),
            self.probing.as_ref().map(|p| p.end),
            self.restore_at,
            self.faults.chatty.then_some(self.next_chatter),
        ]
        .into_iter()
        .flatten()
        .reduce(f64::min)
    }

    /// Run the machine up to time `t`.
    pub fn advance(&mut self, t: f64) {
        while let Some(at) = self.next_event() {
            if at > t {
                break;
            }
            self.now = at;
            if self.block_due().is_some_and(|e| e <= at) {
                let b = self.planner.pop_front().unwrap();
                self.record_tip(b.start, b.end, b.rapid);
                self.done = b.end;
                self.log.extend(b.lines);
                self.exit_speed = b.exit;
                if b.brake {
                    self.end_brake();
                } else if !self.planner.is_empty() {
                    self.start_head();
                }
            }
            if self.dwell.as_ref().is_some_and(|d| d.0 <= at) {
                let (_, line) = self.dwell.take().unwrap();
                self.log.push(line);
                self.say("ok");
            }
            if self.probing.as_ref().is_some_and(|p| p.end <= at) {
                self.end_probe();
            }
            if self.restore_at.is_some_and(|r| r <= at) {
                self.restore_at = None;
                self.door = false;
                self.resume();
            }
            if self.faults.chatty && self.next_chatter <= at {
                self.next_chatter = at + 0.1;
                self.say("[MSG:Pgm End]");
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
        if self.faults.chatty {
            return;
        }
        match b {
            b'?' => {
                let r = self.status();
                self.say(&r);
            }
            b'!' => self.feed_hold(),
            b'~' if !self.stuck => self.cycle_start(),
            SOFT_RESET => self.reset(),
            JOG_CANCEL => self.cancel_jog(),
            super::SAFETY_DOOR => self.open_door(),
            0x90..=0x9d => self.override_by(b),
            super::SPINDLE_STOP => self.spindle_stop(),
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

    /// `b`'s top speed at the overrides now (a jog keeps its own).
    fn top_speed(&self, b: &Block) -> f64 {
        let (f, r, _) = self.ov;
        if b.jog || b.brake {
            b.v
        } else if b.rapid {
            b.top * r as f64 / 100.0
        } else {
            (b.v * f as f64 / 100.0).min(b.top)
        }
    }

    /// How long `b` takes at the overrides now, as planned.
    fn run_time(&self, b: &Block) -> f64 {
        let v = self.top_speed(b);
        planner::run_time(b.dist, b.entry, v, b.exit.min(v), b.a)
    }

    /// Plan the blocks queued with GRBL's look-ahead, the head entered at
    /// the speed the machine has, and time the head from when it started.
    fn plan_head(&mut self) {
        let mut moves: Vec<planner::Move> = self
            .planner
            .iter()
            .map(|b| planner::Move {
                len: b.dist,
                top: self.top_speed(b),
                accel: b.a,
                entry: b.max_entry,
            })
            .collect();
        // no faster into a move than the move before may go
        for k in 1..moves.len() {
            moves[k].entry = moves[k].entry.min(moves[k - 1].top);
        }
        planner::plan(&mut moves, self.exit_speed);
        let exit = planner::exit(&moves, 0);
        let head = self.planner.front_mut().unwrap();
        head.entry = moves[0].entry;
        head.exit = exit;
        let t = self.run_time(self.planner.front().unwrap());
        self.block_end = self.head_start + t;
    }

    /// The head block ends at `end` (resumed from a hold):
    /// it started a run time before.
    fn set_block_end(&mut self, end: f64) {
        self.block_end = end;
        if let Some(b) = self.planner.front() {
            self.head_start = end - self.run_time(b);
        }
    }

    /// The head block starts now.
    fn start_head(&mut self) {
        self.head_start = self.now;
        self.plan_head();
    }

    /// A realtime override byte (0x90-0x9D) as GRBL 1.1 takes it: the
    /// queued blocks are planned again at the new speeds, the running one
    /// from where the machine is at the speed it has (speeding up or
    /// slowing down at its acceleration).
    fn override_by(&mut self, b: u8) {
        let was = self.ov;
        let (f, r, s) = &mut self.ov;
        let step = |v: &mut u32, by: i32| *v = (*v as i32 + by).clamp(10, 200) as u32;
        match b {
            0x90 => *f = 100,
            0x91 => step(f, 10),
            0x92 => step(f, -10),
            0x93 => step(f, 1),
            0x94 => step(f, -1),
            0x95 => *r = 100,
            0x96 => *r = 50,
            0x97 => *r = 25,
            0x99 => *s = 100,
            0x9a => step(s, 10),
            0x9b => step(s, -10),
            0x9c => step(s, 1),
            0x9d => step(s, -1),
            _ => {}
        }
        if self.ov != was {
            self.counters.ovr_changed();
        }
        if self.spindle_dir.is_some() && self.ov.2 != was.2 {
            self.spindle = self
                .settings
                .spindle_rpm(self.modal.speed * self.ov.2 as f64 / 100.0);
        }
        if (self.ov.0, self.ov.1) == (was.0, was.1) || self.braking || self.planner.is_empty() {
            return;
        }
        if self.held_left.is_some() {
            // standing: what is left is planned from rest at the new speeds
            self.exit_speed = 0.0;
            self.start_head();
            self.held_left = Some(self.block_end - self.now);
        } else if let Some((s, v)) = self.head_progress() {
            self.split_head(s);
            self.exit_speed = v;
            self.start_head();
        }
    }

    /// The running head block from `s` mm along it on: the part behind
    /// counts as done, the rest is entered at the speed the machine has.
    fn split_head(&mut self, s: f64) {
        let b = self.planner.front_mut().unwrap();
        if s <= 0.0 || s >= b.dist {
            return;
        }
        let (from, rapid) = (b.start, b.rapid);
        let here = b.start + (b.end - b.start) * (s / b.dist);
        (b.start, b.dist) = (here, b.dist - s);
        b.max_entry = f64::INFINITY;
        self.record_tip(from, here, rapid);
        self.done = here;
    }

    /// Jog cancel (0x85, or a hold while jogging): the jog brakes to a
    /// stop as a hold does, and the jog blocks behind it are dropped.
    fn cancel_jog(&mut self) {
        if self.planner.front().is_some_and(|b| b.jog) && !self.braking {
            self.jog_cancel = true;
            self.hold();
        }
    }

    /// `$J=...` (the words after it): a jog, the machine idle or jogging;
    /// with soft limits on, refused if it would leave the travel.
    fn jog(&mut self, words: &str) -> Result<(), u32> {
        let step = self.modal.jog(&parse_line(words, 0)).map_err(|r| r.code)?;
        if let Some(to) = step.to {
            if self.settings.soft_limits() && self.settings.beyond_travel(to.into()) {
                self.modal.pos = step.from;
                return Err(15);
            }
            self.queue_as(step.from, to, String::new(), Feed::Jog(step.jog_feed));
        }
        Ok(())
    }

    /// The state GRBL would report now.
    /// (A dwell is Idle, as in GRBL: it waits in its main loop.)
    fn state(&self) -> State {
        if self.asleep {
            State::Sleep
        } else if self.alarm.is_some() {
            State::Alarm
        } else if self.door {
            State::Door(if self.restore_at.is_some() {
                3
            } else if self.braking {
                2
            } else {
                0
            })
        } else if self.jog_cancel {
            State::Jog
        } else if self.braking {
            State::Hold(1)
        } else if self.held_left.is_some() || self.stuck || self.paused.is_some() {
            State::Hold(0)
        } else if self.check {
            State::Check
        } else if self.planner.front().is_some_and(|b| b.jog) {
            State::Jog
        } else if !self.planner.is_empty() || self.probing.is_some() {
            State::Run
        } else {
            State::Idle
        }
    }

    /// `$SLP`: spindle and coolant off, asleep until a reset.
    fn sleep(&mut self) {
        self.planner.clear();
        self.set_spindle(false);
        self.set_coolant(false);
        self.asleep = true;
        self.say("ok");
        self.say("[MSG:Sleeping]");
    }

    /// Soft reset, as GRBL's mc_reset and main loop: the steppers stop
    /// where they are (ALARM:3 if they were moving: in a cycle, a jog, or
    /// braking into a hold), buffers, planner, overrides and report
    /// counters start afresh; an alarm or sleep comes back as an alarm.
    pub fn reset(&mut self) {
        let state = self.state();
        let abort = matches!(state, State::Run | State::Jog | State::Home) || self.braking;
        self.stop_here();
        self.rx.clear();
        self.reader = LineFilter::default();
        self.stuck = false;
        self.frozen = false;
        self.paused = None;
        self.waiting = None;
        self.arc_left = None;
        self.dwell = None;
        self.dwell_held = None;
        self.check = false;
        self.braking = false;
        self.jog_cancel = false;
        self.door = false;
        self.restore_at = None;
        self.spindle_stopped = false;
        self.modal = self.modal.after_reset(self.done);
        self.set_spindle(false);
        self.set_coolant(false);
        self.ov = (100, 100, 100);
        self.counters = Default::default();
        self.probed = (DVec3::ZERO, false);
        if self.asleep {
            self.alarm = Some(0);
        }
        self.asleep = false;
        if abort {
            self.alarm = Some(3);
            self.say("ALARM:3");
        }
        self.say(&format!("\r\n{WELCOME}"));
        if self.alarm.is_some() {
            self.say("[MSG:'$H'|'$X' to unlock]");
        } else {
            self.run_startup();
        }
    }

    /// Motion stops where the machine is, mid-block too: the planner
    /// empties and the part of its head block run counts as done.
    fn stop_here(&mut self) {
        let here = self.position();
        if let Some(&Block { start, rapid, .. }) = self.planner.front() {
            if here != start {
                self.record_tip(start, here, rapid);
            }
        }
        self.planner.clear();
        self.last_dir = None;
        self.held_left = None;
        self.probing = None;
        self.done = here;
        self.modal.pos = here;
    }

    /// A reconnection: the link is up again and the board has reset (DTR).
    pub fn reconnect(&mut self) {
        self.disconnected = false;
        self.faults.disconnect_after = None;
        self.reset();
    }

    fn say(&mut self, line: &str) {
        self.say_bytes(line.as_bytes())
    }

    /// A line of bytes as GRBL sends them (a `$I=` text is not UTF-8).
    fn say_bytes(&mut self, line: &[u8]) {
        if self.disconnected {
            return; // the wire is gone
        }
        let mut bytes = line.to_vec();
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
    /// room and nothing holds the main loop (a dwell, a line waiting for
    /// the planner to empty), as GRBL's main loop does.
    fn pump(&mut self) {
        loop {
            // GRBL's main loop takes no line while it waits out a dwell,
            // a probe or a pause, while it sleeps, and while a hold or a
            // door holds it (once the machine stands)
            if self.dwell.is_some()
                || self.probing.is_some()
                || self.paused.is_some()
                || self.frozen
                || self.asleep
                || self.held_left.is_some()
                || (self.door && !self.braking)
            {
                return;
            }
            if self.arc_left.is_some() {
                self.feed_arc();
                if self.arc_left.is_some() {
                    return;
                }
            }
            if let Some(line) = self.waiting.take() {
                if !self.planner.is_empty() {
                    self.waiting = Some(line);
                    return;
                }
                self.run(line);
                continue;
            }
            if self.planner.len() >= PLANNER_BLOCKS {
                return;
            }
            // GRBL's main loop reads the bytes as they come, a line at a
            // time: a long line need not fit the receive buffer
            let line = loop {
                let Some(b) = self.rx.pop_front() else {
                    return;
                };
                if let Some(line) = self.reader.push(b) {
                    break line;
                }
            };
            match line {
                Ok(line) => self.execute(line),
                Err(code) => self.error(code),
            }
        }
    }

    fn execute(&mut self, line: String) {
        if line.is_empty() {
            return self.say("ok");
        }
        if line.starts_with('$') {
            return self.system(&line);
        }
        if self.alarm.is_some() || self.state() == State::Jog {
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
        if !self.planner.is_empty() && self.syncs(&line) {
            self.waiting = Some(line);
        } else {
            self.run(line);
        }
        if self.faults.freeze_at == Some(n) {
            self.frozen = true;
        }
        if self.faults.hold_at == Some(n) {
            self.stuck = true;
            self.hold();
        }
    }

    /// Whether GRBL empties its planner before acting on `line`.
    fn syncs(&self, line: &str) -> bool {
        self.modal
            .clone()
            .apply(&parse_line(line, 0))
            .is_ok_and(|s| s.sync)
    }

    /// Act on a G-code line and answer it (a dwell answers when it ends).
    fn run(&mut self, line: String) {
        let m = &self.modal;
        let before = (m.spindle, m.speed, m.coolant, m.wco());
        let step = match self.interpret(&line) {
            Err(code) => return self.error(code),
            Ok(s) => s,
        };
        let m = &self.modal;
        if m.wco() != before.3 || line.contains("G10") || line.contains("G92") {
            self.counters.wco_changed();
        }
        let spindle = m.spindle != before.0 || (m.speed != before.1 && m.spindle.is_some());
        let coolant = m.coolant != before.2;
        if !self.check && spindle {
            self.set_spindle(true);
        }
        if !self.check && coolant {
            self.set_coolant(true);
        }
        if step.end {
            self.say("[MSG:Pgm End]");
        }
        if step.pause && !self.check {
            // the moves before it are done (it synchronised): hold here,
            // answering once cycle start releases it
            self.paused = Some(line);
            return;
        }
        if let (Some(probe), Some(to)) = (step.probe, step.to) {
            if !self.check {
                return self.start_probe(step.from, to, probe, line);
            }
        }
        if let Some(p) = step.dwell.filter(|_| !self.check) {
            self.dwell = Some((self.now + p, line));
            return;
        }
        match step.to {
            Some(to) => {
                if self.settings.soft_limits() && self.settings.beyond_travel(to.into()) {
                    self.raise(2);
                    return self.say("ok");
                }
                if !self.check {
                    match step.arc {
                        // GRBL plans an arc as its chords, each as the
                        // planner has room; the line is answered once the
                        // last is in (its main loop takes no line meanwhile)
                        Some(a) => {
                            let pts = a.points(step.from, to, self.settings.arc_tolerance());
                            // G93: mc_arc multiplies F by the chords and
                            // plans them at that many mm/min
                            let feed = self.inverse_time_feed(pts.len() as f64);
                            self.arc_left = Some((pts.into(), step.from, line, feed));
                            return self.feed_arc();
                        }
                        None => {
                            let feed = self.inverse_time_feed((to - step.from).length());
                            // G28/G30 by their point on the way
                            let from = match step.via {
                                Some(v) => {
                                    self.queue(step.from, v, String::new());
                                    v
                                }
                                None => step.from,
                            };
                            self.queue_as(from, to, line, feed)
                        }
                    }
                }
            }
            None if !self.check => self.note(line),
            None => {}
        }
        self.say("ok")
    }

    /// A line without motion is executed once the moves before it are.
    fn note(&mut self, line: String) {
        if line.is_empty() {
            return; // an arc's inner chord: its line goes with the last
        }
        match self.planner.back_mut() {
            Some(b) => b.lines.push(line),
            None => self.log.push(line),
        }
    }

    fn error(&mut self, code: u32) {
        self.errors.push((self.gcode_lines, code));
        self.say(&format!("error:{code}"));
    }

    /// An alarm stops motion and the spindle at once and locks G-code out
    /// until $X or $H.
    fn raise(&mut self, code: u32) {
        self.stop_here();
        self.waiting = None;
        self.arc_left = None;
        self.dwell = None;
        // GRBL aborts into its reset on an alarm: spindle and coolant off
        self.set_spindle(false);
        self.set_coolant(false);
        self.alarm = Some(code);
        self.say(&format!("ALARM:{code}"));
    }

    /// Queue a move. Its time follows GRBL's planner in a forward-only
    /// form: it enters at the junction speed its corner with the previous
    /// move allows (junction deviation, as GRBL computes it), never faster
    /// than the previous move got, and accelerates toward its rate.
    fn queue(&mut self, from: DVec3, target: DVec3, line: String) {
        self.queue_as(from, target, line, Feed::Modal)
    }

    /// Queue a move at `feed`.
    fn queue_as(&mut self, from: DVec3, target: DVec3, line: String, feed: Feed) {
        let d = target - from;
        let dist = d.length();
        // GRBL plans in whole steps and drops a block of none
        let steps = self.settings.steps_mm();
        if (from * steps).round() == (target * steps).round() {
            return self.note(line);
        }
        let u = d / dist;
        // the slowest axis' rate and acceleration along the move
        let along = |lim: DVec3| planner::along(u, lim);
        let top = along(self.settings.rates()) / 60.0;
        let jog = matches!(feed, Feed::Jog(_));
        let rapid = self.modal.motion == 0 && !jog;
        let v = match feed {
            Feed::Jog(f) | Feed::Line(f) => (f / 60.0).min(top),
            Feed::Modal if rapid => top,
            Feed::Modal => (self.modal.feed.unwrap_or(1.0) / 60.0).min(top),
        };
        let a = along(self.settings.accels());
        // a move queued behind others may enter as fast as its corner
        // allows; one queued on an idle machine starts from rest
        let max_entry = match (self.planner.back(), self.last_dir) {
            (Some(prev), Some(dir)) => {
                planner::junction_speed(dir, u, a.min(prev.a), self.settings.junction())
            }
            _ => 0.0,
        };
        self.last_dir = Some(u);
        let block = Block {
            dist,
            v,
            top,
            a,
            max_entry,
            entry: 0.0,
            exit: 0.0,
            jog,
            brake: false,
            start: from,
            rapid,
            end: target,
            lines: if line.is_empty() { vec![] } else { vec![line] },
        };
        let idle = self.planner.is_empty();
        self.planner.push_back(block);
        if idle {
            self.exit_speed = 0.0;
            self.start_head();
        } else if self.held_left.is_none() && !self.braking {
            // GRBL replans as moves arrive: the head may now leave faster
            self.plan_head();
        }
    }

    /// The feed of a line: in G93, F (1/min) times `per`, its length
    /// (a line in 1/F minutes) or an arc's chords (as GRBL's mc_arc).
    fn inverse_time_feed(&self, per: f64) -> Feed {
        if self.modal.inverse_time {
            Feed::Line(self.modal.feed.unwrap_or(0.0) * per)
        } else {
            Feed::Modal
        }
    }

    /// Queue an arc's chords while the planner has room; its line is
    /// answered with the last.
    fn feed_arc(&mut self) {
        while let Some((mut pts, from, line, feed)) = self.arc_left.take() {
            if self.planner.len() >= PLANNER_BLOCKS {
                self.arc_left = Some((pts, from, line, feed));
                return;
            }
            let Some(q) = pts.pop_front() else {
                return self.say("ok");
            };
            if pts.is_empty() {
                self.queue_as(from, q, line, feed);
                self.say("ok");
                return;
            }
            self.queue_as(from, q, String::new(), feed);
            self.arc_left = Some((pts, q, line, feed));
        }
    }

    /// Fold a line into the modal state; GRBL's error code for what it
    /// refuses.
    fn interpret(&mut self, line: &str) -> Result<Step, u32> {
        self.modal.apply(&parse_line(line, 0)).map_err(|r| r.code)
    }
}

/// x,y,z as GRBL reports them.
fn triple(p: DVec3) -> String {
    format!("{:.3},{:.3},{:.3}", p.x, p.y, p.z)
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
        assert_eq!(send(&mut s, "G38.1 Z-1 F10\n"), "error:20\r\n");
        assert_eq!(send(&mut s, "$Q\n"), "error:2\r\n");
        assert_eq!(send(&mut s, "$QX\n"), "error:2\r\n");
        assert_eq!(send(&mut s, "$SLX\n"), "error:3\r\n");
        assert_eq!(
            send(&mut s, &format!("G1X1{}\n", "0".repeat(90))),
            "error:11\r\n"
        );
        // beyond the travel is an alarm with soft limits on ($20, which
        // needs homing on, $22); GRBL's machine space runs from 0 down
        assert_eq!(send(&mut s, "$20=1\n"), "error:10\r\n");
        assert_eq!(send(&mut s, "$22=1\n$20=1\n"), "ok\r\nok\r\n");
        assert!(send(&mut s, "G1 X9999 F100\n").starts_with("ALARM:2\r\nok"));
        assert_eq!(send(&mut s, "G1 X1 F100\n"), "error:9\r\n");
        assert!(send(&mut s, "$X\n").ends_with("ok\r\n"));
        // GRBL's default $10=1: machine position, no buffer state; the
        // first report after the welcome carries the work offset
        assert_eq!(
            send(&mut s, "?"),
            "<Idle|MPos:0.000,0.000,0.000|FS:0,0|WCO:0.000,0.000,0.000>\r\n"
        );
        assert_eq!(
            send(&mut s, "?"),
            "<Idle|MPos:0.000,0.000,0.000|FS:0,0|Ov:100,100,100>\r\n"
        );
        assert_eq!(s.log, ["G21G90"]);
    }

    /// A touch plate 20 mm thick at (10, 10), tools 0 and 7.3 mm long:
    /// G38.2 stops where the tip meets the plate's top (a little past it,
    /// decelerating) and reports the trigger point; the G10 L20 that
    /// follows sets work Z there; the second tool (after M0) touches 7.3
    /// mm higher; a probe that meets nothing is ALARM:5.
    #[test]
    fn probing_a_touch_plate() {
        let mut s = machine();
        s.plate = Some(Plate::parse("20@10,10").unwrap());
        s.tool_lengths = vec![0.0, 7.3];
        let run = |s: &mut SimGrbl, text: &str, wait: f64| {
            let mut out = send(s, text);
            let mut t = s.now;
            let until = t + wait;
            while t < until && !out.contains("ok") && !out.contains("ALARM") {
                t += 0.01;
                s.advance(t);
                out.push_str(&String::from_utf8_lossy(&s.take_output()));
            }
            out
        };
        run(&mut s, "G0 X10 Y10 Z30\n", 60.0);
        let out = run(&mut s, "G38.2 Z0 F100\n", 60.0);
        assert!(
            out.starts_with("[PRB:10.000,10.000,20.000:1]\r\nok"),
            "{out}"
        );
        // stopped past the trigger by (100/60)^2 / (2 a): the overshoot
        let over = 20.0 - s.done.z;
        assert!(over > 0.0 && over < 0.1, "overshoot {over}");
        run(&mut s, "G10 L20 P0 Z20\n", 1.0);
        assert!((s.modal.wco().z - (20.0 - over - 20.0)).abs() < 1e-9);
        let st = send(&mut s, "?");
        assert!(st.contains("|WCO:0.000,0.000,"), "{st}");
        assert!(send(&mut s, "$#\n").contains("[PRB:10.000,10.000,20.000:1]"));
        // the next tool, 7.3 mm longer, touches 7.3 mm higher
        run(&mut s, "G0 Z40\n", 60.0);
        // M0 holds, answering only once cycle start releases it
        assert_eq!(run(&mut s, "M0\n", 5.0), "");
        assert!(send(&mut s, "?").starts_with("<Hold"));
        s.receive(b'~');
        assert_eq!(String::from_utf8_lossy(&s.take_output()), "ok\r\n");
        let out = run(&mut s, "G38.2 Z0 F100\n", 60.0);
        assert!(out.contains("[PRB:10.000,10.000,27.300:1]"), "{out}");
        // moves go on after a probe and a work offset set by G10 L2
        run(&mut s, "G91G0Z1\n", 60.0);
        run(&mut s, "G91G38.2Z-2F10\n", 60.0);
        run(&mut s, "G10L2P0Z7.3\n", 60.0);
        run(&mut s, "G90G0Z25\n", 60.0);
        let t = s.now + 10.0;
        s.advance(t);
        let st = send(&mut s, "?");
        assert!(st.starts_with("<Idle|MPos:10.000,10.000,32.300"), "{st}");
        // nothing under the tool: ALARM:5
        run(&mut s, "G0 Z40\n", 60.0);
        run(&mut s, "G0 X100 Y100\n", 60.0);
        let out = run(&mut s, "G38.2 Z0 F500\n", 60.0);
        assert!(out.contains("ALARM:5"), "{out}");
    }

    /// Run `text` on a fresh machine to the end; simulated seconds taken.
    fn run_time_of(text: &str, before: &[u8]) -> f64 {
        let mut s = machine();
        for &b in before {
            s.receive(b);
        }
        let mut t = 0.0;
        for l in text.lines() {
            send(&mut s, &format!("{l}\n"));
            // keep the planner fed as a sender does
            while s.planner.len() >= PLANNER_BLOCKS {
                t += 0.01;
                s.advance(t);
            }
        }
        while !s.planner.is_empty() {
            t += 0.01;
            s.advance(t);
        }
        s.now
    }

    /// Issue 10 acceptance 4: feed override at 50% (five 0x92) doubles a
    /// feed-bound job's time within 5%; rapids follow the rapid override.
    #[test]
    fn feed_override_scales_the_run_time() {
        let mut job = String::from("G1 F300\n");
        for k in 0..40 {
            job.push_str(&format!("G1 X{} Y{}\n", 20 * (k % 2), k));
        }
        let full = run_time_of(&job, &[]);
        let half = run_time_of(&job, &[0x92; 5]);
        let ratio = half / full;
        eprintln!("feed-bound job: {full:.3} s at 100%, {half:.3} s at 50% ({ratio:.4}x)");
        assert!(
            (ratio - 2.0).abs() <= 0.1,
            "{full:.2} s, at 50% {half:.2} s"
        );
        // 0x93/0x94 step by 1%, the range is 10-200%
        let mut s = machine();
        for _ in 0..30 {
            s.receive(0x91);
        }
        s.receive(0x94);
        // the first report gives the work offset, the next the overrides
        assert!(send(&mut s, "??").contains("|Ov:199,100,100"));
        let rapid = "G0 X100 Y100\nG0 X0 Y0\n";
        let r100 = run_time_of(rapid, &[]);
        let r25 = run_time_of(rapid, &[0x97]);
        // (speeding up and slowing down do not scale: 4x the cruise only)
        assert!(r25 > 2.4 * r100, "rapids {r100:.2} s, at 25% {r25:.2} s");
    }

    /// Issue 10 acceptance 4: a jog runs as `$J=` lines, in state Jog, and
    /// 0x85 brakes it to a stop within the planner block it is in,
    /// dropping the rest.
    #[test]
    fn a_jog_is_cancelled_within_its_block() {
        let mut s = machine();
        // with soft limits on, a jog beyond the travel is refused
        assert_eq!(send(&mut s, "$22=1\n$20=1\n"), "ok\r\nok\r\n");
        assert_eq!(send(&mut s, "$J=X9999 F600\n"), "error:15\r\n");
        assert_eq!(send(&mut s, "$J=X-1 F600\n"), "ok\r\n");
        s.advance(10.0);
        assert_eq!(send(&mut s, "$20=0\n$J=G90 X0 F600\n"), "ok\r\nok\r\n");
        s.advance(20.0);
        s.take_output();
        assert_eq!(send(&mut s, "$J=G91 X10 F600\n"), "ok\r\n");
        assert_eq!(send(&mut s, "$J=G91 X10 F600\n"), "ok\r\n");
        assert_eq!(send(&mut s, "$J=X5 F600 S100\n"), "error:36\r\n");
        assert_eq!(send(&mut s, "$J=G1 X5 F600\n"), "error:16\r\n");
        assert_eq!(send(&mut s, "$J=X5\n"), "error:22\r\n");
        // a jog changes no mode: G91 did not stay
        assert!(s.modal.absolute);
        s.advance(20.6);
        assert!(send(&mut s, "?").starts_with("<Jog"));
        s.receive(JOG_CANCEL);
        let x0 = s.position().x;
        // it brakes as a hold does, still jogging, then drops the jogs left
        assert!(send(&mut s, "?").starts_with("<Jog"));
        s.advance(22.0);
        let x = s.done.x;
        eprintln!("jog cancelled at X{x0:.3}, stood at X{x:.3} (its block from X0 to X10)");
        assert!(
            x > x0 && x < x0 + 1.0 && x < 10.0,
            "stopped at X{x}, inside the first jog's block"
        );
        assert!(s.planner.is_empty());
        assert!(send(&mut s, "?").starts_with(&format!("<Idle|MPos:{x:.3},")));
        // a G-code line goes on from there
        assert_eq!(send(&mut s, "G1 X0 F600\n"), "ok\r\n");
    }

    #[test]
    fn planner_runs_in_simulated_time_and_the_buffer_overflows_loudly() {
        let mut s = machine();
        // 10 mm at 600 mm/min from rest (400 mm/s^2): 1.0125 s; the
        // second move goes straight on at full speed and stops at its end
        // (the look-ahead plans a stop after the last move): 1.0125 s
        send(&mut s, "G1 X10 F600\nG1 X20\n");
        assert!(send(&mut s, "?").starts_with("<Run"));
        // reports give the position mid-move and the speed there: 0.125
        // mm up to speed in 0.025 s, then 10 mm/s
        s.advance(1.0);
        let st = send(&mut s, "?");
        assert!(
            st.contains("MPos:9.875,") && st.contains("|FS:600,"),
            "{st}"
        );
        s.advance(1.5);
        assert!(send(&mut s, "?").contains("MPos:14.875,"));
        s.advance(2.02);
        assert!(send(&mut s, "?").starts_with("<Run"));
        s.advance(2.03);
        assert!(send(&mut s, "?").starts_with("<Idle|MPos:20.000"));
        // 16 queued moves fill the planner; the 16th waits in the buffer
        // ($10=3: reports give the buffers' room)
        send(&mut s, "$10=3\n");
        let mv: String = (1..=16).map(|k| format!("G1 X{k}\n")).collect();
        send(&mut s, &mv);
        assert!(send(&mut s, "?").contains("Bf:0,"));
        let flood = "G1 X1 Y1 Z-1\n".repeat(20);
        send(&mut s, &flood);
        assert!(s.overflow > 0);
    }
}
