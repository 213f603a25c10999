//! Stage 2: a shaped gradient field in, a relief in millimetres out
//! (paper sections 3.2-3.3): feature and selective scaling, Poisson
//! integration, optional constant steps at outlines, scaling to depth.

pub mod bands;
pub mod curl;
pub mod file;
pub mod gradient;
pub mod image_input;
pub mod panel;
pub mod poisson;
pub mod shoulders;

use crate::bail;
use crate::error::Result;
use crate::grid::Grid;
use crate::timing::Timings;
use gradient::Field;
use rayon::prelude::*;

/// How depth is reduced to relief height.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Weyrich et al. 2007: gradient-domain compression.
    Gradient,
    /// Cignoni et al. 1997: the depth buffer scaled linearly (baseline).
    Linear,
}

/// What becomes of the background (the pixels that show no surface).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Background {
    /// Flat where the picture has a background to speak of (a tenth of
    /// it inside the frame's margin), free where the scene fills the view
    /// (the demo's plane: its margin is no field to stand on) and with
    /// `--steps`.
    Auto,
    /// Held at 0 (Dirichlet), as a carved panel's field is level.
    Flat,
    /// Free (Neumann), as in Weyrich et al.: it rises and falls round the
    /// subject by what the subject's outline heights differ.
    Free,
}

/// Everything that shapes a relief after the field is made.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Params {
    pub depth_mm: f64,
    pub width_mm: f64,
    pub alpha: f64,
    pub silhouette: f64,
    pub steps_mm: Option<f64>,
    pub background: Background,
    pub bands: Vec<f64>,
    pub mirror: bool,
    pub invert: bool,
    pub method: Method,
    pub fade: Option<panel::Fade>,
    pub tilt: Option<panel::Tilt>,
}

/// Selective scaling: slopes inside `weight` (0..1 per pixel) times `gain`.
pub struct Stencil {
    pub name: String,
    pub weight: Grid<f32>,
    pub gain: f64,
}

/// A relief: heights in mm, 0 = lowest point, `depth_mm` = highest.
#[derive(Clone, Debug)]
pub struct Relief {
    pub heights: Grid<f32>,
    pub width_mm: f64,
    pub height_mm: f64,
    pub depth_mm: f64,
}

impl Relief {
    pub fn pitch_mm(&self) -> f64 {
        self.width_mm / self.heights.w as f64
    }
}

/// Scale a solved height field linearly so that max - min = depth and the
/// lowest point is 0.
fn to_mm(h: &Grid<f64>, depth: f64) -> Grid<f32> {
    let (lo, hi) = extent(h.data.par_iter().copied());
    let k = if hi > lo { depth / (hi - lo) } else { 0.0 };
    h.map(|v| ((v - lo) * k) as f32)
}

/// (min, max) of a parallel stream of values.
fn extent(v: impl ParallelIterator<Item = f64>) -> (f64, f64) {
    v.fold(|| (f64::MAX, f64::MIN), |(l, h), x| (l.min(x), h.max(x)))
        .reduce(|| (f64::MAX, f64::MIN), |x, y| (x.0.min(y.0), x.1.max(y.1)))
}

/// With a flat background: raise each connected part of the subject (4-
/// neighbours in `mask`) by what its lowest sample lies below the field
/// (0), so that no part of it sinks into the background. The integrated
/// slopes may run downhill from an outline (an ear behind a head); the
/// part then stands on a step that height all round.
fn lift_above_field(h: &mut Grid<f64>, mask: &Grid<bool>) {
    let (w, n) = (h.w, h.data.len());
    let mut part = vec![u32::MAX; n];
    let mut lows = Vec::new();
    let mut stack = Vec::new();
    for start in 0..n {
        if !mask.data[start] || part[start] != u32::MAX {
            continue;
        }
        let k = lows.len() as u32;
        let mut low = 0.0f64;
        part[start] = k;
        stack.push(start);
        while let Some(i) = stack.pop() {
            low = low.min(h.data[i]);
            let (x, y) = (i % w, i / w);
            let mut visit = |j: usize| {
                if mask.data[j] && part[j] == u32::MAX {
                    part[j] = k;
                    stack.push(j);
                }
            };
            if x > 0 {
                visit(i - 1);
            }
            if x + 1 < w {
                visit(i + 1);
            }
            if y > 0 {
                visit(i - w);
            }
            if i + w < n {
                visit(i + w);
            }
        }
        lows.push(-low);
    }
    h.data
        .par_iter_mut()
        .zip(part.par_iter())
        .for_each(|(v, &k)| {
            if k != u32::MAX {
                *v += lows[k as usize];
            }
        });
}

