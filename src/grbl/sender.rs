//! Streaming a job to GRBL (DESIGN.md section 8): the welcome handshake,
//! an optional check-mode pass, character-counting streaming (send and
//! wait as the fallback), status polling, stopping on the first error or
//! alarm with the job line and GRBL's meaning, a journal of acknowledged
//! lines, and a safe re-entry to resume from one.

use super::port::Port;
use super::resume::{Journal, Tracker};
use super::state::State;
use super::{
    alarm_meaning, error_meaning, CYCLE_START, FEED_HOLD, SOFT_RESET, SPINDLE_STOP, STATUS,
};
use crate::bail;
use crate::error::Result;
use crate::gcode::modal::Modal;
use crate::gcode::parse::{parse_line, strip};
use glam::DVec3;
use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

/// One line to send: where it is in the file, and what GRBL will get.
#[derive(Clone, Debug, PartialEq)]
pub struct JobLine {
    /// 1-based line in the job file.
    pub number: usize,
    /// Comments and spaces stripped (every byte counts against the buffer).
    pub text: String,
    /// The file's line as written, for messages.
    pub original: String,
    /// relievo reads the line (else GRBL may still take it; the sender
    /// then cannot vouch for running it twice).
    pub known: bool,
    /// Its move along the axis it moves most, mm (infinite for an arc,
    /// 0 without motion): a move of a motor step or more is sure to take
    /// a planner block.
    pub travel: f64,
    /// GRBL empties its planner before it answers the line.
    pub sync: bool,
    /// It moves in G91: running it twice moves twice.
    pub relative: bool,
    /// Seconds of dwell.
    pub dwell: f64,
    /// M0: the machine holds here (a tool change) until cycle start.
    pub pause: bool,
    /// The comments on the lines without G-code just before it (what an
    /// M0 asks of the operator).
    pub note: String,
    /// At an M0, the job's modal state there (units, distance mode, and
    /// where the tool stands in work coordinates), for a touch-off.
    pub state: Option<Box<Modal>>,
}

/// What to do when the job pauses at an M0.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum OnPause {
    /// Show the line and wait for Enter on the terminal.
    #[default]
    Ask,
    /// Continue at once (unattended runs, tests).
    Continue,
    /// Touch off Z on the touch plate (--plate), then continue (asking
    /// first on a terminal, where the tool is to be fitted).
    Probe,
}

/// A Z touch-off on a touch plate: G38.2 down fast, back off, again
/// slowly, then the work Z set from the trigger point so that the plate's
/// top is Z = thickness.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TouchOff {
    pub thickness: f64,
    /// Where the plate lies (work X, Y); None = under the tool.
    pub at: Option<(f64, f64)>,
    /// Fast probing feed, mm/min.
    pub feed: f64,
    /// How far the fast probe may go down, mm.
    pub travel: f64,
}

/// Slow probing feed, mm/min: the machine stops within a micrometre of
/// the trigger (the trigger point itself is what sets Z).
const SLOW_PROBE: f64 = 10.0;
/// Rise over the plate before moving to it, mm.
const PLATE_CLEARANCE: f64 = 10.0;

impl TouchOff {
    /// `THICKNESS[@X,Y]`, mm.
    pub fn parse(s: &str) -> std::result::Result<TouchOff, String> {
        let bad = || format!("'{s}': expected THICKNESS[@X,Y] in mm");
        let num = |v: &str| v.trim().parse::<f64>().ok().filter(|v| v.is_finite());
        let (t, at) = match s.split_once('@') {
            Some((t, at)) => {
                let (x, y) = at.split_once(',').ok_or_else(bad)?;
                (t, Some((num(x).ok_or_else(bad)?, num(y).ok_or_else(bad)?)))
            }
            None => (s, None),
        };
        let thickness = num(t).filter(|t| *t >= 0.0).ok_or_else(bad)?;
        Ok(TouchOff {
            thickness,
            at,
            feed: 100.0,
            travel: 50.0,
        })
    }
}

/// The lines of a job that carry anything for GRBL.
pub fn load_job(path: &Path) -> Result<Vec<JobLine>> {
    let text = crate::input::read_text(path, crate::input::MAX_FILE)?;
    job_lines(&text, &path.display().to_string())
}

