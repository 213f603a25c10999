//! A job streamed for someone who is not at the terminal (the studio's
//! Machine panel): the sender tells it what GRBL says and how far the job
//! is, and takes its realtime bytes (hold, start, overrides), its stop and
//! its "go on" at a pause, in place of the terminal's keys and prompt.

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
    /// Held at a pause (M0) until told to go on: the line and its note
    /// (which tool to fit); None once it goes on.
    Paused(Option<String>),
}

type Listener = dyn Fn(Told) + Send + Sync;

/// Shared between the sender's thread and the watcher's.
#[derive(Clone)]
pub struct Remote {
    bytes: Arc<Mutex<VecDeque<u8>>>,
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
}
