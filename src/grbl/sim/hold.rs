//! GRBL 1.1h's suspends: a feed hold (the motion its stepper segment
//! buffer already holds runs on, then the machine decelerates along its
//! path at the move's acceleration and stands in Hold:0; cycle start goes
//! on from there, from rest), a jog cancel (the same braking, then the
//! jog is dropped), the safety door (a hold that turns the spindle and
//! coolant off, and restores them at cycle start) and the spindle stop
//! override in a hold. GRBL's main loop takes no line while one holds it.

use super::SimGrbl;
use crate::gcode::planner;
use crate::grbl::state::State;
use glam::DVec3;

/// Motion GRBL has already cut into step segments when a hold comes: its
/// segment buffer holds 5 segments of 10 ms (SEGMENT_BUFFER_SIZE 6,
/// ACCELERATION_TICKS_PER_SECOND 100), the running one part done. In the
/// 9 holds recorded on the firmware (tests/data/conformance/holds.jsonl)
/// braking began 43-49 ms after the hold.
const SEGMENT_LAG: f64 = 0.045;

/// config.h: the spindle's and the coolant's time to come back up after
/// the door (SAFETY_DOOR_SPINDLE_DELAY, SAFETY_DOOR_COOLANT_DELAY).
const DOOR_SPINDLE_DELAY: f64 = 4.0;
const DOOR_COOLANT_DELAY: f64 = 1.0;

impl SimGrbl {
    /// How far along the running head block the machine is, and how fast
    /// it goes (None when nothing runs).
    pub(super) fn head_progress(&self) -> Option<(f64, f64)> {
        let b = self.planner.front()?;
        if self.held_left.is_some() || self.paused.is_some() || self.frozen {
            return None;
        }
        let v = self.top_speed(b);
        let t = self.now - self.head_start;
        Some(planner::at_time(b.dist, b.entry, v, b.exit.min(v), b.a, t))
    }

    /// The machine's position now (machine coordinates), between block
    /// ends too.
    pub fn position(&self) -> DVec3 {
        match (self.planner.front(), self.head_progress()) {
            (Some(b), Some((s, _))) => b.start + (b.end - b.start) * (s / b.dist),
            _ => self.done,
        }
    }

    /// The machine's speed now, mm/s (0 standing).
    pub(super) fn speed_now(&self) -> f64 {
        self.head_progress().map_or(0.0, |(_, v)| v)
    }

    /// A feed hold ('!'): the running block is cut where the machine will
    /// stand, braking from the speed it has; the rest of it waits, with
    /// its line, for cycle start. A hold near a block's end stops at that
    /// end (GRBL would brake on into the next block, a few hundredths of a
    /// millimetre further at the most).
    pub(super) fn hold(&mut self) {
        if self.held_left.is_some() || self.braking {
            return;
        }
        let Some((s, v)) = self.head_progress() else {
            if !self.planner.is_empty() {
                self.held_left = Some((self.block_end - self.now).max(0.0));
            }
            return;
        };
        let b = self.planner.pop_front().unwrap();
        let u = (b.end - b.start) / b.dist;
        let stop_at = (s + v * SEGMENT_LAG + v * v / (2.0 * b.a)).min(b.dist);
        let (here, stop) = (b.start + u * s, b.start + u * stop_at);
        self.record_tip(b.start, here, b.rapid);
        self.done = here;
        let rest = b.dist - stop_at;
        let mut brake = b.clone();
        (brake.start, brake.end, brake.dist) = (here, stop, stop_at - s);
        (brake.v, brake.top, brake.entry, brake.exit) = (v, v, v, 0.0);
        brake.brake = true;
        if rest > 1e-9 {
            let mut after = b;
            (after.start, after.dist, after.max_entry) = (stop, rest, 0.0);
            brake.lines = Vec::new();
            self.planner.push_front(after);
        }
        self.planner.push_front(brake);
        self.braking = true;
        self.head_start = self.now;
        self.block_end = self.now + self.run_time(self.planner.front().unwrap());
    }

