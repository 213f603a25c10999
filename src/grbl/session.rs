//! A live connection to a GRBL controller outside a job: one thread owns
//! the port, polls status five times a second, sends the operator's lines
//! one at a time (each waits for its `ok`/`error`), writes realtime bytes
//! at once, and keeps a readout (state, positions, feed and spindle,
//! overrides, buffer, alarm) and a console of what went each way with
//! GRBL's meaning of every error and alarm code. The studio's Machine
//! panel is a view of it; connecting sends nothing but `?`.

use super::port::Port;
use super::remote::{Remote, Step, Told};
use super::replies::{parse_status, Replies};
use super::state::State;
use super::touchoff::Routine;
use super::{alarm_meaning, error_meaning, STATUS};
use crate::error::Result;
use crate::gcode::emit::num;
use std::collections::VecDeque;
use std::sync::mpsc::{channel, Receiver, Sender};
use std::sync::{Arc, Condvar, Mutex};
use std::time::Duration;

/// Status polls per second (GRBL advises at most 5).
const POLL_HZ: f64 = 5.0;
/// Console lines kept.
const CONSOLE_KEEP: usize = 400;
/// Seconds without any answer after which the readout says so.
const SILENT: f64 = 3.0;
/// Operator lines waiting their turn, at most: a page that floods the
/// queue is refused rather than queued for minutes.
const MAX_QUEUED: usize = 64;

/// GRBL 1.1's realtime bytes the operator may send.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Realtime {
    Hold,
    Start,
    /// 0x18: stops at once; a machine in motion loses its position.
    Reset,
    JogCancel,
    FeedReset,
    FeedUp,
    FeedDown,
    RapidFull,
    RapidHalf,
    RapidQuarter,
    SpindleReset,
    SpindleUp,
    SpindleDown,
}

impl Realtime {
    /// The byte, as GRBL 1.1h's `config.h` defines it.
    pub fn byte(self) -> u8 {
        match self {
            Realtime::Hold => super::FEED_HOLD,
            Realtime::Start => super::CYCLE_START,
            Realtime::Reset => super::SOFT_RESET,
            Realtime::JogCancel => super::JOG_CANCEL,
            Realtime::FeedReset => 0x90,
            Realtime::FeedUp => 0x91,
            Realtime::FeedDown => 0x92,
            Realtime::RapidFull => 0x95,
            Realtime::RapidHalf => 0x96,
            Realtime::RapidQuarter => 0x97,
            Realtime::SpindleReset => 0x99,
            Realtime::SpindleUp => 0x9A,
            Realtime::SpindleDown => 0x9B,
        }
    }

    /// By the name the page and the command line use.
    pub fn named(name: &str) -> Option<Realtime> {
        Some(match name {
            "hold" => Realtime::Hold,
            "start" => Realtime::Start,
            "reset" => Realtime::Reset,
            "jog_cancel" => Realtime::JogCancel,
            "feed_reset" => Realtime::FeedReset,
            "feed_up" => Realtime::FeedUp,
            "feed_down" => Realtime::FeedDown,
            "rapid_100" => Realtime::RapidFull,
            "rapid_50" => Realtime::RapidHalf,
            "rapid_25" => Realtime::RapidQuarter,
            "spindle_reset" => Realtime::SpindleReset,
            "spindle_up" => Realtime::SpindleUp,
            "spindle_down" => Realtime::SpindleDown,
            _ => return None,
        })
    }
}

/// A jog by `delta` (mm, relative, work axes) at `feed` mm/min.
pub fn jog_line(delta: [Option<f64>; 3], feed: f64) -> std::result::Result<String, String> {
    let words: String = ['X', 'Y', 'Z']
        .iter()
        .zip(delta)
        .filter_map(|(c, v)| v.map(|v| (c, v)))
        .map(|(c, v)| {
            if v.is_finite() {
                Ok(format!("{c}{}", num(v)))
            } else {
                Err(format!("jog {c}{v}: not a distance"))
            }
        })
        .collect::<std::result::Result<_, _>>()?;
    if words.is_empty() {
        return Err("jog: give a distance along X, Y and/or Z (mm)".into());
    }
    if !(feed.is_finite() && feed > 0.0) {
        return Err(format!("jog feed {feed}: must be positive, mm/min"));
    }
    Ok(format!("$J=G91G21{words}F{}", num(feed)))
}

