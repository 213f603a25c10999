//! The finishing stage: the finishing tool's own layers wherever more is
//! left than it may cut at once, then its raster, waterlines and pencil
//! passes, the touch-off pad last.

use super::setup::Work;
use super::{order, Direction, Finish, Op, ToolpathJob};
use crate::bail;
use crate::error::Result;
use crate::toolpath::{waterline, Pass};

/// Title of the finishing tool's own layers (where more is left than it
/// may cut at once).
pub(super) const LAYERS: &str = "finishing-tool layers";

/// How sharply (times 1 / tool radius, per mm) the finishing tool's CL
/// surface must bend up across a valley for raster+waterline to run a
/// pencil pass along it: valleys the ball fits into with up to four radii
/// to spare, where a row running along the bottom leaves a cusp over the
/// scallop (Suzanne, 400 px at 60 mm, smooth shading, 2 mm ball: 0.0101
/// -> 0.0058 mm over the flat scallop for 2% more lines; at 0.5 and 1
/// the valley was missed).
const PENCIL_BEND: f64 = 0.25;

/// A keep-out test for the strategies.
type Keep<'a> = Option<&'a (dyn Fn(f64, f64) -> bool + Sync)>;

impl ToolpathJob {
    /// The finishing tool in layers wherever more is left than it may cut
    /// at once: what roughing could not reach, or all of a relief too deep
    /// for it when there is no roughing.
    pub(super) fn finishing_layers(&self, w: &mut Work) -> Option<Op> {
        let tool = w.tool;
        let fd = w.limits.layer(&tool);
        // the layers come closer than the finish, up to the pad and a tool
        // radius round it: they clear the strip the finish keeps off down
        // to what the finish may cut, where its rows beside the keep-out
        // reach in (a 1 mm ball's rows there met the roughing's 0.3 mm and
        // its terraces at full height: 0.521 mm, 0.5 allowed)
        let mut t = std::mem::take(&mut w.t);
        let layers_here = |x: f64, y: f64| w.here(x, y, tool.radius() + 0.5);
        let keep: Keep = w.keeps_out().then_some(&layers_here);
        let op = t.time("rest layers", || {
            self.rest_layers(
                w.hf_main(),
                &tool,
                &w.planned,
                w.panel,
                w.floor,
                fd,
                &w.finish_settings,
                keep,
            )
        });
        w.t = t;
        let op = op?;
        w.notes.push(format!(
            "{} steps down in layers of {:.2} mm where more than {fd:.2} mm is left",
            tool.spec(),
            op.1
        ));
        w.raw_points += op.0.iter().map(|p| p.pts.len()).sum::<usize>();
        let passes = w.planned.ramp_and_cut(op.0, tool, false);
        Some(Op {
            title: LAYERS,
            tool,
            zero: String::new(),
            settings: w.finish_settings.clone(),
            strategy: format!("layers {:.3} mm with the finishing tool", op.1),
            passes,
        })
    }

    /// The finish: raster and/or waterlines (and pencil passes beside a
    /// raster), off the pad, then the pad.
    pub(super) fn finishing(&self, w: &mut Work) -> Result<Op> {
        let (passes, mut what) = self.finish_passes(w)?;
        let tool = w.tool;
        let passes = match w.pad {
            Some(p) => {
                what.push(format!("then the touch-off pad at X{:.1} Y{:.1}", p.0, p.1));
                self.pad_last(w, passes, p)
            }
            None => {
                let planned = &mut w.planned;
                w.t.time("stock", || planned.ramp_and_cut(passes, tool, true))
            }
        };
        Ok(Op {
            title: "finishing",
            tool,
            zero: String::new(),
            settings: w.finish_settings.clone(),
            strategy: format!("finishing, {}", what.join(" + ")),
            passes,
        })
    }

