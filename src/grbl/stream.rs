//! Streaming a job to GRBL as a state machine. The stream is in one
//! `Phase` (sending, at a pause, stopping); what GRBL says (ok, error,
//! alarm, a status report, a reset's welcome), the operator does (a key,
//! Ctrl-C) or the clock tells (silence, a hold or a stall past its limit)
//! is an `Event`, and each event is one transition. Character counting
//! fills GRBL's receive buffer (send and wait as the fallback); the
//! journal records each line sent, acknowledged and executed.

use super::lines::JobLine;
use super::remote::{Remote, Told};
use super::replies::{parse_status, Replies, Status};
use super::resume::{highest_z, reentry_at, Journal, Tracker};
use super::sender::{OnPause, Options, Outcome, Stop, STALL_MARGIN};
use super::session::Realtime;
use super::state::{Standing, State};
use super::touchoff::{touch_off, Routine};
use super::{CYCLE_START, FEED_HOLD, SPINDLE_STOP, STATUS};
use crate::bail;
use crate::error::Result;
use crate::gcode::modal::Modal;
use crate::gcode::parse::parse_line;
use glam::DVec3;
use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};

/// Where the stream is.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Phase {
    /// Lines go out as GRBL's buffer has room.
    Sending,
    /// An M0 (item index) is sent: nothing more goes until the machine
    /// holds there, the operator releases it (`released`), and GRBL has
    /// answered it. GRBL's check mode answers an M0 and goes on, so a
    /// check never enters this phase.
    AtPause { item: usize, released: bool },
    /// After an error: the rest held, nothing more sent, replies collected
    /// for a moment (`since`) before the spindle is stopped.
    Stopping { since: Option<f64> },
}

/// What happened: GRBL's line, or nothing within the wait.
#[derive(Debug)]
enum Event {
    Ok,
    Error(u32),
    Alarm(u32),
    Status(Status),
    /// GRBL's welcome: it was reset.
    Welcome,
    /// Anything else (`[MSG:]`, echoes): nothing to do.
    Other,
}

impl Event {
    fn of(l: &str) -> Event {
        let code = |c: &str| c.trim().parse().unwrap_or(0);
        if l == "ok" {
            Event::Ok
        } else if let Some(c) = l.strip_prefix("error:") {
            Event::Error(code(c))
        } else if let Some(c) = l.strip_prefix("ALARM:") {
            Event::Alarm(code(c))
        } else if let Some(st) = parse_status(l) {
            Event::Status(st)
        } else if l.starts_with("Grbl ") {
            Event::Welcome
        } else {
            Event::Other
        }
    }
}

/// Whether the stream goes on after a transition.
#[derive(PartialEq)]
enum Flow {
    Go,
    End,
}

/// The clocks the watchdogs read, in the port's seconds.
struct Watch {
    /// GRBL's last line of any kind: silence past the link timeout is a
    /// dead link (status polls are answered even in a hold).
    last_reply: f64,
    last_poll: f64,
    /// Since when the machine reports Idle with an empty buffer while
    /// replies are owed.
    idle_since: Option<f64>,
    /// Since when the machine holds (not at the job's own pause).
    hold_since: Option<f64>,
    /// When a line was last acknowledged, when the tool last moved and
    /// where it was, and whether the stall was told.
    last_ack: f64,
    last_move: f64,
    last_pos: Option<[f64; 3]>,
    told: bool,
    /// The slower of the feed and rapid overrides, as a fraction.
    pace: f64,
}

/// One thing to send: a job line (its index) or a preamble line.
struct Item<'a> {
    job: Option<usize>,
    text: &'a str,
    /// Seconds of dwell GRBL takes before it answers.
    dwell: f64,
}