/// Spread of a step across its outline (output samples): the standard
/// deviation of the Gaussian laid over the unit steps, so that a step
/// rises over about one sample along the outline's normal and its edge is
/// a smooth line, not the sampling's staircase.
const STEP_SPREAD: f32 = 0.6;

/// The step field blurred by a separable Gaussian of `STEP_SPREAD`
/// samples; blurring a field blurs what it integrates to, and keeps each
/// step's total rise.
fn spread_steps(g: &Grid<f32>) -> Grid<f32> {
    let k: Vec<f32> = (-2i32..=2)
        .map(|i| (-(i * i) as f32 / (2.0 * STEP_SPREAD * STEP_SPREAD)).exp())
        .collect();
    let sum: f32 = k.iter().sum();
    let k: Vec<f32> = k.iter().map(|v| v / sum).collect();
    let (w, h) = (g.w, g.h);
    let mut rows = Grid::new(w, h, 0.0f32);
    rows.data
        .par_chunks_mut(w)
        .zip(g.data.par_chunks(w))
        .for_each(|(o, r)| {
            for (x, out) in o.iter_mut().enumerate() {
                for (j, kj) in k.iter().enumerate() {
                    let xx = x as isize + j as isize - 2;
                    if xx >= 0 && (xx as usize) < w {
                        *out += kj * r[xx as usize];
                    }
                }
            }
        });
    let mut out = Grid::new(w, h, 0.0f32);
    out.data.par_chunks_mut(w).enumerate().for_each(|(y, o)| {
        for (j, kj) in k.iter().enumerate() {
            let yy = y as isize + j as isize - 2;
            if yy >= 0 && (yy as usize) < h {
                let r = &rows.data[yy as usize * w..(yy as usize + 1) * w];
                for (a, b) in o.iter_mut().zip(r) {
                    *a += kj * b;
                }
            }
        }
    });
    out
}

/// The divergence of slopes `gx`, `gy` in the field's units.
fn divergence(field: &Field, gx: &Grid<f32>, gy: &Grid<f32>) -> Grid<f64> {
    let n = field.gx.w.max(field.gx.h);
    poisson::divergence(gx, gy, 1.0 / n as f64)
}

/// The field's slopes `gx`, `gy` integrated: free (Neumann), or held at 0
/// off `subject` (a flat background) with the subject kept on or above it.
fn integrate(
    field: &Field,
    gx: &Grid<f32>,
    gy: &Grid<f32>,
    subject: Option<&Grid<bool>>,
) -> Grid<f64> {
    let div = divergence(field, gx, gy);
    match subject {
        Some(s) => poisson::solve_obstacle(&div, s).0,
        None => poisson::solve_neumann(&div),
    }
}

/// The unit steps at the field's outlines integrated on their own, in
/// the units of the field's slopes (a unit step is 1 / `n_fine`): `build`
/// adds them, scaled to `--steps` mm, to the integrated slopes, so a
/// relief's steps are `steps_mm * n_fine` times this. Spread over about a
/// sample with a free background; a flat background cannot take half a
/// step's spread.
pub fn unit_steps(field: &Field, flat_background: bool) -> Grid<f64> {
    if flat_background {
        poisson::solve_masked(&divergence(field, &field.sx, &field.sy), &field.mask).0
    } else {
        integrate(
            field,
            &spread_steps(&field.sx),
            &spread_steps(&field.sy),
            None,
        )
    }
}