    /// The finishing strategies' passes off the pad, and what they are.
    fn finish_passes(&self, w: &mut Work) -> Result<(Vec<Pass>, Vec<String>)> {
        let (tool, step, floor, safe) = (w.tool, w.step, w.floor, w.finish_settings.safe_z);
        let mut t = std::mem::take(&mut w.t);
        let finish_here = |x: f64, y: f64| w.here(x, y, w.finish_round);
        let keep_off_pad: Keep = w.keeps_out().then_some(&finish_here);
        let mut passes = Vec::new();
        let mut what = Vec::new();
        let mut raw_points = 0;
        if self.finish != Finish::Waterline {
            let (main, raw) = t.time("raster", || {
                self.raster(&w.hf, &tool, w.panel, floor, step, keep_off_pad)
            });
            raw_points += raw;
            passes.extend(main.into_iter().map(|pts| Pass { pts, clear_z: safe }));
            what.push(format!(
                "raster {}, angle {} deg, stepover {step:.4} mm",
                match self.direction {
                    None => "zigzag",
                    Some(Direction::Climb) => "one-way climb",
                    Some(Direction::Conventional) => "one-way conventional",
                },
                self.angle
            ));
        }
        if self.finish != Finish::Raster {
            let climb = self.direction != Some(Direction::Conventional);
            // beside a raster: waterlines on every slope of at least
            // GENTLEST, their levels close enough to lie at most a
            // stepover apart there
            let dz = if self.finish == Finish::RasterWaterline {
                step * waterline::GENTLEST
            } else {
                step
            };
            self.bound_waterlines(w, dz)?;
            let loops = t.time("waterline", || {
                self.waterlines(&w.hf, &tool, &w.relief, floor, dz, climb, keep_off_pad)
            });
            raw_points += loops.iter().map(Vec::len).sum::<usize>();
            let loops = t.time("order", || {
                if self.finish == Finish::RasterWaterline {
                    order::tour(loops, passes.last().and_then(|p| p.pts.last().copied()))
                } else {
                    loops
                }
            });
            passes.extend(loops.into_iter().map(|pts| Pass { pts, clear_z: safe }));
            what.push(format!(
                "waterline {}, Z step {dz:.4} mm",
                if climb { "climb" } else { "conventional" },
            ));
        }
        if self.finish == Finish::RasterWaterline {
            // beside a raster: one pencil pass along each valley the
            // waterlines leave to it, gentle ground on one side or both
            // (a row running along it leaves a cusp in its bottom)
            let keep = |x: f64, y: f64| keep_off_pad.is_none_or(|k| k(x, y));
            let start = passes.last().and_then(|p: &Pass| p.pts.last().copied());
            let (pencil, raw) = t.time("pencil", || {
                let kappa = PENCIL_BEND / tool.radius();
                self.pencil(&w.hf, &tool, w.panel, floor, kappa, &keep, start, safe)
            });
            raw_points += raw;
            what.push(format!("{} pencil passes along valleys", pencil.len()));
            passes.extend(pencil);
        }
        w.t = t;
        w.raw_points += raw_points;
        Ok((passes, what))
    }

    /// Refuse waterlines `dz` apart that would contour the CL grid more
    /// often than allowed.
    fn bound_waterlines(&self, w: &Work, dz: f64) -> Result<()> {
        let step = w.step;
        let levels = (w.relief.depth_mm / dz).ceil();
        let k = waterline::node_pitch(&w.hf, &w.tool) / w.hf.pitch;
        let grid = (w.relief.heights.w * w.relief.heights.h) as f64 / (k * k);
        if levels * grid > 10.0 * super::setup::MAX_CL_POINTS {
            bail!(
                "--stepover {step:.4e} mm: {levels:.0} waterline levels over {grid:.0} \
                 grid nodes, more than allowed; raise --stepover"
            );
        }
        Ok(())
    }

    /// The finish's passes cut into the planned stock, then the pad where
    /// it stands: the finishing tool's layers there, then its surface.
    fn pad_last(&self, w: &mut Work, passes: Vec<Pass>, p: (f64, f64, f64)) -> Vec<Pass> {
        let (tool, safe) = (w.tool, w.finish_settings.safe_z);
        let (pw, ph) = (w.relief.width_mm, w.relief.height_mm);
        let r = w.finish_round + 0.5;
        let win = [
            (p.0 - p.2 / 2.0 - r).max(0.0),
            (p.1 - p.2 / 2.0 - r).max(0.0),
            (p.0 + p.2 / 2.0 + r).min(pw),
            (p.1 + p.2 / 2.0 + r).min(ph),
        ];
        let planned = &mut w.planned;
        let mut out =
            w.t.time("stock", || planned.ramp_and_cut(passes, tool, true));
        let fd = w.limits.layer(&tool);
        let layers = self.rest_layers(
            &w.hf,
            &tool,
            &w.planned,
            win,
            w.floor,
            fd,
            &w.finish_settings,
            None,
        );
        if let Some(op) = layers {
            out.extend(w.planned.ramp_and_cut(op.0, tool, false));
        }
        let (surf, _) = self.raster(&w.hf, &tool, win, w.floor, w.step, None);
        let surf = surf
            .into_iter()
            .map(|pts| Pass { pts, clear_z: safe })
            .collect();
        out.extend(w.planned.ramp_and_cut(surf, tool, true));
        out
    }
}
