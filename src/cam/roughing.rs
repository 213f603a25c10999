//! The roughing stage: layers of the roughing tool down to the relief plus
//! the stock to leave, round the touch-off pad, and with --boundary
//! subject the background cut to its level.

use super::setup::Work;
use super::{Op, ToolpathJob};
use crate::bail;
use crate::error::Result;
use crate::toolpath::rough;

impl ToolpathJob {
    /// The roughing op, when the job roughs; its passes cut the planned
    /// stock.
    pub(super) fn roughing(&self, w: &mut Work) -> Result<Option<Op>> {
        let Some(rc) = &w.rough else {
            return Ok(None);
        };
        let (r, rt) = (&rc.asked, rc.tool);
        let settings = self.settings(&w.machine, &rt, w.material.as_ref(), &mut w.notes)?;
        // layers no deeper than the roughing tool may slot, nor than the
        // finishing tool may take off the terraces they leave (the latter
        // unless that would take more than twice the layers: a small
        // finishing tool then steps down itself)
        let step_down = r.step_down.unwrap_or_else(|| {
            let own = rc
                .cutting
                .as_ref()
                .map_or(rt.radius(), |c| c.step_down)
                .min(w.limits.layer(&rt));
            let fits_finish = w.limits.layer(&w.tool) - r.stock_to_leave;
            if fits_finish >= 0.5 * own {
                own.min(fits_finish)
            } else {
                own
            }
        });
        if !(step_down.is_finite() && step_down > 0.0) {
            bail!("--step-down {step_down}: must be positive");
        }
        if !(r.stock_to_leave.is_finite() && r.stock_to_leave >= 0.0) {
            bail!("--stock-to-leave {}: must be 0 or more", r.stock_to_leave);
        }
        // with --boundary subject, roughing cuts the level background to
        // its height (the finishing tool keeps to the subject): the
        // samples off the subject, but not the pad's
        let hf_main = w.hf_pad.as_ref().unwrap_or(&w.hf);
        let (z, zm) = (w.hf.samples(), hf_main.samples());
        let bg = w.subject.as_ref().map(|sub| {
            move |i: usize, j: usize| !*sub.inside.get(i, j) && zm.get(i, j) == z.get(i, j)
        });
        let params = rough::Params {
            tool: rt,
            stepover: rc.step,
            step_down,
            stock_to_leave: r.stock_to_leave,
            angle: self.angle,
            region: w.panel,
            material: None,
            background: bg
                .as_ref()
                .map(|f| f as &(dyn Fn(usize, usize) -> bool + Sync)),
        };
        let floor = w.floor;
        let passes =
            w.t.time("roughing", || rough::passes(hf_main, floor, &params))?;
        w.raw_points += passes.iter().map(|p| p.pts.len()).sum::<usize>();
        let passes =
            w.t.time("roughing check", || self.checked(hf_main, &rt, passes));
        let planned = &mut w.planned;
        let passes =
            w.t.time("stock", || planned.ramp_and_cut(passes, rt, false));
        let background = match &w.subject {
            Some(sub) => format!(
                ", the background cut to its level ({:.3} mm over the floor)",
                sub.level
            ),
            None => String::new(),
        };
        Ok(Some(Op {
            title: "roughing",
            tool: rt,
            zero: String::new(),
            settings,
            strategy: format!(
                "roughing, layers {step_down:.3} mm, stepover {:.3} mm, \
                 stock to leave {} mm{background}",
                rc.step, r.stock_to_leave
            ),
            passes,
        }))
    }
}
