//! The `toolpath` command as one library call: a relief in, a GRBL job out:
//! optional roughing, then raster and/or waterline finishing, each move
//! checked against the exact swept tool before it is written.

use crate::bail;
use crate::error::Result;
use crate::gcode::emit::Settings;
use crate::machine::Machine;
use crate::output::check_writable;
use crate::relief::Relief;
use crate::sim;
use crate::timing::Timings;
use crate::tool::Tool;
use crate::toolpath::dropcutter::HeightField;
use crate::toolpath::{merge, path, rough, waterline, Pass};
use deliver::Made;
use std::path::{Path, PathBuf};

mod boundary;
pub mod cutout;
mod deliver;
mod finish;
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
    /// The estimate by op, in job order: ("roughing flat:3.175", seconds),
    /// an op's time in every file (tiles) added together.
    pub time_by_op: Vec<(String, f64)>,
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

impl CamSummary {
    /// The estimate, with its split by op when the job changes tools:
    /// "2h 10m 59s (roughing flat:3.175 1h 11m 32s, finishing ...)".
    pub fn time_text(&self) -> String {
        let total = sim::hms(self.time_s);
        if self.time_by_op.len() > 1 {
            format!("{total} ({})", sim::shares_text(&self.time_by_op))
        } else {
            total
        }
    }
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

/// What a job's flags name, checked before any work: the machine, the
/// material, the tools and the finishing stepover (mm).
struct Setup {
    m: Machine,
    material: Option<crate::materials::Material>,
    tool: Tool,
    step: f64,
    /// The roughing tool asked for (an added one is chosen later).
    rough_tool: Option<Tool>,
    rest_tool: Option<Tool>,
}

/// The finest stepover taken, mm.
const MIN_STEPOVER: f64 = 1e-3;

/// The most cutter-location points a finishing pass may take (about a
/// minute of dropping on two cores, 0.7 GB held): a job never comes to
/// more moves than `simulate` reads (gcode::MAX_SEGMENTS). Past it the job
/// is refused with the figure.
const MAX_CL_POINTS: f64 = crate::gcode::MAX_SEGMENTS as f64;

/// Title of the finishing tool's own layers (where more is left than it
/// may cut at once).
const LAYERS: &str = "finishing-tool layers";

/// Size of the touch-off pad left by roughing, mm (a square).
const PAD: f64 = 8.0;

/// How sharply (times 1 / tool radius, per mm) the finishing tool's CL
/// surface must bend up across a valley for raster+waterline to run a
/// pencil pass along it: valleys the ball fits into with up to four radii
/// to spare, where a row running along the bottom leaves a cusp over the
/// scallop (Suzanne, 400 px at 60 mm, smooth shading, 2 mm ball: 0.0101
/// -> 0.0058 mm over the flat scallop for 2% more lines; at 0.5 and 1
/// the valley was missed).
const PENCIL_BEND: f64 = 0.25;

impl ToolpathJob {
    /// What can be refused before there is a relief: tolerance, Z zero,
    /// machine, material, tools, stepover and angle. `carve` asks first,
    /// so that a bad flag is one error line, not a relief's notes and then
    /// the error; `run` asks again.
    pub fn check(&self) -> Result<()> {
        self.setup().map(|_| ())
    }

    /// `check`'s findings, for `run`.
    fn setup(&self) -> Result<Setup> {
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
        let tool = m.tool_for("--tool", &self.tool)?;
        let rough_tool = self
            .rough
            .as_ref()
            .map(|r| m.tool_for("--rough", &r.tool))
            .transpose()?;
        let rest_tool = self
            .rest
            .as_ref()
            .map(|r| m.tool_for("--rest", &r.tool))
            .transpose()?;
        let step = self.finish_step(&tool, material.as_ref())?;
        if !(self.angle.is_finite() && self.angle.abs() <= 360.0) {
            bail!(
                "--angle {}: must be a number of degrees within -360..360",
                self.angle
            );
        }
        Ok(Setup {
            m,
            material,
            tool,
            step,
            rough_tool,
            rest_tool,
        })
    }