/// The lines of job `text` (named `what` in errors) that carry anything
/// for GRBL.
pub fn job_lines(text: &str, what: &str) -> Result<Vec<JobLine>> {
    let mut out = Vec::new();
    let mut modal = Modal::new(DVec3::ZERO);
    let mut note = String::new();
    for (k, l) in text.lines().enumerate() {
        let s = strip(l);
        // '%' marks a program's start and end in a file; GRBL takes it
        // for a bad word, so it is not sent
        if s.is_empty() || s == "%" {
            for c in parse_line(l, k + 1).comments {
                if !note.is_empty() {
                    note.push_str("; ");
                }
                note.push_str(&c);
            }
            continue;
        }
        // GRBL acts on these bytes wherever they come, even inside a line:
        // a '!' in a job would hold the machine and the job end "done"
        if let Some(b) = s
            .bytes()
            .find(|&b| matches!(b, b'?' | b'!' | b'~') || !(0x20..0x7f).contains(&b))
        {
            bail!(
                "{what}: line {}: the byte 0x{b:02x} is a GRBL realtime command or not G-code; \
                 a job line cannot carry it",
                k + 1
            );
        }
        if s.len() > 79 {
            bail!(
                "{what}: line {}: {} characters after stripping; GRBL takes 79",
                k + 1,
                s.len()
            );
        }
        let step = modal.apply(&parse_line(&s, k + 1)).ok();
        let travel = step.as_ref().map_or(0.0, |st| match st.to {
            Some(_) if st.motion >= 2 => f64::INFINITY,
            Some(to) => (to - st.from).abs().max_element(),
            None => 0.0,
        });
        out.push(JobLine {
            number: k + 1,
            text: s,
            original: l.trim().to_string(),
            known: step.is_some(),
            travel,
            sync: step.as_ref().is_some_and(|st| st.sync),
            relative: step.as_ref().is_some_and(|st| st.relative),
            pause: step.as_ref().is_some_and(|st| st.pause),
            state: step
                .as_ref()
                .is_some_and(|st| st.pause)
                .then(|| Box::new(modal.clone())),
            dwell: step.and_then(|st| st.dwell).unwrap_or(0.0),
            note: std::mem::take(&mut note),
        });
    }
    if out.is_empty() {
        bail!("{what}: no G-code in the job");
    }
    Ok(out)
}

#[derive(Clone, Debug)]
pub struct Options {
    /// Character counting (false = send one line, wait for its reply).
    pub char_counting: bool,
    /// GRBL's receive buffer, bytes.
    pub rx_buffer: usize,
    /// Status polls per second (at most 5, as GRBL advises).
    pub poll_hz: f64,
    /// Seconds to wait for the welcome before a soft reset.
    pub welcome_timeout: f64,
    /// Journal of sent, acknowledged and executed job lines.
    pub journal: Option<PathBuf>,
    /// Progress bar / log lines on stderr.
    pub progress: bool,
    /// Keys on the terminal while streaming (space: hold/resume, + and -:
    /// feed override by 10%, 0: back to 100%).
    pub keys: bool,
    /// Seconds without an answer (`ok`, `error`, alarm or status report)
    /// that mean the link is dead.
    pub link_timeout: f64,
    /// Seconds the machine may stay in Hold (or Door), or stand still
    /// acknowledging nothing, before the sender gives up, stops the spindle
    /// and says so.
    pub hold_limit: f64,
    /// Seconds of standing still with nothing acknowledged (beyond a
    /// dwell's own time) before the sender says so.
    pub stall_warning: f64,
    /// GRBL's planner blocks (from a status report's `Bf:` when idle).
    pub planner: usize,
    /// When each line should end by the time estimate (for the ETA).
    pub clock: Option<Vec<f64>>,
    pub on_pause: OnPause,
    /// The touch plate for `OnPause::Probe`.
    pub plate: Option<TouchOff>,
    /// The shortest move sure to take a planner block: a step of the
    /// coarsest axis ($100-$102), since GRBL drops a move of no steps.
    pub min_move: f64,
}

impl Default for Options {
    fn default() -> Options {
        Options {
            char_counting: true,
            rx_buffer: 128,
            poll_hz: 4.0,
            welcome_timeout: 2.5,
            journal: None,
            progress: false,
            link_timeout: 10.0,
            hold_limit: 600.0,
            stall_warning: 30.0,
            planner: super::sim::PLANNER_BLOCKS,
            min_move: MIN_MOVE,
            clock: None,
            on_pause: OnPause::Ask,
            plate: None,
            keys: false,
        }
    }
}

/// How a stream ended short of the job's end.
#[derive(Clone, Debug, PartialEq)]
pub enum Stop {
    /// `error:N` at a job line.
    Error {
        line: usize,
        text: String,
        code: u32,
    },
    /// `ALARM:N`, while the oldest unacknowledged line was `line`.
    Alarm {
        line: Option<usize>,
        code: u32,
    },
    Cancelled,
    /// The machine stayed in Hold longer than the limit.
    Held {
        seconds: f64,
    },
    /// The machine neither moved nor acknowledged a line for longer than
    /// the limit, while still answering status polls.
    Stalled {
        seconds: f64,
        state: State,
        line: Option<usize>,
    },
}

impl Stop {
    pub fn describe(&self) -> String {
        match self {
            Stop::Error { line, text, code } => format!(
                "GRBL refused job line {line} '{text}': error:{code} ({})",
                error_meaning(*code)
            ),
            Stop::Alarm { line, code } => format!(
                "ALARM:{code} ({}){}",
                alarm_meaning(*code),
                line.map_or(String::new(), |l| format!(" at job line {l}"))
            ),
            Stop::Cancelled => "stopped by the operator: feed hold, spindle stopped".into(),
            Stop::Held { seconds } => format!(
                "the machine stayed in Hold for {seconds:.0} s (a hold button, an open door?): \
                 streaming stopped and the spindle was stopped"
            ),
            Stop::Stalled {
                seconds,
                state,
                line,
            } => format!(
                "GRBL reported {state} but neither moved nor acknowledged a line for \
                 {seconds:.0} s{}: streaming stopped and the spindle was stopped",
                line.map_or(String::new(), |l| format!(" (waiting on job line {l})"))
            ),
        }
    }
}

