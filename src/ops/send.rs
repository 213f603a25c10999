//! The `send` command as one library call: a job file and a port in, the
//! job streamed (optionally checked first, optionally resumed), or one
//! clear error saying where it stopped, what is known to have run and how
//! to resume.

use crate::bail;
use crate::error::Result;
use crate::grbl::port::Port;
use crate::grbl::resume::{reentry, resume_point, standing};
use crate::grbl::sender::{self, JobLine, Options, Outcome, Replies};
use crate::grbl::state::State;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

#[derive(Clone, Debug, Default)]
pub struct SendJob {
    pub job: PathBuf,
    /// Validate the whole job in GRBL's check mode first.
    pub check: bool,
    /// Only validate: check mode, then stop.
    pub check_only: bool,
    /// Send one line and wait for its reply (instead of character counting).
    pub send_response: bool,
    /// Start at this job file line (with a safe re-entry).
    pub resume_from: Option<usize>,
    /// Resume at the first line this journal leaves in doubt.
    pub resume: Option<PathBuf>,
    /// Journal of sent, acknowledged and executed lines; `None` =
    /// JOB.journal.
    pub journal: Option<PathBuf>,
    pub progress: bool,
    pub rx_buffer: usize,
    /// Seconds of silence that mean a dead link (default 10).
    pub link_timeout: Option<f64>,
    /// Seconds the machine may stay in Hold (default 600).
    pub hold_limit: Option<f64>,
    /// How long a stalled controller is waited on (default: derived from
    /// the planner's time).
    pub stall: Option<sender::Stall>,
    /// What to do at an M0.
    pub on_pause: sender::OnPause,
    /// The touch plate, for `OnPause::Probe`.
    pub plate: Option<sender::TouchOff>,
    /// The tool setter, for `OnPause::Setter`.
    pub setter: Option<sender::Setter>,
    /// Keys on the terminal while streaming (hold/resume, feed override).
    pub keys: bool,
    /// Watched and steered from elsewhere (the studio's page) instead of
    /// the terminal.
    pub remote: Option<crate::grbl::remote::Remote>,
}

impl SendJob {
    pub fn journal_path(&self) -> PathBuf {
        self.journal.clone().unwrap_or_else(|| {
            let mut p = self.job.clone().into_os_string();
            p.push(".journal");
            p.into()
        })
    }

    pub fn run(&self, port: &mut dyn Port, cancel: &AtomicBool) -> Result<(Outcome, usize)> {
        // read once: the lines to send, and the text the clock times
        let text = crate::input::read_text(&self.job, crate::input::MAX_FILE)?;
        let lines = sender::job_lines(&text, &self.job.display().to_string())?;
        let start = self.start(&lines)?;
        let journal = self.journal_path();
        let defaults = Options::default();
        let mut opts = Options {
            char_counting: !self.send_response,
            rx_buffer: self.rx_buffer.max(16),
            journal: Some(journal.clone()),
            progress: self.progress,
            link_timeout: self.link_timeout.unwrap_or(defaults.link_timeout),
            hold_limit: self.hold_limit.unwrap_or(defaults.hold_limit),
            stall: self.stall.unwrap_or(defaults.stall),
            on_pause: self.on_pause,
            plate: self.plate,
            setter: self.setter.map(|s| (s, Default::default())),
            keys: self.keys,
            remote: self.remote.clone(),
            ..defaults
        };
        let mut r = Replies::new(port);
        r.handshake(opts.welcome_timeout)?;
        let st = ready(&mut r, &opts)?;
        // an idle machine's free planner blocks are all its blocks
        if let (State::Idle, Some((blocks, _))) = (st.state, st.free) {
            opts.planner = blocks.max(1);
        }
        self.read_settings(&mut r, &mut opts, (&text, &lines), start, &st)?;
        if (self.check || self.check_only) && self.check(&mut r, &lines, &opts)? {
            return Ok((Outcome::default(), 0));
        }
        if self.resume.is_none() && self.resume_from.is_none() {
            // a fresh run starts a fresh journal
            crate::grbl::resume::Journal::open(&journal, true)?;
        }
        if let (sender::OnPause::Setter, Some((setter, top))) = (self.on_pause, &opts.setter) {
            // the tool in the spindle set Z0: its reading is the reference
            let said = sender::Routine::SetterReference(*setter, top.clone())
                .run(&mut r)
                .map_err(|e| {
                    crate::Error(format!("{}: before the job: {}", self.job.display(), e.0))
                })?;
            if self.progress {
                eprintln!("{said}");
            }
        }
        let preamble = if start > 0 {
            reentry(&lines, start)
        } else {
            Vec::new()
        };
        let out = match sender::stream(&mut r, &lines[start..], &preamble, &opts, false, cancel) {
            Ok(o) => o,
            Err(e) => bail!("{}: {e}{}", self.job.display(), standing(&lines, &journal)),
        };
        if let Some(stop) = &out.stop {
            bail!(
                "{}: {}{}",
                self.job.display(),
                stop.describe(),
                standing(&lines, &journal)
            );
        }
        Ok((out, lines.len() - start))
    }

