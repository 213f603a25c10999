//! `relievo relief`: a model (or the demo scene) to a relief file; the
//! relief flags it shares with `carve`.

use super::print_timings;
use clap::Args;
use relievo::ops::relief::ReliefJob;
use relievo::progress::Progress;
use relievo::relief::{Background, Method};
use relievo::scene::{Camera, Up, View};
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
    pub opts: ReliefOpts,
}

#[derive(Args)]
pub struct ReliefOpts {
    /// View preset (where the eye is, seen from the model's own front, top and sides).
    #[arg(long, value_enum, default_value_t = View::Front)]
    pub view: View,
    /// The model's up axis: y, z, -y, -z, x or -x [default: z for STL, y for OBJ].
    /// Front is +z for y-up models and -y for z-up models.
    #[arg(long, value_enum, allow_hyphen_values = true)]
    pub up: Option<Up>,
    /// Turn the picture counter-clockwise by this many degrees.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub roll: f64,
    /// Extra turn about the vertical axis, degrees.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub yaw: f64,
    /// Extra elevation of the eye, degrees.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub pitch: f64,
    /// Field of view in degrees; 0 = orthographic.
    #[arg(long, default_value_t = 20.0, allow_negative_numbers = true)]
    pub fov: f64,
    /// Long side of the relief in pixels (meshes render at twice this).
    #[arg(long, default_value_t = 512, allow_negative_numbers = true)]
    pub resolution: usize,
    /// Panel width in mm (the height follows the aspect).
    #[arg(long, default_value_t = 100.0, allow_negative_numbers = true)]
    pub width: f64,
    /// Relief depth in mm [default: from --material, else 5].
    #[arg(long, allow_negative_numbers = true)]
    pub depth: Option<f64>,
    /// Compression strength: C(x) = ln(1 + alpha x) / alpha [default: from --material, else 4].
    #[arg(long, allow_negative_numbers = true)]
    pub alpha: Option<f64>,
    /// Outline threshold, in slope units (scene depth per image width). Meshes: the largest depth
    /// mismatch between two samples' surfaces that still counts as one continuous surface (a steep
    /// surface is not an outline); depth and normal-map PNGs: the slope above which an edge is one.
    #[arg(long, default_value_t = 8.0, allow_negative_numbers = true)]
    pub silhouette: f64,
    /// Trace every outline with a constant step of this height (mm).
    #[arg(long, allow_negative_numbers = true)]
    pub steps: Option<f64>,
    /// Hold the background flat at height 0 (Dirichlet), as a carved panel's field is level.
    /// The default wherever the picture has a background (a tenth of it inside the frame's
    /// margin); this holds even a scene's thin margin (the demo's)
    #[arg(long)]
    pub flat_background: bool,
    /// Leave the background free (Neumann), as Weyrich et al. do: it then rises and falls round
    /// the subject by what the subject's outline heights differ
    #[arg(long, conflicts_with = "flat_background")]
    pub free_background: bool,
    /// Feature-band gains, finest first, e.g. 2,1.5,1 [default: from --material].
    #[arg(long, value_delimiter = ',')]
    pub bands: Option<Vec<f64>>,
    /// Scale one OBJ object's slopes: NAME=GAIN (repeatable).
    #[arg(long, value_parser = parse_emphasis)]
    pub emphasize: Vec<(String, f64)>,
    /// Grayscale mask PNG for selective scaling (white = full gain).
    #[arg(long)]
    pub stencil: Option<PathBuf>,
    /// Gain inside --stencil.
    #[arg(long, default_value_t = 2.0, allow_negative_numbers = true)]
    pub stencil_gain: f64,
    /// Material preset: depth ratio, bands and compression (see machines/materials.toml).
    #[arg(long)]
    pub material: Option<String>,
    /// Mirror left to right (for stamping dies).
    #[arg(long)]
    pub mirror: bool,
    /// Hollow relief (for moulds).
    #[arg(long)]
    pub invert: bool,
    /// Smooth shading (the default for meshes): slopes from vertex normals
    /// (the OBJ's own, else computed), split at creases sharper than ANGLE
    /// degrees, so a tessellated model's facets do not carve.
    #[arg(long, value_name = "ANGLE", num_args = 0..=1, default_value = "45", default_missing_value = "45")]
    pub smooth: f64,
    /// Flat facets: each triangle's own plane, as the mesh is (low-poly art).
    #[arg(long, conflicts_with = "smooth")]
    pub faceted: bool,
    /// Fade the heights linearly toward a side: DIR[:AMOUNT], DIR = right, top,
    /// left, bottom or degrees counter-clockwise from the right; AMOUNT 0..1
    /// (1 = to nothing at that side).
    #[arg(long)]
    pub fade: Option<String>,
    /// Tilt the panel: DEG[:DIR], a plane rising at DEG degrees toward DIR
    /// (default top); its rise comes out of the depth.
    #[arg(long)]
    pub tilt: Option<String>,
    /// gradient (Weyrich 2007) or linear (Cignoni 1997 baseline).
    #[arg(long, value_enum, default_value_t = Method::Gradient)]
    pub method: Method,
    /// Also write the relief as a watertight binary STL solid.
    #[arg(long)]
    pub stl: Option<PathBuf>,
    /// Base thickness under the relief in the STL, mm.
    #[arg(long, default_value_t = 2.0, allow_negative_numbers = true)]
    pub base: f64,
    /// Also write the depth buffer (at relief resolution) as a 16-bit PNG.
    #[arg(long)]
    pub depth_out: Option<PathBuf>,
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

pub fn parse_emphasis(s: &str) -> Result<(String, f64), String> {
    let (name, gain) = s
        .split_once('=')
        .ok_or_else(|| format!("'{s}': expected NAME=GAIN"))?;
    let gain: f64 = gain
        .parse()
        .map_err(|_| format!("'{s}': GAIN must be a number"))?;
    Ok((name.to_string(), gain))
}

impl ReliefOpts {
    pub fn job(self, model: Option<PathBuf>, output: PathBuf) -> ReliefJob {
        ReliefJob {
            model,
            camera: Camera {
                view: self.view,
                yaw: self.yaw,
                pitch: self.pitch,
                fov: self.fov,
                up: Up::Y,
                roll: self.roll,
            },
            up: self.up,
            resolution: self.resolution,
            width_mm: self.width,
            depth_mm: self.depth,
            alpha: self.alpha,
            silhouette: self.silhouette,
            steps_mm: self.steps,
            background: match (self.flat_background, self.free_background) {
                (true, _) => Background::Flat,
                (_, true) => Background::Free,
                _ => Background::Auto,
            },
            bands: self.bands,
            emphasize: self.emphasize,
            stencil: self.stencil,
            stencil_gain: self.stencil_gain,
            material: self.material,
            mirror: self.mirror,
            invert: self.invert,
            method: self.method,
            smooth: (!self.faceted).then_some(self.smooth),
            fade: self.fade,
            tilt: self.tilt,
            output,
            stl: self.stl,
            base_mm: self.base,
            preview: None,
            depth_out: self.depth_out,
        }
    }
}

/// `relievo relief`.
pub fn run(args: ReliefArgs, quiet: bool, verbose: bool) -> relievo::Result<()> {
    let mut job = args.opts.job(args.model, args.output);
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
