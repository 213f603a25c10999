//! `relievo toolpath`: a relief file to a GRBL job; the cutting flags
//! it shares with `carve`.

use super::{parse_pair, parse_size, parse_stock, print_timings, with_spinner};
use clap::Args;
use std::path::PathBuf;

/// What `--help` ends with.
pub const EXAMPLES: &str = "Examples:
  relievo toolpath relief.png -o job.nc                 # roughing + raster finish, GRBL
  relievo toolpath relief.png --tool ball:1 --finish raster+waterline --machine 3018
  relievo toolpath relief.png --material oak --stock 120x90x12 --svg job.svg";

#[derive(Args)]
pub struct ToolpathArgs {
    /// Relief PNG (its JSON sidecar gives the size).
    pub relief: PathBuf,
    /// Output G-code job.
    #[arg(short, long, default_value = "job.nc")]
    pub output: PathBuf,
    /// Relief width in mm, for a heightmap without sidecar.
    #[arg(long, allow_negative_numbers = true)]
    pub width: Option<f64>,
    /// Relief depth in mm, for a heightmap without sidecar.
    #[arg(long, allow_negative_numbers = true)]
    pub depth: Option<f64>,
    /// Material preset for feeds, speeds, stepovers and step-downs.
    #[arg(long)]
    pub material: Option<String>,
    #[command(flatten)]
    pub cut: CutOpts,
}

