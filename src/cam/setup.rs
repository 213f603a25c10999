//! The toolpath job's first stage: its settings checked and resolved
//! (machine, material, tools, stepover), and the planning state that every
//! later stage reads and adds to.

use super::{boundary, layout, stock, Boundary, Finish, Roughing, Stepover, ToolpathJob, ZZero};
use crate::bail;
use crate::cutter::dropcutter::HeightField;
use crate::error::Result;
use crate::gcode::emit::Settings;
use crate::machine::Machine;
use crate::materials::{Cutting, Material};
use crate::output::check_writable;
use crate::relief::Relief;
use crate::sim;
use crate::timing::Timings;
use crate::tool::Tool;
use std::path::PathBuf;

/// The finest stepover taken, mm.
pub(super) const MIN_STEPOVER: f64 = 1e-3;

/// The most cutter-location points a finishing pass may take (about a
/// minute of dropping on two cores, 0.7 GB held): a job never comes to
/// more moves than `simulate` reads (gcode::MAX_SEGMENTS). Past it the job
/// is refused with the figure.
pub(super) const MAX_CL_POINTS: f64 = crate::gcode::MAX_SEGMENTS as f64;

/// Size of the touch-off pad left by roughing, mm (a square).
const PAD: f64 = 8.0;

/// What a job's settings name, checked before any work: the machine, the
/// material, the tools and the finishing stepover (mm).
pub(super) struct Setup {
    pub machine: Machine,
    pub material: Option<Material>,
    pub tool: Tool,
    pub step: f64,
    /// The roughing tool asked for (an added one is chosen later).
    pub rough_tool: Option<Tool>,
    pub rest_tool: Option<Tool>,
}

/// How deep each tool may cut: (depth of cut, slotting depth) by the
/// material's cutting data for its working diameter.
pub(super) struct Limits {
    pub material: Material,
    /// The material's name as the user should read it.
    pub name: String,
    pub off: bool,
}

impl Limits {
    pub fn of(&self, t: &Tool) -> (f64, f64) {
        if self.off {
            return (f64::INFINITY, f64::INFINITY);
        }
        self.material_of(t)
    }
    /// The material's own limits, even with --allow-deep-cuts.
    pub fn material_of(&self, t: &Tool) -> (f64, f64) {
        self.material
            .cutting_for(t.working_diameter())
            .map_or((f64::INFINITY, f64::INFINITY), |c| {
                (c.step_down, c.slot_depth)
            })
    }
    /// The deepest a fresh full-width cut may go.
    pub fn layer(&self, t: &Tool) -> f64 {
        let (d, s) = self.of(t);
        d.min(s)
    }
}

/// The roughing the job does, asked for or added: its tool, the material's
/// cutting data for it, and its stepover (mm).
pub(super) struct RoughCut {
    pub asked: Roughing,
    pub tool: Tool,
    pub cutting: Option<Cutting>,
    pub step: f64,
}

/// The planning state the stages share: what setup resolved, the relief's
/// height field, the stock as planned so far, and the notes, points and
/// timings gathered on the way.
pub(super) struct Work {
    /// The relief as it lies on the machine (turned when asked).
    pub relief: Relief,
    pub machine: Machine,
    pub material: Option<Material>,
    pub limits: Limits,
    /// The finishing tool, its stepover (mm) and its feeds.
    pub tool: Tool,
    pub step: f64,
    pub finish_settings: Settings,
    pub plan: layout::Plan,
    pub hf: HeightField,
    /// `hf` with the touch-off pad standing: what roughing and the
    /// finishing tool's layers work round.
    pub hf_pad: Option<HeightField>,
    pub floor: f64,
    pub panel: [f64; 4],
    /// The planned stock's cell size (mm).
    pub cell: f64,
    pub planned: stock::Planned,
    pub subject: Option<boundary::Subject>,
    pub rough: Option<RoughCut>,
    pub rest_tool: Option<Tool>,
    /// The touch-off pad: centre and side (mm).
    pub pad: Option<(f64, f64, f64)>,
    /// How far beyond the pad's edge the finish keeps off (mm).
    pub finish_round: f64,
    pub notes: Vec<String>,
    /// CL points before merging, over all ops.
    pub raw_points: usize,
    pub t: Timings,
    /// Where a split job's roughing goes.
    pub rough_out: PathBuf,
}

impl Work {
    /// What roughing and the finishing tool's layers cut round.
    pub fn hf_main(&self) -> &HeightField {
        self.hf_pad.as_ref().unwrap_or(&self.hf)
    }

    /// Whether the finish keeps out of anywhere (the pad, the background).
    pub fn keeps_out(&self) -> bool {
        self.pad.is_some() || self.subject.is_some()
    }

    /// Off the pad by `round` (mm beyond its edge), and with --boundary
    /// subject on the subject and its margin.
    pub fn here(&self, x: f64, y: f64, round: f64) -> bool {
        let off_pad = self.pad.is_none_or(|p| {
            let k = p.2 / 2.0 + round;
            (x - p.0).abs() > k || (y - p.1).abs() > k
        });
        off_pad && self.subject.as_ref().is_none_or(|s| s.is_near(x, y))
    }
}

