//! `relievo relief`: a model (or the demo scene) to a relief file; the
//! relief flags it shares with `carve`.

use super::print_timings;
use clap::Args;
use relievo::ops::relief::ReliefJob;
use relievo::ops::settings::ReliefSettings;
use relievo::progress::Progress;
use relievo::relief::Background;
use relievo::scene::Up;
use std::path::PathBuf;

/// What `--help` ends with.
pub const EXAMPLES: &str = "Examples:
  relievo relief                                        # the built-in demo scene -> relief.png
  relievo relief bunny.obj --view left --depth 4 --width 120 -o bunny.png
  relievo relief bust.stl --up z --material oak --preview bust-look.png";

#[derive(Args)]
pub struct ReliefArgs {
    /// OBJ, STL (ASCII or binary), grayscale depth PNG (white = near) or RGB normal-map PNG.
    pub model: Option<PathBuf>,
    /// Output relief: 16-bit PNG; a JSON sidecar is written beside it.
    #[arg(short, long, default_value = "relief.png")]
    pub output: PathBuf,
    /// Also write a shaded preview PNG.
    #[arg(long)]
    pub preview: Option<PathBuf>,
    #[command(flatten)]
    pub opts: ReliefSettings,
    #[command(flatten)]
    pub files: ReliefFiles,
}

/// The files a relief's command line names besides its output: read
/// (a stencil) or written (an STL solid, the depth buffer).
#[derive(Args)]
pub struct ReliefFiles {
    /// Grayscale mask PNG for selective scaling (white = full gain).
    #[arg(long)]
    pub stencil: Option<PathBuf>,
    /// Gain inside --stencil.
    #[arg(long, default_value_t = 2.0, allow_negative_numbers = true)]
    pub stencil_gain: f64,
    /// Also write the relief as a watertight binary STL solid.
    #[arg(long)]
    pub stl: Option<PathBuf>,
    /// Also write the depth buffer (at relief resolution) as a 16-bit PNG.
    #[arg(long)]
    pub depth_out: Option<PathBuf>,
}

impl ReliefFiles {
    /// The files set on `job`.
    pub fn onto(self, job: &mut ReliefJob) {
        job.stencil = self.stencil;
        job.stencil_gain = self.stencil_gain;
        job.stl = self.stl;
        job.depth_out = self.depth_out;
    }
}

/// After a relief is made: the up axis a mesh was read with when its file
/// type chose it (so that a model lying on its back is explained), the
/// background when the picture chose to hold it flat, and the relief's
/// warnings.
pub fn say_notes(job: &ReliefJob, made: &relievo::ops::relief::Summary, quiet: bool) {
    let mesh = job.model.is_some() && !job.model_is("png");
    if let (false, (up, true), true) = (quiet, job.up(), mesh) {
        let kind = if up == Up::Z { "STL" } else { "OBJ" };
        eprintln!("up axis: {} ({kind} default; --up to change)", up.name());
    }
    if !quiet && job.background == Background::Auto && made.params.background == Background::Flat {
        eprintln!(
            "background: held flat at 0 (the default where the picture has one; \
             --free-background lets it float)"
        );
    }
    for w in &made.warnings {
        eprintln!("warning: {w}");
    }
}

/// `relievo relief`.
pub fn run(args: ReliefArgs, quiet: bool, verbose: bool) -> relievo::Result<()> {
    let mut job = args.opts.job(args.model, args.output);
    args.files.onto(&mut job);
    job.preview = args.preview;
    let progress = Progress::on_terminal(quiet);
    let res = job.run(&progress);
    progress.finish();
    let s = res?;
    say_notes(&job, &s, quiet);
    if !quiet {
        let r = &s.relief;
        eprintln!(
            "relief {} x {} px, {:.1} x {:.1} mm, depth {:.2} mm, {} silhouette edges -> {}",
            r.heights.w,
            r.heights.h,
            r.width_mm,
            r.height_mm,
            r.depth_mm,
            s.silhouette_edges,
            super::paths(&s.written)
        );
    }
    if verbose {
        print_timings(&s.timings);
    }
    Ok(())
}