/// Work zero on `axes` (some of x, y, z) where the tool is: G10 L20 P0.
pub fn zero_line(axes: &str) -> std::result::Result<String, String> {
    let axes = axes.to_ascii_uppercase();
    if axes.is_empty() || !axes.chars().all(|c| "XYZ".contains(c)) {
        return Err(format!("zero {axes}: some of x, y, z"));
    }
    Ok(format!(
        "G10L20P0{}",
        axes.chars().map(|c| format!("{c}0")).collect::<String>()
    ))
}

/// One console line: what was sent or what GRBL said, with its meaning.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Said {
    pub seq: u64,
    /// "sent", "got" or "note" (the session's own word).
    pub dir: &'static str,
    pub text: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub meaning: Option<&'static str>,
}

/// A job the session streams (by the front end's sender, on this port).
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct JobRun {
    pub name: String,
    /// Check mode: parsed by GRBL, nothing moves.
    pub check: bool,
    pub running: bool,
    pub acked: usize,
    pub total: usize,
    pub elapsed: f64,
    /// Seconds left by the job's time estimate, scaled by how the machine
    /// keeps to it.
    pub left: Option<f64>,
    /// Held at a pause: the line and what it asks (which tool to fit).
    pub paused: Option<String>,
    /// How it ended: done, or why not (with the resume point).
    pub outcome: Option<String>,
    pub ok: Option<bool>,
    /// The journal offers a safe point to resume from.
    pub resumable: bool,
}

/// What the machine last said about itself.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Readout {
    /// Bumped at every change, so a watcher knows what it has seen.
    pub seq: u64,
    pub port: String,
    pub connected: bool,
    /// Why the link ended, when it did.
    pub error: Option<String>,
    pub state: Option<String>,
    pub mpos: Option<[f64; 3]>,
    pub wpos: Option<[f64; 3]>,
    /// Work coordinate offset (GRBL reports it every few reports).
    pub wco: Option<[f64; 3]>,
    /// Actual feed (mm/min) and spindle speed (rpm).
    pub feed: Option<f64>,
    pub spindle: Option<f64>,
    /// Feed, rapid and spindle overrides, percent.
    pub overrides: Option<[u32; 3]>,
    /// Free planner blocks and receive-buffer bytes.
    pub buffer: Option<[u32; 2]>,
    /// Input pins that read active (`Pn:`), e.g. "P" for the probe.
    pub pins: String,
    /// Spindle, coolant (`A:`).
    pub accessories: String,
    /// The last alarm, with its meaning, until GRBL leaves Alarm.
    pub alarm: Option<(u32, &'static str)>,
    /// No answer, not even to `?`, for a few seconds.
    pub silent: bool,
    /// Operator lines sent and not yet answered, or waiting to be sent.
    pub pending: usize,
    pub job: Option<JobRun>,
    pub console: VecDeque<Said>,
}

/// What a status report can change that the page shows.
type Glance = (
    Option<String>,
    Option<[f64; 3]>,
    Option<[f64; 3]>,
    [Option<f64>; 2],
    Option<[u32; 3]>,
    Option<[u32; 2]>,
    String,
);

impl Readout {
    fn glance(&self) -> Glance {
        (
            self.state.clone(),
            self.mpos,
            self.wco,
            [self.feed, self.spindle],
            self.overrides,
            self.buffer,
            self.pins.clone() + &self.accessories,
        )
    }

    fn say(&mut self, dir: &'static str, text: &str, meaning: Option<&'static str>) {
        let seq = self.console.back().map_or(1, |s| s.seq + 1);
        self.console.push_back(Said {
            seq,
            dir,
            text: text.to_string(),
            meaning,
        });
        while self.console.len() > CONSOLE_KEEP {
            self.console.pop_front();
        }
    }