impl ToolpathJob {
    /// What can be refused before there is a relief: tolerance, Z zero,
    /// machine, material, tools, stepover and angle. `carve` asks first,
    /// so that a bad setting is one error line, not a relief's notes and
    /// then the error; `run` asks again.
    pub fn check(&self) -> Result<()> {
        self.setup().map(|_| ())
    }

    /// `check`'s findings, for `run`.
    pub(super) fn setup(&self) -> Result<Setup> {
        if !(self.tolerance > 0.0 && self.tolerance <= 1.0) {
            bail!("--tolerance {}: must be in (0, 1] mm", self.tolerance);
        }
        if self.z_zero == ZZero::Bottom && self.layout.stock.is_none() {
            bail!(
                "--z-zero bottom: the job needs the stock's thickness to reach its top; \
                 give it with --stock WxHxT"
            );
        }
        let machine = Machine::load(&self.machine)?;
        let material = self
            .material
            .as_deref()
            .map(crate::materials::find)
            .transpose()?;
        let tool = machine.tool_for("--tool", &self.tool)?;
        let rough_tool = self
            .rough
            .as_ref()
            .map(|r| machine.tool_for("--rough", &r.tool))
            .transpose()?;
        let rest_tool = self
            .rest
            .as_ref()
            .map(|r| machine.tool_for("--rest", &r.tool))
            .transpose()?;
        let step = self.finish_step(&tool, material.as_ref())?;
        if !(self.angle.is_finite() && self.angle.abs() <= 360.0) {
            bail!(
                "--angle {}: must be a number of degrees within -360..360",
                self.angle
            );
        }
        Ok(Setup {
            machine,
            material,
            tool,
            step,
            rough_tool,
            rest_tool,
        })
    }

    /// The finishing stepover in mm: asked for, else the material's for
    /// the tool, else 10% of its working diameter.
    fn finish_step(&self, tool: &Tool, material: Option<&Material>) -> Result<f64> {
        let cutting = material.and_then(|mt| mt.cutting_for(tool.working_diameter()));
        self.stepover
            .or(cutting.map(|c| Stepover::Percent(c.finish_stepover)))
            .unwrap_or(Stepover::Percent(10.0))
            .mm(tool)
    }

    /// The setup stage: outputs checked writable, settings resolved, the
    /// work a finish implies bounded, the panel laid out, the height field
    /// and stock planned, the roughing and the pad chosen.
    pub(super) fn work(&self, relief: &Relief) -> Result<Work> {
        let mut t = Timings::default();
        let rough_out = super::rough_path(&self.output);
        for o in [Some(&self.output), self.svg.as_ref(), self.preview.as_ref()]
            .into_iter()
            .flatten()
            .chain((self.split && self.rough.is_some()).then_some(&rough_out))
        {
            check_writable(o)?;
        }
        let setup = self.setup()?;
        let (machine, material, tool, step) =
            (setup.machine, setup.material, setup.tool, setup.step);
        let (rough_tool, rest_tool) = (setup.rough_tool, setup.rest_tool);
        let limits = Limits {
            material: match &material {
                Some(mt) => mt.clone(),
                None => crate::materials::find("wood")?,
            },
            name: self
                .material
                .clone()
                .unwrap_or_else(|| "wood (no --material given)".into()),
            off: self.allow_deep_cuts,
        };
        let mut notes: Vec<String> = Vec::new();
        let relief = layout::turned(relief, self.layout.rotate);
        let finish_settings = self.settings(&machine, &tool, material.as_ref(), &mut notes)?;
        self.bound_finish(&relief, step)?;
        let plan = self
            .layout
            .plan(&relief, &machine, finish_settings.safe_z, self.origin)?;
        let hf = t.time("heightfield", || HeightField::of_relief(&relief));
        let (pw, ph) = (relief.width_mm, relief.height_mm);
        self.check_rest(&tool, rest_tool.as_ref())?;
        let main_r = rough_tool.map_or(tool.radius(), |t| t.radius().min(tool.radius()));
        let rest_r = rest_tool.as_ref().map(|t| t.radius().max(0.05));
        let most = layout::cell_limit(main_r.max(0.05), rest_r);
        let cell = layout::cell(relief.pitch_mm(), most);
        let planned = stock::Planned::new(plan.stock_in_panel(cell, ph));
        let subject = (self.boundary == Boundary::Subject)
            .then(|| boundary::Subject::find(&relief, tool.working_diameter()))
            .transpose()?;
        let rough = self.roughing_chosen(&relief, &machine, &tool, &limits, subject.as_ref())?;
        if let Some(n) = &rough.1 {
            notes.push(n.clone());
        }
        let rough = rough
            .0
            .map(|asked| self.rough_cut(asked, &machine, material.as_ref()))
            .transpose()?;
        // the touch-off pad: Z0 for the next tool after roughing
        let pad = (rough.is_some() && self.z_zero == ZZero::Top)
            .then(|| layout::pad_site(&relief, PAD.min(0.25 * pw.min(ph))));
        let hf_pad = pad.map(|p| {
            let mut z = hf.samples().clone();
            layout::raise(&mut z, &relief, p, 0.0);
            HeightField::new(z, relief.pitch_mm())
        });
        // finishing keeps off the pad until the pad's own turn at the end:
        // off the pad, the strip beside it that rows a stepover apart
        // (roughing's, and the finishing tool's layers at 40%) leave
        // standing, and a tool radius round them. (Rows keep off the pad
        // where their tool would touch it, so the nearest row's reach can
        // stop up to a stepover short of it: on the 48 px demo a strip
        // 1.2 mm wide stood at the stock top beside the pad.)
        let strip = rough
            .as_ref()
            .map_or(0.0, |c| c.step)
            .max(0.4 * tool.working_diameter());
        if let Some(s) = &subject {
            notes.push(format!(
                "finishing over the subject and {:.2} mm round it: {:.0}% of the panel",
                tool.working_diameter(),
                100.0 * s.share()
            ));
        }
        Ok(Work {
            floor: -relief.depth_mm,
            panel: [0.0, 0.0, pw, ph],
            relief,
            machine,
            material,
            limits,
            tool,
            step,
            finish_settings,
            plan,
            hf,
            hf_pad,
            cell,
            planned,
            subject,
            rough,
            rest_tool,
            pad,
            finish_round: strip + tool.radius() + 0.5,
            notes,
            raw_points: 0,
            t,
            rough_out,
        })
    }

