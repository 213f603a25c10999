//! `relievo carve`: relief and job in one call, all or nothing.

use super::relief::ReliefFiles;
use super::toolpath::{report, CutFiles};
use clap::Args;
use relievo::ops::settings::{CutSettings, ReliefSettings};
use std::path::PathBuf;

/// What `--help` ends with.
pub const EXAMPLES: &str = "Examples:
  relievo carve                                         # the demo scene -> job.nc and its relief
  relievo carve bunny.obj --width 80 --depth 4 --machine shapeoko -o bunny.nc
  relievo carve coin.stl --up z --tool vbit:60 --finish raster+waterline";

#[derive(Args)]
pub struct CarveArgs {
    /// Model as for `relief`; without it, the demo scene.
    pub model: Option<PathBuf>,
    /// Output G-code job; the relief is written beside it as NAME-relief.png.
    #[arg(short, long, default_value = "job.nc")]
    pub output: PathBuf,
    #[command(flatten)]
    pub relief: ReliefSettings,
    #[command(flatten)]
    pub relief_files: ReliefFiles,
    #[command(flatten)]
    pub cut: CutSettings,
    #[command(flatten)]
    pub cut_files: CutFiles,
}

/// `relievo carve`.
pub fn run(args: CarveArgs, quiet: bool, verbose: bool) -> relievo::Result<()> {
    let stem = args
        .output
        .file_stem()
        .map(|s| s.to_string_lossy().to_string())
        .unwrap_or("job".into());
    let relief_path = args.output.with_file_name(format!("{stem}-relief.png"));
    let material = args.relief.material.clone();
    let mut rjob = args.relief.job(args.model, relief_path.clone());
    args.relief_files.onto(&mut rjob);
    let mut cam = args.cut.job(
        args.output.clone(),
        relief_path.display().to_string(),
        material,
    );
    args.cut_files.onto(&mut cam);
    relievo::output::check_writable(&args.output)?;
    // the job's flags before the relief: a bad one is one error line
    cam.check()?;
    // all or nothing, also when interrupted: no relief without its job
    relievo::output::interrupt::hold();
    let progress = relievo::progress::Progress::on_terminal(quiet);
    let r = rjob.run(&progress);
    progress.finish();
    let r = r?;
    super::relief::say_notes(&rjob, &r, quiet);
    let s = match super::with_spinner(quiet, "planning and checking the job", || {
        cam.run(&r.relief)
    }) {
        Ok(s) => s,
        Err(e) => {
            // all or nothing: no relief without its job
            for p in &r.written {
                let _ = std::fs::remove_file(p);
            }
            return Err(e);
        }
    };
    relievo::output::interrupt::keep_all();
    if !quiet {
        eprintln!("relief -> {}", super::paths(&r.written));
    }
    report(&s, quiet, verbose);
    Ok(())
}
