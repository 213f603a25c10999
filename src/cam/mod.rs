//! The `toolpath` command as one library call: a relief in, a GRBL job out:
//! optional roughing, then raster and/or waterline finishing, each move
//! checked against the exact swept tool before it is written.

use crate::bail;
use crate::error::Result;
use crate::gcode::emit::{Emitter, Settings};
use crate::machine::Machine;
use crate::output::{check_writable, Outputs};
use crate::relief::Relief;
use crate::sim;
use crate::timing::Timings;
use crate::tool::Tool;
use crate::toolpath::dropcutter::HeightField;
use crate::toolpath::{path, pencil, raster, rough, waterline, Pass};
use glam::DVec3;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

mod boundary;
pub mod cutout;
mod judge;
pub mod layout;
mod order;
pub mod rest;
mod stock;
pub mod tile;
mod view;

/// Where the job's X0 Y0 is on the panel.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Origin {
    LowerLeft,
    Center,
}

/// Finishing strategy.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Finish {
    Raster,
    Waterline,
    /// Raster everywhere, and waterlines wherever the CL surface slopes by
    /// more than 1 in 10, where rows crossing the slope or a crease along
    /// them leave wide scallops.
    #[value(name = "raster+waterline")]
    RasterWaterline,
}

/// Cutting direction (M3, clockwise spindle): climb keeps the material on
/// the tool's right. `None` in a job: zigzag rasters, climb waterlines.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Direction {
    Climb,
    Conventional,
}

/// Roughing before the finish.
#[derive(Clone, Debug)]
pub struct Roughing {
    /// Tool spec or tool-table name.
    pub tool: String,
    /// Layer depth, mm; `None` = the material's, else half the diameter.
    pub step_down: Option<f64>,
    /// `None` = the material's, else 40%.
    pub stepover: Option<Stepover>,
    /// Material left on the relief for the finish, mm.
    pub stock_to_leave: f64,
}

/// Distance between raster rows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Stepover {
    Mm(f64),
    /// Percent of the tool diameter.
    Percent(f64),
    /// Scallop height (mm) left by a ball on a flat.
    Scallop(f64),
}

impl Stepover {
    pub fn parse(s: &str) -> std::result::Result<Stepover, String> {
        let t = s.trim();
        let (v, pct) = match t.strip_suffix('%') {
            Some(p) => (p, true),
            None => (t.strip_suffix("mm").unwrap_or(t), false),
        };
        let v: f64 = v
            .trim()
            .parse()
            .map_err(|_| format!("'{s}': expected MM or PERCENT%"))?;
        Ok(if pct {
            Stepover::Percent(v)
        } else {
            Stepover::Mm(v)
        })
    }

    /// The stepover in mm. A percentage and a scallop go by the tool's
    /// working diameter: a tapered ball's tip, not its shank.
    pub fn mm(&self, tool: &Tool) -> Result<f64> {
        let d = tool.working_diameter();
        let v = match *self {
            Stepover::Mm(v) => v,
            Stepover::Percent(p) => p / 100.0 * d,
            Stepover::Scallop(h) => {
                let r = match *tool {
                    Tool::Ball { d } => d / 2.0,
                    Tool::TaperBall { tip_r, .. } => tip_r,
                    _ => bail!("--scallop needs a ball or tapered ball tool"),
                };
                if !(h > 0.0 && h < r) {
                    bail!("--scallop {h}: must be between 0 and the ball radius");
                }
                2.0 * (r * r - (r - h) * (r - h)).sqrt()
            }
        };
        let most = 2.0 * tool.radius();
        if !(v.is_finite() && v >= MIN_STEPOVER && v <= most) {
            bail!(
                "stepover {v:.4e} mm: must be {MIN_STEPOVER} mm to the tool diameter ({most} mm)"
            );
        }
        Ok(v)
    }
}

/// Where the operator sets Z0.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ZZero {
    /// On the stock top; after roughing, on the touch-off pad it leaves.
    Top,
    /// On the stock's bottom (the spoilboard), which survives any roughing.
    Bottom,
}

/// Where the finishing tool works.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Boundary {
    /// The whole panel.
    Panel,
    /// The subject and a tool's diameter round it; the roughing tool
    /// clears the background at its level.
    Subject,
}

/// Units of the G-code.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Units {
    Mm,
    In,
}

#[derive(Clone, Debug)]
pub struct ToolpathJob {
    /// Finishing tool: a spec or a name in the machine's tool table.
    pub tool: String,
    pub finish: Finish,
    pub direction: Option<Direction>,
    /// `None` = the material's finishing stepover, else 10%.
    pub stepover: Option<Stepover>,
    pub angle: f64,
    /// Merge tolerance, mm.
    pub tolerance: f64,
    /// Arcs (G2/G3) where runs of points fit a circle.
    pub arcs: bool,
    /// Cutting feed, mm/min; `None` = the material's, else 1000; within
    /// the machine's XY limit.
    pub feed: Option<f64>,
    /// Plunge feed, mm/min; `None` = the material's, else 300.
    pub plunge_feed: Option<f64>,
    /// Spindle speed; `None` = the material's, else 18000, within range.
    pub rpm: Option<f64>,
    /// Travel height above the stock top, mm.
    pub safe_z: f64,
    pub machine: String,
    pub material: Option<String>,
    pub origin: Origin,
    pub rough: Option<Roughing>,
    /// A smaller tool after the finish, where it left too much.
    pub rest: Option<rest::Rest>,
    /// Roughing in its own file (NAME-rough.nc) instead of an M0 tool change.
    pub split: bool,
    /// Write cuts deeper than the tools' limits (and say so).
    pub allow_deep_cuts: bool,
    pub z_zero: ZZero,
    pub units: Units,
    /// The panel's layout on the stock and the machine.
    pub layout: layout::Layout,
    /// A profile round the panel through the stock, on tabs.
    pub cutout: Option<cutout::Cutout>,
    pub boundary: Boundary,
    pub output: PathBuf,
    /// Top view of the toolpath.
    pub svg: Option<PathBuf>,
    /// The simulated cut, shaded.
    pub preview: Option<PathBuf>,
    /// Light for the preview: azimuth and elevation, degrees.
    pub light: Option<(f64, f64)>,
    /// Name of the relief in the header.
    pub relief_name: String,
}

pub struct CamSummary {
    /// G-code lines over all files.
    pub lines: usize,
    /// CL points before merging (one line each if unmerged).
    pub raw_points: usize,
    pub time_s: f64,
    pub stepover_mm: f64,
    /// Every file written, the job first.
    pub written: Vec<PathBuf>,
    /// What the job chose or capped, for the user (also in the header).
    pub notes: Vec<String>,
    /// What the simulated job asks of its tools.
    pub engagement: sim::Engagement,
    /// Simulated residual material: max and mean, mm.
    pub residual: (f64, f64),
    /// Simulated deepest gouge, mm.
    pub gouge: f64,
    /// Rapid and cutting travel, mm.
    pub rapid_mm: f64,
    pub cut_mm: f64,
    pub timings: Timings,
}