#[derive(Args)]
pub struct CutOpts {
    /// Finishing tool: ball:D, flat:D, vbit:ANGLE[:D],
    /// taperball:TIP_RADIUS:HALF_ANGLE[:D], or a name from the machine's
    /// tool table (T1, T2, ...).
    #[arg(long, default_value = "ball:3.175")]
    pub tool: String,
    /// Finishing strategy.
    #[arg(long, value_enum, default_value_t = relievo::cam::Finish::Raster)]
    pub finish: relievo::cam::Finish,
    /// Distance between rows (and waterline levels): MM or PERCENT% of the
    /// tool diameter [default: the material's, else 10%].
    #[arg(long, value_parser = relievo::cam::Stepover::parse)]
    pub stepover: Option<relievo::cam::Stepover>,
    /// Scallop height in mm; sets the stepover for a ball.
    #[arg(long)]
    pub scallop: Option<f64>,
    /// Raster angle in degrees.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub angle: f64,
    /// Climb milling: one-way rows, waterlines with the material on the
    /// right [default: zigzag rows, climb waterlines].
    #[arg(long, conflicts_with = "conventional")]
    pub climb: bool,
    /// Conventional milling: one-way rows, waterlines the other way round.
    #[arg(long)]
    pub conventional: bool,
    /// Rough first with this tool (flat:D or ball:D, or a tool-table name).
    #[arg(long)]
    pub rough: Option<String>,
    /// Roughing layer depth, mm [default: the material's, else the tool radius].
    #[arg(long, requires = "rough")]
    pub step_down: Option<f64>,
    /// Roughing stepover, MM or PERCENT% [default: the material's, else 40%].
    #[arg(long, requires = "rough", value_parser = relievo::cam::Stepover::parse)]
    pub rough_stepover: Option<relievo::cam::Stepover>,
    /// Material roughing leaves on the relief for the finish, mm.
    #[arg(
        long,
        default_value_t = 0.3,
        requires = "rough",
        allow_negative_numbers = true
    )]
    pub stock_to_leave: f64,
    /// After the finish, a smaller tool (ball:D, ... or a tool-table name)
    /// only where the finish left more than --rest-threshold, as the
    /// simulated cut shows: creases the finishing tool cannot reach.
    #[arg(long)]
    pub rest: Option<String>,
    /// Material left over the relief (mm) that calls for the rest tool.
    #[arg(long, default_value_t = relievo::cam::rest::THRESHOLD, requires = "rest")]
    pub rest_threshold: f64,
    /// Write the roughing to NAME-rough.nc instead of one job with an M0
    /// tool change.
    #[arg(long, requires = "rough")]
    pub split: bool,
    /// Merge dropped points into moves that pass within this distance above
    /// them (never below), mm.
    #[arg(long, default_value_t = 0.005)]
    pub tolerance: f64,
    /// Arcs: G2/G3 where a circle fits within the tolerance, for
    /// waterlines in XY (G17) and, from a tolerance of 0.006 mm, for raster
    /// rows along X or Y in their vertical plane (G18/G19), as the very
    /// chords GRBL cuts them into with its default $12 arc tolerance
    /// (0.002 mm).
    #[arg(long, value_enum, default_value_t = OnOff::On)]
    pub arcs: OnOff,
    /// Cutting feed, mm/min [default: the material's, else 1000; within the machine's limit].
    #[arg(long)]
    pub feed: Option<f64>,
    /// Plunge feed, mm/min [default: the material's, else 300].
    #[arg(long)]
    pub plunge_feed: Option<f64>,
    /// Spindle speed [default: the material's, else 18000; within the machine's range].
    #[arg(long)]
    pub rpm: Option<f64>,
    /// Travel height above the stock top, mm.
    #[arg(long, default_value_t = 5.0)]
    pub safe_z: f64,
    /// Machine profile: grbl-generic, 3018, shapeoko, or a TOML file.
    #[arg(long, default_value = "grbl-generic")]
    pub machine: String,
    /// Job origin on the panel.
    #[arg(long, value_enum, default_value_t = relievo::cam::Origin::LowerLeft)]
    pub origin: relievo::cam::Origin,
    /// Also write a top view of the toolpath (SVG: cuts blue, rapids red).
    #[arg(long)]
    pub svg: Option<PathBuf>,
    /// Also write the simulated cut, shaded (PNG).
    #[arg(long)]
    pub preview: Option<PathBuf>,
    /// Light of the preview: azimuth (clockwise from the panel's top
    /// edge) and elevation, degrees [default: 315,35].
    #[arg(long, value_parser = parse_pair, allow_negative_numbers = true)]
    pub light: Option<(f64, f64)>,
    /// Write cuts deeper than the material allows the tool (the header and
    /// the summary say where).
    #[arg(long)]
    pub allow_deep_cuts: bool,
    /// Where Z0 is set: the stock top (roughing leaves a touch-off pad
    /// for the next tool) or the stock's bottom, the spoilboard (needs
    /// --stock).
    #[arg(long, value_enum, default_value_t = relievo::cam::ZZero::Top)]
    pub z_zero: relievo::cam::ZZero,
    /// Units of the G-code (flags stay in mm).
    #[arg(long, value_enum, default_value_t = relievo::cam::Units::Mm)]
    pub units: relievo::cam::Units,
    /// Stock width x height x thickness, mm [default: the panel plus
    /// margins, the relief's depth + 3 mm thick]; the panel is centred on
    /// it unless --margin places it.
    #[arg(long, value_parser = parse_stock)]
    pub stock: Option<(f64, f64, f64)>,
    /// Stock around the panel, mm (the panel sits this far from the
    /// stock's lower-left corner).
    #[arg(long)]
    pub margin: Option<f64>,
    /// Where the finishing tool works: the whole panel, or the subject
    /// and a tool's diameter round it (the roughing tool then clears the
    /// background at its own level).
    #[arg(long, value_enum, default_value_t = relievo::cam::Boundary::Panel)]
    pub boundary: relievo::cam::Boundary,
    /// Cut a panel larger than the machine's travel in tiles of at most
    /// WIDTHxHEIGHT mm, one job each (NAME-tileC-R.nc), the stock moved
    /// between them as each job's header says.
    #[arg(long, value_parser = parse_size)]
    pub tile: Option<(f64, f64)>,
    /// Cut the panel out of the stock at the end: a profile round it,
    /// through the stock, holding it by tabs (needs stock round the
    /// panel: --stock or --margin).
    #[arg(long)]
    pub cutout: bool,
    /// Tabs holding the panel in the cutout.
    #[arg(long, default_value_t = 4, requires = "cutout")]
    pub tabs: usize,
    /// Length of each tab along the panel's edge, mm.
    #[arg(long, default_value_t = 6.0, requires = "cutout")]
    pub tab_width: f64,
    /// Height of each tab over the stock's bottom, mm.
    #[arg(long, default_value_t = 2.0, requires = "cutout")]
    pub tab_height: f64,
    /// Turn the panel a quarter (90 degrees counter-clockwise) on the machine.
    #[arg(long, value_parser = parse_rotation)]
    pub rotate: Option<bool>,
}

