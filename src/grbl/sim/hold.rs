//! A feed hold as GRBL 1.1h makes one: the motion its stepper segment
//! buffer already holds runs on, then the machine decelerates along its
//! path at the move's acceleration and stands in Hold:0; cycle start goes
//! on from there, from rest.

use super::{SimGrbl, TipMove};
use crate::gcode::planner;
use glam::DVec3;

/// Motion GRBL has already cut into step segments when a hold comes: its
/// segment buffer holds 5 segments of 10 ms (SEGMENT_BUFFER_SIZE 6,
/// ACCELERATION_TICKS_PER_SECOND 100), the running one part done. In the
/// 9 holds recorded on the firmware (tests/data/conformance/holds.jsonl)
/// braking began 43-49 ms after the hold.
const SEGMENT_LAG: f64 = 0.045;

impl SimGrbl {
    /// How far along the running head block the machine is, and how fast
    /// it goes (None when nothing runs).
    fn head_progress(&self) -> Option<(f64, f64)> {
        let b = self.planner.front()?;
        if self.held_left.is_some() || self.paused.is_some() || self.frozen {
            return None;
        }
        let v = self.top_speed(b);
        let t = self.now - self.head_start;
        Some(planner::at_time(
            b.dist,
            b.entry.min(v),
            v,
            b.exit.min(v),
            b.a,
            t,
        ))
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
        let tip = self.tip();
        self.tips.push(TipMove {
            from: b.start - tip,
            to: here - tip,
            rapid: b.rapid,
            tool: self.tool,
        });
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
    /// left is planned from rest for when cycle start comes.
    pub(super) fn end_brake(&mut self) {
        self.braking = false;
        self.exit_speed = 0.0;
        if self.planner.is_empty() {
            self.held_left = Some(0.0);
        } else {
            self.start_head();
            self.held_left = Some(self.block_end - self.now);
        }
    }
}
