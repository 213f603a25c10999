//! A job streamed for someone who is not at the terminal (the studio's
//! Machine panel): the sender tells it what GRBL says and how far the job
//! is, and takes its realtime bytes (hold, start, overrides), its stop and
//! its "go on" at a pause, in place of the terminal's keys and prompt.
//! At a tool change the sender stops before the M0, so the machine stands
//! Idle and takes the page's lines (jog, zero, probe); going on, it puts
//! the machine back in the job's state there (`resume::reentry_at`).

use super::replies::{parse_status, Replies};
use super::state::Standing;
use super::touchoff::Routine;
use crate::bail;
use crate::error::Result;
use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

/// What the sender tells the one watching.
pub enum Told<'a> {
    /// A line GRBL said (status reports included).
    Heard(&'a str),
    /// Job lines acknowledged of all, seconds since the start and left
    /// (by the job's time estimate, when there is one).
    Progress {
        acked: usize,
        total: usize,
        elapsed: f64,
        left: Option<f64>,
    },
    /// A note of the sender's own for the console (a routine's outcome).
    Said(&'a str),
    /// Held at a pause (M0) until told to go on: the line and its note
    /// (which tool to fit); None once it goes on.
    Paused(Option<String>),
}

type Listener = dyn Fn(Told) + Send + Sync;

/// What the page asks of the machine, in turn: outside a job, or of a
/// job held at a tool change.
pub enum Step {
    Line(String),
    Routine(Routine),
}

/// Shared between the sender's thread and the watcher's.
#[derive(Clone)]
pub struct Remote {
    bytes: Arc<Mutex<VecDeque<u8>>>,
    steps: Arc<Mutex<VecDeque<Step>>>,
    go_on: Arc<AtomicBool>,
    pub stop: Arc<AtomicBool>,
    listener: Arc<Listener>,
}

impl std::fmt::Debug for Remote {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Remote")
    }
}

impl Remote {
    pub fn new(listener: impl Fn(Told) + Send + Sync + 'static) -> Remote {
        Remote {
            bytes: Arc::default(),
            steps: Arc::default(),
            go_on: Arc::default(),
            stop: Arc::default(),
            listener: Arc::new(listener),
        }
    }

    /// A realtime byte for GRBL, written by whoever holds the port next.
    pub fn push(&self, byte: u8) {
        self.lock().push_back(byte);
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, VecDeque<u8>> {
        self.bytes.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The realtime bytes asked for since the last call.
    pub fn take_bytes(&self) -> Vec<u8> {
        self.lock().drain(..).collect()
    }

    /// Go on from the pause the job waits at.
    pub fn go_on(&self) {
        self.go_on.store(true, Ordering::SeqCst);
    }

    /// Whether "go on" was asked since the last call.
    pub fn take_go_on(&self) -> bool {
        self.go_on.swap(false, Ordering::SeqCst)
    }

    pub fn tell(&self, t: Told) {
        (self.listener)(t)
    }

    fn queue(&self) -> std::sync::MutexGuard<'_, VecDeque<Step>> {
        self.steps.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// A line, a touch-off or a tool setter's measure from the page for
    /// a job held at a tool change.
    pub fn push_step(&self, step: Step) {
        self.queue().push_back(step);
    }

    /// Held before a pause line `what` with the machine Idle: the page's
    /// realtime bytes and lines go through (one line at a time, each
    /// answered), the readout stays live; once told to go on with the
    /// machine Idle (two reports in a row) and nothing left to send, `back` (the job's own state
    /// there) is sent, each line answered, and the job goes on. Returns
    /// at once when told to stop.
    pub fn tool_change(
        &self,
        r: &mut Replies,
        what: String,
        back: &[String],
        poll: f64,
    ) -> Result<()> {
        self.tell(Told::Paused(Some(what)));
        let mut last_poll = f64::MIN;
        // (the sender paused with the machine standing)
        let (mut awaiting, mut idle) = (false, Standing::sure());
        loop {
            if self.stop.load(Ordering::Relaxed) {
                return Ok(());
            }
            let bytes = self.take_bytes();
            if !bytes.is_empty() {
                r.port.write_all(&bytes)?;
            }
            if !awaiting {
                let step = self.queue().pop_front();
                match step {
                    Some(Step::Line(l)) => {
                        r.port.write_all(format!("{l}\n").as_bytes())?;
                        awaiting = true;
                        idle.sent();
                    }
                    Some(Step::Routine(routine)) => {
                        let said = routine.run(r).unwrap_or_else(|e| e.0);
                        self.tell(Told::Said(&said));
                        idle.sent();
                    }
                    None => {}
                }
            }
            if r.port.now() - last_poll >= poll {
                r.port.write_all(&[super::STATUS])?;
                last_poll = r.port.now();
            }
            if let Some(l) = r.next(0.05)? {
                self.tell(Told::Heard(&l));
                awaiting &= !(l == "ok" || l.starts_with("error:"));
                if let Some(st) = parse_status(&l) {
                    idle.report(st.state, awaiting);
                }
            }
            let queued = !self.queue().is_empty();
            if idle.is_sure() && !awaiting && !queued && self.take_go_on() {
                break;
            }
        }
        for l in back {
            let reply = r.command(l, 10.0).map_err(|e| {
                crate::Error(format!(
                    "going back to the job after the tool change: {}",
                    e.0
                ))
            })?;
            for a in &reply {
                self.tell(Told::Heard(a));
            }
            if let Some(a) = reply.last().filter(|a| a.starts_with("error:")) {
                bail!("going back to the job after the tool change: GRBL refused '{l}': {a}");
            }
        }
        self.tell(Told::Paused(None));
        Ok(())
    }
}