/// Range (max - min) of a + c b.
fn range(a: &Grid<f64>, b: &Grid<f64>, c: f64) -> f64 {
    let (lo, hi) = extent(
        a.data
            .par_iter()
            .zip(b.data.par_iter())
            .map(|(x, y)| x + c * y),
    );
    hi - lo
}

impl Params {
    pub fn validate(&self) -> Result<()> {
        let pos = |v: f64| v.is_finite() && v > 0.0;
        if !pos(self.depth_mm) || self.depth_mm > 1000.0 {
            bail!(
                "--depth {}: must be a positive number of mm up to 1000",
                self.depth_mm
            );
        }
        if !pos(self.width_mm) || self.width_mm > 100_000.0 {
            bail!(
                "--width {}: must be a positive number of mm up to 100000",
                self.width_mm
            );
        }
        if !self.alpha.is_finite() || self.alpha < 0.0 {
            bail!(
                "--alpha {}: must be 0 (no compression) or positive",
                self.alpha
            );
        }
        if !pos(self.silhouette) {
            bail!("--silhouette {}: must be a positive slope", self.silhouette);
        }
        if let Some(s) = self.steps_mm {
            if !pos(s) || s >= self.depth_mm {
                bail!(
                    "--steps {s}: must be positive and smaller than the depth ({} mm)",
                    self.depth_mm
                );
            }
        }
        if self.bands.len() > 10 || self.bands.iter().any(|a| !a.is_finite() || *a < 0.0) {
            bail!("--bands: at most 10 gains, each a number >= 0");
        }
        Ok(())
    }
}

/// Why a relief came out flat or nearly flat, if it did: all of it at one
/// height, or 98% of the subject within half the depth (the rest spent on
/// a few spikes). The reason names what to change.
pub fn flatness(r: &Relief, field: &Field) -> Option<String> {
    let mut fg: Vec<f32> = r
        .heights
        .data
        .iter()
        .zip(&field.mask.data)
        .filter(|(_, &m)| m)
        .map(|(h, _)| *h)
        .collect();
    if fg.is_empty() {
        return None;
    }
    let on_outline = field
        .barrier
        .data
        .iter()
        .zip(&field.mask.data)
        .filter(|(b, m)| **b && **m)
        .count() as f64
        / fg.len() as f64;
    let why = if on_outline > 0.5 {
        format!(
            "{:.0}% of the subject's samples touch an outline, so their slopes were zeroed; raise --silhouette",
            100.0 * on_outline
        )
    } else {
        "the model shows little depth from this view, or a few outline ends or holes took the depth; try another view, --steps or a larger --alpha".to_string()
    };
    let (lo, hi) = fg
        .iter()
        .fold((f32::MAX, f32::MIN), |(l, h), v| (l.min(*v), h.max(*v)));
    if hi - lo <= 1e-6 * r.depth_mm as f32 {
        return Some(format!("the relief is flat: {why}"));
    }
    let spread = spread98(&mut fg);
    // shipped models keep 80-95% of the depth in 98% of the subject
    (spread < 0.5 * r.depth_mm).then(|| {
        format!(
            "the relief is nearly flat: 98% of the subject lies within {spread:.2} mm of the {} mm depth; {why}",
            r.depth_mm
        )
    })
}

/// The range the middle 98% of `v` spans (1st to 99th percentile), by
/// selection; `v` is reordered.
fn spread98(v: &mut [f32]) -> f64 {
    let k = v.len() / 100;
    let top = v.len() - 1 - k;
    let high = *v.select_nth_unstable_by(top, f32::total_cmp).1;
    let lows = &mut v[..top.max(1)];
    let low = *lows
        .select_nth_unstable_by(k.min(lows.len() - 1), f32::total_cmp)
        .1;
    (high - low) as f64
}