#[derive(Clone, Debug, Default)]
pub struct Outcome {
    /// Job lines GRBL acknowledged with `ok`.
    pub acked: usize,
    /// Bytes of job lines written (status polls not counted).
    pub bytes: usize,
    pub seconds: f64,
    /// Every error (check mode goes on after one).
    pub errors: Vec<Stop>,
    /// Why streaming stopped early, if it did.
    pub stop: Option<Stop>,
}

impl Outcome {
    /// Job bytes over what the line could carry in the time taken.
    pub fn utilisation(&self, baud: u32) -> f64 {
        self.bytes as f64 / (self.seconds * baud as f64 / 10.0)
    }
}

/// Reply lines from the port; bytes GRBL never sends (non-ASCII and
/// control bytes other than the line end) are line noise and dropped.
pub struct Replies<'a> {
    pub port: &'a mut dyn Port,
    partial: Vec<u8>,
    ready: VecDeque<String>,
}

impl<'a> Replies<'a> {
    pub fn new(port: &'a mut dyn Port) -> Replies<'a> {
        Replies {
            port,
            partial: Vec::new(),
            ready: VecDeque::new(),
        }
    }

    /// The next reply line, waiting up to `timeout` seconds.
    pub fn next(&mut self, timeout: f64) -> Result<Option<String>> {
        let until = self.port.now() + timeout;
        loop {
            if let Some(l) = self.ready.pop_front() {
                return Ok(Some(l));
            }
            let left = until - self.port.now();
            if left <= 0.0 {
                return Ok(None);
            }
            for b in self.port.read(left)? {
                match b {
                    b'\n' => {
                        let l = String::from_utf8_lossy(&self.partial).trim().to_string();
                        self.partial.clear();
                        if !l.is_empty() {
                            self.ready.push_back(l);
                        }
                    }
                    0x20..=0x7e => self.partial.push(b),
                    _ => {} // \r and noise
                }
            }
        }
    }

    /// Wait for the welcome; soft-reset once if it does not come.
    pub fn handshake(&mut self, timeout: f64) -> Result<()> {
        for attempt in 0..2 {
            if attempt == 1 {
                self.port.write_all(&[SOFT_RESET])?;
            }
            let until = self.port.now() + timeout;
            while self.port.now() < until {
                if let Some(l) = self.next(until - self.port.now())? {
                    if l.starts_with("Grbl ") {
                        // and whatever follows it at once ([MSG:..]), for
                        // half a second at most: a chatty device never ends
                        let t = self.port.now() + 0.5;
                        while self.port.now() < t && self.next(0.05)?.is_some() {}
                        return Ok(());
                    }
                }
            }
        }
        bail!("no GRBL welcome within {timeout} s, not even after a soft reset")
    }

    /// A status report (None if none comes within a second).
    pub fn status(&mut self) -> Result<Option<Status>> {
        self.port.write_all(&[STATUS])?;
        let until = self.port.now() + 1.0;
        while self.port.now() < until {
            if let Some(l) = self.next(until - self.port.now())? {
                if let Some(st) = parse_status(&l) {
                    return Ok(Some(st));
                }
            }
        }
        Ok(None)
    }

    /// Send one command and collect its reply lines up to `ok`/`error`.
    pub fn command(&mut self, cmd: &str, timeout: f64) -> Result<Vec<String>> {
        self.port.write_all(format!("{cmd}\n").as_bytes())?;
        let mut got = Vec::new();
        let until = self.port.now() + timeout;
        while self.port.now() < until {
            let Some(l) = self.next(until - self.port.now())? else {
                continue;
            };
            let done = l == "ok" || l.starts_with("error:");
            got.push(l);
            if done {
                return Ok(got);
            }
        }
        bail!("no reply to '{cmd}' within {timeout} s")
    }
}

/// A status report: `<State|MPos:x,y,z|Bf:blocks,bytes|...>`.
#[derive(Clone, Debug, PartialEq)]
pub struct Status {
    pub state: State,
    pub pos: [f64; 3],
    /// Free planner blocks and free receive-buffer bytes.
    pub free: Option<(usize, usize)>,
}

/// Parse a status report line.
pub fn parse_status(l: &str) -> Option<Status> {
    let body = l.strip_prefix('<')?.strip_suffix('>')?;
    let mut parts = body.split('|');
    let state = State::parse(parts.next()?)?;
    let mut pos = [0.0; 3];
    let mut bf = None;
    for p in parts {
        if let Some(v) = p.strip_prefix("MPos:").or_else(|| p.strip_prefix("WPos:")) {
            for (k, x) in v.split(',').take(3).enumerate() {
                pos[k] = x.parse().ok()?;
            }
        } else if let Some(v) = p.strip_prefix("Bf:") {
            let (a, b) = v.split_once(',')?;
            bf = Some((a.parse().ok()?, b.parse().ok()?));
        }
    }
    Some(Status {
        state,
        pos,
        free: bf,
    })
}

/// The shortest move sure to take a planner block when the controller
/// does not tell its steps per mm: one step at 40 steps/mm (a Shapeoko's
/// belts, the coarsest common drive).
pub const MIN_MOVE: f64 = 0.025;

/// GRBL's `$$` setting `$N`, if listed.
fn setting(settings: &[String], n: u32) -> Option<f64> {
    let key = format!("${n}=");
    settings
        .iter()
        .find_map(|l| l.strip_prefix(&key)?.trim().parse().ok())
}

/// When each job line should end, in seconds from the start, by the
/// planner-based time estimate with the controller's own rates,
/// accelerations and junction deviation (`$110-$112`, `$120-$122`, `$11`;
/// a generic profile's where it does not list them). None when the job
/// has lines relievo cannot read.
pub fn clock(lines: &[JobLine], text: &str, settings: &[String]) -> Option<Vec<f64>> {
    let prog = crate::gcode::program(text).ok()?;
    let mut m = crate::machine::Machine::load("grbl-generic").ok()?;
    for k in 0..3 {
        for (axes, n) in [(&mut m.max_rate, 110), (&mut m.acceleration, 120)] {
            if let Some(x) = setting(settings, n + k as u32).filter(|x| *x > 0.0) {
                *axes.get_mut(k) = x;
            }
        }
    }
    if let Some(j) = setting(settings, 11).filter(|x| *x > 0.0) {
        m.junction_deviation = j;
    }
    let times = crate::sim::line_times(&prog, &m);
    let mut out = Vec::with_capacity(lines.len());
    let (mut t, mut k) = (0.0, 0);
    for l in lines {
        while k < times.len() && times[k].0 <= l.number {
            t += times[k].1;
            k += 1;
        }
        out.push(t);
    }
    Some(out)
}

/// Steps per mm from GRBL's `$$` listing, as the shortest move sure to
/// take a planner block.
pub fn min_move(settings: &[String]) -> Option<f64> {
    let steps: Vec<f64> = (100..=102)
        .map(|n| setting(settings, n))
        .collect::<Option<_>>()?;
    // GRBL rounds each target to whole steps, so a move of a whole step
    // or more (along one axis) changes the rounded position however the
    // work offset falls
    let coarsest = steps.into_iter().fold(f64::INFINITY, f64::min);
    (coarsest.is_finite() && coarsest > 0.0).then(|| 1.000001 / coarsest)
}

/// One thing to send: a job line (its index) or a preamble line.
struct Item<'a> {
    job: Option<usize>,
    text: &'a str,
    /// Seconds of dwell GRBL takes before it answers.
    dwell: f64,
}

