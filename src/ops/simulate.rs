//! The `simulate` command as one library call: a job and a relief in, the
//! cut surface, a deviation map and a report out.

use crate::bail;
use crate::cam::layout::Frame;
use crate::cutter::dropcutter::HeightField;
use crate::error::Result;
use crate::gcode;
use crate::grid::Grid;
use crate::machine::Machine;
use crate::output::{check_writable, Outputs};
use crate::relief::{file, Relief};
use crate::sim::cells::{between_cells, oversample_for, MAX_CELLS, MAX_OVERSAMPLE};
use crate::sim::{self, Report, Stock};
use crate::timing::Timings;
use crate::tool::Tool;
use std::path::PathBuf;

#[derive(Clone, Debug)]
pub struct SimulateJob {
    /// The job's files, cut in turn into one stock (a split job: the
    /// roughing file, then the finishing file).
    pub jobs: Vec<PathBuf>,
    pub relief: PathBuf,
    /// For a plain heightmap without sidecar (also override it).
    pub relief_width: Option<f64>,
    pub relief_depth: Option<f64>,
    /// Tool spec; `None` = from the job's `(tool: SPEC)` comment.
    pub tool: Option<String>,
    /// Stock width x height x thickness (mm); `None` = the stock the job's
    /// `(frame: ...)` header states, else the relief's panel, as thick as
    /// its depth plus 3 mm.
    pub stock: Option<(f64, f64, f64)>,
    /// Stock cells per relief pixel along each axis; `None` = fine enough
    /// that a cut's bottom between cell centres lies within
    /// `BETWEEN_CELLS` of what the cells show (`oversample_for`).
    pub oversample: Option<usize>,
    pub machine: String,
    /// Job coordinates of the machine travel box's lower-left corner;
    /// `None` = the stock's lower-left corner.
    pub travel_origin: Option<(f64, f64)>,
    /// Where the tool stands when each file starts (work coordinates);
    /// `None` = where the job's frame header puts the work zero (the
    /// tool on the stock top over X0 Y0), else the job's highest Z over
    /// X0 Y0.
    pub start: Option<glam::DVec3>,
    pub output: PathBuf,
    pub report: Option<PathBuf>,
    pub deviation: Option<PathBuf>,
}

impl Default for SimulateJob {
    fn default() -> Self {
        SimulateJob {
            jobs: Vec::new(),
            relief: PathBuf::new(),
            relief_width: None,
            relief_depth: None,
            tool: None,
            stock: None,
            oversample: None,
            machine: "grbl-generic".into(),
            travel_origin: None,
            start: None,
            output: PathBuf::from("cut.png"),
            report: None,
            deviation: None,
        }
    }
}

pub struct SimSummary {
    pub report: Report,
    /// The frame read from the job's header, if it had one.
    pub frame: Option<Frame>,
    pub tool: Tool,
    pub cells: (usize, usize),
    /// The stock the job cut, its cut surface (Z of each cell, 0 = the
    /// stock top) and each cell's deviation from the relief (mm, > 0 =
    /// material left, < 0 = gouge, NaN = off the panel).
    pub stock: Stock,
    pub cut: Grid<f32>,
    pub deviation: Grid<f32>,
    /// Job coordinates of the panel's lower-left corner.
    pub panel_at: (f64, f64),
    pub timings: Timings,
}

/// The deviation map with its legend (`sim::map`): residual as its
/// mean over the finishing stepover (mm, from the job's header) so
/// that scallops sampled by the cells do not beat into bands.
fn deviation_png(dev: &Grid<f32>, gouge: f64, cell: f64, stepover: Option<f64>) -> Vec<u8> {
    let shown = sim::map::smoothed(dev, stepover.map_or(1.0, |s| s / cell));
    let most = shown
        .data
        .iter()
        .filter(|d| d.is_finite())
        .fold(0.0f64, |m, d| m.max(*d as f64));
    let (w, h, rgb) = sim::map::picture(&shown, sim::map::nice_scale(gouge.max(most)));
    file::png_rgb(w, h, &rgb)
}

/// The job's files read: each with its name, program and the offset that
/// moves it into the first file's frame.
struct Jobs {
    progs: Vec<(String, gcode::Program, glam::DVec3)>,
    frame: Option<Frame>,
    /// The finishing stepover the headers state (the largest).
    stepover: Option<f64>,
}

