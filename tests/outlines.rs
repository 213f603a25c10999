//! The paper's inset scene, two crossed tubes over a plane: with `--steps`
//! every outline is a step of the requested height and no jump between
//! neighbouring samples exceeds it plus one sample's slope.

mod common;

use common::{relief_params, shaped};
use relievo::grid::Grid;
use relievo::relief::build;
use relievo::scene::{demo, Camera};
use relievo::timing::Timings;

fn relief(steps: Option<f64>, res: usize) -> (Grid<f32>, Grid<bool>) {
    let cam = Camera {
        pitch: 20.0,
        ..Camera::default()
    };
    let p = relief_params(steps);
    let field = shaped(&demo::crossed_tubes(0.0), cam, res, &p, None);
    assert!(field.silhouette_edges > 100);
    let r = build(&field, &p, &[], &mut Timings::default()).unwrap();
    (r.heights, field.barrier)
}

/// Outline pairs are neighbours where either sample touches a silhouette
/// edge. "One sample's slope" is the steepest jump between neighbours
/// that are not at an outline. Returns (worst excess of an outline jump
/// over step + slope, largest outline jump, that slope, outline pairs).
fn outline_jumps(h: &Grid<f32>, bar: &Grid<bool>, step: f64) -> (f64, f64, f64, usize) {
    let (w, hh) = (h.w, h.h);
    let at = |x: usize, y: usize| *h.get(x, y) as f64;
    let mut outline = Vec::new();
    let mut slope = 0.0f64;
    for (dx, dy) in [(1, 0), (0, 1)] {
        for y in 0..hh - dy {
            for x in 0..w - dx {
                let jump = (at(x + dx, y + dy) - at(x, y)).abs();
                if *bar.get(x, y) || *bar.get(x + dx, y + dy) {
                    outline.push(jump);
                } else {
                    slope = slope.max(jump);
                }
            }
        }
    }
    let biggest = outline.iter().cloned().fold(0.0, f64::max);
    (biggest - (step + slope), biggest, slope, outline.len())
}

#[test]
fn steps_bound_every_outline_jump() {
    let step = 0.25;
    let (h, bar) = relief(Some(step), 256);
    let (worst, biggest, slope, n) = outline_jumps(&h, &bar, step);
    eprintln!("with steps {step} mm: {n} outline pairs, largest jump {biggest:.4} mm, slope {slope:.4} mm");
    // quantisation of the 16-bit file is 5 mm / 65535 = 8e-5 mm
    assert!(
        worst <= 1e-4,
        "an outline jump exceeds the step plus one sample's slope by {worst} mm"
    );
    // and the steps are really there
    assert!(
        biggest >= 0.4 * step,
        "largest outline jump {biggest} mm: steps missing"
    );
}

/// Without steps, outlines are flattened to the surfaces' own slopes
/// (what remains is the Poisson residual of the compressed field).
#[test]
fn zeroed_silhouettes_leave_no_cliff() {
    let (h, bar) = relief(None, 256);
    let (_, biggest, slope, n) = outline_jumps(&h, &bar, 0.0);
    eprintln!(
        "without steps: {n} outline pairs, largest jump {biggest:.4} mm, slope {slope:.4} mm"
    );
    // depth jumps of up to the whole scene shrink to under 2% of the relief
    assert!(
        biggest <= 0.02 * 5.0,
        "an outline keeps a cliff of {biggest} mm"
    );
}
