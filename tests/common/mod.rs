//! Helpers shared by the integration tests: run the real binary, read
//! its outputs.
#![allow(dead_code)]

pub mod browser;
pub mod firmware;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_relievo"))
}

/// Run the binary with `args`; returns the output.
pub fn run(args: &[&str]) -> Output {
    bin().args(args).output().expect("relievo runs")
}

/// A file in fixtures/ (the models, with their sources in SOURCES.md).
pub fn fixture(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures")
        .join(name)
        .display()
        .to_string()
}

/// A fresh scratch directory for one test.
pub fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("relievo-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A 16-bit grayscale PNG as (w, h, values 0..65535).
pub fn read_png16(p: &Path) -> (usize, usize, Vec<u16>) {
    let img = image::open(p)
        .unwrap_or_else(|e| panic!("{}: {e}", p.display()))
        .to_luma16();
    (img.width() as usize, img.height() as usize, img.into_raw())
}

pub fn write_png16(p: &Path, w: usize, h: usize, v: &[u16]) {
    image::ImageBuffer::<image::Luma<u16>, _>::from_raw(w as u32, h as u32, v.to_vec())
        .unwrap()
        .save(p)
        .unwrap();
}

pub fn sidecar(p: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(p.with_extension("json")).unwrap()).unwrap()
}

/// Relief heights in mm from a relief PNG and its sidecar.
pub fn relief_mm(p: &Path) -> (usize, usize, Vec<f64>, f64) {
    let (w, h, v) = read_png16(p);
    let depth = sidecar(p)["depth_mm"].as_f64().unwrap();
    (
        w,
        h,
        v.iter().map(|&x| x as f64 / 65535.0 * depth).collect(),
        depth,
    )
}

pub fn ok(out: &Output) {
    assert!(
        out.status.success(),
        "relievo failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Run `simulate JOB --relief RELIEF -o CUT --report` (plus `extra`) and
/// return the JSON report.
pub fn simulate_report(job: &Path, relief: &Path, cut: &Path, extra: &[&str]) -> serde_json::Value {
    let rep = cut.with_file_name("report.json");
    let mut args = vec![
        "simulate",
        job.to_str().unwrap(),
        "--relief",
        relief.to_str().unwrap(),
        "-o",
        cut.to_str().unwrap(),
    ];
    args.extend(["--report", rep.to_str().unwrap(), "-q"]);
    args.extend(extra);
    ok(&run(&args));
    serde_json::from_str(&std::fs::read_to_string(rep).unwrap()).unwrap()
}

/// The demo relief at `res` px, 60 mm wide and 3 mm deep, written to `png`.
pub fn demo_relief(png: &Path, res: &str) {
    ok(&run(&[
        "relief",
        "--resolution",
        res,
        "--width",
        "60",
        "--depth",
        "3",
        "-o",
        png.to_str().unwrap(),
        "-q",
    ]));
}

/// Simulate `dir/job.nc`-style `job` against `dir/job-relief.png` on the
/// Shapeoko profile (cut into `dir/cut.png`); assert no rapid went through
/// stock; return the report's deepest gouge (mm).
pub fn judged_gouge(dir: &Path, job: &Path) -> f64 {
    let report = simulate_report(
        job,
        &dir.join("job-relief.png"),
        &dir.join("cut.png"),
        &["--machine", "shapeoko"],
    );
    let rapids = report["rapids_in_stock"].as_array().unwrap();
    assert!(
        rapids.is_empty(),
        "{}: rapids through stock at lines {rapids:?}",
        job.display()
    );
    report["max_gouge_mm"].as_f64().unwrap()
}

/// The relief parameters the library-level tests start from: 100 mm wide,
/// 5 mm deep, alpha 4, silhouette 8, free background.
pub fn relief_params(steps: Option<f64>) -> relievo::relief::Params {
    relievo::relief::Params {
        depth_mm: 5.0,
        width_mm: 100.0,
        alpha: 4.0,
        silhouette: 8.0,
        steps_mm: steps,
        background: relievo::relief::Background::Free,
        bands: vec![],
        mirror: false,
        invert: false,
        method: relievo::relief::Method::Gradient,
        fade: None,
        tilt: None,
    }
}

/// `mesh` rendered at `res` px (meshes render at twice that) and shaped
/// with `p`'s compression and silhouette threshold.
pub fn shaped(
    mesh: &relievo::scene::Mesh,
    cam: relievo::scene::Camera,
    res: usize,
    p: &relievo::relief::Params,
    smooth: Option<f64>,
) -> relievo::relief::gradient::Field {
    let dm =
        relievo::scene::render(mesh, &cam, res, 2, (1 << 26, "allowed"), smooth, &|_| {}).unwrap();
    let shaping = relievo::relief::gradient::Shaping {
        alpha: p.alpha,
        threshold: p.silhouette,
    };
    relievo::relief::gradient::shape_field(&dm, 2, shaping)
}

/// What GRBL's line buffer holds for each line of a job's text (comments
/// and spaces stripped), blank lines and '%' marks left out: what the
/// simulated machine's log lists when every line ran once, in order.
pub fn grbl_lines(text: &str) -> Vec<String> {
    text.lines()
        .map(relievo::gcode::parse::strip)
        .filter(|l| !l.is_empty() && l != "%")
        .collect()
}

/// Lowest surface a tool can reach over each sample: the envelope of the
/// tool placed on the CL surface at every sample centre.
pub fn reachable(
    hf: &relievo::cutter::dropcutter::HeightField,
    tool: &relievo::tool::Tool,
    w: usize,
    h: usize,
) -> Vec<f64> {
    let p = hf.pitch;
    let k = (tool.radius() / p).ceil() as isize;
    let cl: Vec<Option<f64>> = (0..w * h)
        .map(|i| {
            let (x, y) = hf.centre(i % w, i / w);
            hf.drop(tool, x, y)
        })
        .collect();
    (0..w * h)
        .map(|i| {
            let (ci, cj) = ((i % w) as isize, (i / w) as isize);
            let mut best = f64::INFINITY;
            for dj in -k..=k {
                for di in -k..=k {
                    let (ii, jj) = (ci + di, cj + dj);
                    if ii < 0 || jj < 0 || ii >= w as isize || jj >= h as isize {
                        continue;
                    }
                    if let Some(z) = cl[jj as usize * w + ii as usize] {
                        let rho = ((di * di + dj * dj) as f64).sqrt() * p;
                        best = best.min(z + tool.profile(rho));
                    }
                }
            }
            best
        })
        .collect()
}