/// Seconds of G4 dwell in a preamble line.
fn dwell_of(text: &str) -> f64 {
    Modal::new(DVec3::ZERO)
        .apply(&parse_line(text, 0))
        .ok()
        .and_then(|s| s.dwell)
        .unwrap_or(0.0)
}

/// Stream `lines` (with `preamble` lines sent first, unjournaled).
/// Returns when every line is acknowledged, or at the first error or
/// alarm (in check mode errors are collected and streaming goes on).
pub fn stream(
    r: &mut Replies,
    lines: &[JobLine],
    preamble: &[String],
    opts: &Options,
    check_mode: bool,
    cancel: &AtomicBool,
) -> Result<Outcome> {
    let start = r.port.now();
    let mut journal = match &opts.journal {
        Some(p) if !check_mode => Some(Journal::open(p, false)?),
        _ => None,
    };
    let items: Vec<Item> = preamble
        .iter()
        .map(|p| Item {
            job: None,
            text: p,
            dwell: dwell_of(p),
        })
        .chain(lines.iter().enumerate().map(|(k, l)| Item {
            job: Some(k),
            text: &l.text,
            dwell: l.dwell,
        }))
        .collect();
    let budget = opts.rx_buffer.saturating_sub(1).max(1);
    // sent, unanswered: (item, bytes)
    let mut inflight: VecDeque<(usize, usize)> = VecDeque::new();
    let mut used = 0;
    let mut next = 0;
    let mut out = Outcome::default();
    let mut stopping = false;
    let poll = 1.0 / opts.poll_hz.clamp(0.1, 5.0);
    let mut last_poll = f64::MIN;
    let mut idle_since: Option<f64> = None;
    let mut hold_since: Option<f64> = None;
    let mut stop_time: Option<f64> = None;
    let mut last_reply = start;
    // the watchdog: when a line was last acknowledged or the tool last
    // moved, and whether the stall was told
    let (mut last_sign, mut last_pos, mut told) = (start, None, false);
    let mut tracker = Tracker::new(opts.planner, opts.min_move);
    // a sent M0 (item index) nothing is sent past until its pause is
    // dealt with; and whether cycle start has released it
    let mut gate: Option<(usize, bool)> = None;
    let mut progress = Progress::new(opts.progress, lines.len(), opts.clock.clone());
    let mut keys = Keys::new(opts.keys && !check_mode);
    let mut holding = false;
    let mut batch = Vec::new();
    loop {
        if cancel.load(Ordering::Relaxed) && !stopping {
            r.port.write_all(&[FEED_HOLD])?;
            spindle_stop_once_held(r)?;
            out.stop = Some(Stop::Cancelled);
            break;
        }
        match keys.key() {
            Some(b' ') => r
                .port
                .write_all(&[if holding { CYCLE_START } else { FEED_HOLD }])?,
            Some(b'+') => r.port.write_all(&[FEED_OVERRIDE_UP])?,
            Some(b'-') => r.port.write_all(&[FEED_OVERRIDE_DOWN])?,
            Some(b'0') => r.port.write_all(&[FEED_OVERRIDE_RESET])?,
            _ => {}
        }
        batch.clear();
        while !stopping && next < items.len() && gate.is_none() {
            let len = items[next].text.len() + 1;
            let fits = if opts.char_counting {
                used + len <= budget || inflight.is_empty()
            } else {
                inflight.is_empty()
            };
            if !fits {
                break;
            }
            if let (Some(j), Some(k)) = (journal.as_mut(), items[next].job) {
                j.sent(lines[k].number)?;
            }
            batch.extend_from_slice(items[next].text.as_bytes());
            batch.push(b'\n');
            out.bytes += len;
            inflight.push_back((next, len));
            used += len;
            // GRBL's check mode answers an M0 and goes on: no pause to wait for
            if !check_mode && items[next].job.is_some_and(|k| lines[k].pause) {
                gate = Some((next, false));
            }
            next += 1;
        }
        if !batch.is_empty() {
            // the journal knows a line is sent before the wire does
            if let Some(j) = journal.as_mut() {
                j.flush()?;
            }
            r.port.write_all(&batch)?;
        }
        if inflight.is_empty() && (next == items.len() || stopping) {
            break;
        }
        let now = r.port.now();
        // after a stop, lines still buffered behind a held planner may
        // never be answered: collect replies for a moment, then report
        if stopping && now - *stop_time.get_or_insert(now) > 1.0 {
            break;
        }
        // status polls are answered even in a hold: silence is a dead link
        if now - last_reply > opts.link_timeout {
            bail!(
                "no answer from GRBL for {} s with {} line(s) unacknowledged (link down?)",
                opts.link_timeout,
                inflight.len()
            );
        }
        if now - last_poll >= poll {
            r.port.write_all(&[STATUS])?;
            last_poll = now;
        }
        let Some(l) = r.next(poll / 2.0)? else {
            continue;
        };
        let job_line = |item: usize| items[item].job.map(|k| lines[k].number);
        if l == "ok" || l.starts_with("error:") {
            last_reply = r.port.now();
            let Some((item, len)) = inflight.pop_front() else {
                continue; // a reply to nothing of ours
            };
            used -= len;
            idle_since = None;
            last_sign = last_reply;
            told = false;
            if let Some(code) = l.strip_prefix("error:") {
                let code = code.trim().parse().unwrap_or(0);
                let (line, text) = match items[item].job {
                    Some(k) => (lines[k].number, lines[k].original.clone()),
                    None => (0, "(resume preamble)".into()),
                };
                let e = Stop::Error { line, text, code };
                out.errors.push(e.clone());
                if !check_mode && !stopping {
                    // hold what is buffered, send nothing more
                    r.port.write_all(&[FEED_HOLD])?;
                    stopping = true;
                    out.stop = Some(e);
                }
            } else if let Some(k) = items[item].job {
                out.acked += 1;
                progress.set(k + 1, None);
                if let Some(j) = journal.as_mut() {
                    j.acked(lines[k].number)?;
                    if let Some(e) = tracker.acked(lines, k) {
                        j.executed(lines[e].number)?;
                    }
                }
            }
        } else if let Some(code) = l.strip_prefix("ALARM:") {
            let code = code.trim().parse().unwrap_or(0);
            let line = inflight.front().and_then(|f| job_line(f.0));
            let a = Stop::Alarm { line, code };
            out.errors.push(a.clone());
            out.stop = Some(a);
            break;
        } else if let Some(st) = parse_status(&l) {
            last_reply = r.port.now();
            holding = matches!(st.state, State::Hold(_));
            progress.set(out.acked, Some(st.pos));
            if let (Some(j), Some((blocks, _))) = (journal.as_mut(), st.free) {
                if let Some(e) = tracker.status(blocks) {
                    j.executed(lines[e].number)?;
                }
            }
            // held at the gate's M0 (everything before it answered; GRBL
            // answers the M0 itself when released)
            let at_gate = gate.filter(|g| !g.1 && inflight.front().is_none_or(|f| f.0 >= g.0));
            if let (Some((g, _)), State::Hold(_)) = (at_gate, st.state) {
                let k = items[g].job.unwrap_or(0);
                keys.cooked(|| progress.suspend(|| resume_pause(r, &lines[k], opts.on_pause)))?;
                gate = Some((g, true));
                hold_since = None;
                // (the operator's time is not the link's silence)
                last_reply = r.port.now();
            } else if st.state.is_held() {
                let since = *hold_since.get_or_insert(now);
                if now - since > opts.hold_limit && !stopping {
                    r.port.write_all(&[super::SPINDLE_STOP])?;
                    out.stop = Some(Stop::Held {
                        seconds: now - since,
                    });
                    break;
                }
            } else {
                hold_since = None;
            }
            if last_pos != Some(st.pos) {
                (last_pos, last_sign, told) = (Some(st.pos), now, false);
            }
            // standing still, nothing acknowledged, not held nor dwelling:
            // say so, and past the limit stop
            let dwell = inflight.front().map_or(0.0, |f| items[f.0].dwell);
            let still = now - last_sign - dwell;
            let stalled = !inflight.is_empty() && !stopping && !st.state.is_held();
            if stalled && still > opts.stall_warning && !told {
                told = true;
                let line = inflight.front().and_then(|f| job_line(f.0)).unwrap_or(0);
                progress.suspend(|| {
                    eprintln!(
                        "warning: GRBL reports {} at X{:.3} Y{:.3} Z{:.3} but has neither moved nor \
                         acknowledged a line for {:.0} s (waiting on job line {line}); \
                         Ctrl-C stops the job",
                        st.state, st.pos[0], st.pos[1], st.pos[2], still
                    )
                });
            }
            if stalled && still > opts.hold_limit {
                r.port.write_all(&[FEED_HOLD])?;
                spindle_stop_once_held(r)?;
                out.stop = Some(Stop::Stalled {
                    seconds: still,
                    state: st.state,
                    line: inflight.front().and_then(|f| job_line(f.0)),
                });
                break;
            }
            // an Idle machine with an empty buffer still owing replies
            // has lost them (a cheap adapter dropped bytes); a dwell is
            // answered when it ends
            let drained = st
                .free
                .is_some_and(|(p, rx)| p == opts.planner && rx >= opts.rx_buffer);
            if st.state == State::Idle && drained && !inflight.is_empty() && !check_mode {
                let since = *idle_since.get_or_insert(now);
                let grace = 2.0 + inflight.front().map_or(0.0, |f| items[f.0].dwell);
                if now - since > grace {
                    bail!(
                        "GRBL is idle with an empty buffer but {} line(s) are unacknowledged \
                         (replies lost on the link); stopped at job line {}",
                        inflight.len(),
                        inflight.front().and_then(|f| job_line(f.0)).unwrap_or(0)
                    );
                }
            } else {
                idle_since = None;
            }
        } else if l.starts_with("Grbl ") {
            bail!("GRBL reset during the job (power or a soft reset); nothing more was sent");
        }
        // released and answered: the touch-off, then on with the job
        if let Some((g, true)) = gate {
            if inflight.is_empty() && !stopping {
                let k = items[g].job.unwrap_or(0);
                if let (OnPause::Probe, Some(plate)) = (opts.on_pause, opts.plate) {
                    let state = lines[k].state.as_deref().cloned();
                    let state = state.unwrap_or_else(|| Modal::new(DVec3::ZERO));
                    progress.suspend(|| touch_off(r, &plate, Some(&state)))?;
                    last_reply = r.port.now();
                }
                gate = None;
            }
        }
        if let Some(j) = journal.as_mut() {
            j.flush()?;
        }
    }
    if let Some(j) = journal.as_mut() {
        j.flush()?;
    }
    if stopping {
        // a refused job must not leave the spindle turning: once the hold
        // has taken (as on Ctrl-C), the spindle-stop override; and an M5
        // for a machine that had nothing left to hold (lines still
        // buffered behind a hold are not overrun)
        spindle_stop_once_held(r)?;
        if inflight.is_empty() {
            r.port.write_all(b"M5\n")?;
            let t = r.port.now();
            while r.port.now() < t + 2.0 {
                if let Some(l) = r.next(0.1)? {
                    if l == "ok" || l.starts_with("error:") {
                        break;
                    }
                }
            }
        }
    }
    progress.finish();
    out.seconds = r.port.now() - start;
    Ok(out)
}

