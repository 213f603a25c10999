//! Probing on the simulated GRBL: the touch plate, and a G38 move's
//! trigger and stop.

use super::{triple, SimGrbl, TipMove};
use crate::gcode::modal::Probe;
use glam::DVec3;

/// A touch plate lying on the work: its top `thickness` over the stock
/// top (machine Z 0 for a tool of length 0), a square of `size` centred
/// at (x, y) machine coordinates. A probe touches it when the tool's tip
/// reaches its top over it.
#[derive(Clone, Copy, Debug)]
pub struct Plate {
    pub thickness: f64,
    pub x: f64,
    pub y: f64,
    pub size: f64,
}

impl Plate {
    /// `THICKNESS[@X,Y]` (mm; at 0,0 by default), 50 mm square.
    pub fn parse(s: &str) -> Result<Plate, String> {
        let bad = || format!("'{s}': expected THICKNESS[@X,Y] in mm");
        let (t, at) = s.split_once('@').unwrap_or((s, "0,0"));
        let (x, y) = at.split_once(',').ok_or_else(bad)?;
        let num = |v: &str| v.trim().parse::<f64>().ok().filter(|v| v.is_finite());
        match (num(t), num(x), num(y)) {
            (Some(thickness), Some(x), Some(y)) if thickness >= 0.0 => Ok(Plate {
                thickness,
                x,
                y,
                size: 50.0,
            }),
            _ => Err(bad()),
        }
    }

    fn under(&self, p: DVec3) -> bool {
        (p.x - self.x).abs() <= self.size / 2.0 && (p.y - self.y).abs() <= self.size / 2.0
    }
}

/// A probing move under way: when it ends, where the machine stops, the
/// `[PRB:...]` report, and its line.
#[derive(Clone, Debug)]
pub(super) struct Probing {
    pub(super) end: f64,
    stop: DVec3,
    touched: Option<DVec3>,
    must_touch: bool,
    line: String,
}

impl SimGrbl {
    /// Where the tip is below the spindle: the current tool's length.
    pub(super) fn tip(&self) -> DVec3 {
        DVec3::new(
            0.0,
            0.0,
            self.tool_lengths.get(self.tool).copied().unwrap_or(0.0),
        )
    }

    /// A move the machine made, from `from` to `to` (machine
    /// coordinates), as the tip of the tool in the spindle went.
    pub(super) fn record_tip(&mut self, from: DVec3, to: DVec3, rapid: bool) {
        let tip = self.tip();
        self.tips.push(TipMove {
            from: from - tip,
            to: to - tip,
            rapid,
            tool: self.tool,
        });
    }

    /// A probing move from `from` toward `to` at the modal feed: where
    /// the tip meets the plate's top (or, away, leaves it), and where the
    /// machine stops, decelerating from the probe feed past the trigger.
    pub(super) fn start_probe(&mut self, from: DVec3, to: DVec3, probe: Probe, line: String) {
        let tip = self.tip();
        let top = self.plate.map(|p| p.thickness);
        let contact = |q: DVec3| {
            self.plate
                .is_some_and(|p| p.under(q) && q.z - tip.z <= p.thickness + 1e-9)
        };
        if contact(from) != probe.away {
            // already touching (or, away, not touching): GRBL refuses
            self.raise(4);
            return self.say("ok");
        }
        let d = to - from;
        let len = d.length();
        let u = d / len;
        // the trigger: the tip crossing the plate's top over the plate
        let touched = top.and_then(|t| {
            let z0 = from.z - tip.z - t;
            let z1 = to.z - tip.z - t;
            if (z0 > 0.0) == (z1 > 0.0) || z0 == z1 {
                return None;
            }
            let q = from + d * (z0 / (z0 - z1));
            (contact(q) != probe.away || self.plate.is_some_and(|p| p.under(q))).then_some(q)
        });
        let feed = self.modal.feed.unwrap_or(1.0) / 60.0;
        let a = crate::gcode::planner::along(u, self.settings.accels());
        let stop = match touched {
            Some(q) => {
                let run = (q - from).length();
                let over = (feed * feed / (2.0 * a)).min(len - run);
                from + u * (run + over)
            }
            None => to,
        };
        let dist = (stop - from).length();
        let duration = dist / feed + feed / a;
        self.probing = Some(Probing {
            end: self.now + duration,
            stop,
            touched,
            must_touch: probe.must_touch,
            line,
        });
    }

    /// The probing move has ended: report, or raise ALARM:5 when a G38.2
    /// or G38.4 met nothing.
    pub(super) fn end_probe(&mut self) {
        let Some(p) = self.probing.take() else { return };
        self.record_tip(self.done, p.stop, false);
        self.done = p.stop;
        self.modal.pos = p.stop;
        // GRBL keeps the probe's position only when it touched or was
        // allowed not to (G38.3/G38.5); a failed G38.2 is ALARM:5, then
        // the probe report and the line's ok as ever
        self.probed = match p.touched {
            Some(t) => (t, true),
            None if !p.must_touch => (p.stop, false),
            None => (self.probed.0, false),
        };
        if p.touched.is_none() && p.must_touch {
            self.raise(5);
        }
        let r = format!(
            "[PRB:{}:{}]",
            triple(self.probed.0),
            u8::from(self.probed.1)
        );
        self.say(&r);
        self.log.push(p.line);
        self.say("ok");
    }
}
