//! The simulated GRBL's status report as GRBL 1.1h's report.c prints it:
//! the fields `$10` asks for, the actual feed and spindle speed, and the
//! work offset and overrides only on the turns its two counters give them
//! (every 10th report standing, 30th/20th busy, and the next one after a
//! change), the overrides with the spindle and coolant pins (`A:`).

use super::{SimGrbl, PLANNER_BLOCKS};
use crate::grbl::state::State;

/// config.h: reports between work offsets and between overrides.
const WCO_BUSY: u8 = 30;
const WCO_IDLE: u8 = 10;
const OVR_BUSY: u8 = 20;
const OVR_IDLE: u8 = 10;

/// GRBL's report counters: reports left before the next work offset and
/// the next overrides (0: this one).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Counters {
    wco: u8,
    ovr: u8,
}

impl Counters {
    /// The work offset changed: the next report gives it.
    pub fn wco_changed(&mut self) {
        self.wco = 0;
    }

    /// An override or the spindle's or coolant's state changed: the next
    /// report gives the overrides.
    pub fn ovr_changed(&mut self) {
        self.ovr = 0;
    }
}

impl SimGrbl {
    /// A status report, and the counters turned as GRBL turns them.
    pub(super) fn status(&mut self) -> String {
        let mut state = self.state();
        let stale = self.faults.stale_idle_after;
        if state == State::Run && stale.is_some_and(|n| self.gcode_lines >= n) {
            self.faults.stale_idle_after = None;
            state = State::Idle;
        }
        let busy = matches!(
            state,
            State::Run | State::Hold(_) | State::Jog | State::Home | State::Door(_)
        );
        let p = self.position();
        let wco = self.modal.wco();
        let mut s = format!("<{state}");
        if self.settings.report_mpos() {
            s += &format!("|MPos:{}", self.coords(p));
        } else {
            s += &format!("|WPos:{}", self.coords(p - wco));
        }
        if self.settings.report_buffers() {
            s += &format!(
                "|Bf:{},{}",
                PLANNER_BLOCKS.saturating_sub(self.planner.len()),
                self.rx_size - self.rx.len()
            );
        }
        let speed = if busy { self.speed_now() * 60.0 } else { 0.0 };
        s += &format!(
            "|FS:{},{}",
            self.rate(speed),
            super::settings::grbl_float(self.spindle as f32, 0)
        );
        let c = &mut self.counters;
        if c.wco > 0 {
            c.wco -= 1;
        } else {
            c.wco = if busy { WCO_BUSY } else { WCO_IDLE } - 1;
            if c.ovr == 0 {
                c.ovr = 1;
            }
            s += &format!("|WCO:{}", self.coords(wco));
        }
        let c = &mut self.counters;
        if c.ovr > 0 {
            c.ovr -= 1;
        } else {
            c.ovr = if busy { OVR_BUSY } else { OVR_IDLE } - 1;
            s += &format!("|Ov:{},{},{}", self.ov.0, self.ov.1, self.ov.2);
            let pins = self.accessories();
            if !pins.is_empty() {
                s += &format!("|A:{pins}");
            }
        }
        s.push('>');
        s
    }

    /// The spindle's and coolant's pins as `A:` spells them: S clockwise,
    /// C counter-clockwise, F flood (mist has no letter without M7 built
    /// in, as in GRBL's default build).
    fn accessories(&self) -> String {
        let mut a = String::new();
        match self.spindle_dir {
            Some(3) => a.push('S'),
            Some(_) => a.push('C'),
            None => {}
        }
        if self.flood {
            a.push('F');
        }
        a
    }

    /// Set the spindle as GRBL's spindle_set_state does: on in the modal
    /// direction at the modal speed under the override, clamped to `$30`
    /// and `$31`, or off.
    pub(super) fn set_spindle(&mut self, on: bool) {
        self.spindle_dir = self.modal.spindle.filter(|_| on);
        self.spindle = match self.spindle_dir {
            Some(_) => self
                .settings
                .spindle_rpm(self.modal.speed * self.ov.2 as f64 / 100.0),
            None => 0.0,
        };
        self.counters.ovr_changed();
    }

    /// Set the coolant (flood) as the modal state says, or off.
    pub(super) fn set_coolant(&mut self, on: bool) {
        self.flood = on && self.modal.coolant.1;
        self.counters.ovr_changed();
    }
}