/// The stream's state: the phase, what is in GRBL's buffer, the clocks,
/// and what the operator sees.
struct Stream<'a> {
    lines: &'a [JobLine],
    items: Vec<Item<'a>>,
    opts: &'a Options,
    check_mode: bool,
    phase: Phase,
    /// Sent, unanswered: (item, bytes); `used` bytes of GRBL's buffer.
    inflight: VecDeque<(usize, usize)>,
    used: usize,
    budget: usize,
    /// The next item to send.
    next: usize,
    out: Outcome,
    watch: Watch,
    poll: f64,
    journal: Option<Journal>,
    tracker: Tracker,
    progress: Progress,
    keys: Keys,
    /// The last status report said Hold.
    holding: bool,
    /// Whether the machine stands with every line sent answered.
    standing: Standing,
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
    let mut s = Stream::new(start, lines, preamble, opts, check_mode)?;
    let ran = s.run(r, cancel);
    s.progress.finish();
    ran?;
    let mut out = s.out;
    out.seconds = r.port.now() - start;
    Ok(out)
}

impl<'a> Stream<'a> {
    fn new(
        start: f64,
        lines: &'a [JobLine],
        preamble: &'a [String],
        opts: &'a Options,
        check_mode: bool,
    ) -> Result<Stream<'a>> {
        let journal = match &opts.journal {
            Some(p) if !check_mode => Some(Journal::open(p, false)?),
            _ => None,
        };
        let items = preamble
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
        Ok(Stream {
            lines,
            items,
            opts,
            check_mode,
            phase: Phase::Sending,
            inflight: VecDeque::new(),
            used: 0,
            budget: opts.rx_buffer.saturating_sub(1).max(1),
            next: 0,
            out: Outcome::default(),
            watch: Watch {
                last_reply: start,
                last_poll: f64::MIN,
                idle_since: None,
                hold_since: None,
                last_ack: start,
                last_move: start,
                last_pos: None,
                told: false,
                pace: 1.0,
            },
            poll: 1.0 / opts.poll_hz.clamp(0.1, 5.0),
            journal,
            tracker: Tracker::new(opts.planner, opts.min_move),
            progress: Progress::new(
                opts.progress,
                lines.len(),
                opts.clock.clone(),
                opts.remote.clone(),
            ),
            keys: Keys::new(opts.keys && !check_mode),
            holding: false,
            standing: Standing::default(),
        })
    }

    fn stopping(&self) -> bool {
        matches!(self.phase, Phase::Stopping { .. })
    }

    /// The job line of item `item`, if it is one.
    fn job_line(&self, item: usize) -> Option<usize> {
        self.items[item].job.map(|k| self.lines[k].number)
    }

    /// The job line GRBL is working on: the oldest unanswered.
    fn waiting_on(&self) -> Option<usize> {
        self.inflight.front().and_then(|f| self.job_line(f.0))
    }

    /// The loop: the operator, sending, the clocks, then GRBL's next line.
    fn run(&mut self, r: &mut Replies, cancel: &AtomicBool) -> Result<()> {
        loop {
            let remote = self.opts.remote.as_ref();
            let stop = remote.is_some_and(|rm| rm.stop.load(Ordering::Relaxed));
            if (cancel.load(Ordering::Relaxed) || stop) && !self.stopping() {
                r.port.write_all(&[FEED_HOLD])?;
                spindle_stop_once_held(r)?;
                self.out.stop = Some(Stop::Cancelled);
                break;
            }
            if let Some(k) = self.keys.key() {
                self.on_key(r, k)?;
            }
            if let Some(bytes) = remote.map(|rm| rm.take_bytes()).filter(|b| !b.is_empty()) {
                r.port.write_all(&bytes)?;
            }
            self.send(r)?;
            if self.inflight.is_empty() && (self.next == self.items.len() || self.stopping()) {
                break;
            }
            let now = r.port.now();
            if self.clocks(r, now)? == Flow::End {
                break;
            }
            let Some(l) = r.next(self.poll / 2.0)? else {
                continue;
            };
            if let Some(rm) = &self.opts.remote {
                rm.tell(Told::Heard(&l));
            }
            let flow = match Event::of(&l) {
                Event::Ok => self.on_answer(r, None)?,
                Event::Error(code) => self.on_answer(r, Some(code))?,
                Event::Alarm(code) => self.on_alarm(code),
                Event::Status(st) => self.on_status(r, st, now)?,
                Event::Welcome => bail!(
                    "GRBL reset during the job (power or a soft reset); nothing more was sent"
                ),
                Event::Other => Flow::Go,
            };
            if flow == Flow::End {
                break;
            }
            self.leave_pause(r)?;
            if let Some(j) = self.journal.as_mut() {
                j.flush()?;
            }
        }
        if let Some(j) = self.journal.as_mut() {
            j.flush()?;
        }
        if self.stopping() {
            self.stop_spindle(r)?;
        }
        Ok(())
    }

    /// A key on the terminal: space holds or resumes, + and - step the
    /// feed override by 10%, 0 sets it back to 100%.
    fn on_key(&mut self, r: &mut Replies, k: u8) -> Result<()> {
        let byte = match k {
            b' ' if self.holding => CYCLE_START,
            b' ' => FEED_HOLD,
            b'+' => Realtime::FeedUp.byte(),
            b'-' => Realtime::FeedDown.byte(),
            b'0' => Realtime::FeedReset.byte(),
            _ => return Ok(()),
        };
        r.port.write_all(&[byte])
    }

    /// Send what fits in GRBL's buffer (character counting), or the next
    /// line once the last is answered; never past a pause.
    fn send(&mut self, r: &mut Replies) -> Result<()> {
        let mut batch = Vec::new();
        while self.phase == Phase::Sending && self.next < self.items.len() {
            let item = &self.items[self.next];
            // the page's tool change: not the M0, but a stop before it
            if self.page_pauses() && item.job.is_some_and(|k| self.lines[k].pause) {
                self.phase = Phase::AtPause {
                    item: self.next,
                    released: false,
                };
                break;
            }
            let len = item.text.len() + 1;
            let fits = if self.opts.char_counting {
                self.used + len <= self.budget || self.inflight.is_empty()
            } else {
                self.inflight.is_empty()
            };
            if !fits {
                break;
            }
            if let (Some(j), Some(k)) = (self.journal.as_mut(), item.job) {
                j.sent(self.lines[k].number)?;
            }
            batch.extend_from_slice(item.text.as_bytes());
            batch.push(b'\n');
            self.out.bytes += len;
            self.inflight.push_back((self.next, len));
            self.standing.sent();
            self.used += len;
            if !self.check_mode && item.job.is_some_and(|k| self.lines[k].pause) {
                self.phase = Phase::AtPause {
                    item: self.next,
                    released: false,
                };
            }
            self.next += 1;
        }
        if !batch.is_empty() {
            // the journal knows a line is sent before the wire does
            if let Some(j) = self.journal.as_mut() {
                j.flush()?;
            }
            r.port.write_all(&batch)?;
        }
        Ok(())
    }

    /// The clocks: the moment after a stop, the link's silence, the
    /// status poll.
    fn clocks(&mut self, r: &mut Replies, now: f64) -> Result<Flow> {
        // after a stop, lines still buffered behind a held planner may
        // never be answered: collect replies for a moment, then report
        if let Phase::Stopping { since } = &mut self.phase {
            if now - *since.get_or_insert(now) > 1.0 {
                return Ok(Flow::End);
            }
        }
        if now - self.watch.last_reply > self.opts.link_timeout {
            bail!(
                "no answer from GRBL for {} s with {} line(s) unacknowledged (link down?)",
                self.opts.link_timeout,
                self.inflight.len()
            );
        }
        if now - self.watch.last_poll >= self.poll {
            r.port.write_all(&[STATUS])?;
            self.watch.last_poll = now;
        }
        Ok(Flow::Go)
    }

    /// `ok` or `error:N` for the oldest line in GRBL's buffer.
    fn on_answer(&mut self, r: &mut Replies, error: Option<u32>) -> Result<Flow> {
        self.watch.last_reply = r.port.now();
        let Some((item, len)) = self.inflight.pop_front() else {
            return Ok(Flow::Go); // a reply to nothing of ours
        };
        self.used -= len;
        self.watch.idle_since = None;
        self.watch.last_ack = self.watch.last_reply;
        self.watch.told = false;
        if let Some(code) = error {
            let (line, text) = match self.items[item].job {
                Some(k) => (self.lines[k].number, self.lines[k].original.clone()),
                None => (0, "(resume preamble)".into()),
            };
            let e = Stop::Error { line, text, code };
            self.out.errors.push(e.clone());
            if !self.check_mode && !self.stopping() {
                // hold what is buffered, send nothing more
                r.port.write_all(&[FEED_HOLD])?;
                self.phase = Phase::Stopping { since: None };
                self.out.stop = Some(e);
            }
        } else if let Some(k) = self.items[item].job {
            self.out.acked += 1;
            self.progress.set(k + 1, None);
            let ran = self.tracker.acked(self.lines, k);
            if let Some(j) = self.journal.as_mut() {
                j.acked(self.lines[k].number)?;
                if let Some(e) = ran {
                    j.executed(self.lines[e].number)?;
                }
            }
        }
        Ok(Flow::Go)
    }

    /// `ALARM:N`: GRBL has stopped everything; so does the stream.
    fn on_alarm(&mut self, code: u32) -> Flow {
        let a = Stop::Alarm {
            line: self.waiting_on(),
            code,
        };
        self.out.errors.push(a.clone());
        self.out.stop = Some(a);
        Flow::End
    }

    /// A status report: progress and the journal's executed lines, the
    /// job's pause reached, a hold or a stall past its limit, replies lost
    /// on the link.
    fn on_status(&mut self, r: &mut Replies, st: Status, now: f64) -> Result<Flow> {
        self.watch.last_reply = r.port.now();
        self.holding = matches!(st.state, State::Hold(_));
        self.progress.set(self.out.acked, Some(st.pos));
        if let Some((blocks, _)) = st.free {
            let ran = self.tracker.status(blocks);
            if let (Some(j), Some(e)) = (self.journal.as_mut(), ran) {
                j.executed(self.lines[e].number)?;
            }
        }
        if let Some([feed, rapid, _]) = st.overrides {
            self.watch.pace = (feed.min(rapid) as f64 / 100.0).max(0.01);
        }
        // held at the pause's M0 (everything before it answered; GRBL
        // answers the M0 itself when released)
        let at_pause = match self.phase {
            Phase::AtPause {
                item,
                released: false,
            } if self.inflight.front().is_none_or(|f| f.0 >= item) => Some(item),
            _ => None,
        };
        // the page's pause stands Idle before the M0, the terminal's in
        // the M0's Hold
        let page = self.page_pauses();
        self.standing.report(st.state, !self.inflight.is_empty());
        let standing = if page {
            self.standing.is_sure()
        } else {
            matches!(st.state, State::Hold(_))
        };
        if let Some(item) = at_pause.filter(|_| standing && page) {
            self.page_tool_change(r, item)?;
        } else if let Some(item) = at_pause.filter(|_| standing) {
            let k = self.items[item].job.unwrap_or(0);
            let (line, on) = (&self.lines[k], self.opts.on_pause);
            let progress = &self.progress;
            self.keys
                .cooked(|| progress.suspend(|| resume_pause(r, line, on)))?;
            self.phase = Phase::AtPause {
                item,
                released: true,
            };
            self.watch.hold_since = None;
            // (the operator's time is not the link's silence)
            self.watch.last_reply = r.port.now();
        } else if st.state.is_held() {
            let since = *self.watch.hold_since.get_or_insert(now);
            if now - since > self.opts.hold_limit && !self.stopping() {
                r.port.write_all(&[SPINDLE_STOP])?;
                self.out.stop = Some(Stop::Held {
                    seconds: now - since,
                });
                return Ok(Flow::End);
            }
        } else {
            self.watch.hold_since = None;
        }
        if self.stalled(r, &st, now)? == Flow::End {
            return Ok(Flow::End);
        }
        self.lost_replies(&st, now)?;
        Ok(Flow::Go)
    }

    /// Nothing acknowledged for longer than the limit (`Stall`: by
    /// default the planner's time for what GRBL holds ahead of the line it
    /// owes, twice over, plus a margin) while the tool stands still, not
    /// held: told at half the limit, stopped past it.
    fn stalled(&mut self, r: &mut Replies, st: &Status, now: f64) -> Result<Flow> {
        let w = &mut self.watch;
        if w.last_pos != Some(st.pos) {
            (w.last_pos, w.last_move) = (Some(st.pos), now);
        }
        let Some(&(item, _)) = self.inflight.front() else {
            return Ok(Flow::Go);
        };
        if self.stopping() || st.state.is_held() {
            return Ok(Flow::Go);
        }
        let limit = self
            .opts
            .stall
            .limit(self.planned_ahead(item), self.items[item].dwell);
        let w = &mut self.watch;
        let (silent, still) = (now - w.last_ack, now - w.last_move.max(w.last_ack));
        let standing = still >= (STALL_MARGIN / 2.0).min(limit / 2.0);
        if standing && silent > limit / 2.0 && !w.told {
            w.told = true;
            let line = self.waiting_on().unwrap_or(0);
            self.progress.suspend(|| {
                eprintln!(
                    "warning: GRBL reports {} at X{:.3} Y{:.3} Z{:.3} but has acknowledged no \
                     line for {silent:.0} s and stands still (waiting on job line {line}; \
                     stopped at {limit:.0} s); Ctrl-C stops the job",
                    st.state, st.pos[0], st.pos[1], st.pos[2]
                )
            });
        }
        if standing && silent > limit {
            r.port.write_all(&[FEED_HOLD])?;
            spindle_stop_once_held(r)?;
            self.out.stop = Some(Stop::Stalled {
                seconds: silent,
                limit,
                state: st.state,
                pos: st.pos,
                line: self.waiting_on(),
            });
            return Ok(Flow::End);
        }
        Ok(Flow::Go)
    }

    /// The planner's seconds, at the reported overrides, from the first
    /// line that may not have run to the end of `item`'s line: what GRBL
    /// must do before it can answer it. None without a time estimate.
    fn planned_ahead(&self, item: usize) -> Option<f64> {
        let k = self.items[item].job?;
        let clock = self
            .opts
            .clock
            .as_ref()
            .filter(|c| c.len() == self.lines.len())?;
        let from = self.tracker.first_unrun().min(k);
        let before = if from == 0 { 0.0 } else { clock[from - 1] };
        Some((clock[k] - before).max(0.0) / self.watch.pace)
    }

    /// An Idle machine with an empty buffer still owing replies has lost
    /// them (a cheap adapter dropped bytes); a dwell is answered when it
    /// ends.
    fn lost_replies(&mut self, st: &Status, now: f64) -> Result<()> {
        let drained = st
            .free
            .is_some_and(|(p, rx)| p == self.opts.planner && rx >= self.opts.rx_buffer);
        if st.state == State::Idle && drained && !self.inflight.is_empty() && !self.check_mode {
            let since = *self.watch.idle_since.get_or_insert(now);
            let grace = 2.0 + self.inflight.front().map_or(0.0, |f| self.items[f.0].dwell);
            if now - since > grace {
                bail!(
                    "GRBL is idle with an empty buffer but {} line(s) are unacknowledged \
                     (replies lost on the link); stopped at job line {}",
                    self.inflight.len(),
                    self.waiting_on().unwrap_or(0)
                );
            }
        } else {
            self.watch.idle_since = None;
        }
        Ok(())
    }

    /// Pauses are the page's: the sender stops before an M0 (see
    /// `remote`), not at it.
    fn page_pauses(&self) -> bool {
        !self.check_mode && self.opts.remote.is_some() && self.opts.on_pause != OnPause::Continue
    }

    /// The page's tool change before pause item `item`; the M0 itself is
    /// not sent (the machine stood Idle for the change), so it counts as
    /// answered.
    fn page_tool_change(&mut self, r: &mut Replies, item: usize) -> Result<()> {
        let Some(rm) = self.opts.remote.as_ref() else {
            return Ok(());
        };
        let k = self.items[item].job.unwrap_or(0);
        let line = &self.lines[k];
        let mut what = format!("paused at job line {} '{}'", line.number, line.original);
        if !line.note.is_empty() {
            what.push_str(&format!(" ({})", line.note));
        }
        let state = line.state.as_deref().cloned();
        let state = state.unwrap_or_else(|| Modal::new(DVec3::ZERO));
        let back = reentry_at(&state, highest_z(self.lines));
        rm.tool_change(r, what, &back, self.poll)?;
        if let Some(j) = self.journal.as_mut() {
            j.sent(line.number)?;
            j.acked(line.number)?;
        }
        self.out.acked += 1;
        self.next = item + 1;
        self.phase = Phase::Sending;
        self.watch.hold_since = None;
        self.watch.last_reply = r.port.now();
        self.watch.last_ack = self.watch.last_reply;
        Ok(())
    }

    /// Released and answered: the touch-off if asked for, then on with the
    /// job.
    fn leave_pause(&mut self, r: &mut Replies) -> Result<()> {
        let Phase::AtPause {
            item,
            released: true,
        } = self.phase
        else {
            return Ok(());
        };
        if !self.inflight.is_empty() {
            return Ok(());
        }
        let k = self.items[item].job.unwrap_or(0);
        let state = self.lines[k].state.as_deref().cloned();
        let state = state.unwrap_or_else(|| Modal::new(DVec3::ZERO));
        if let (OnPause::Probe, Some(plate)) = (self.opts.on_pause, self.opts.plate) {
            self.progress
                .suspend(|| touch_off(r, &plate, Some(&state)))?;
            self.watch.last_reply = r.port.now();
        }
        if let (OnPause::Setter, Some((setter, top))) = (self.opts.on_pause, &self.opts.setter) {
            let measured = Routine::SetterApply(*setter, top.clone());
            let said = self.progress.suspend(|| measured.run(r))?;
            self.progress.suspend(|| eprintln!("{said}"));
            // back where the job paused, its modes restored
            for l in reentry_at(&state, highest_z(self.lines)) {
                let reply = r.command(&l, 60.0)?;
                if let Some(e) = reply.last().filter(|a| a.starts_with("error:")) {
                    bail!("going back to the job after the tool setter: '{l}' got {e}");
                }
            }
            self.watch.last_reply = r.port.now();
        }
        self.phase = Phase::Sending;
        Ok(())
    }

    /// A refused job must not leave the spindle turning: once the hold has
    /// taken (as on Ctrl-C), the spindle-stop override; and an M5 for a
    /// machine that had nothing left to hold (lines still buffered behind
    /// a hold are not overrun).
    fn stop_spindle(&mut self, r: &mut Replies) -> Result<()> {
        spindle_stop_once_held(r)?;
        if self.inflight.is_empty() {
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
        Ok(())
    }
}