/// A free background is not a flat field: where the subject's outline
/// heights differ (its own slopes say they must), the least-squares
/// solve carries them into the background, which rises and falls around
/// the subject (2-3 mm of a 5 mm bunny, teapot or Spot) and takes that
/// much of the depth from the subject. Said when the middle 98% of the
/// background spans more than a fifth of the depth.
pub fn background_rise(r: &Relief, field: &Field, p: &Params) -> Option<String> {
    // a tilt or fade slopes the field on purpose
    if holds_background(field, p)
        || p.method != Method::Gradient
        || p.tilt.is_some()
        || p.fade.is_some()
    {
        return None;
    }
    let mut bg = field_background(field, |x, y| *r.heights.get(x, y))?;
    let spread = spread98(&mut bg);
    let remedy = if p.background == Background::Free {
        "without --free-background it is held flat at 0"
    } else {
        // free by default with --steps
        "--flat-background holds it flat at 0"
    };
    (spread > 0.2 * r.depth_mm).then(|| {
        format!(
            "the free background rises and falls by {spread:.2} mm of the {} mm depth around the subject; \
             {remedy} and leaves the depth to the subject",
            r.depth_mm
        )
    })
}

/// `at` over the background inside the margin the camera frames every
/// scene with (2.5% of its long side, at least 3 px, and one more), if
/// that is at least a tenth of the picture: a scene that fills the view
/// (the demo's plane) has none, and its margin is no field.
fn field_background<T>(field: &Field, at: impl Fn(usize, usize) -> T) -> Option<Vec<T>> {
    let (w, h) = (field.mask.w, field.mask.h);
    let band = ((0.025 * w.max(h) as f64).ceil() as usize).max(3) + 1;
    let mut bg = Vec::new();
    for y in band..h.saturating_sub(band) {
        for x in band..w.saturating_sub(band) {
            if !*field.mask.get(x, y) {
                bg.push(at(x, y));
            }
        }
    }
    (bg.len() >= w * h / 10).then_some(bg)
}

/// Whether the background is held at 0: asked for, or by default where
/// the picture has one, unless `--steps` trace the outlines (a flat
/// field cannot take half a step's spread, so each step would be the
/// sampling's staircase where it meets the field).
pub fn holds_background(field: &Field, p: &Params) -> bool {
    match p.background {
        Background::Flat => field.mask.data.iter().any(|&m| !m),
        Background::Free => false,
        Background::Auto => p.steps_mm.is_none() && field_background(field, |_, _| ()).is_some(),
    }
}