/// At an M0 the machine holds (the moves before it are done): say so, and
/// continue with cycle start once the operator presses Enter, or at once.
fn resume_pause(r: &mut Replies, line: &JobLine, on: OnPause) -> Result<()> {
    use std::io::IsTerminal;
    let mut what = format!("paused at job line {} '{}'", line.number, line.original);
    if !line.note.is_empty() {
        what.push_str(&format!(" ({})", line.note));
    }
    let ask = on == OnPause::Ask || (on == OnPause::Probe && std::io::stdin().is_terminal());
    if ask {
        if !std::io::stdin().is_terminal() {
            bail!(
                "{what}, and there is no terminal to ask: the machine is holding; continue \
                 with cycle start yourself, or send with --on-pause continue"
            );
        }
        eprint!("{what}: do what it asks, then press Enter to continue ");
        let mut answer = String::new();
        std::io::stdin()
            .read_line(&mut answer)
            .map_err(|e| crate::Error(format!("reading the terminal: {e}")))?;
    } else if on == OnPause::Probe {
        eprintln!("{what}: touching off on the plate (--on-pause probe)");
    } else {
        eprintln!("{what}: continuing (--on-pause continue)");
    }
    r.port.write_all(&[super::CYCLE_START])
}

/// GRBL's feed override bytes: +10%, -10%, 100%.
const FEED_OVERRIDE_UP: u8 = 0x91;
const FEED_OVERRIDE_DOWN: u8 = 0x92;
const FEED_OVERRIDE_RESET: u8 = 0x90;