/// One file of a job: where it goes, its ops, its frame, its header notes.
type JobFile = (PathBuf, Vec<Op>, layout::Plan, Vec<String>);

/// One tool's share of the job.
#[derive(Clone)]
pub(crate) struct Op {
    title: &'static str,
    tool: Tool,
    /// What the operator zeroes Z on when this op's tool goes in.
    zero: String,
    settings: Settings,
    strategy: String,
    passes: Vec<Pass>,
}

/// How deep each tool may cut: (depth of cut, slotting depth) by the
/// material's cutting data for its working diameter.
struct Limits {
    material: crate::materials::Material,
    /// The material's name as the user should read it.
    name: String,
    off: bool,
}

impl Limits {
    fn of(&self, t: &Tool) -> (f64, f64) {
        if self.off {
            return (f64::INFINITY, f64::INFINITY);
        }
        self.material_of(t)
    }
    /// The material's own limits, even with --allow-deep-cuts.
    fn material_of(&self, t: &Tool) -> (f64, f64) {
        self.material
            .cutting_for(t.working_diameter())
            .map_or((f64::INFINITY, f64::INFINITY), |c| {
                (c.step_down, c.slot_depth)
            })
    }
    /// The deepest a fresh full-width cut may go.
    fn layer(&self, t: &Tool) -> f64 {
        let (d, s) = self.of(t);
        d.min(s)
    }
}

/// The finest stepover taken, mm.
const MIN_STEPOVER: f64 = 1e-3;

/// The most cutter-location points a finishing pass may take (about a
/// minute of dropping on two cores, 0.7 GB held): a job never comes to
/// more moves than `simulate` reads (gcode::MAX_SEGMENTS). Past it the job
/// is refused with the figure.
const MAX_CL_POINTS: f64 = crate::gcode::MAX_SEGMENTS as f64;

/// Size of the touch-off pad left by roughing, mm (a square).
const PAD: f64 = 8.0;

