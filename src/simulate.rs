//! The `simulate` command as one library call: a job and a relief in, the
//! cut surface, a deviation map and a report out.

use crate::bail;
use crate::error::{Context, Result};
use crate::gcode;
use crate::grid::Grid;
use crate::machine::Machine;
use crate::output::{check_writable, Outputs};
use crate::relief::{file, Relief};
use crate::sim::{self, Report, Stock};
use crate::timing::Timings;
use crate::tool::Tool;
use std::path::PathBuf;

#[derive(Clone, Debug)]
pub struct SimulateJob {
    pub job: PathBuf,
    pub relief: PathBuf,
    /// For a plain heightmap without sidecar (also override it).
    pub relief_width: Option<f64>,
    pub relief_depth: Option<f64>,
    /// Tool spec; `None` = from the job's `(tool: SPEC)` comment.
    pub tool: Option<String>,
    /// Stock width x height x thickness (mm); `None` = the relief's panel,
    /// as thick as its depth plus 3 mm.
    pub stock: Option<(f64, f64, f64)>,
    /// Stock cells per relief pixel along each axis.
    pub oversample: usize,
    pub machine: String,
    /// Job coordinates of the machine travel box's lower-left corner.
    pub travel_origin: (f64, f64),
    pub output: PathBuf,
    pub report: Option<PathBuf>,
    pub deviation: Option<PathBuf>,
}

impl Default for SimulateJob {
    fn default() -> Self {
        SimulateJob {
            job: PathBuf::new(),
            relief: PathBuf::new(),
            relief_width: None,
            relief_depth: None,
            tool: None,
            stock: None,
            oversample: 1,
            machine: "grbl-generic".into(),
            travel_origin: (0.0, 0.0),
            output: PathBuf::from("cut.png"),
            report: None,
            deviation: None,
        }
    }
}

pub struct SimSummary {
    pub report: Report,
    pub tool: Tool,
    pub cells: (usize, usize),
    pub timings: Timings,
}

/// Colour the deviation: red = gouge, blue = residual (each scaled to its
/// own maximum), grey = within 1 micrometre, black = outside the relief.
fn deviation_png(dev: &Grid<f32>, gouge: f64, residual: f64) -> Vec<u8> {
    let mut rgb = Vec::with_capacity(dev.data.len() * 3);
    for &d in &dev.data {
        let d = d as f64;
        let px = if d.is_nan() {
            [0, 0, 0]
        } else if d < -1e-3 {
            let k = (-d / gouge.max(1e-3)).min(1.0);
            [255, (200.0 * (1.0 - k)) as u8, (200.0 * (1.0 - k)) as u8]
        } else if d > 1e-3 {
            let k = (d / residual.max(1e-3)).min(1.0);
            [(200.0 * (1.0 - k)) as u8, (200.0 * (1.0 - k)) as u8, 255]
        } else {
            [200, 200, 200]
        };
        rgb.extend(px);
    }
    file::png_rgb(dev.w, dev.h, &rgb)
}

impl SimulateJob {
    pub fn run(&self) -> Result<SimSummary> {
        let mut t = Timings::default();
        if !(1..=16).contains(&self.oversample) {
            bail!("--oversample {}: must be 1 to 16", self.oversample);
        }
        for o in [
            Some(&self.output),
            self.report.as_ref(),
            self.deviation.as_ref(),
        ]
        .into_iter()
        .flatten()
        {
            check_writable(o)?;
        }
        let machine = Machine::load(&self.machine)?;
        let what = self.job.display().to_string();
        let text = t.time("read job", || std::fs::read(&self.job)).ctx(&what)?;
        let text = String::from_utf8(text)
            .map_err(|_| crate::Error(format!("{what}: not a text file")))?;
        let prog = t
            .time("parse", || gcode::program(&text))
            .map_err(|e| crate::Error(format!("{what}: {e}")))?;
        let relief: Relief = t.time("load relief", || {
            file::load(&self.relief, self.relief_width, self.relief_depth)
        })?;
        let pitch = relief.pitch_mm() / self.oversample as f64;
        let (sw, sh, st) =
            self.stock
                .unwrap_or((relief.width_mm, relief.height_mm, relief.depth_mm + 3.0));
        if !(sw > 0.0 && sh > 0.0 && st > 0.0 && sw.is_finite() && sh.is_finite() && st.is_finite())
        {
            bail!("--stock {sw}x{sh}x{st}: sizes must be positive");
        }
        let stock = Stock {
            x0: 0.0,
            y0: 0.0,
            width: sw,
            height: sh,
            thickness: st,
            pitch,
        };
        let (w, h) = stock.cells();
        if w * h > 1 << 28 {
            bail!("--stock/--oversample: {w} x {h} cells is too many");
        }
        let mut cut = Grid::new(w, h, 0.0f32);
        let tool = self.tool.as_deref().map(Tool::parse).transpose()?;
        let (rapids, moves, runs) = t
            .time("cut", || {
                sim::cut_program_measured(&stock, &mut cut, &prog, tool)
            })
            .map_err(|e| crate::Error(format!("{what}: {e}")))?;
        let tool = runs[runs.len() - 1].2;
        let engagement = sim::Engagement::measure(&prog, &moves, &runs, stock.pitch);
        let (gouge, residual, mean, dev) = t.time("compare", || {
            sim::deviation(&stock, &cut, &relief, (0.0, 0.0))
        });
        let report = Report {
            max_gouge_mm: gouge,
            max_residual_mm: residual,
            mean_residual_mm: mean,
            removed_mm3: sim::removed(&stock, &cut),
            rapids_in_stock: rapids,
            out_of_travel: sim::out_of_travel(&prog, &machine, self.travel_origin),
            time_s: t.time("time estimate", || sim::estimate_time(&prog, &machine)),
            lines: prog.lines,
            engagement,
        };
        let mut out = Outputs::default();
        t.time("encode", || {
            // the cut as a relief file: same depth scale as the target
            let d = relief.depth_mm;
            let heights = cut.map(|z| (*z as f64 + d).clamp(0.0, d) as f32);
            let as_relief = Relief {
                heights,
                width_mm: sw,
                height_mm: sh,
                depth_mm: d,
            };
            let (png, json) = file::encode_relief(
                &as_relief,
                serde_json::json!({"simulated": what, "tool": tool}),
            );
            out.add(&self.output, png);
            out.add(&file::sidecar_path(&self.output), json);
            if let Some(p) = &self.report {
                let mut j = serde_json::to_vec_pretty(&report).expect("report serializes");
                j.push(b'\n');
                out.add(p, j);
            }
            if let Some(p) = &self.deviation {
                out.add(p, deviation_png(&dev, gouge, residual));
            }
        });
        t.time("write", || out.commit())?;
        Ok(SimSummary {
            report,
            tool,
            cells: (w, h),
            timings: t,
        })
    }
}