/// Single keys from the terminal while a job streams: the terminal is
/// put in non-canonical mode without echo (Ctrl-C still interrupts) and
/// restored when the stream ends, however it ends.
struct Keys {
    saved: Option<libc::termios>,
}

impl Keys {
    fn new(on: bool) -> Keys {
        use std::io::IsTerminal;
        if !on || !std::io::stdin().is_terminal() {
            return Keys { saved: None };
        }
        // SAFETY: termios is plain data, filled by tcgetattr on fd 0
        let mut t: libc::termios = unsafe { std::mem::zeroed() };
        if unsafe { libc::tcgetattr(0, &mut t) } != 0 {
            return Keys { saved: None };
        }
        let k = Keys { saved: Some(t) };
        k.raw();
        k
    }

    fn raw(&self) {
        if let Some(mut t) = self.saved {
            t.c_lflag &= !(libc::ICANON | libc::ECHO);
            t.c_cc[libc::VMIN] = 0;
            t.c_cc[libc::VTIME] = 0;
            // SAFETY: a termios from tcgetattr, modified, on fd 0
            unsafe { libc::tcsetattr(0, libc::TCSANOW, &t) };
        }
    }

    fn restore(&self) {
        if let Some(t) = self.saved {
            // SAFETY: the termios tcgetattr gave, on fd 0
            unsafe { libc::tcsetattr(0, libc::TCSANOW, &t) };
        }
    }