    /// The roughing's tool, the material's cutting data for it, and its
    /// stepover: asked for, else the material's, else 40%.
    fn rough_cut(
        &self,
        asked: Roughing,
        m: &Machine,
        material: Option<&Material>,
    ) -> Result<RoughCut> {
        let tool = m.tool_for("--rough", &asked.tool)?;
        let cutting = material.and_then(|mt| mt.cutting_for(tool.working_diameter()));
        let step = asked
            .stepover
            .or(cutting
                .as_ref()
                .map(|c| Stepover::Percent(c.rough_stepover)))
            .unwrap_or(Stepover::Percent(40.0))
            .mm(&tool)?;
        Ok(RoughCut {
            asked,
            tool,
            cutting,
            step,
        })
    }

    /// Refuse a raster finish that would take more CL points than allowed,
    /// before any of its work is done.
    fn bound_finish(&self, relief: &Relief, step: f64) -> Result<()> {
        let (pw, ph) = (relief.width_mm, relief.height_mm);
        let rows = (pw.hypot(ph) / step).ceil();
        let per_row = (pw.hypot(ph) / relief.pitch_mm().min(step)).ceil();
        if self.finish != Finish::Waterline && rows * per_row > MAX_CL_POINTS {
            bail!(
                "--stepover {step:.4e} mm: {rows:.0} rows of up to {per_row:.0} points ({:.0} million \
                 CL points), more than the {:.0} million allowed; raise --stepover",
                rows * per_row / 1e6,
                MAX_CL_POINTS / 1e6
            );
        }
        Ok(())
    }

    /// A rest tool must be smaller than the finishing tool, its threshold
    /// positive.
    fn check_rest(&self, tool: &Tool, rest_tool: Option<&Tool>) -> Result<()> {
        if let (Some(r), Some(rt)) = (&self.rest, rest_tool) {
            if rt.working_diameter() >= tool.working_diameter() {
                bail!(
                    "--rest {}: {} is not smaller than the finishing tool {}",
                    r.tool,
                    rt.spec(),
                    tool.spec()
                );
            }
            if !(r.threshold.is_finite() && r.threshold > 0.0) {
                bail!("--rest-threshold {}: must be positive, mm", r.threshold);
            }
        }
        Ok(())
    }

    /// Roughing: asked for, or added (with a note saying why) when the
    /// finishing tool may not cut the relief's depth in one pass or the
    /// background is to be cleared.
    fn roughing_chosen(
        &self,
        relief: &Relief,
        m: &Machine,
        tool: &Tool,
        limits: &Limits,
        subject: Option<&boundary::Subject>,
    ) -> Result<(Option<Roughing>, Option<String>)> {
        if let Some(r) = &self.rough {
            return Ok((Some(r.clone()), None));
        }
        if relief.depth_mm <= limits.layer(tool) + sim::engage::SLACK && subject.is_none() {
            return Ok((None, None));
        }
        let Some((name, spec)) = m.roughing_tool(tool) else {
            if subject.is_some() {
                bail!(
                    "--boundary subject: {} has no flat end mill in its tool table to clear \
                     the background; name one with --rough flat:D",
                    m.name
                );
            }
            return Ok((None, None));
        };
        let note = if subject.is_some() {
            format!(
                "roughing added with {name} ({spec}) to clear the background \
                 (--boundary subject)"
            )
        } else {
            format!(
                "roughing added with {name} ({spec}): the relief is {:.2} mm \
                 deep, {} may cut {:.2} mm at once in {}",
                relief.depth_mm,
                tool.spec(),
                limits.layer(tool),
                limits.name
            )
        };
        let r = Roughing {
            tool: name,
            step_down: None,
            stepover: None,
            stock_to_leave: 0.3,
        };
        Ok((Some(r), Some(note)))
    }
}
