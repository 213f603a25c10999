//! The simulated GRBL's `$` system commands.

use super::{triple, SimGrbl, PLANNER_BLOCKS};
use crate::gcode::modal::PROBE_TOWARD;
use glam::DVec3;

impl SimGrbl {
    pub(super) fn system(&mut self, cmd: &str) {
        if let Some(words) = cmd.strip_prefix("J=") {
            return self.jog(words);
        }
        match cmd {
            "C" => {
                if self.check {
                    self.say("[MSG:Disabled]");
                    self.say("ok");
                    self.reset();
                } else {
                    self.check = true;
                    self.say("[MSG:Enabled]");
                    self.say("ok");
                }
            }
            "X" => {
                if self.alarm.take().is_some() {
                    self.say("[MSG:Caution: Unlocked]");
                }
                self.say("ok");
            }
            "H" => {
                if !self.planner.is_empty() {
                    return self.error(8);
                }
                self.alarm = None;
                self.done = DVec3::ZERO;
                self.modal.pos = DVec3::ZERO;
                self.say("ok");
            }
            "$" => {
                let t = self.travel;
                let r = self.max_rate;
                let s = self.steps;
                let a = self.accel;
                self.say(&format!("$11={:.3}", self.junction));
                for (k, v) in [
                    (100, s.x),
                    (101, s.y),
                    (102, s.z),
                    (110, r.x),
                    (111, r.y),
                    (112, r.z),
                    (120, a.x),
                    (121, a.y),
                    (122, a.z),
                    (130, t.x),
                    (131, t.y),
                    (132, t.z),
                ] {
                    self.say(&format!("${k}={v:.3}"));
                }
                self.say("ok");
            }
            "#" => {
                let m = &self.modal;
                let mut lines: Vec<String> = (0..6)
                    .map(|k| format!("[G{}:{}]", 54 + k, triple(m.stored.wcs[k])))
                    .collect();
                lines.push(format!("[G28:{}]", triple(m.stored.g28)));
                lines.push(format!("[G30:{}]", triple(m.stored.g30)));
                lines.push(format!("[G92:{}]", triple(m.g92)));
                lines.push(format!("[TLO:{:.3}]", m.tlo));
                lines.push(format!(
                    "[PRB:{}:{}]",
                    triple(self.probed.0),
                    u8::from(self.probed.1)
                ));
                for l in lines {
                    self.say(&l);
                }
                self.say("ok");
            }
            "G" => {
                let m = &self.modal;
                let motion = match m.motion {
                    p if p >= PROBE_TOWARD => format!("38.{}", p - PROBE_TOWARD + 2),
                    p => p.to_string(),
                };
                let coolant = match m.coolant {
                    (false, false) => "M9".to_string(),
                    (mist, flood) => [(mist, "M7"), (flood, "M8")]
                        .iter()
                        .filter(|c| c.0)
                        .map(|c| c.1)
                        .collect::<Vec<_>>()
                        .join(" "),
                };
                let s = format!(
                    "[GC:G{motion} G{} G{} {} {} {} M{} {coolant} T{} F{} S{}]",
                    54 + m.coord,
                    m.plane.code(),
                    if m.inches { "G20" } else { "G21" },
                    if m.absolute { "G90" } else { "G91" },
                    if m.inverse_time { "G93" } else { "G94" },
                    m.spindle.unwrap_or(5),
                    m.tool,
                    m.feed.unwrap_or(0.0),
                    m.speed
                );
                self.say(&s);
                self.say("ok");
            }
            "I" => {
                self.say("[VER:1.1h.20190830:relievo simulated machine]");
                self.say(&format!("[OPT:V,{PLANNER_BLOCKS},{}]", self.rx_size));
                self.say("ok");
            }
            _ => self.error(3),
        }
    }
}