    /// The finishing stepover in mm: asked for, else the material's for
    /// the tool, else 10% of its working diameter.
    fn finish_step(
        &self,
        tool: &Tool,
        material: Option<&crate::materials::Material>,
    ) -> Result<f64> {
        let cutting = material.and_then(|mt| mt.cutting_for(tool.working_diameter()));
        self.stepover
            .or(cutting.map(|c| Stepover::Percent(c.finish_stepover)))
            .unwrap_or(Stepover::Percent(10.0))
            .mm(tool)
    }

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
        let Setup {
            m,
            material,
            tool,
            step,
            rough_tool,
            rest_tool,
        } = self.setup()?;
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
        let finish_settings = self.settings(&m, &tool, material.as_ref(), &mut notes)?;
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
        let hf = t.time("heightfield", || HeightField::of_relief(relief));
        let floor = -relief.depth_mm;
        let (pw, ph) = (relief.width_mm, relief.height_mm);
        let panel = [0.0, 0.0, pw, ph];
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
        let main_r = rough_tool.map_or(tool.radius(), |t| t.radius().min(tool.radius()));
        let rest_r = rest_tool.as_ref().map(|t| t.radius().max(0.05));
        let most = layout::cell_limit(main_r.max(0.05), rest_r);
        let cell = layout::cell(relief.pitch_mm(), most);
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
                let rt = m.tool_for("--rough", &r.tool)?;
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
        // how far beyond the pad's edge the finish keeps off
        let finish_round = strip + tool.radius() + 0.5;
        // off the pad by `round` (mm beyond its edge), and with --boundary
        // subject on the subject and its margin
        let here = |x: f64, y: f64, round: f64| {
            let off_pad = pad.is_none_or(|p| {
                let k = p.2 / 2.0 + round;
                (x - p.0).abs() > k || (y - p.1).abs() > k
            });
            off_pad && subject.as_ref().is_none_or(|s| s.is_near(x, y))
        };
        let finish_here = |x: f64, y: f64| here(x, y, finish_round);
        let keep_off_pad: Option<&(dyn Fn(f64, f64) -> bool + Sync)> =
            (pad.is_some() || subject.is_some()).then_some(&finish_here);
        // the finishing tool's layers come closer, up to the pad and a
        // tool radius round it: they clear the strip the finish keeps off
        // down to what the finish may cut, where its rows beside the
        // keep-out reach in (a 1 mm ball's rows there met the roughing's
        // 0.3 mm and its terraces at full height: 0.521 mm, 0.5 allowed)
        let layers_here = |x: f64, y: f64| here(x, y, tool.radius() + 0.5);
        let keep_layers: Option<&(dyn Fn(f64, f64) -> bool + Sync)> =
            (pad.is_some() || subject.is_some()).then_some(&layers_here);
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
            // its height (the finishing tool keeps to the subject): the
            // samples off the subject, but not the pad's
            let (z, zm) = (hf.samples(), hf_main.samples());
            let bg = subject.as_ref().map(|sub| {
                move |i: usize, j: usize| !*sub.inside.get(i, j) && zm.get(i, j) == z.get(i, j)
            });
            let params = rough::Params {
                tool: rt,
                stepover: rstep,
                step_down,
                stock_to_leave: r.stock_to_leave,
                angle: self.angle,
                region: panel,
                material: None,
                background: bg
                    .as_ref()
                    .map(|f| f as &(dyn Fn(usize, usize) -> bool + Sync)),
            };
            let passes = t.time("roughing", || rough::passes(hf_main, floor, &params))?;
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
                keep_layers,
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
                title: LAYERS,
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
        if self.finish == Finish::RasterWaterline {
            // beside a raster: one pencil pass along each valley the
            // waterlines leave to it, gentle ground on one side or both
            // (a row running along it leaves a cusp in its bottom)
            let keep = |x: f64, y: f64| keep_off_pad.is_none_or(|k| k(x, y));
            let start = passes.last().and_then(|p: &Pass| p.pts.last().copied());
            let (pencil, raw) = t.time("pencil", || {
                let kappa = PENCIL_BEND / tool.radius();
                self.pencil(&hf, &tool, panel, floor, kappa, &keep, start, safe)
            });
            raw_points += raw;
            what.push(format!("{} pencil passes along valleys", pencil.len()));
            passes.extend(pencil);
        }
        // the pad goes last: layers where it stands, then the surface
        if let Some(p) = pad {
            let r = finish_round + 0.5;
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
        self.deliver(
            ops,
            Made {
                relief,
                plan: &plan,
                m: &m,
                tool,
                cell,
                pad,
                limits: &limits,
                raw_points,
                step,
                rough_out,
            },
            notes,
            t,
        )
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
                pts: path::verify(hf, tool, &merge::merge(&p.pts, self.tolerance), false),
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
        let start = passes.last().and_then(|p: &Pass| p.pts.last().copied());
        let (pencil, raw) =
            self.pencil(hf, &rt, panel, floor, kappa, &keep, start, settings.safe_z);
        let n_pencil = pencil.len();
        *raw_points += raw;
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
}

/// Where `path` is the job, the roughing file beside it.
pub fn rough_path(path: &Path) -> PathBuf {
    path.with_file_name(format!(
        "{}-rough.nc",
        path.file_stem()
            .map_or("job".into(), |s| s.to_string_lossy())
    ))
}