/// What cutting every file found.
struct Cut {
    by_moves: sim::MoveGouge,
    engagement: sim::Engagement,
    rapids: Vec<usize>,
    out_of_travel: Vec<usize>,
    lines: usize,
    time_s: f64,
    time_by_tool: Vec<(String, f64)>,
    last_tool: Option<Tool>,
}

impl SimulateJob {
    /// Read the jobs and the relief, place the stock, cut every file into
    /// it, compare with the relief, and write the cut, the report and the
    /// deviation map (all or nothing).
    pub fn run(&self) -> Result<SimSummary> {
        let mut t = Timings::default();
        if let Some(k) = self
            .oversample
            .filter(|k| !(1..=MAX_OVERSAMPLE).contains(k))
        {
            bail!("--oversample {k}: must be 1 to {MAX_OVERSAMPLE}");
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
        if self.jobs.is_empty() {
            bail!("simulate: no job given");
        }
        let mut jobs = self.read_jobs(&mut t)?;
        let relief: Relief = t.time("load relief", || {
            file::load(&self.relief, self.relief_width, self.relief_depth)
        })?;
        let tool = self
            .tool
            .as_deref()
            .map(|s| machine.tool_for("--tool", s))
            .transpose()?;
        let mut tools = Vec::new();
        for (what, prog, _) in &jobs.progs {
            let runs =
                sim::tool_runs(prog, tool).map_err(|e| crate::Error(format!("{what}: {e}")))?;
            tools.extend(runs.iter().map(|r| r.2));
        }
        let stock = self.stock_for(&relief, jobs.frame, &tools)?;
        let (w, h) = stock.cells();
        let panel_at = jobs.frame.map_or((0.0, 0.0), |f| f.panel);
        let mut cut = Grid::new(w, h, 0.0f32);
        let surface = t.time("heightfield", || HeightField::of_relief(&relief));
        let done = self.cut_all(
            &mut jobs,
            &stock,
            &mut cut,
            tool,
            (&surface, panel_at),
            &machine,
            &mut t,
        )?;
        let tool = done.last_tool.expect("at least one job");
        let (at_cells, residual, mean, dev) = t.time("compare", || {
            sim::deviation(&stock, &cut, &relief, panel_at)
        });
        let by_moves = done.by_moves;
        let gouge = at_cells.max(by_moves.mm);
        let max_gouge_line = by_moves.line.filter(|_| by_moves.mm >= at_cells);
        let max_gouge_at_mm = (at_cells > 0.0 && max_gouge_line.is_none())
            .then(|| {
                dev.data
                    .iter()
                    .position(|&d| !d.is_nan() && -(d as f64) >= at_cells)
                    .map(|k| stock.centre(k % dev.w, k / dev.w))
            })
            .flatten();
        let report = Report {
            max_gouge_mm: gouge,
            max_gouge_at_mm,
            max_gouge_line,
            gouge_exact_per_move: by_moves.every_tool,
            max_residual_mm: residual,
            mean_residual_mm: mean,
            removed_mm3: sim::removed(&stock, &cut),
            rapids_in_stock: done.rapids,
            out_of_travel: done.out_of_travel,
            time_s: done.time_s,
            time_by_tool: done.time_by_tool,
            lines: done.lines,
            engagement: done.engagement,
            frame: jobs.frame.map(|f| f.comment()),
            cell_mm: stock.pitch,
            between_cells_mm: between_cells(&tools, stock.pitch),
        };
        let what = jobs
            .progs
            .iter()
            .map(|p| p.0.as_str())
            .collect::<Vec<_>>()
            .join(" + ");
        let outputs = t.time("encode", || {
            self.outputs(
                &what,
                tool,
                (&relief, &stock, &cut),
                &report,
                &dev,
                jobs.stepover,
            )
        });
        t.time("write", || outputs.commit())?;
        Ok(SimSummary {
            report,
            frame: jobs.frame,
            tool,
            cells: (w, h),
            stock,
            cut,
            deviation: dev,
            panel_at,
            timings: t,
        })
    }

    /// Each job file read and parsed; a file placed by its own frame (a
    /// tile, say) moves into the first file's coordinates, and must share
    /// its stock and panel.
    fn read_jobs(&self, t: &mut Timings) -> Result<Jobs> {
        let mut progs = Vec::new();
        let mut frame = None;
        let mut stepover: Option<f64> = None;
        for job in &self.jobs {
            let what = job.display().to_string();
            let text = t.time("read job", || {
                crate::input::read_text(job, crate::input::MAX_FILE)
            })?;
            let f = Frame::find(&text).map_err(|e| crate::Error(format!("{what}: {e}")))?;
            if let Some(s) = sim::map::finishing_stepover(&text) {
                stepover = Some(stepover.map_or(s, |m: f64| m.max(s)));
            }
            let mut offset = glam::DVec3::ZERO;
            match (frame, f) {
                (None, f) => frame = f,
                (Some(a), Some(b)) => {
                    let same_stock =
                        (a.stock.2, a.stock.3, a.stock.4) == (b.stock.2, b.stock.3, b.stock.4);
                    let d = (a.stock.0 - b.stock.0, a.stock.1 - b.stock.1);
                    let same_panel = ((a.panel.0 - b.panel.0) - d.0).abs() < 1e-3
                        && ((a.panel.1 - b.panel.1) - d.1).abs() < 1e-3;
                    if !(same_stock && same_panel && a.z_bottom == b.z_bottom) {
                        bail!(
                            "{what}: its frame ({}) is not the first job's stock and panel ({})",
                            b.comment(),
                            a.comment()
                        );
                    }
                    offset = glam::DVec3::new(d.0, d.1, 0.0);
                }
                _ => {}
            }
            let start = self.start.or(f.map(|f| f.start()));
            let prog = t
                .time("parse", || gcode::program_at(&text, start))
                .map_err(|e| crate::Error(format!("{what}: {e}")))?;
            progs.push((what, prog, offset));
        }
        Ok(Jobs {
            progs,
            frame,
            stepover,
        })
    }

    /// The stock where the job's header puts it (else the relief's panel,
    /// its depth plus 3 mm thick), its cells on the relief's samples, once
    /// per relief pixel or oversampled for the job's tools.
    fn stock_for(&self, relief: &Relief, frame: Option<Frame>, tools: &[Tool]) -> Result<Stock> {
        let cells_per_px = self.oversample.unwrap_or_else(|| {
            oversample_for(
                tools,
                relief.pitch_mm(),
                relief.heights.w * relief.heights.h,
            )
        });
        let pitch = relief.pitch_mm() / cells_per_px as f64;
        let (x0, y0, fw, fh, ft) = frame.map_or(
            (
                0.0,
                0.0,
                relief.width_mm,
                relief.height_mm,
                relief.depth_mm + 3.0,
            ),
            |f| f.stock,
        );
        let (sw, sh, st) = self.stock.unwrap_or((fw, fh, ft));
        if !(sw > 0.0 && sh > 0.0 && st > 0.0 && sw.is_finite() && sh.is_finite() && st.is_finite())
        {
            bail!("--stock {sw}x{sh}x{st}: sizes must be positive");
        }
        let panel_at = frame.map_or((0.0, 0.0), |f| f.panel);
        let stock = Stock {
            x0,
            y0,
            width: sw,
            height: sh,
            thickness: st,
            pitch,
        }
        .aligned_to(panel_at.0, panel_at.1 + relief.height_mm);
        let (w, h) = stock.cells();
        if w.saturating_mul(h) > MAX_CELLS {
            bail!(
                "--stock/--oversample: {w} x {h} cells, more than the {} million taken \
                 (memory); lower --oversample or --stock",
                MAX_CELLS >> 20
            );
        }
        Ok(stock)
    }

    /// Every file cut into the stock in turn: its travel judged, its cut,
    /// its gouge along the moves, its engagement, its rapids in the stock
    /// and its time by tool; lines numbered on from file to file.
    #[allow(clippy::too_many_arguments)]
    fn cut_all(
        &self,
        jobs: &mut Jobs,
        stock: &Stock,
        cut: &mut Grid<f32>,
        tool: Option<Tool>,
        (surface, panel_at): (&HeightField, (f64, f64)),
        machine: &Machine,
        t: &mut Timings,
    ) -> Result<Cut> {
        // Z0 on the stock's bottom: the stock top is at Z = T
        let z_shift = jobs.frame.filter(|f| f.z_bottom).map_or(0.0, |f| f.stock.4);
        let travel_origin = self.travel_origin.unwrap_or((stock.x0, stock.y0));
        let mut c = Cut {
            by_moves: sim::MoveGouge::NONE,
            engagement: sim::Engagement::default(),
            rapids: Vec::new(),
            out_of_travel: Vec::new(),
            lines: 0,
            time_s: 0.0,
            time_by_tool: Vec::new(),
            last_tool: None,
        };
        for (what, prog, offset) in jobs.progs.iter_mut() {
            let lines = c.lines;
            // the machine's travel is judged on the moves as written; a
            // file moved into the first one's frame (a tile) has the
            // machine's travel where its own moves begin
            let origin = if *offset == glam::DVec3::ZERO || self.travel_origin.is_some() {
                travel_origin
            } else {
                let (lo, _) = prog.bounds();
                (lo.x, lo.y)
            };
            c.out_of_travel.extend(
                sim::out_of_travel(prog, machine, origin)
                    .iter()
                    .map(|n| n + lines),
            );
            // then shifted in place (a copy of a 30 million move job is 2 GB)
            prog.shift(*offset - glam::DVec3::new(0.0, 0.0, z_shift));
            let prog = &*prog;
            let (r, moves, runs) = t
                .time("cut", || sim::cut_program_measured(stock, cut, prog, tool))
                .map_err(|e| crate::Error(format!("{what}: {e}")))?;
            c.last_tool = Some(runs[runs.len() - 1].2);
            let g = t.time("gouge along moves", || {
                sim::move_gouge(prog, &runs, surface, panel_at, true)
            });
            // lines are numbered per file; a second file's follow on
            c.by_moves = c.by_moves.max(sim::MoveGouge {
                line: g.line.map(|n| n + lines),
                ..g
            });
            c.engagement
                .absorb(sim::Engagement::measure(prog, &moves, &runs, stock.pitch));
            c.rapids.extend(r.iter().map(|n| n + lines));
            // the estimate by tool: each run from its (tool: ..) comment
            // (one run when --tool overrides them)
            let starts: Vec<usize> = if runs.len() == prog.tool_lines.len() {
                prog.tool_lines.iter().map(|l| l - 1).collect()
            } else {
                vec![0]
            };
            let parts = t.time("time estimate", || {
                sim::time_by_part(prog, machine, &starts)
            });
            for (r, secs) in runs.iter().zip(parts) {
                c.time_s += secs;
                match c.time_by_tool.last_mut() {
                    Some(last) if last.0 == r.2.spec() => last.1 += secs,
                    _ => c.time_by_tool.push((r.2.spec(), secs)),
                }
            }
            c.lines += prog.lines;
        }
        Ok(c)
    }

    /// The cut as a relief file (same depth scale as the target, placed by
    /// its lower-left corner in job coordinates), the report and the
    /// deviation map, ready to write.
    #[allow(clippy::too_many_arguments)]
    fn outputs(
        &self,
        what: &str,
        tool: Tool,
        (relief, stock, cut): (&Relief, &Stock, &Grid<f32>),
        report: &Report,
        dev: &Grid<f32>,
        stepover: Option<f64>,
    ) -> Outputs<'_> {
        let mut out = Outputs::default();
        let d = relief.depth_mm;
        let heights = cut.map(|z| (*z as f64 + d).clamp(0.0, d) as f32);
        let as_relief = Relief {
            heights,
            width_mm: stock.width,
            height_mm: stock.height,
            depth_mm: d,
        };
        let (png, json) = file::encode_relief(
            &as_relief,
            serde_json::json!({
                "simulated": what,
                "tool": tool,
                "x0_mm": stock.x0,
                "y0_mm": stock.y0,
            }),
        );
        out.add(&self.output, png);
        out.add(&file::sidecar_path(&self.output), json);
        if let Some(p) = &self.report {
            let mut j = serde_json::to_vec_pretty(report).expect("report serializes");
            j.push(b'\n');
            out.add(p, j);
        }
        if let Some(p) = &self.deviation {
            out.add(
                p,
                deviation_png(dev, report.max_gouge_mm, stock.pitch, stepover),
            );
        }
        out
    }
}
