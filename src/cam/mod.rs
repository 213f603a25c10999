//! The `toolpath` command as one library call: a relief in, a GRBL job out:
//! optional roughing, then raster and/or waterline finishing, each move
//! checked against the exact swept tool before it is written.

use crate::bail;
use crate::error::Result;
use crate::gcode::emit::Settings;
use crate::relief::Relief;
use crate::sim;
use crate::timing::Timings;
use crate::tool::Tool;
use crate::toolpath::Pass;
use setup::MIN_STEPOVER;
use std::path::{Path, PathBuf};

mod boundary;
pub mod cutout;
mod deliver;
mod feeds;
mod finishing;
mod judge;
pub mod layout;
mod order;
pub mod rest;
mod roughing;
mod setup;
mod stock;
mod strategy;
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
                let Some(r) = tool.tip_radius() else {
                    bail!("--scallop needs a ball or tapered ball tool");
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

impl ToolpathJob {
    /// The pipeline: setup, roughing, the finishing tool's layers, the
    /// finish, rest machining, the cutout, then delivery (emitted, judged
    /// by the simulator, headed and written). Each stage cuts the planned
    /// stock the next one reads.
    pub fn run(&self, relief: &Relief) -> Result<CamSummary> {
        let mut w = self.work(relief)?;
        let mut ops: Vec<Op> = Vec::new();
        ops.extend(self.roughing(&mut w)?);
        ops.extend(self.finishing_layers(&mut w));
        ops.push(self.finishing(&mut w)?);
        ops.extend(self.rest_stage(&mut w)?);
        // the cutout last: the panel stays held by the whole stock while
        // it is carved
        ops.extend(self.cutout_stage(&mut w)?);
        self.deliver(ops, w)
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