    /// GRBL's `$$`: steps per mm tell which moves surely take a planner
    /// block; the rates and accelerations time the job (the ETA's and the
    /// watchdog's clock) from where the machine stands.
    fn read_settings(
        &self,
        r: &mut Replies,
        opts: &mut Options,
        (text, lines): (&str, &[sender::JobLine]),
        start: usize,
        st: &sender::Status,
    ) -> Result<()> {
        let Ok(settings) = r.command("$$", 2.0) else {
            return Ok(());
        };
        if let Some(m) = sender::min_move(&settings) {
            opts.min_move = m;
        }
        // the job starts where the machine stands, if the report says
        let at = (st.work || st.wco.is_some()) && start == 0;
        let at = at.then(|| glam::DVec3::from(st.positions(st.wco.unwrap_or_default()).1));
        opts.clock = sender::clock(lines, text, &settings, at).map(|c| {
            let base = if start > 0 { c[start - 1] } else { 0.0 };
            c[start..].iter().map(|t| t - base).collect()
        });
        Ok(())
    }

    /// The whole job through GRBL's check mode; true when that is all
    /// that was asked.
    fn check(&self, r: &mut Replies, lines: &[sender::JobLine], opts: &Options) -> Result<bool> {
        let errors = sender::check(r, lines, opts)?;
        if !errors.is_empty() {
            let list: Vec<String> = errors.iter().map(|e| e.describe()).collect();
            bail!(
                "{}: check mode found {} bad line(s), nothing was moved: {}",
                self.job.display(),
                errors.len(),
                list.join("; ")
            );
        }
        if self.progress || self.check_only {
            eprintln!(
                "{}: check passed: {} lines",
                self.job.display(),
                lines.len()
            );
        }
        Ok(self.check_only)
    }

    /// Index of the first job line to send.
    fn start(&self, lines: &[JobLine]) -> Result<usize> {
        let from = match (&self.resume, self.resume_from) {
            (Some(_), Some(_)) => bail!("--resume and --resume-from: give one"),
            (Some(j), None) => return resume_point(lines, j),
            (None, Some(n)) => n,
            (None, None) => return Ok(0),
        };
        match lines.iter().position(|l| l.number >= from) {
            Some(k) => Ok(k),
            None => bail!(
                "{}: nothing left to send from line {from} (the job has {} lines)",
                self.job.display(),
                lines.last().map_or(0, |l| l.number)
            ),
        }
    }
}

/// The machine as found, ready for a job: taken out of check mode (left
/// so by a check cut short), else refused when busy, held or in alarm.
fn ready(r: &mut Replies, opts: &Options) -> Result<sender::Status> {
    let mut st = machine_state(r)?;
    if st.state == State::Check {
        // nothing moves in check mode, and leaving it (GRBL resets) loses
        // nothing a job needs
        eprintln!("GRBL was in check mode ($C): leaving it first");
        sender::leave_check_mode(r, opts.welcome_timeout)?;
        st = machine_state(r)?;
    }
    if matches!(
        st.state,
        State::Hold(_) | State::Door(_) | State::Run | State::Jog | State::Home
    ) {
        bail!(
            "GRBL is in {} (a job, a hold or an open door): left as it is, nothing was \
             sent; finish or resume it on the machine (or `relievo machine reset` to stop \
             it), then send again",
            st.state
        );
    }
    if st.state == State::Alarm {
        bail!(
            "GRBL is in alarm (position may be lost after a reset in motion): check the \
             machine, then `relievo machine home` or `unlock` on this port, and send again"
        );
    }
    Ok(st)
}

/// The machine's state as its status report gives it.
fn machine_state(r: &mut Replies) -> Result<sender::Status> {
    match r.status()? {
        Some(st) => Ok(st),
        None => bail!(
            "no status report within 1 s after the welcome: not a GRBL 1.1 controller, or \
             the link is bad; nothing was sent"
        ),
    }
}