/// Turn a shaped field into a relief.
pub fn build(field: &Field, p: &Params, stencils: &[Stencil], t: &mut Timings) -> Result<Relief> {
    p.validate()?;
    let (w, h) = (field.gx.w, field.gx.h);
    let height_mm = p.width_mm * h as f64 / w as f64;
    // a tilt's plane takes its rise out of the depth; the subject keeps
    // its own scale (and `--steps` its exact height) under it
    let rise = p.tilt.map_or(0.0, |t| t.rise(p.width_mm, height_mm));
    if rise >= 0.9 * p.depth_mm {
        bail!(
            "--tilt: the plane rises {rise:.2} mm over the panel, leaving too little of the {} mm depth for the relief; use a smaller angle or a deeper relief",
            p.depth_mm
        );
    }
    let subject = p.depth_mm - rise;
    if let Some(s) = p.steps_mm.filter(|&s| s >= subject) {
        bail!("--steps {s}: must be smaller than the depth left under the tilt ({subject:.2} mm)");
    }
    let mut heights = match p.method {
        Method::Linear => t.time("linear scale", || {
            to_mm(&field.depth.map(|v| *v as f64), subject)
        }),
        Method::Gradient => {
            let (mut gx, mut gy) = scaled_gradients(field, p, stencils, t);
            // with a flat background (where there is any), no part of the
            // subject below it
            if p.background == Background::Flat && field.mask.data.iter().all(|&m| m) {
                bail!("--flat-background: the input has no background pixels to hold at 0");
            }
            // with a flat background the solve keeps the subject on or
            // above the field; steps added to it can still sink a part
            // (an inner outline stepping down), which is then lifted
            let hold = holds_background(field, p).then_some(&field.mask);
            let lift = |h: &mut Grid<f64>| {
                if let Some(mask) = hold {
                    lift_above_field(h, mask);
                }
            };
            let solve = |gx: &Grid<f32>, gy: &Grid<f32>| integrate(field, gx, gy, hold);
            match p.steps_mm {
                Some(s) if field.silhouette_edges > 0 => {
                    // the steps first: if they alone exceed the depth, the
                    // main solve is not worth doing
                    let steps = t.time("poisson (steps)", || unit_steps(field, hold.is_some()));
                    let nf = field.n_fine as f64;
                    if s * nf * range(&steps, &steps, 0.0) >= subject {
                        bail!("--steps {s}: the steps alone exceed the depth; use smaller steps");
                    }
                    t.time("shoulders", || shoulders::flatten(&mut gx, &mut gy, field));
                    let main = t.time("poisson", || solve(&gx, &gy));
                    // choose c so a unit step (1 / n_fine of h) becomes s mm
                    // after the final scaling to depth
                    let mut c = s * nf * range(&main, &steps, 0.0) / subject;
                    let mut converged = false;
                    for _ in 0..200 {
                        let next = s * nf * range(&main, &steps, c) / subject;
                        converged = (next - c).abs() <= 1e-9 * c.abs();
                        c = next;
                        if converged || !c.is_finite() {
                            break;
                        }
                    }
                    if !converged || c <= 0.0 {
                        bail!("--steps {s}: the steps alone exceed the depth; use smaller steps");
                    }
                    let mut total = main;
                    total
                        .data
                        .par_iter_mut()
                        .zip(steps.data.par_iter())
                        .for_each(|(a, b)| *a += c * b);
                    lift(&mut total);
                    to_mm(&total, subject)
                }
                _ => {
                    let h = t.time("poisson", || solve(&gx, &gy));
                    to_mm(&h, subject)
                }
            }
        }
    };
    if let Some(f) = &p.fade {
        panel::fade(&mut heights, f);
    }
    if let Some(t) = &p.tilt {
        panel::tilt(&mut heights, t, p.width_mm, height_mm);
    }
    if p.invert {
        heights
            .data
            .par_iter_mut()
            .for_each(|v| *v = p.depth_mm as f32 - *v);
    }
    if p.mirror {
        heights.flip_x();
    }
    Ok(Relief {
        heights,
        width_mm: p.width_mm,
        height_mm,
        depth_mm: p.depth_mm,
    })
}

/// The field's gradients with the feature bands' and the stencils' gains
/// applied.
fn scaled_gradients(
    field: &Field,
    p: &Params,
    stencils: &[Stencil],
    t: &mut Timings,
) -> (Grid<f32>, Grid<f32>) {
    let (mut gx, mut gy) = (field.gx.clone(), field.gy.clone());
    if !p.bands.is_empty() {
        (gx, gy) = t.time("feature bands", || {
            rayon::join(
                || bands::feature_scale(&gx, &field.barrier, &p.bands),
                || bands::feature_scale(&gy, &field.barrier, &p.bands),
            )
        });
    }
    for s in stencils {
        t.time("selective scale", || {
            for g in [&mut gx, &mut gy] {
                g.data
                    .par_iter_mut()
                    .zip(s.weight.data.par_iter())
                    .for_each(|(v, wt)| {
                        *v *= 1.0 + (s.gain as f32 - 1.0) * wt;
                    });
            }
        });
    }
    (gx, gy)
}