    /// A key pressed since the last call, if any (never waits).
    fn key(&mut self) -> Option<u8> {
        self.saved?;
        let mut b = [0u8; 1];
        // SAFETY: reading one byte into a one-byte buffer; VMIN = VTIME = 0
        // make it return at once
        let n = unsafe { libc::read(0, b.as_mut_ptr() as *mut libc::c_void, 1) };
        (n == 1).then_some(b[0])
    }

    /// Run `f` with the terminal as it was (for a question on it).
    fn cooked<T>(&mut self, f: impl FnOnce() -> T) -> T {
        self.restore();
        let out = f();
        self.raw();
        out
    }
}

impl Drop for Keys {
    fn drop(&mut self) {
        self.restore();
    }
}

/// One line at a time, outside the job: its reply lines up to `ok`; an
/// error or alarm is the touch-off's failure.
fn exchange(r: &mut Replies, line: &str, timeout: f64) -> Result<Vec<String>> {
    r.port.write_all(format!("{line}\n").as_bytes())?;
    let until = r.port.now() + timeout;
    let mut got = Vec::new();
    while r.port.now() < until {
        let Some(l) = r.next(until - r.port.now())? else {
            continue;
        };
        if l == "ok" {
            return Ok(got);
        }
        if l.starts_with("error:") || l.starts_with("ALARM:") {
            bail!(
                "touch-off: '{line}' got {l}{}; the machine stands where the probe stopped",
                if l == "ALARM:5" {
                    " (the probe met nothing: is the plate under the tool and its clip on?)"
                } else {
                    ""
                }
            );
        }
        if !l.starts_with('<') {
            got.push(l);
        }
    }
    bail!("touch-off: no reply to '{line}' within {timeout} s")
}

/// x, y, z in a `[NAME:x,y,z...]` report line.
fn report_triple(lines: &[String], name: &str) -> Option<DVec3> {
    let body = lines
        .iter()
        .find_map(|l| l.strip_prefix(&format!("[{name}:")))?;
    let v: Vec<f64> = body
        .trim_end_matches(']')
        .split([',', ':'])
        .take(3)
        .map(|x| x.parse().ok())
        .collect::<Option<_>>()?;
    (v.len() == 3).then(|| DVec3::new(v[0], v[1], v[2]))
}

/// A Z touch-off, the machine idle: over the plate (rising over it
/// first), probe down fast, back off, probe slowly, set the active
/// system's Z from the slow probe's trigger point (G10 L2, net of G92 and
/// the tool length offset, so the machine's overshoot does not count),
/// rise clear of the plate; at a job's pause (`job`), return to where it
/// paused, its units and distance mode restored.
pub fn touch_off(r: &mut Replies, t: &TouchOff, job: Option<&Modal>) -> Result<()> {
    let n = crate::gcode::emit::num;
    let work = job.map(|m| m.pos - m.wco());
    let probe_time = 60.0 * t.travel / t.feed + 30.0;
    exchange(r, "G21", 5.0)?;
    if let Some((x, y)) = t.at {
        exchange(
            r,
            &format!("G91G0Z{}", n(t.thickness + PLATE_CLEARANCE)),
            60.0,
        )?;
        exchange(r, &format!("G90G0X{}Y{}", n(x), n(y)), 120.0)?;
    }
    exchange(
        r,
        &format!("G91G38.2Z-{}F{}", n(t.travel), n(t.feed)),
        probe_time,
    )?;
    exchange(r, "G91G0Z1", 30.0)?;
    let got = exchange(r, &format!("G91G38.2Z-2F{}", n(SLOW_PROBE)), 60.0)?;
    let prb = report_triple(&got, "PRB")
        .ok_or_else(|| crate::Error("touch-off: no [PRB:] report after G38.2".into()))?;
    let params = exchange(r, "$#", 5.0)?;
    let g92 = report_triple(&params, "G92").unwrap_or(DVec3::ZERO);
    let tlo = params
        .iter()
        .find_map(|l| l.strip_prefix("[TLO:"))
        .and_then(|v| v.trim_end_matches(']').parse::<f64>().ok())
        .unwrap_or(0.0);
    // work Z at the trigger = the plate's thickness
    let wcs_z = prb.z - g92.z - tlo - t.thickness;
    exchange(r, &format!("G10L2P0Z{}", n(wcs_z)), 5.0)?;
    let clear = work.map_or(0.0, |w| w.z).max(t.thickness + 5.0);
    exchange(r, &format!("G90G0Z{}", n(clear)), 60.0)?;
    if let (Some(_), Some(w)) = (t.at, work) {
        exchange(r, &format!("G90G0X{}Y{}", n(w.x), n(w.y)), 120.0)?;
        exchange(r, &format!("G90G0Z{}", n(w.z)), 60.0)?;
    }
    eprintln!(
        "touch-off: the plate's top at machine Z{:.3}; work Z0 set {:.3} mm below it",
        prb.z, t.thickness
    );
    if job.is_some_and(|m| m.inches) {
        exchange(r, "G20", 5.0)?;
    }
    if job.is_some_and(|m| !m.absolute) {
        exchange(r, "G91", 5.0)?;
    }
    Ok(())
}

