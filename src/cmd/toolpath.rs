//! `relievo toolpath`: a relief file to a GRBL job; the cutting flags
//! it shares with `carve`.

use super::{print_timings, with_spinner};
use clap::Args;
use relievo::ops::settings::CutSettings;
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
    pub cut: CutSettings,
    #[command(flatten)]
    pub files: CutFiles,
}

/// The views of a job its command line may write besides the job.
#[derive(Args)]
pub struct CutFiles {
    /// Also write a top view of the toolpath (SVG: cuts blue, rapids red).
    #[arg(long)]
    pub svg: Option<PathBuf>,
    /// Also write the simulated cut, shaded (PNG).
    #[arg(long)]
    pub preview: Option<PathBuf>,
}

impl CutFiles {
    /// The views set on `job`.
    pub fn onto(self, job: &mut relievo::cam::ToolpathJob) {
        job.svg = self.svg;
        job.preview = self.preview;
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
    let mut job = args.cut.job(
        args.output.clone(),
        args.relief.display().to_string(),
        args.material,
    );
    args.files.onto(&mut job);
    let what = format!(
        "planning and checking the job on the {} x {} px relief",
        relief.heights.w, relief.heights.h
    );
    let s = with_spinner(quiet, &what, || job.run(&relief))?;
    report(&s, quiet, verbose);
    Ok(())
}