impl ToolpathJob {
    pub fn run(&self, relief: &Relief) -> Result<CamSummary> {
        let mut t = Timings::default();
        let rough_out = rough_path(&self.output);
        for o in [Some(&self.output), self.svg.as_ref(), self.preview.as_ref()]
            .into_iter()
            .flatten()
            .chain((self.split && self.rough.is_some()).then_some(&rough_out))
        {
            check_writable(o)?;
        }
        if !(self.tolerance > 0.0 && self.tolerance <= 1.0) {
            bail!("--tolerance {}: must be in (0, 1] mm", self.tolerance);
        }
        if self.z_zero == ZZero::Bottom && self.layout.stock.is_none() {
            bail!(
                "--z-zero bottom: the job needs the stock's thickness to reach its top; \
                 give it with --stock WxHxT"
            );
        }
        let m = Machine::load(&self.machine)?;
        let material = self
            .material
            .as_deref()
            .map(crate::materials::find)
            .transpose()?;
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
        let relief = &layout::turned(relief, self.layout.rotate);
        let tool = m.tool(&self.tool)?;
        let finish_settings = self.settings(&m, &tool, material.as_ref(), &mut notes)?;
        let cutting = material
            .as_ref()
            .and_then(|mt| mt.cutting_for(tool.working_diameter()));
        let stepover = self
            .stepover
            .or(cutting
                .as_ref()
                .map(|c| Stepover::Percent(c.finish_stepover)))
            .unwrap_or(Stepover::Percent(10.0));
        let step = stepover.mm(&tool)?;
        if !(self.angle.is_finite() && self.angle.abs() <= 360.0) {
            bail!(
                "--angle {}: must be a number of degrees within -360..360",
                self.angle
            );
        }
        // the work a finish implies, before any of it is done
        let (pw0, ph0) = (relief.width_mm, relief.height_mm);
        let rows = (pw0.hypot(ph0) / step).ceil();
        let per_row = (pw0.hypot(ph0) / relief.pitch_mm().min(step)).ceil();
        if self.finish != Finish::Waterline && rows * per_row > MAX_CL_POINTS {
            bail!(
                "--stepover {step:.4e} mm: {rows:.0} rows of up to {per_row:.0} points ({:.0} million \
                 CL points), more than the {:.0} million allowed; raise --stepover",
                rows * per_row / 1e6,
                MAX_CL_POINTS / 1e6
            );
        }
        let plan = self
            .layout
            .plan(relief, &m, finish_settings.safe_z, self.origin)?;
        let hf = t.time("heightfield", || {
            HeightField::new(
                relief.heights.map(|v| *v as f64 - relief.depth_mm),
                relief.pitch_mm(),
            )
        });
        let floor = -relief.depth_mm;
        let (pw, ph) = (relief.width_mm, relief.height_mm);
        let panel = [0.0, 0.0, pw, ph];
        let rest_tool = self.rest.as_ref().map(|r| m.tool(&r.tool)).transpose()?;
        if let (Some(r), Some(rt)) = (&self.rest, &rest_tool) {
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
        let min_r = [
            self.rough.as_ref().map(|r| m.tool(&r.tool)).transpose()?,
            rest_tool,
        ]
        .into_iter()
        .flatten()
        .fold(tool.radius(), |a, t| a.min(t.radius()));
        let cell = layout::cell(relief.pitch_mm(), min_r.max(0.05));
        let mut planned = stock::Planned::new(plan.stock_in_panel(cell, ph));
        let mut ops: Vec<Op> = Vec::new();
        let mut raw_points = 0;
        // roughing: asked for, or added when the finishing tool may not
        // cut the relief's depth in one pass
        let subject = (self.boundary == Boundary::Subject)
            .then(|| boundary::Subject::find(relief, tool.working_diameter()))
            .transpose()?;
        let rough = match &self.rough {
            Some(r) => Some(r.clone()),
            None if relief.depth_mm > limits.layer(&tool) + sim::engage::SLACK
                || subject.is_some() =>
            {
                match m.roughing_tool(&tool) {
                    Some((name, spec)) => {
                        notes.push(if subject.is_some() {
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
                                limits.layer(&tool),
                                limits.name
                            )
                        });
                        Some(Roughing {
                            tool: name,
                            step_down: None,
                            stepover: None,
                            stock_to_leave: 0.3,
                        })
                    }
                    None if subject.is_some() => bail!(
                        "--boundary subject: {} has no flat end mill in its tool table to clear \
                         the background; name one with --rough flat:D",
                        m.name
                    ),
                    None => None,
                }
            }
            None => None,
        };
        // the roughing tool, its material entry and its stepover (its
        // rows' and layers' distance apart, which the pad's keep-out needs)
        let rough_cut = match &rough {
            Some(r) => {
                let rt = m.tool(&r.tool)?;
                let rc = material
                    .as_ref()
                    .and_then(|mt| mt.cutting_for(rt.working_diameter()));
                let rstep = r
                    .stepover
                    .or(rc.as_ref().map(|c| Stepover::Percent(c.rough_stepover)))
                    .unwrap_or(Stepover::Percent(40.0))
                    .mm(&rt)?;
                Some((r, rt, rc, rstep))
            }
            None => None,
        };
        // the touch-off pad: Z0 for the next tool after roughing
        let pad = (rough.is_some() && self.z_zero == ZZero::Top)
            .then(|| layout::pad_site(relief, PAD.min(0.25 * pw.min(ph))));
        let hf_pad = pad.map(|p| {
            let mut z = hf.samples().clone();
            layout::raise(&mut z, relief, p, 0.0);
            HeightField::new(z, relief.pitch_mm())
        });
        let hf_main = hf_pad.as_ref().unwrap_or(&hf);
        // finishing keeps off the pad until the pad's own turn at the end:
        // off the pad, the strip beside it that rows a stepover apart
        // (roughing's, and the finishing tool's layers at 40%) leave
        // standing, and a tool radius round them. (Rows keep off the pad
        // where their tool would touch it, so the nearest row's reach can
        // stop up to a stepover short of it: on the 48 px demo a strip
        // 1.2 mm wide stood at the stock top beside the pad.)
        let strip = rough_cut
            .as_ref()
            .map_or(0.0, |c| c.3)
            .max(0.4 * tool.working_diameter());
        let keep_out = pad.map(|p| p.2 / 2.0 + strip + tool.radius() + 0.5);
        let off_pad = |x: f64, y: f64| match (pad, keep_out) {
            (Some(p), Some(k)) => (x - p.0).abs() > k || (y - p.1).abs() > k,
            _ => true,
        };
        // ... and, with --boundary subject, to the subject and its margin
        let finish_here =
            |x: f64, y: f64| off_pad(x, y) && subject.as_ref().is_none_or(|s| s.is_near(x, y));
        let keep_off_pad: Option<&(dyn Fn(f64, f64) -> bool + Sync)> =
            (pad.is_some() || subject.is_some()).then_some(&finish_here);
        if let Some(s) = &subject {
            notes.push(format!(
                "finishing over the subject and {:.2} mm round it: {:.0}% of the panel",
                tool.working_diameter(),
                100.0 * s.share()
            ));
        }
        if let Some((r, rt, rc, rstep)) = rough_cut {
            let settings = self.settings(&m, &rt, material.as_ref(), &mut notes)?;
            // layers no deeper than the roughing tool may slot, nor than
            // the finishing tool may take off the terraces they leave
            // (the latter unless that would take more than twice the
            // layers: a small finishing tool then steps down itself)
            let step_down = r.step_down.unwrap_or_else(|| {
                let own = rc
                    .as_ref()
                    .map_or(rt.radius(), |c| c.step_down)
                    .min(limits.layer(&rt));
                let fits_finish = limits.layer(&tool) - r.stock_to_leave;
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
            // its height (the finishing tool keeps to the subject)
            let lowered = subject.as_ref().map(|sub| {
                let (z, zm) = (hf.samples(), hf_main.samples());
                let bg = |i: usize, j: usize| !*sub.inside.get(i, j) && zm.get(i, j) == z.get(i, j);
                let low = (0..z.h)
                    .flat_map(|j| (0..z.w).map(move |i| (i, j)))
                    .filter(|&(i, j)| bg(i, j))
                    .map(|(i, j)| *z.get(i, j))
                    .fold(f64::INFINITY, f64::min);
                (rough::lower_background(hf_main, r.stock_to_leave, bg), low)
            });
            let params = rough::Params {
                tool: rt,
                stepover: rstep,
                step_down,
                stock_to_leave: r.stock_to_leave,
                angle: self.angle,
                region: panel,
                material: None,
                background: lowered.as_ref().map(|l| l.1).filter(|z| z.is_finite()),
            };
            let hf_rough = lowered.as_ref().map_or(hf_main, |l| &l.0);
            let passes = t.time("roughing", || rough::passes(hf_rough, floor, &params))?;
            raw_points += passes.iter().map(|p| p.pts.len()).sum::<usize>();
            let passes = t.time("roughing check", || self.checked(hf_main, &rt, passes));
            let passes = t.time("stock", || planned.ramp_and_cut(passes, rt, false));
            let background = match &subject {
                Some(sub) => format!(
                    ", the background cut to its level ({:.3} mm over the floor)",
                    sub.level
                ),
                None => String::new(),
            };
            ops.push(Op {
                title: "roughing",
                tool: rt,
                zero: String::new(),
                settings: settings.clone(),
                strategy: format!(
                    "roughing, layers {step_down:.3} mm, stepover {rstep:.3} mm, \
                     stock to leave {} mm{background}",
                    r.stock_to_leave
                ),
                passes,
            });
        }
        // the finishing tool in layers wherever more is left than it may
        // cut at once: what roughing could not reach, or all of a relief
        // too deep for it when there is no roughing
        let fd = limits.layer(&tool);
        if let Some(op) = t.time("rest layers", || {
            self.rest_layers(
                hf_main,
                &tool,
                &planned,
                panel,
                floor,
                fd,
                &finish_settings,
                keep_off_pad,
            )
        }) {
            notes.push(format!(
                "{} steps down in layers of {:.2} mm where more than {fd:.2} mm is left",
                tool.spec(),
                op.1
            ));
            raw_points += op.0.iter().map(|p| p.pts.len()).sum::<usize>();
            let passes = planned.ramp_and_cut(op.0, tool, false);
            ops.push(Op {
                title: "finishing-tool layers",
                tool,
                zero: String::new(),
                settings: finish_settings.clone(),
                strategy: format!("layers {:.3} mm with the finishing tool", op.1),
                passes,
            });
        }
        let safe = finish_settings.safe_z;
        let mut passes = Vec::new();
        let mut what = Vec::new();
        if self.finish != Finish::Waterline {
            let (main, raw) = t.time("raster", || {
                self.raster(&hf, &tool, panel, floor, step, keep_off_pad)
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
            // each level contours the whole CL grid
            let levels = (relief.depth_mm / dz).ceil();
            let k = waterline::node_pitch(&hf, &tool) / hf.pitch;
            let grid = (relief.heights.w * relief.heights.h) as f64 / (k * k);
            if levels * grid > 10.0 * MAX_CL_POINTS {
                bail!(
                    "--stepover {step:.4e} mm: {levels:.0} waterline levels over {grid:.0} \
                     grid nodes, more than allowed; raise --stepover"
                );
            }
            let loops = t.time("waterline", || {
                self.waterlines(&hf, &tool, relief, floor, dz, climb, keep_off_pad)
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
        // the pad goes last: layers where it stands, then the surface
        if let Some(p) = pad {
            let r = keep_out.unwrap_or(0.0) - p.2 / 2.0 + 0.5;
            let win = [
                (p.0 - p.2 / 2.0 - r).max(0.0),
                (p.1 - p.2 / 2.0 - r).max(0.0),
                (p.0 + p.2 / 2.0 + r).min(pw),
                (p.1 + p.2 / 2.0 + r).min(ph),
            ];
            let mut pp = Vec::new();
            let fin = t.time("stock", || planned.ramp_and_cut(passes, tool, true));
            pp.extend(fin);
            if let Some(op) =
                self.rest_layers(&hf, &tool, &planned, win, floor, fd, &finish_settings, None)
            {
                pp.extend(planned.ramp_and_cut(op.0, tool, false));
            }
            let (surf, _) = self.raster(&hf, &tool, win, floor, step, None);
            pp.extend(
                planned.ramp_and_cut(
                    surf.into_iter()
                        .map(|pts| Pass { pts, clear_z: safe })
                        .collect(),
                    tool,
                    true,
                ),
            );
            what.push(format!("then the touch-off pad at X{:.1} Y{:.1}", p.0, p.1));
            passes = pp;
        } else {
            passes = t.time("stock", || planned.ramp_and_cut(passes, tool, true));
        }
        ops.push(Op {
            title: "finishing",
            tool,
            zero: String::new(),
            settings: finish_settings,
            strategy: format!("finishing, {}", what.join(" + ")),
            passes,
        });
        if let (Some(r), Some(rt)) = (&self.rest, rest_tool) {
            let subject = subject.as_ref();
            let op = t.time("rest", || {
                self.rest_op(
                    r,
                    (&tool, rt),
                    (&hf, relief, floor),
                    &mut planned,
                    subject,
                    (&m, material.as_ref(), &limits),
                    &mut notes,
                    &mut raw_points,
                )
            })?;
            ops.extend(op);
        }
        // the cutout last: the panel stays held by the whole stock while
        // it is carved
        if let Some(c) = &self.cutout {
            ops.push(self.cutout_op(
                c,
                &m,
                &tool,
                &rough,
                &plan,
                relief,
                &limits,
                material.as_ref(),
                &mut planned,
                &mut notes,
            )?);
        }
        // emit: one file, tool changes with M0, or one file per tool
        let shift = plan.shift;
        let z_shift = match self.z_zero {
            ZZero::Top => 0.0,
            ZZero::Bottom => plan.stock.2,
        };
        let zero = match (self.z_zero, pad) {
            (ZZero::Bottom, _) => "set Z0 on the spoilboard (the stock's bottom)".to_string(),
            (ZZero::Top, Some(p)) => format!(
                "set Z0 on the pad's top at X{:.1} Y{:.1} (the stock top)",
                p.0 + shift.x,
                p.1 + shift.y
            ),
            (ZZero::Top, None) => "set Z0 on the stock top again".to_string(),
        };
        for op in &mut ops {
            op.zero = match (self.z_zero, op.title) {
                (ZZero::Top, "cutout") => "set Z0 on the stock top beside the panel".into(),
                _ => zero.clone(),
            };
        }
        let n_rough = ops.iter().take_while(|o| o.title == "roughing").count();
        let mut header_notes = notes.clone();
        if let Some(p) = pad {
            header_notes.push(format!(
                "touch-off pad: {:.0} mm square at X{:.1} Y{:.1}, left at the stock top by roughing, cut last",
                p.2,
                p.0 + shift.x,
                p.1 + shift.y
            ));
        }
        // the files: one job, a split job, or one job per tile; each with
        // its own frame and header notes
        let files: Vec<JobFile> = match self.layout.tile {
            Some(size) => t.time("tiles", || {
                self.tiled(
                    ops,
                    relief,
                    &plan,
                    size,
                    (&tool, cell),
                    &header_notes,
                    z_shift,
                )
            })?,
            None if self.split && n_rough > 0 => {
                let rest = ops.split_off(n_rough);
                vec![
                    (rough_out, ops, plan.clone(), header_notes.clone()),
                    (
                        self.output.clone(),
                        rest,
                        plan.clone(),
                        header_notes.clone(),
                    ),
                ]
            }
            None => vec![(self.output.clone(), ops, plan.clone(), header_notes.clone())],
        };
        let mut texts = Vec::new();
        for (file, group, fplan, fnotes) in &files {
            let text = t.time("g-code", || {
                self.emit(group, relief, fplan, &m, z_shift, fnotes)
            });
            texts.push((file.clone(), text));
        }
        // the simulator judges the job: depth of cut, plunges, residual;
        // every file placed in the one job's frame
        let progs: Vec<crate::gcode::Program> = texts
            .iter()
            .map(|(_, text)| crate::gcode::program(text))
            .collect::<Result<_>>()?;
        for ((file, _), prog) in texts.iter().zip(&progs) {
            judge::fits_travel(prog, &m, file)?;
        }
        let progs: Vec<crate::gcode::Program> = progs
            .iter()
            .zip(&files)
            .map(|(p, f)| p.moved(plan.shift - f.2.shift))
            .collect();
        let mut judged = t.time("judge", || judge::run(&progs, relief, &plan, z_shift, cell))?;
        let groups = &files;
        if let Some((k, o)) = judge::first_over(&judged, &progs, &|tl| limits.of(tl)) {
            let what = format!(
                "{}line {}: {} cuts {:.3} mm deep{} (allowed {:.3} mm in {})",
                if groups.len() > 1 {
                    format!("{}, ", groups[k].0.display())
                } else {
                    String::new()
                },
                o.line,
                o.tool.spec(),
                o.depth,
                if o.slotting { " at full width" } else { "" },
                o.limit,
                limits.name
            );
            bail!("{what}: rough first (--rough), lower --step-down, or pass --allow-deep-cuts");
        }
        if self.finish == Finish::Waterline {
            notes.push(format!(
                "waterline alone leaves up to {:.3} mm (mean {:.3} mm) on gentle slopes, \
                 where its loops lie far apart; raster+waterline finishes them",
                judged.residual.0, judged.residual.1
            ));
        }
        // what goes into each file's header now that it is judged: the
        // notes not yet there and its time; the lines reported move on by
        // as many lines as that takes
        let mut extra: Vec<String> = notes
            .iter()
            .filter(|n| !header_notes.contains(n))
            .cloned()
            .collect();
        let times: Vec<f64> = progs.iter().map(|p| sim::estimate_time(p, &m)).collect();
        let estimate = |secs: f64| format!("estimated time: {} on {}", sim::hms(secs), m.name);
        let added =
            |extra: &[String], secs: f64| comment_lines(extra) + comment_lines(&[estimate(secs)]);
        if self.allow_deep_cuts {
            if let Some((k, o)) = judge::first_over(&judged, &progs, &|tl| limits.material_of(tl)) {
                let note = |by: usize| {
                    format!(
                        "--allow-deep-cuts: line {} cuts {:.3} mm deep with {} (limit {:.3} mm)",
                        o.line + by,
                        o.depth,
                        o.tool.spec(),
                        o.limit
                    )
                };
                // the note's own lines count: settle the number twice
                let mut by = added(&extra, times[k]);
                for _ in 0..2 {
                    let with: Vec<String> = extra.iter().cloned().chain([note(by)]).collect();
                    by = added(&with, times[k]);
                }
                notes.push(note(by));
                extra.push(note(by));
            }
        }
        judged.engagement.shift_lines(added(&extra, times[0]));
        let mut out = Outputs::default();
        let (mut lines, mut time_s) = (0, 0.0);
        let mut written = Vec::new();
        for ((file, text), secs) in texts.into_iter().zip(times) {
            time_s += secs;
            let mut text = with_comments(text, &extra);
            text = with_comments(text, &[estimate(secs)]);
            // counted as written: a wrapped comment takes several lines
            lines += text.lines().count();
            out.add(&file, text.into_bytes());
            written.push(file);
        }
        // the job comes first in the list
        written.rotate_right(1);
        if let Some(svg) = &self.svg {
            let doc = t.time("svg", || view::top_view(&progs, relief, &plan, z_shift));
            out.add(svg, doc.into_bytes());
            written.push(svg.clone());
        }
        if let Some(pv) = &self.preview {
            let png = t.time("preview", || {
                view::simulated_preview(&judged, relief, self.light)
            });
            out.add(pv, png?);
            written.push(pv.clone());
        }
        t.time("write", || out.commit())?;
        let (rapid_mm, cut_mm) = judge::travel(&progs);
        Ok(CamSummary {
            lines,
            raw_points,
            time_s,
            stepover_mm: step,
            written,
            notes,
            engagement: judged.engagement,
            residual: judged.residual,
            gouge: judged.gouge,
            rapid_mm,
            cut_mm,
            timings: t,
        })
    }

    /// The job's ops cut into tiles of at most `size` (row by row from the
    /// lower-left), one file each: every pass clipped to its tile (the
    /// clearing ops to the tile grown by the finishing tool's radius and
    /// a little, so that finishing along a border meets cleared stock),
    /// ramped in again where it now starts in material, travelling at
    /// safe Z; X0 Y0 at the tile's lower-left corner.
    #[allow(clippy::too_many_arguments)]
    fn tiled(
        &self,
        ops: Vec<Op>,
        relief: &Relief,
        plan: &layout::Plan,
        (tw, th): (f64, f64),
        (finish, cell): (&Tool, f64),
        notes: &[String],
        z_shift: f64,
    ) -> Result<Vec<JobFile>> {
        if !(tw.is_finite() && th.is_finite() && tw > 0.0 && th > 0.0) {
            bail!("--tile {tw}x{th}: sizes must be positive");
        }
        if self.cutout.is_some() {
            bail!("--tile with --cutout: cut the tiles out one by one is not supported; leave out --cutout");
        }
        if self.split {
            bail!(
                "--tile with --split: every tile is a file of its own already; leave out --split"
            );
        }
        if self.z_zero == ZZero::Top && ops.iter().any(|o| o.tool != ops[0].tool) {
            bail!(
                "--tile: the job changes tools, and the stock top does not survive roughing in \
                 every tile; zero Z on the spoilboard: --z-zero bottom --stock WxHxT"
            );
        }
        let (pw, ph) = (relief.width_mm, relief.height_mm);
        let tiles = tile::grid(pw, ph, tw, th);
        let grow = finish.radius() + 0.5;
        let mut planned = stock::Planned::new(plan.stock_in_panel(cell, ph));
        let stem = self
            .output
            .file_stem()
            .map_or("job".into(), |s| s.to_string_lossy().to_string());
        let (nx, ny) = tiles.last().map_or((1, 1), |t| t.1);
        let mut out = Vec::new();
        let mut prev: Option<[f64; 4]> = None;
        for (rect, (c, r)) in &tiles {
            let mut tile_ops = Vec::new();
            for op in &ops {
                let g = if op.title == "finishing" { 0.0 } else { grow };
                let around = [rect[0] - g, rect[1] - g, rect[2] + g, rect[3] + g];
                let safe = op.settings.safe_z;
                let pieces: Vec<Pass> = op
                    .passes
                    .iter()
                    .flat_map(|p| tile::clip(&p.pts, around))
                    .map(|pts| Pass { pts, clear_z: safe })
                    .collect();
                let passes = planned.ramp_and_cut(pieces, op.tool, true);
                if !passes.is_empty() {
                    tile_ops.push(Op {
                        passes,
                        ..op.clone()
                    });
                }
            }
            if tile_ops.is_empty() {
                continue;
            }
            let tplan = layout::Plan {
                shift: DVec3::new(-rect[0], -rect[1], 0.0),
                ..plan.clone()
            };
            let (sx, sy) = (rect[0] + plan.panel_at.0, rect[1] + plan.panel_at.1);
            let mut n = notes.to_vec();
            n.push(format!(
                "tile {c},{r} of {nx} x {ny}: panel X{:.2}..{:.2} Y{:.2}..{:.2}; X0 Y0 at its \
                 lower-left corner, X{sx:.2} Y{sy:.2} from the stock's lower-left corner{}",
                rect[0],
                rect[2],
                rect[1],
                rect[3],
                match prev {
                    Some(p) => format!(
                        "; from the last tile, move the stock by X{:.2} Y{:.2} (or zero X and Y there)",
                        -(rect[0] - p[0]),
                        -(rect[1] - p[1])
                    ),
                    None => String::new(),
                }
            ));
            if z_shift > 0.0 {
                n.push("Z0 stays on the spoilboard from tile to tile".into());
            }
            prev = Some(*rect);
            let file = self.output.with_file_name(format!("{stem}-tile{c}-{r}.nc"));
            out.push((file, tile_ops, tplan, n));
        }
        Ok(out)
    }

    /// The cutout with the job's roughing tool, else the machine's
    /// largest flat end mill up to 1/4 in, else the finishing tool; in
    /// layers no deeper than it may slot.
    #[allow(clippy::too_many_arguments)]
    fn cutout_op(
        &self,
        c: &cutout::Cutout,
        m: &Machine,
        finish: &Tool,
        rough: &Option<Roughing>,
        plan: &layout::Plan,
        relief: &Relief,
        limits: &Limits,
        material: Option<&crate::materials::Material>,
        planned: &mut stock::Planned,
        notes: &mut Vec<String>,
    ) -> Result<Op> {
        let name = match rough {
            Some(r) => Some(r.tool.clone()),
            None => m.roughing_tool(finish).map(|(n, _)| n),
        };
        let ct = match &name {
            Some(n) => m.tool(n)?,
            None => *finish,
        };
        let d = ct.working_diameter();
        let (pw, ph) = (relief.width_mm, relief.height_mm);
        let (sw, sh, st) = plan.stock;
        let (ax, ay) = plan.panel_at;
        let room = ax.min(ay).min(sw - pw - ax).min(sh - ph - ay);
        if room < d - 1e-9 {
            bail!(
                "--cutout: {} needs {d:.2} mm of stock round the panel, there is {room:.2} mm; \
                 give a larger --stock or a --margin",
                ct.spec()
            );
        }
        let ok_tab = c.tab_width.is_finite() && c.tab_width > 0.0;
        if !(ok_tab && c.tab_height.is_finite() && c.tab_height > 0.0 && c.tab_height < st) {
            bail!(
                "--tab-width {} / --tab-height {}: must be positive, the height below the \
                 stock's {st} mm",
                c.tab_width,
                c.tab_height
            );
        }
        let (dc, slot) = limits.material_of(&ct);
        let step = if dc.min(slot).is_finite() {
            dc.min(slot)
        } else {
            ct.radius()
        };
        let settings = self.settings(m, &ct, material, notes)?;
        let passes = cutout::passes(
            [0.0, 0.0, pw, ph],
            ct.radius(),
            st,
            step,
            c,
            settings.safe_z,
        );
        let layers = passes.len();
        notes.push(format!(
            "cutout with {}: {layers} layers of {:.2} mm through {:.2} mm, {} tabs {} mm long, \
             {} mm high",
            ct.spec(),
            (st + cutout::BREAK_THROUGH) / layers as f64,
            st + cutout::BREAK_THROUGH,
            c.tabs,
            c.tab_width,
            c.tab_height
        ));
        let passes = planned.ramp_and_cut(passes, ct, true);
        Ok(Op {
            title: "cutout",
            tool: ct,
            zero: String::new(),
            settings,
            strategy: format!(
                "cutout round the panel, {:.2} mm deep in {layers} layers, {} tabs {} mm long \
                 and {} mm high",
                st + cutout::BREAK_THROUGH,
                c.tabs,
                c.tab_width,
                c.tab_height
            ),
            passes,
        })
    }

    /// Passes cleaned for the machine: merged within the tolerance, then
    /// every move checked exactly.
    fn checked(&self, hf: &HeightField, tool: &Tool, passes: Vec<Pass>) -> Vec<Pass> {
        passes
            .into_iter()
            .map(|p| Pass {
                pts: path::verify(hf, tool, &path::merge(&p.pts, self.tolerance), false),
                clear_z: p.clear_z,
            })
            .collect()
    }

    /// The rest pass: `rt` in layers where the planned stock holds more
    /// than it may cut at once, then a raster at its finishing stepover,
    /// both only near where the tools before it left more than the
    /// threshold (the rows on either side of such a place both come in).
    /// None (and a note) where nothing is left.
    #[allow(clippy::too_many_arguments)]
    fn rest_op(
        &self,
        r: &rest::Rest,
        (finishing, rt): (&Tool, Tool),
        (hf, relief, floor): (&HeightField, &Relief, f64),
        planned: &mut stock::Planned,
        subject: Option<&boundary::Subject>,
        (m, material, limits): (&Machine, Option<&crate::materials::Material>, &Limits),
        notes: &mut Vec<String>,
        raw_points: &mut usize,
    ) -> Result<Option<Op>> {
        let settings = self.settings(m, &rt, material, notes)?;
        let step = material
            .and_then(|mt| mt.cutting_for(rt.working_diameter()))
            .map(|c| Stepover::Percent(c.finish_stepover))
            .or(self.stepover.filter(|s| matches!(s, Stepover::Percent(_))))
            .unwrap_or(Stepover::Percent(10.0))
            .mm(&rt)?;
        let left = rest::Unfinished::find(planned, relief, r.threshold, step + planned.stock.pitch);
        if left.share() == 0.0 {
            notes.push(format!(
                "--rest {}: nothing left over {} mm; no rest pass",
                rt.spec(),
                r.threshold
            ));
            return Ok(None);
        }
        let keep = |x: f64, y: f64| left.near(x, y) && subject.is_none_or(|s| s.is_near(x, y));
        let panel = [0.0, 0.0, relief.width_mm, relief.height_mm];
        let mut passes = Vec::new();
        if let Some((layers, depth)) = self.rest_layers(
            hf,
            &rt,
            planned,
            panel,
            floor,
            limits.layer(&rt),
            &settings,
            Some(&keep),
        ) {
            *raw_points += layers.iter().map(|p| p.pts.len()).sum::<usize>();
            notes.push(format!(
                "{} steps down in layers of {depth:.2} mm where more is left than it may cut",
                rt.spec()
            ));
            passes.extend(planned.ramp_and_cut(layers, rt, false));
        }
        let (rows, raw) = self.raster(hf, &rt, panel, floor, step, Some(&keep));
        *raw_points += raw;
        let rows = order::tour(rows, None);
        let rows = rest::linked(hf, &rt, rows, floor, self.tolerance, rt.working_diameter());
        let rows = rows
            .into_iter()
            .map(|pts| Pass {
                pts,
                clear_z: settings.safe_z,
            })
            .collect();
        passes.extend(planned.ramp_and_cut(rows, rt, true));
        // pencil passes last, one clean line along each crease: valleys
        // of the rest tool's CL surface sharper than the finishing tool
        // fits into
        let kappa = 1.0 / (finishing.radius() - rt.radius()).max(rt.radius());
        let pencil: Vec<Vec<DVec3>> = pencil::lines(hf, &rt, panel, floor, kappa, &keep)
            .par_iter()
            .map(|l| {
                let m = path::merge(l, self.tolerance);
                path::check_and_refine(hf, &rt, &m, floor, self.tolerance, None)
            })
            .collect();
        let n_pencil = pencil.len();
        *raw_points += pencil.iter().map(Vec::len).sum::<usize>();
        let start = passes.last().and_then(|p: &Pass| p.pts.last().copied());
        let pencil = order::tour(pencil, start)
            .into_iter()
            .map(|pts| Pass {
                pts,
                clear_z: settings.safe_z,
            })
            .collect();
        passes.extend(planned.ramp_and_cut(pencil, rt, true));
        let what = format!(
            "rest machining where more than {} mm was left ({:.1}% of the stock), raster, \
             stepover {step:.4} mm, then {n_pencil} pencil passes along creases",
            r.threshold,
            100.0 * left.share()
        );
        notes.push(format!("{}: {what}", rt.spec()));
        Ok(Some(Op {
            title: "rest",
            tool: rt,
            zero: String::new(),
            settings,
            strategy: what,
            passes,
        }))
    }

    /// The finishing tool in layers over `region` wherever the planned
    /// stock holds more above the relief than it may cut at once (`most`);
    /// None where nothing is. Returns the passes and the layer depth.
    #[allow(clippy::too_many_arguments)]
    fn rest_layers(
        &self,
        hf: &HeightField,
        tool: &Tool,
        planned: &stock::Planned,
        region: [f64; 4],
        floor: f64,
        most: f64,
        s: &Settings,
        keep: Option<&(dyn Fn(f64, f64) -> bool + Sync)>,
    ) -> Option<(Vec<Pass>, f64)> {
        let left = planned.left_above(hf, region, tool);
        // (sampled a quarter radius apart: keep a fifth in hand)
        if left <= 0.8 * most {
            return None;
        }
        // room for the scallops and terraces the layers leave
        let layer = 0.5 * most.min(left);
        let r = tool.radius();
        // (where the finishing tool does not go, nor do its layers)
        let material = |x: f64, y: f64| {
            if keep.is_none_or(|k| k(x, y)) {
                planned.highest(x, y, r)
            } else {
                f64::NEG_INFINITY
            }
        };
        let params = rough::Params {
            tool: *tool,
            stepover: 0.4 * tool.working_diameter(),
            step_down: layer,
            stock_to_leave: 0.0,
            angle: self.angle,
            region,
            material: Some(&material),
            background: None,
        };
        let passes = rough::passes(hf, floor, &params).ok()?;
        let passes: Vec<Pass> = self
            .checked(hf, tool, passes)
            .into_iter()
            .map(|p| Pass {
                // the layers' own travels go over the relief, not over
                // material earlier operations left: travel at safe Z
                clear_z: s.safe_z,
                ..p
            })
            .collect();
        (!passes.is_empty()).then_some((passes, layer))
    }

    /// The raster over `region`, only where `keep` holds: zigzag runs of
    /// whole rows (a row cut short by `keep` is a pass of its own), or
    /// one-way rows. Returns the passes and the CL points dropped.
    #[allow(clippy::too_many_arguments)]
    fn raster(
        &self,
        hf: &HeightField,
        tool: &Tool,
        region: [f64; 4],
        floor: f64,
        step: f64,
        keep: Option<&(dyn Fn(f64, f64) -> bool + Sync)>,
    ) -> (Vec<Vec<DVec3>>, usize) {
        let rows = raster::rows_in(region, self.angle, step, raster::point_spacing(hf, tool));
        let tol = self.tolerance;
        let climb = self.direction == Some(Direction::Climb);
        // runs of whole rows; pieces of cut rows alone
        // (whole rows?, rows)
        type Group = (bool, Vec<Vec<(f64, f64)>>);
        let mut groups: Vec<Group> = Vec::new();
        for (k, row) in rows.into_iter().enumerate() {
            let pieces = match keep {
                None => vec![row.clone()],
                Some(f) => row
                    .split(|&(x, y)| !f(x, y))
                    .filter(|p| p.len() > 1)
                    .map(|p| p.to_vec())
                    .collect(),
            };
            if pieces.len() == 1 && pieces[0].len() == row.len() {
                match groups.last_mut() {
                    Some((true, g)) => g.push(row),
                    _ => groups.push((true, vec![row])),
                }
            } else {
                // odd rows run right to left: their pieces too, in turn
                let mut pieces = pieces;
                if k % 2 == 1 {
                    pieces.reverse();
                }
                for mut p in pieces {
                    if k % 2 == 1 {
                        p.reverse();
                    }
                    groups.push((false, vec![p]));
                }
            }
        }
        // every group at once: the pieces beside a keep-out are single
        // rows, each too small to keep both cores busy alone
        let done: Vec<(Vec<Vec<DVec3>>, usize)> = groups
            .into_par_iter()
            .map(|(whole, g)| {
                let cl = raster::drop_rows(hf, tool, &g, floor);
                let raw = cl.iter().map(Vec::len).sum::<usize>();
                // (pass, the CL points it was merged from)
                let main: Vec<(Vec<DVec3>, Vec<DVec3>)> = match (self.direction, whole) {
                    (None, true) => vec![raster::zigzag(hf, tool, &cl, floor, tol, self.arcs)],
                    (None, false) => cl
                        .into_iter()
                        .map(|c| (raster::thin(&c, tol, self.arcs), c))
                        .collect(),
                    (Some(_), _) => raster::one_way(&cl, climb, tol, self.arcs),
                };
                let checked = main
                    .iter()
                    .map(|(c, drops)| path::check_and_refine(hf, tool, c, floor, tol, Some(drops)))
                    .collect();
                (checked, raw)
            })
            .collect();
        let raw = done.iter().map(|d| d.1).sum();
        (done.into_iter().flat_map(|d| d.0).collect(), raw)
    }

    /// Feeds and speeds for `tool`: flags, else the material's entry for
    /// its diameter, else generic values; defaults are capped at the
    /// machine's limits (and `notes` says so), flags beyond them refused.
    fn settings(
        &self,
        m: &Machine,
        tool: &Tool,
        material: Option<&crate::materials::Material>,
        notes: &mut Vec<String>,
    ) -> Result<Settings> {
        let c = material.and_then(|mt| mt.cutting_for(tool.working_diameter()));
        let rate = m.max_rate.x.min(m.max_rate.y);
        let mut cap = |what: &str, v: f64, lo: f64, hi: f64, unit: &str| {
            let capped = v.clamp(lo, hi);
            if capped != v {
                let n = format!(
                    "{what} {v} {unit} for {} with {} capped at {}'s {capped} {unit}",
                    self.material.as_deref().unwrap_or("generic cutting"),
                    tool.spec(),
                    m.name
                );
                if !notes.contains(&n) {
                    notes.push(n);
                }
            }
            capped
        };
        let s = Settings {
            feed: match self.feed {
                Some(f) => f,
                None => cap(
                    "feed",
                    c.as_ref().map_or(1000.0, |c| c.feed),
                    0.0,
                    rate,
                    "mm/min",
                ),
            },
            plunge_feed: match self.plunge_feed {
                Some(f) => f,
                None => cap(
                    "plunge feed",
                    c.as_ref().map_or(300.0, |c| c.plunge),
                    0.0,
                    m.max_rate.z,
                    "mm/min",
                ),
            },
            rpm: match self.rpm {
                Some(r) => r,
                None => cap(
                    "spindle speed",
                    c.as_ref().map_or(18000.0, |c| c.rpm),
                    m.spindle.min,
                    m.spindle.max,
                    "rpm",
                ),
            },
            safe_z: self.safe_z,
            dwell: 2.0,
        };
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !(positive(s.safe_z) && positive(s.feed) && positive(s.plunge_feed) && s.rpm >= 0.0) {
            bail!("--safe-z, --feed and --plunge-feed must be positive and --rpm >= 0");
        }
        if s.feed > rate || s.plunge_feed > m.max_rate.z {
            bail!(
                "feed {} / plunge {} mm/min exceed {}'s limits ({rate} XY, {} Z)",
                s.feed,
                s.plunge_feed,
                m.name,
                m.max_rate.z
            );
        }
        if s.rpm < m.spindle.min || s.rpm > m.spindle.max {
            bail!(
                "--rpm {}: outside {}'s spindle range {}..{}",
                s.rpm,
                m.name,
                m.spindle.min,
                m.spindle.max
            );
        }
        Ok(s)
    }

    /// Waterline passes `dz` apart, level by level from the top, nearest
    /// first.
    #[allow(clippy::too_many_arguments)]
    fn waterlines(
        &self,
        hf: &HeightField,
        tool: &Tool,
        relief: &Relief,
        floor: f64,
        dz: f64,
        climb: bool,
        keep_also: Option<&(dyn Fn(f64, f64) -> bool + Sync)>,
    ) -> Vec<Vec<DVec3>> {
        let g = waterline::ClGrid::new(hf, tool, relief.width_mm, relief.height_mm, floor);
        let steep_only = self.finish == Finish::RasterWaterline;
        let (w, h) = (relief.width_mm, relief.height_mm);
        // every level's contours, then all of them placed, refined and
        // checked at once: one level may hold a single long contour
        let levels = waterline::levels(&g, dz);
        let contours: Vec<(usize, waterline::Contour)> = levels
            .par_iter()
            .enumerate()
            .map(|(n, &level)| {
                // beside a raster, steep ground takes every m-th level only
                let k = ((level - floor) / dz).round() as i64;
                let keep = |p: DVec3, slope: f64| {
                    (0.0..=w).contains(&p.x)
                        && (0.0..=h).contains(&p.y)
                        && (!steep_only || waterline::every_nth(slope).is_some_and(|m| k % m == 0))
                        && keep_also.is_none_or(|f| f(p.x, p.y))
                };
                waterline::contours(&g, level)
                    .iter()
                    .flat_map(|c| waterline::parts(c, keep))
                    .map(|c| (n, c))
                    .collect::<Vec<_>>()
            })
            .flatten_iter()
            .collect();
        // (closed?, points) of each piece, by level
        type Pieces = Vec<(bool, Vec<DVec3>)>;
        let done: Vec<(usize, Pieces)> = contours
            .par_iter()
            .map(|(n, c)| {
                let c = waterline::place(hf, tool, floor, c);
                let c = waterline::refine(hf, tool, floor, &c);
                let mut pts = waterline::simplify(&c, self.tolerance);
                if climb {
                    pts.reverse();
                }
                // within the panel, where the job's travel is checked
                let pts = waterline::clear(hf, tool, &pts);
                let pieces = tile::clip(&pts, [0.0, 0.0, w, h]);
                let whole = pieces.len() == 1 && pieces[0].len() == pts.len();
                let closed = c.closed && whole;
                (*n, pieces.into_iter().map(|p| (closed, p)).collect())
            })
            .collect();
        let mut by_level: Vec<Pieces> = vec![Vec::new(); levels.len()];
        for (n, pieces) in done {
            by_level[n].extend(pieces);
        }
        let mut out: Vec<Vec<DVec3>> = Vec::new();
        for mut loops in by_level {
            // nearest next: closed loops start where they are nearest
            let mut at = out
                .last()
                .and_then(|p| p.last().copied())
                .unwrap_or_default();
            while !loops.is_empty() {
                let d = |p: &DVec3| (*p - at).truncate().length_squared();
                let (k, start) = loops
                    .iter()
                    .enumerate()
                    .map(|(k, (closed, pts))| {
                        let s = if *closed {
                            (0..pts.len() - 1)
                                .min_by(|&a, &b| d(&pts[a]).total_cmp(&d(&pts[b])))
                                .unwrap_or(0)
                        } else {
                            0
                        };
                        (k, s, d(&pts[s]))
                    })
                    .min_by(|a, b| a.2.total_cmp(&b.2))
                    .map(|(k, s, _)| (k, s))
                    .unwrap();
                let (closed, mut pts) = loops.swap_remove(k);
                if closed && start > 0 {
                    pts.pop();
                    pts.rotate_left(start);
                    pts.push(pts[0]);
                }
                at = *pts.last().unwrap();
                out.push(pts);
            }
        }
        out
    }

    /// One G-code file for `ops`, tool changes between them.
    #[allow(clippy::too_many_arguments)]
    fn emit(
        &self,
        ops: &[Op],
        relief: &Relief,
        plan: &layout::Plan,
        m: &Machine,
        z_shift: f64,
        notes: &[String],
    ) -> String {
        let header = |op: &Op| {
            vec![
                format!(
                    "tool: {} (radius {} mm) for {}",
                    op.tool.spec(),
                    op.tool.radius(),
                    op.title
                ),
                format!("strategy: {}", op.strategy),
                format!(
                    "feed {} plunge {} mm/min, {} rpm, safe Z {}",
                    op.settings.feed, op.settings.plunge_feed, op.settings.rpm, op.settings.safe_z
                ),
            ]
        };
        let (sw, sh, st) = plan.stock;
        let mut top = vec![
            "relievo GRBL 1.1 job".to_string(),
            format!("relief: {}", self.relief_name),
            format!(
                "material: {}",
                self.material.as_deref().unwrap_or("not given")
            ),
            format!(
                "panel: {:.2} x {:.2} mm, relief depth {:.3} mm{}",
                relief.width_mm,
                relief.height_mm,
                relief.depth_mm,
                if self.layout.rotate {
                    ", turned 90 deg"
                } else {
                    ""
                }
            ),
            format!(
                "stock: {sw:.2} x {sh:.2} x {st:.2} mm, origin at its {}",
                if self.origin == Origin::Center {
                    "centre"
                } else {
                    "lower-left corner"
                }
            ),
            match self.z_zero {
                ZZero::Top => "Z0 = stock top".to_string(),
                ZZero::Bottom => format!("Z0 = stock bottom (spoilboard), stock top at Z{st}"),
            },
            // machine-readable: the simulator places the relief by it
            plan.frame(z_shift).comment(),
            format!(
                "machine: {}, units: {}",
                m.name,
                if self.units == Units::In {
                    "inch (G20)"
                } else {
                    "mm"
                }
            ),
        ];
        top.extend(notes.iter().cloned());
        top.extend(header(&ops[0]));
        let inch = self.units == Units::In;
        let mut e = Emitter::new(&top, &ops[0].settings, inch, z_shift);
        e.arcs = self.arcs;
        e.steps = Some(DVec3::new(
            m.steps_per_mm.x,
            m.steps_per_mm.y,
            m.steps_per_mm.z,
        ));
        let shift = plan.shift;
        for (k, op) in ops.iter().enumerate() {
            if k > 0 && op.tool != ops[k - 1].tool {
                e.tool_change(&header(op), &op.settings, &op.zero);
            } else if k > 0 {
                for h in header(op).iter().skip(1) {
                    crate::gcode::emit::comment(&mut e.out, h);
                }
            }
            for pass in &op.passes {
                let pts: Vec<DVec3> = pass
                    .pts
                    .iter()
                    .map(|p| DVec3::new(p.x + shift.x, p.y + shift.y, p.z))
                    .collect();
                e.pass(&pts, &op.settings, pass.clear_z);
            }
        }
        e.finish(&ops[ops.len() - 1].settings)
    }
}

/// How many lines `with_comments` adds for `notes`.
fn comment_lines(notes: &[String]) -> usize {
    let mut s = String::new();
    for n in notes {
        crate::gcode::emit::comment(&mut s, n);
    }
    s.lines().count()
}

/// Insert comment lines after the header comments.
fn with_comments(mut text: String, lines: &[String]) -> String {
    let mut add = String::new();
    for l in lines {
        crate::gcode::emit::comment(&mut add, l);
    }
    let at = text
        .lines()
        .take_while(|l| l.starts_with('('))
        .map(|l| l.len() + 1)
        .sum();
    text.insert_str(at, &add);
    text
}

/// Where `path` is the job, the roughing file beside it.
pub fn rough_path(path: &Path) -> PathBuf {
    path.with_file_name(format!(
        "{}-rough.nc",
        path.file_stem()
            .map_or("job".into(), |s| s.to_string_lossy())
    ))
}