/// After a feed hold: half a second for the hold to take (replies read
/// meanwhile), then the spindle-stop override, which GRBL honours in Hold.
fn spindle_stop_once_held(r: &mut Replies) -> Result<()> {
    let t = r.port.now();
    while r.port.now() < t + 0.5 {
        r.next(0.1)?;
    }
    r.port.write_all(&[SPINDLE_STOP])
}

/// Validate the whole job in check mode: `$C`, stream everything, `$C`
/// again (GRBL resets leaving it). Returns every error.
pub fn check(r: &mut Replies, lines: &[JobLine], opts: &Options) -> Result<Vec<Stop>> {
    let reply = r.command("$C", 5.0)?;
    if reply.last().is_none_or(|l| l != "ok") {
        bail!("GRBL did not enter check mode: {}", reply.join(" "));
    }
    let quiet = Options {
        progress: false,
        journal: None,
        ..opts.clone()
    };
    let o = stream(r, lines, &[], &quiet, true, &AtomicBool::new(false))?;
    r.command("$C", 5.0)?;
    r.handshake(opts.welcome_timeout)?;
    Ok(o.errors)
}

/// Progress on stderr: a bar on a terminal, a log line every 5 s
/// otherwise. The ETA comes from the job's time estimate (`clock`: when
/// each line should end), scaled by how the machine keeps to it so far;
/// without an estimate, from the lines.
struct Progress {
    bar: Option<indicatif::ProgressBar>,
    log: bool,
    total: usize,
    clock: Option<Vec<f64>>,
    start: std::time::Instant,
    last_log: std::time::Instant,
    pos: Option<[f64; 3]>,
}

impl Progress {
    fn new(on: bool, total: usize, clock: Option<Vec<f64>>) -> Progress {
        use std::io::IsTerminal;
        let tty = std::io::stderr().is_terminal();
        let bar = (on && tty).then(|| {
            let b = indicatif::ProgressBar::new(total as u64);
            b.set_style(indicatif::ProgressStyle::with_template("{bar:20} {msg}").unwrap());
            b
        });
        Progress {
            bar,
            log: on && !tty,
            total,
            clock: clock.filter(|c| c.len() == total && c.last().is_some_and(|t| *t > 0.0)),
            start: std::time::Instant::now(),
            last_log: std::time::Instant::now(),
            pos: None,
        }
    }

    /// Seconds left, from `done` lines acknowledged so far.
    fn eta(&self, done: usize) -> Option<f64> {
        let elapsed = self.start.elapsed().as_secs_f64();
        let (so_far, all) = match &self.clock {
            Some(c) => (if done == 0 { 0.0 } else { c[done - 1] }, c[c.len() - 1]),
            None => (done as f64, self.total as f64),
        };
        (so_far > 0.0 && elapsed > 1.0).then(|| (all - so_far).max(0.0) * elapsed / so_far)
    }

    fn set(&mut self, done: usize, pos: Option<[f64; 3]>) {
        if pos.is_some() {
            self.pos = pos;
        }
        let eta = self.eta(done).map_or("--:--".into(), |s| {
            let s = s.round() as u64;
            format!("{}:{:02}", s / 60, s % 60)
        });
        let at = self.pos.map_or(String::new(), |p| {
            format!(" X{:.3} Y{:.3} Z{:.3}", p[0], p[1], p[2])
        });
        let pct = 100.0 * done as f64 / self.total.max(1) as f64;
        // fits 80 columns with the 20-column bar
        let msg = format!("{done}/{} {pct:.0}% eta {eta}{at}", self.total);
        if let Some(b) = &self.bar {
            b.set_position(done as u64);
            b.set_message(msg);
        } else if self.log && self.last_log.elapsed().as_secs_f64() >= 5.0 {
            self.last_log = std::time::Instant::now();
            eprintln!("{msg}");
        }
    }

    /// Run `f` with the bar off the screen (it prints and may ask).
    fn suspend<T>(&self, f: impl FnOnce() -> T) -> T {
        match &self.bar {
            Some(b) => b.suspend(f),
            None => f(),
        }
    }

    fn finish(&mut self) {
        if let Some(b) = self.bar.take() {
            b.finish_and_clear();
        }
    }
}