    /// The braking block ended: the machine stands, held, and what is
    /// left is planned from rest for when cycle start comes (a jog
    /// cancelled: dropped; a door: the spindle and coolant go off).
    pub(super) fn end_brake(&mut self) {
        self.braking = false;
        self.exit_speed = 0.0;
        if std::mem::take(&mut self.jog_cancel) {
            self.planner.clear();
            self.last_dir = None;
            self.modal.pos = self.done;
            return self.pump();
        }
        if self.door {
            self.set_spindle(false);
            self.set_coolant(false);
        }
        if self.planner.is_empty() {
            self.held_left = Some(0.0);
        } else {
            self.start_head();
            self.held_left = Some(self.block_end - self.now);
        }
    }

    /// '!': a hold, as GRBL takes it in each state (none in an alarm, in
    /// check mode or behind a door; a jog is cancelled). Standing, the
    /// machine holds at once, a dwell with it.
    pub(super) fn feed_hold(&mut self) {
        if self.alarm.is_some() || self.check || self.door || self.asleep {
            return;
        }
        if self.planner.front().is_some_and(|b| b.jog) {
            return self.cancel_jog();
        }
        if self.planner.is_empty() && self.probing.is_none() && self.paused.is_none() {
            return self.hold_standing();
        }
        self.hold();
    }

    /// Held where the machine stands (no move runs): a dwell waits with
    /// the hold, for its time left.
    fn hold_standing(&mut self) {
        if let Some((end, line)) = self.dwell.take() {
            self.dwell_held = Some((end - self.now, line));
        }
        self.held_left.get_or_insert(0.0);
    }

    /// '~': a standing hold goes on (restoring the spindle its override
    /// stopped), a door restores the spindle and coolant first.
    pub(super) fn cycle_start(&mut self) {
        if self.braking {
            return; // GRBL resumes only a hold complete
        }
        if self.door {
            if self.restore_at.is_some() {
                return;
            }
            let mut wait = 0.0;
            if self.modal.spindle.is_some() {
                self.set_spindle(true);
                wait += DOOR_SPINDLE_DELAY;
            }
            if self.modal.coolant.1 {
                self.set_coolant(true);
                wait += DOOR_COOLANT_DELAY;
            }
            self.restore_at = Some(self.now + wait);
            return self.advance(self.now);
        }
        if std::mem::take(&mut self.spindle_stopped) && self.held_left.is_some() {
            self.say("[MSG:Restoring spindle]");
            self.set_spindle(true);
        }
        self.resume();
    }

    /// A hold's end: the move, the dwell or the pause it held go on.
    pub(super) fn resume(&mut self) {
        if let Some(left) = self.held_left.take() {
            if !self.planner.is_empty() {
                self.set_block_end(self.now + left);
            }
        }
        if let Some((left, line)) = self.dwell_held.take() {
            self.dwell = Some((self.now + left, line));
        }
        if let Some(line) = self.paused.take() {
            // the operator changed the tool while it held
            self.fit_next_tool();
            self.log.push(line);
            self.say("ok");
        }
        self.pump();
    }

    /// 0x84, the safety door opened: `[MSG:Check Door]`; moving, the
    /// machine brakes as in a hold (Door:2), then stands with the spindle
    /// and coolant off (Door:0, the door closed again: this machine has
    /// no door switch, as GRBL's default build).
    pub(super) fn open_door(&mut self) {
        if self.alarm.is_some() || self.check || self.asleep {
            return;
        }
        self.say("[MSG:Check Door]");
        if self.planner.front().is_some_and(|b| b.jog) {
            self.cancel_jog();
        }
        let was = self.door;
        self.door = true;
        self.restore_at = None;
        if self.braking {
            return;
        }
        if !was && !self.planner.is_empty() && self.held_left.is_none() {
            return self.hold();
        }
        self.hold_standing();
        self.spindle_stopped = false;
        self.set_spindle(false);
        self.set_coolant(false);
    }

    /// 0x9E in a hold: the spindle off, or back on.
    pub(super) fn spindle_stop(&mut self) {
        if !matches!(self.state(), State::Hold(_)) {
            return;
        }
        if self.spindle_stopped {
            self.spindle_stopped = false;
            self.say("[MSG:Restoring spindle]");
            self.set_spindle(true);
        } else if self.modal.spindle.is_some() {
            self.spindle_stopped = true;
            self.set_spindle(false);
        }
    }
}