    /// A line GRBL said: a status report into the readout, anything else
    /// into the console with the meaning of its error or alarm code (an
    /// `ok` only when `log_ok`: a job's are too many). Whether the page
    /// needs telling.
    fn take(&mut self, l: &str, log_ok: bool) -> bool {
        if l.starts_with('<') {
            let before = self.glance();
            self.status(l);
            let was_silent = std::mem::replace(&mut self.silent, false);
            return before != self.glance() || was_silent;
        }
        if l == "ok" && !log_ok {
            return false;
        }
        let code = |p: &str| l.strip_prefix(p).and_then(|c| c.parse::<u32>().ok());
        let meaning = code("error:")
            .map(error_meaning)
            .or(code("ALARM:").map(alarm_meaning));
        if let Some(c) = code("ALARM:") {
            self.alarm = Some((c, alarm_meaning(c)));
        }
        self.say("got", l, meaning);
        true
    }

    /// Take a status report's fields (a report leaves out what it has
    /// not changed: WCO and Ov come every few reports).
    fn status(&mut self, l: &str) -> bool {
        let Some(st) = parse_status(l) else {
            return false;
        };
        self.wco = st.wco.or(self.wco);
        let (mpos, wpos) = st.positions(self.wco.unwrap_or_default());
        (self.mpos, self.wpos) = (Some(mpos), Some(wpos));
        if let Some((feed, spindle)) = st.feed {
            self.feed = Some(feed);
            self.spindle = spindle.or(self.spindle);
        }
        self.overrides = st.overrides.or(self.overrides);
        self.buffer = st.free.map(|(b, r)| [b as u32, r as u32]).or(self.buffer);
        self.pins = st.pins;
        // A: comes with Ov only (none there: spindle and coolant off)
        if st.overrides.is_some() {
            self.accessories = st.accessories;
        }
        if st.state != State::Alarm {
            self.alarm = None;
        }
        self.state = Some(st.state.to_string());
        true
    }
}

/// What the operator asks of the session.
pub enum Ask {
    /// A line (G-code or `$` command), sent when the one before is
    /// answered; or a touch-off or a setter's measure, run then.
    Step(Step),
    /// Lend the port to a job's sender; the session waits meanwhile.
    Lend(Lent),
    Close,
}

/// Work done with the session's port, on its thread.
pub type Lent = Box<dyn FnOnce(&mut dyn Port) + Send>;

/// The readout, shared between the session's thread and its watchers.
pub struct Shared {
    readout: Mutex<Readout>,
    changed: Condvar,
}

