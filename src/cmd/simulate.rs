//! `relievo simulate`: judge any G-code job against a relief.

use super::{print_timings, with_spinner};
use clap::Args;
use relievo::ops::settings::{parse_pair, parse_stock};
use std::path::PathBuf;

/// What `--help` ends with.
pub const EXAMPLES: &str = "Examples:
  relievo simulate job.nc --relief job-relief.png       # judge a job against its relief
  relievo simulate other.nc --relief r.png --tool ball:3 --stock 100x80x8 -o cut.png";

#[derive(Args)]
pub struct SimulateArgs {
    /// G-code job (GRBL 1.1 dialect); several files (a split job's
    /// roughing, then its finishing) cut one stock in turn.
    #[arg(required = true)]
    pub jobs: Vec<PathBuf>,
    /// Target relief PNG (its JSON sidecar gives the size).
    #[arg(long)]
    pub relief: PathBuf,
    /// Relief width in mm, for a heightmap without sidecar.
    #[arg(long, allow_negative_numbers = true)]
    pub width: Option<f64>,
    /// Relief depth in mm, for a heightmap without sidecar.
    #[arg(long, allow_negative_numbers = true)]
    pub depth: Option<f64>,
    /// ball:D, flat:D, taperball:TIP_RADIUS:HALF_ANGLE[:D], vbit:ANGLE[:D], or a name from
    /// the machine's tool table (T1, T2, ...) [default: the job's (tool: ..) comment].
    #[arg(long)]
    pub tool: Option<String>,
    /// Stock WIDTHxHEIGHTxTHICKNESS in mm [default: as the job's frame
    /// header states it, else the relief's panel from the origin, depth +
    /// 3 mm thick].
    #[arg(long, value_parser = parse_stock)]
    pub stock: Option<(f64, f64, f64)>,
    /// Stock cells per relief pixel along each axis [default: the fewest
    /// (odd, up to 15) that keep what a cut hides between cell centres
    /// within 1 um for the job's tools].
    #[arg(long)]
    pub oversample: Option<usize>,
    /// Machine profile: grbl-generic, 3018, shapeoko, or a TOML file.
    #[arg(long, default_value = "grbl-generic")]
    pub machine: String,
    /// Job coordinates X,Y of the travel box's lower-left corner
    /// [default: the stock's lower-left corner, from the job's frame
    /// header, else 0,0].
    #[arg(long, value_parser = parse_pair, allow_negative_numbers = true)]
    pub travel_origin: Option<(f64, f64)>,
    /// Where the tool stands when the job starts, work X,Y,Z mm [default:
    /// on the work zero the job's frame header names (X0 Y0, the stock
    /// top), else the job's highest Z over X0 Y0].
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_start, allow_hyphen_values = true)]
    pub start: Option<glam::DVec3>,
    /// Cut surface as a relief PNG (+ JSON sidecar).
    #[arg(short, long, default_value = "cut.png")]
    pub output: PathBuf,
    /// Report as JSON.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Deviation map PNG: red = gouge, blue = residual.
    #[arg(long)]
    pub deviation: Option<PathBuf>,
}

pub fn run(args: SimulateArgs, quiet: bool, verbose: bool) -> relievo::Result<()> {
    let job = relievo::ops::simulate::SimulateJob {
        jobs: args.jobs,
        relief: args.relief,
        relief_width: args.width,
        relief_depth: args.depth,
        tool: args.tool,
        stock: args.stock,
        oversample: args.oversample,
        machine: args.machine,
        travel_origin: args.travel_origin,
        start: args.start,
        output: args.output,
        report: args.report,
        deviation: args.deviation,
    };
    let s = with_spinner(quiet, "simulating", || job.run())?;
    if !quiet {
        eprintln!(
            "simulated {} on {} x {} cells{}\n{}",
            s.tool.spec(),
            s.cells.0,
            s.cells.1,
            s.frame
                .map(|f| format!(", placed by the job's {}", f.comment()))
                .unwrap_or_default(),
            s.report.summary()
        );
    }
    if verbose {
        print_timings(&s.timings);
    }
    Ok(())
}

/// `X,Y,Z`, mm.
fn parse_start(s: &str) -> Result<glam::DVec3, String> {
    relievo::ops::settings::parse_xyz(s).map(glam::DVec3::from)
}