/// Seconds of G4 dwell in a preamble line.
fn dwell_of(text: &str) -> f64 {
    Modal::new(DVec3::ZERO)
        .apply(&parse_line(text, 0))
        .ok()
        .and_then(|s| s.dwell)
        .unwrap_or(0.0)
}

/// At an M0 the machine holds (the moves before it are done): say so, and
/// continue with cycle start once the operator presses Enter, or at once.
fn resume_pause(r: &mut Replies, line: &JobLine, on: OnPause) -> Result<()> {
    use std::io::IsTerminal;
    let mut what = format!("paused at job line {} '{}'", line.number, line.original);
    if !line.note.is_empty() {
        what.push_str(&format!(" ({})", line.note));
    }
    let touches = matches!(on, OnPause::Probe | OnPause::Setter);
    let ask = on == OnPause::Ask || (touches && std::io::stdin().is_terminal());
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
    } else if on == OnPause::Setter {
        eprintln!("{what}: measuring the new tool on the setter (--on-pause setter)");
    } else {
        eprintln!("{what}: continuing (--on-pause continue)");
    }
    r.port.write_all(&[CYCLE_START])
}

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

/// After a feed hold: half a second for the hold to take (replies read
/// meanwhile), then the spindle-stop override, which GRBL honours in Hold.
fn spindle_stop_once_held(r: &mut Replies) -> Result<()> {
    let t = r.port.now();
    while r.port.now() < t + 0.5 {
        r.next(0.1)?;
    }
    r.port.write_all(&[SPINDLE_STOP])
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
    remote: Option<Remote>,
}

impl Progress {
    fn new(on: bool, total: usize, clock: Option<Vec<f64>>, remote: Option<Remote>) -> Progress {
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
            remote,
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
        if let Some(rm) = &self.remote {
            rm.tell(Told::Progress {
                acked: done,
                total: self.total,
                elapsed: self.start.elapsed().as_secs_f64(),
                left: self.eta(done),
            });
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