impl Shared {
    /// A copy of the readout now.
    pub fn now(&self) -> Readout {
        self.lock().clone()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Readout> {
        // a watcher that panicked leaves the readout whole
        self.readout.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The readout once its `seq` differs from `seen`, or after `timeout`
    /// seconds whatever it is.
    pub fn after(&self, seen: u64, timeout: f64) -> Readout {
        let g = self.lock();
        let (g, _) = self
            .changed
            .wait_timeout_while(g, Duration::from_secs_f64(timeout), |r| r.seq == seen)
            .unwrap_or_else(|e| e.into_inner());
        g.clone()
    }

    fn update(&self, f: impl FnOnce(&mut Readout)) {
        let mut g = self.lock();
        f(&mut g);
        g.seq += 1;
        self.changed.notify_all();
    }
}

/// A connection to a controller, alive while its thread runs.
pub struct Session {
    asks: Sender<Ask>,
    pub shared: Arc<Shared>,
    /// A job's channel to the page: realtime bytes, stop, go on.
    remote: Remote,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Session {
    /// Start talking to the controller on `port` (named `name`): status
    /// polls only, no reset, no line until the operator sends one.
    pub fn open(port: Box<dyn Port + Send>, name: &str) -> Session {
        let shared = Arc::new(Shared {
            readout: Mutex::new(Readout {
                port: name.to_string(),
                connected: true,
                ..Readout::default()
            }),
            changed: Condvar::new(),
        });
        let remote = job_remote(shared.clone());
        let (asks, rx) = channel();
        let (s, rm) = (shared.clone(), remote.clone());
        let thread = std::thread::spawn(move || {
            let mut port = port;
            let end = Link::new(&s, rm).run(&mut *port, &rx);
            s.update(|r| {
                r.connected = false;
                r.pending = 0;
                if let Err(e) = end {
                    r.error = Some(e.0.clone());
                    r.say("note", &format!("link ended: {}", e.0), None);
                } else {
                    r.say("note", "disconnected", None);
                }
            });
        });
        Session {
            asks,
            shared,
            remote,
            thread: Some(thread),
        }
    }

    /// Queue a line; refused when the link is down or too many wait.
    pub fn line(&self, text: &str) -> std::result::Result<(), String> {
        let text = text.trim();
        if text.is_empty() || text.len() > 120 || !text.is_ascii() {
            return Err(format!(
                "'{text}': a line is 1 to 120 ASCII characters (GRBL's line buffer)"
            ));
        }
        self.step(Step::Line(text.to_string()))
    }

    /// A touch-off or a setter's measure, after the lines before it.
    pub fn routine(&self, routine: Routine) -> std::result::Result<(), String> {
        self.step(Step::Routine(routine))
    }

    /// Queue a line or a routine; a job held at its tool change has its
    /// sender pass it on. Refused when the link is down, a job runs, or
    /// (lines) too many wait.
    fn step(&self, step: Step) -> std::result::Result<(), String> {
        let r = self.shared.now();
        if !r.connected {
            return Err("not connected".into());
        }
        if let Some(j) = r.job.as_ref().filter(|j| j.running) {
            if j.paused.is_none() {
                return Err(match step {
                    Step::Line(_) => "a job is running: lines wait for its tool change",
                    Step::Routine(_) => "a job is running: probing waits for its tool change",
                }
                .into());
            }
            if let Step::Line(text) = &step {
                self.shared.update(|s| s.say("sent", text, None));
            }
            self.remote.push_step(step);
            return Ok(());
        }
        if matches!(step, Step::Line(_)) && r.pending >= MAX_QUEUED {
            return Err(format!("{} lines already wait for GRBL", r.pending));
        }
        self.shared.update(|r| r.pending += 1);
        self.asks
            .send(Ask::Step(step))
            .map_err(|_| "not connected".to_string())
    }

    /// A realtime byte, at once (during a job too: hold, start,
    /// overrides).
    pub fn realtime(&self, rt: Realtime) -> std::result::Result<(), String> {
        if !self.shared.now().connected {
            return Err("not connected".into());
        }
        self.remote.push(rt.byte());
        self.shared
            .update(|s| s.say("sent", &format!("{rt:?} (0x{:02x})", rt.byte()), None));
        Ok(())
    }

    /// Run `work` with the port on the session's thread: a job's sender,
    /// told by and steered through `remote()`. `job` is what the page
    /// shows of it until `work` ends it with `end_job`.
    pub fn lend(&self, job: JobRun, work: Lent) -> std::result::Result<(), String> {
        let r = self.shared.now();
        if !r.connected {
            return Err("not connected".into());
        }
        if r.job.as_ref().is_some_and(|j| j.running) {
            return Err("a job is running already".into());
        }
        self.remote
            .stop
            .store(false, std::sync::atomic::Ordering::SeqCst);
        self.remote.take_go_on();
        self.remote.take_bytes();
        self.shared.update(|s| {
            s.say("note", &format!("job {} started", job.name), None);
            s.job = Some(JobRun {
                running: true,
                ..job
            });
        });
        self.asks
            .send(Ask::Lend(work))
            .map_err(|_| "not connected".to_string())
    }

    /// The channel a lent job's sender takes.
    pub fn remote(&self) -> Remote {
        self.remote.clone()
    }

    /// Stop the running job (feed hold, spindle off; the sender's stop).
    pub fn stop(&self) {
        self.remote
            .stop
            .store(true, std::sync::atomic::Ordering::SeqCst);
    }

    /// Go on from the pause the job waits at.
    pub fn go_on(&self) {
        self.remote.go_on();
    }
}

impl Shared {
    /// The lent job ended: how, and whether its journal can resume it.
    pub fn end_job(&self, outcome: String, ok: bool, resumable: bool) {
        self.update(|s| {
            s.say("note", &outcome, None);
            if let Some(j) = s.job.as_mut() {
                j.running = false;
                j.paused = None;
                j.outcome = Some(outcome);
                j.ok = Some(ok);
                j.resumable = resumable;
            }
        });
    }
}

/// The remote a job's sender tells: status into the readout, answers
/// into the console, progress at most five times a second.
fn job_remote(shared: Arc<Shared>) -> Remote {
    let last = Mutex::new(f64::MIN);
    Remote::new(move |t| match t {
        Told::Heard(l) => {
            let mut g = shared.lock();
            if g.take(l, false) {
                g.seq += 1;
                shared.changed.notify_all();
            }
        }
        Told::Progress {
            acked,
            total,
            elapsed,
            left,
        } => {
            let mut at = last.lock().unwrap_or_else(|e| e.into_inner());
            // (a new job's clock starts below the last one's)
            if !(0.0..1.0 / POLL_HZ).contains(&(elapsed - *at)) || acked == total {
                *at = elapsed;
                shared.update(|s| {
                    if let Some(j) = s.job.as_mut() {
                        (j.acked, j.total, j.elapsed, j.left) = (acked, total, elapsed, left);
                    }
                });
            }
        }
        Told::Said(t) => shared.update(|s| s.say("note", t, None)),
        Told::Paused(p) => shared.update(|s| {
            if let Some(j) = s.job.as_mut() {
                j.paused = p;
            }
        }),
    })
}

impl Drop for Session {
    fn drop(&mut self) {
        let _ = self.asks.send(Ask::Close);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// The session thread's own state.
struct Link<'a> {
    shared: &'a Shared,
    remote: Remote,
    queue: VecDeque<Step>,
    /// The operator line GRBL has and has not answered.
    awaiting: Option<String>,
    last_poll: f64,
    last_heard: f64,
}

impl<'a> Link<'a> {
    fn new(shared: &'a Shared, remote: Remote) -> Link<'a> {
        Link {
            shared,
            remote,
            queue: VecDeque::new(),
            awaiting: None,
            last_poll: f64::MIN,
            last_heard: 0.0,
        }
    }

    fn run(&mut self, port: &mut dyn Port, asks: &Receiver<Ask>) -> Result<()> {
        let mut r = Replies::new(port);
        self.last_heard = r.port.now();
        loop {
            while let Ok(ask) = asks.try_recv() {
                match ask {
                    Ask::Close => return Ok(()),
                    Ask::Step(step) => self.queue.push_back(step),
                    Ask::Lend(work) => {
                        work(&mut *r.port);
                        self.last_heard = r.port.now();
                    }
                }
            }
            let bytes = self.remote.take_bytes();
            if !bytes.is_empty() {
                r.port.write_all(&bytes)?;
            }
            if self.awaiting.is_none() {
                match self.queue.pop_front() {
                    Some(Step::Line(l)) => {
                        r.port.write_all(format!("{l}\n").as_bytes())?;
                        self.shared.update(|s| s.say("sent", &l, None));
                        self.awaiting = Some(l);
                    }
                    Some(Step::Routine(routine)) => {
                        let said = routine.run(&mut r);
                        self.shared.update(|s| match &said {
                            Ok(t) => s.say("note", t, None),
                            Err(e) => s.say("note", &e.0, None),
                        });
                        self.last_heard = r.port.now();
                    }
                    None => {}
                }
            }
            let now = r.port.now();
            if now - self.last_poll >= 1.0 / POLL_HZ {
                r.port.write_all(&[STATUS])?;
                self.last_poll = now;
            }
            let silent = now - self.last_heard > SILENT;
            if silent != self.shared.lock().silent {
                self.shared.update(|s| s.silent = silent);
            }
            if let Some(l) = r.next(0.02)? {
                self.last_heard = r.port.now();
                self.heard(&l);
            }
        }
    }

    /// One line from GRBL into the readout and the console; the operator's
    /// line it answers, or a reset that drops them all.
    fn heard(&mut self, l: &str) {
        let mut g = self.shared.lock();
        let changed = g.take(l, true);
        if l == "ok" || l.starts_with("error:") {
            self.awaiting = None;
        } else if l.starts_with("Grbl ") {
            // a reset: what was asked before it is gone
            self.awaiting = None;
            self.queue.clear();
        }
        let pending = self.queue.len() + self.awaiting.is_some() as usize;
        if changed || g.pending != pending {
            g.pending = pending;
            g.seq += 1;
            self.shared.changed.notify_all();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grbl::port::MemPort;
    use crate::grbl::sim::SimGrbl;
    use crate::machine::Machine;

    #[test]
    fn status_reports_fill_the_readout() {
        let mut r = Readout::default();
        assert!(r.status("<Idle|MPos:10.000,5.000,-1.000|FS:0,0|WCO:2.000,1.000,-3.000>"));
        assert_eq!(r.wpos, Some([8.0, 4.0, 2.0]));
        assert!(r.status("<Run|MPos:11.000,5.000,-1.000|FS:500,12000|Ov:120,100,90|Bf:14,100>"));
        assert_eq!(r.wpos, Some([9.0, 4.0, 2.0]), "the last WCO is kept");
        assert_eq!((r.feed, r.spindle), (Some(500.0), Some(12000.0)));
        assert_eq!(r.overrides, Some([120, 100, 90]));
        assert_eq!(r.buffer, Some([14, 100]));
        assert_eq!(r.state.as_deref(), Some("Run"));
        assert!(r.status("<Hold:1|WPos:1.000,2.000,3.000|Pn:PZ>"));
        assert_eq!(r.mpos, Some([3.0, 3.0, 0.0]));
        assert_eq!(
            (r.state.as_deref(), r.pins.as_str()),
            (Some("Hold:1"), "PZ")
        );
        // A: comes with Ov alone: kept between, cleared by an Ov without it
        assert!(r.status("<Run|MPos:0,0,0|FS:500,12000|Ov:100,100,100|A:SF>"));
        assert!(r.status("<Run|MPos:0,0,0|FS:500,12000>"));
        assert_eq!(r.accessories, "SF");
        assert!(r.status("<Idle|MPos:0,0,0|FS:0,0|Ov:100,100,100>"));
        assert_eq!(r.accessories, "");
        assert!(!r.status("<Dancing|MPos:0,0,0>") && !r.status("ok"));
    }

    #[test]
    fn jog_and_zero_lines_are_grbl_s() {
        assert_eq!(
            jog_line([Some(10.0), None, Some(-0.1)], 800.0).unwrap(),
            "$J=G91G21X10Z-0.1F800"
        );
        assert!(jog_line([None; 3], 800.0).is_err());
        assert!(jog_line([Some(f64::NAN), None, None], 800.0).is_err());
        assert!(jog_line([Some(1.0), None, None], 0.0).is_err());
        assert_eq!(zero_line("xz").unwrap(), "G10L20P0X0Z0");
        assert!(zero_line("xa").is_err() && zero_line("").is_err());
        assert_eq!(Realtime::named("jog_cancel").map(|r| r.byte()), Some(0x85));
        assert_eq!(Realtime::named("feed_up").map(|r| r.byte()), Some(0x91));
    }

    /// The session against the simulated machine in simulated time: it
    /// reads the state, runs a jog and a zero, and tells an error's meaning.
    #[test]
    fn a_session_jogs_zeroes_and_explains() {
        let sim = SimGrbl::new(&Machine::load("shapeoko").unwrap());
        let port = MemPort::new(sim, 115200);
        let s = Session::open(Box::new(port), "sim");
        let wait = |what: &str, f: &dyn Fn(&Readout) -> bool| {
            let mut r = s.shared.now();
            for _ in 0..400 {
                if f(&r) {
                    return r;
                }
                r = s.shared.after(r.seq, 0.05);
            }
            panic!("{what}: {r:?}");
        };
        wait("idle", &|r| r.state.as_deref() == Some("Idle"));
        s.line(&jog_line([Some(10.0), None, None], 2000.0).unwrap())
            .unwrap();
        wait("jogged", &|r| {
            r.wpos.is_some_and(|p| (p[0] - 10.0).abs() < 1e-6) && r.state.as_deref() == Some("Idle")
        });
        s.line(&zero_line("x").unwrap()).unwrap();
        wait("zeroed", &|r| r.wpos.is_some_and(|p| p[0].abs() < 1e-6));
        s.line("G1 X1 Q7").unwrap();
        let r = wait("error", &|r| r.console.iter().any(|c| c.text == "error:20"));
        let e = r.console.iter().find(|c| c.text == "error:20").unwrap();
        assert!(
            e.meaning.is_some_and(|m| m.contains("unsupported")),
            "{e:?}"
        );
        assert!(s.line("").is_err() && s.line(&"G0".repeat(70)).is_err());
    }
}