pub fn parse_rotation(s: &str) -> Result<bool, String> {
    match s.trim() {
        "90" => Ok(true),
        "0" => Ok(false),
        _ => Err(format!("'{s}': 0 or 90 (degrees)")),
    }
}

impl CutOpts {
    pub fn job(
        self,
        output: PathBuf,
        relief_name: String,
        material: Option<String>,
    ) -> relievo::cam::ToolpathJob {
        use relievo::cam::{Direction, Roughing, Stepover};
        let direction = match (self.climb, self.conventional) {
            (true, _) => Some(Direction::Climb),
            (_, true) => Some(Direction::Conventional),
            _ => None,
        };
        relievo::cam::ToolpathJob {
            tool: self.tool,
            finish: self.finish,
            direction,
            stepover: self.scallop.map(Stepover::Scallop).or(self.stepover),
            angle: self.angle,
            tolerance: self.tolerance,
            arcs: self.arcs == OnOff::On,
            feed: self.feed,
            plunge_feed: self.plunge_feed,
            rpm: self.rpm,
            safe_z: self.safe_z,
            machine: self.machine,
            material,
            origin: self.origin,
            rough: self.rough.map(|tool| Roughing {
                tool,
                step_down: self.step_down,
                stepover: self.rough_stepover,
                stock_to_leave: self.stock_to_leave,
            }),
            rest: self.rest.map(|tool| relievo::cam::rest::Rest {
                tool,
                threshold: self.rest_threshold,
            }),
            split: self.split,
            output,
            allow_deep_cuts: self.allow_deep_cuts,
            z_zero: self.z_zero,
            units: self.units,
            layout: relievo::cam::layout::Layout {
                stock: self.stock,
                margin: self.margin,
                rotate: self.rotate.unwrap_or(false),
                tile: self.tile,
            },
            boundary: self.boundary,
            cutout: self.cutout.then_some(relievo::cam::cutout::Cutout {
                tabs: self.tabs,
                tab_width: self.tab_width,
                tab_height: self.tab_height,
            }),
            svg: self.svg,
            preview: self.preview,
            light: self.light,
            relief_name,
        }
    }
}

pub fn report(s: &relievo::cam::CamSummary, quiet: bool, verbose: bool) {
    if !quiet {
        for n in &s.notes {
            println!("{n}");
        }
        println!("{}", s.engagement.summary());
        println!(
            "rapids {:.1} m, cutting {:.1} m; simulated gouge {:.4} mm, residual max {:.3} / mean {:.4} mm",
            s.rapid_mm / 1000.0,
            s.cut_mm / 1000.0,
            s.gouge,
            s.residual.0,
            s.residual.1
        );
        eprintln!(
            "{}: {} lines ({} CL points merged), stepover {:.3} mm, estimated {}",
            super::paths(&s.written),
            s.lines,
            s.raw_points,
            s.stepover_mm,
            s.time_text()
        );
    }
    if verbose {
        print_timings(&s.timings);
    }
}

/// `relievo toolpath`.
pub fn run(args: ToolpathArgs, quiet: bool, verbose: bool) -> relievo::Result<()> {
    let relief = relievo::relief::file::load(&args.relief, args.width, args.depth)?;
    let job = args.cut.job(
        args.output.clone(),
        args.relief.display().to_string(),
        args.material,
    );
    let what = format!(
        "planning and checking the job on the {} x {} px relief",
        relief.heights.w, relief.heights.h
    );
    let s = with_spinner(quiet, &what, || job.run(&relief))?;
    report(&s, quiet, verbose);
    Ok(())
}

/// A switch.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum OnOff {
    On,
    Off,
}
