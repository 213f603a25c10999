//! Sending a job to GRBL (DESIGN.md section 8): what the sender is told
//! (Options), how a stream ends (Outcome, Stop), the check-mode pass, and
//! the job's clock for the ETA. The stream itself is `stream`'s state
//! machine; the job's lines, GRBL's replies and the touch-off have their
//! own modules, named here too.

pub use super::lines::{job_lines, load_job, JobLine};
pub use super::replies::{parse_status, whole_report, Replies, Status};
use super::state::State;
pub use super::stream::stream;
pub use super::touchoff::{touch_off, Routine, Setter, TouchOff};
use super::{alarm_meaning, error_meaning};
use crate::bail;
use crate::error::Result;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};

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
    /// Measure the new tool on the tool setter (--setter) and move work
    /// Z0 by its difference from the tool that set Z0 (measured before
    /// the job starts), then continue (asking first on a terminal).
    Setter,
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
    /// Seconds the machine may stay in Hold (or Door) before the sender
    /// gives up, stops the spindle and says so.
    pub hold_limit: f64,
    /// How long a machine that stands still with a line unacknowledged is
    /// waited on before the sender holds, stops the spindle and gives up.
    pub stall: Stall,
    /// GRBL's planner blocks (from a status report's `Bf:` when idle).
    pub planner: usize,
    /// When each line should end by the time estimate (for the ETA).
    pub clock: Option<Vec<f64>>,
    pub on_pause: OnPause,
    /// The touch plate for `OnPause::Probe`.
    pub plate: Option<TouchOff>,
    /// The tool setter for `OnPause::Setter`, and its reference (the
    /// setter's top in work Z as the tool that set Z0 reads it).
    pub setter: Option<(Setter, Arc<Mutex<Option<f64>>>)>,
    /// The shortest move sure to take a planner block: a step of the
    /// coarsest axis ($100-$102), since GRBL drops a move of no steps.
    pub min_move: f64,
    /// Someone away from the terminal (the studio's page) watching and
    /// steering the job.
    pub remote: Option<super::remote::Remote>,
}

/// The watchdog's limit on a stalled controller: one that answers status
/// polls but neither moves nor acknowledges a line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Stall {
    /// The planner's own time for what GRBL holds ahead of the line it
    /// owes (at the reported overrides), twice over, plus `STALL_MARGIN`:
    /// a machine still busy with long moves is given their time, a frozen
    /// one is told within the margin.
    Derived,
    /// A fixed number of seconds (beyond a dwell's own time).
    Seconds(f64),
}

/// Seconds beyond the planned time (and a dwell's own) before a still,
/// silent controller is called stalled: longer than any pause GRBL makes
/// on its own between answered lines.
pub const STALL_MARGIN: f64 = 20.0;

impl Stall {
    /// The limit, in seconds since the last acknowledgement, given the
    /// planned seconds of the moves ahead (None without a time estimate)
    /// and the dwell of the line owed.
    pub fn limit(self, planned: Option<f64>, dwell: f64) -> f64 {
        match self {
            Stall::Derived => 2.0 * planned.unwrap_or(0.0) + STALL_MARGIN + dwell,
            Stall::Seconds(s) => s + dwell,
        }
    }

    /// `auto`, or seconds.
    pub fn parse(s: &str) -> std::result::Result<Stall, String> {
        if s == "auto" {
            return Ok(Stall::Derived);
        }
        match s.parse::<f64>() {
            Ok(x) if x.is_finite() && x > 0.0 => Ok(Stall::Seconds(x)),
            _ => Err(format!(
                "'{s}' is not a stall timeout: 'auto' (the planner's time plus \
                 {STALL_MARGIN} s) or seconds above 0"
            )),
        }
    }
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
            stall: Stall::Derived,
            planner: super::sim::PLANNER_BLOCKS,
            min_move: MIN_MOVE,
            clock: None,
            on_pause: OnPause::Ask,
            plate: None,
            setter: None,
            keys: false,
            remote: None,
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
        /// Since the last acknowledgement, and the limit it passed.
        seconds: f64,
        limit: f64,
        state: State,
        pos: [f64; 3],
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
                limit,
                state,
                pos,
                line,
            } => format!(
                "GRBL reported {state} at X{:.3} Y{:.3} Z{:.3} but acknowledged no line for \
                 {seconds:.1} s (limit {limit:.1} s){}: streaming stopped and the spindle was \
                 stopped",
                pos[0],
                pos[1],
                pos[2],
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
/// a generic profile's where it does not list them), the tool starting at
/// `start` (work coordinates, where the machine reports it; None = the
/// job's highest Z). None when the job has lines relievo cannot read.
pub fn clock(
    lines: &[JobLine],
    text: &str,
    settings: &[String],
    start: Option<glam::DVec3>,
) -> Option<Vec<f64>> {
    let prog = crate::gcode::program_at(text, start).ok()?;
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

/// Validate the whole job in check mode: `$C`, stream everything, `$C`
/// again (GRBL resets leaving it). Returns every error. A check that
/// fails on the way (a lost link, a reset) still tries to leave check
/// mode, so the next send does not find GRBL checking instead of cutting.
pub fn check(r: &mut Replies, lines: &[JobLine], opts: &Options) -> Result<Vec<Stop>> {
    let reply = r.command("$C", 5.0)?;
    if !reply.iter().any(|l| l == "[MSG:Enabled]") || reply.last().is_none_or(|l| l != "ok") {
        if reply.iter().any(|l| l == "[MSG:Disabled]") {
            r.handshake(opts.welcome_timeout)?;
        }
        bail!("GRBL did not enter check mode: {}", reply.join(" "));
    }
    let quiet = Options {
        progress: false,
        journal: None,
        ..opts.clone()
    };
    let streamed = stream(r, lines, &[], &quiet, true, &AtomicBool::new(false));
    let left = leave_check_mode(r, opts.welcome_timeout);
    let o = streamed?;
    if let Some(stop) = o.stop.filter(|s| !matches!(s, Stop::Error { .. })) {
        bail!("the check stopped: {}", stop.describe());
    }
    left?;
    Ok(o.errors)
}

/// `$C` on a machine in check mode: GRBL says `[MSG:Disabled]`, answers
/// ok and resets (its welcome follows).
pub fn leave_check_mode(r: &mut Replies, welcome_timeout: f64) -> Result<()> {
    let reply = r.command("$C", 5.0)?;
    if !reply.iter().any(|l| l == "[MSG:Disabled]") {
        bail!("GRBL did not leave check mode: {}", reply.join(" "));
    }
    r.handshake(welcome_timeout)
}
