//! The `toolpath` command as one library call: a relief in, a GRBL job out:
//! optional roughing, then raster and/or waterline finishing, each move
//! checked against the exact swept tool before it is written.

use crate::bail;
use crate::error::Result;
use crate::gcode::emit::{Emitter, Settings};
use crate::machine::Machine;
use crate::output::{check_writable, Outputs};
use crate::relief::Relief;
use crate::sim;
use crate::timing::Timings;
use crate::tool::Tool;
use crate::toolpath::dropcutter::HeightField;
use crate::toolpath::{path, raster, rough, waterline, Pass};
use glam::DVec3;
use std::path::{Path, PathBuf};

/// Where the job's X0 Y0 is on the panel.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Origin {
    LowerLeft,
    Center,
}

/// Finishing strategy.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Finish {
    Raster,
    Waterline,
    /// Raster everywhere, and waterlines wherever the CL surface slopes by
    /// more than 1 in 10, where rows crossing the slope or a crease along
    /// them leave wide scallops.
    #[value(name = "raster+waterline")]
    RasterWaterline,
}

/// Cutting direction (M3, clockwise spindle): climb keeps the material on
/// the tool's right. `None` in a job: zigzag rasters, climb waterlines.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Direction {
    Climb,
    Conventional,
}

/// Roughing before the finish.
#[derive(Clone, Debug)]
pub struct Roughing {
    /// Tool spec or tool-table name.
    pub tool: String,
    /// Layer depth, mm; `None` = the material's, else half the diameter.
    pub step_down: Option<f64>,
    /// `None` = the material's, else 40%.
    pub stepover: Option<Stepover>,
    /// Material left on the relief for the finish, mm.
    pub stock_to_leave: f64,
}

/// Distance between raster rows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Stepover {
    Mm(f64),
    /// Percent of the tool diameter.
    Percent(f64),
    /// Scallop height (mm) left by a ball on a flat.
    Scallop(f64),
}

impl Stepover {
    pub fn parse(s: &str) -> std::result::Result<Stepover, String> {
        let t = s.trim();
        let (v, pct) = match t.strip_suffix('%') {
            Some(p) => (p, true),
            None => (t.strip_suffix("mm").unwrap_or(t), false),
        };
        let v: f64 = v
            .trim()
            .parse()
            .map_err(|_| format!("'{s}': expected MM or PERCENT%"))?;
        Ok(if pct {
            Stepover::Percent(v)
        } else {
            Stepover::Mm(v)
        })
    }

    pub fn mm(&self, tool: &Tool) -> Result<f64> {
        let d = 2.0 * tool.radius();
        let v = match *self {
            Stepover::Mm(v) => v,
            Stepover::Percent(p) => p / 100.0 * d,
            Stepover::Scallop(h) => {
                let Tool::Ball { d } = tool else {
                    bail!("--scallop needs a ball tool")
                };
                let r = d / 2.0;
                if !(h > 0.0 && h < r) {
                    bail!("--scallop {h}: must be between 0 and the ball radius");
                }
                2.0 * (r * r - (r - h) * (r - h)).sqrt()
            }
        };
        if !(v.is_finite() && v > 0.0 && v <= d) {
            bail!("stepover {v:.4} mm: must be positive and at most the tool diameter ({d} mm)");
        }
        Ok(v)
    }
}

#[derive(Clone, Debug)]
pub struct ToolpathJob {
    /// Finishing tool: a spec or a name in the machine's tool table.
    pub tool: String,
    pub finish: Finish,
    pub direction: Option<Direction>,
    /// `None` = the material's finishing stepover, else 10%.
    pub stepover: Option<Stepover>,
    pub angle: f64,
    /// Merge tolerance, mm.
    pub tolerance: f64,
    /// Cutting feed, mm/min; `None` = the material's, else 1000; within
    /// the machine's XY limit.
    pub feed: Option<f64>,
    /// Plunge feed, mm/min; `None` = the material's, else 300.
    pub plunge_feed: Option<f64>,
    /// Spindle speed; `None` = the material's, else 18000, within range.
    pub rpm: Option<f64>,
    /// Travel height above the stock top, mm.
    pub safe_z: f64,
    pub machine: String,
    pub material: Option<String>,
    pub origin: Origin,
    pub rough: Option<Roughing>,
    /// Roughing in its own file (NAME-rough.nc) instead of an M0 tool change.
    pub split: bool,
    pub output: PathBuf,
    /// Top view of the toolpath.
    pub svg: Option<PathBuf>,
    /// The simulated cut, shaded.
    pub preview: Option<PathBuf>,
    /// Name of the relief in the header.
    pub relief_name: String,
}

pub struct CamSummary {
    /// G-code lines over all files.
    pub lines: usize,
    /// CL points before merging (one line each if unmerged).
    pub raw_points: usize,
    pub time_s: f64,
    pub stepover_mm: f64,
    /// Every file written, the job first.
    pub written: Vec<PathBuf>,
    pub timings: Timings,
}

/// One tool's share of the job.
struct Op {
    title: &'static str,
    tool: Tool,
    settings: Settings,
    strategy: String,
    passes: Vec<Pass>,
}

impl ToolpathJob {
    pub fn run(&self, relief: &Relief) -> Result<CamSummary> {
        let mut t = Timings::default();
        let rough_out = rough_path(&self.output);
        for o in [Some(&self.output), self.svg.as_ref(), self.preview.as_ref()]
            .into_iter()
            .flatten()
            .chain((self.split && self.rough.is_some()).then_some(&rough_out))
        {
            check_writable(o)?;
        }
        if !(self.tolerance > 0.0 && self.tolerance <= 1.0) {
            bail!("--tolerance {}: must be in (0, 1] mm", self.tolerance);
        }
        let m = Machine::load(&self.machine)?;
        let material = self
            .material
            .as_deref()
            .map(crate::materials::find)
            .transpose()?;
        let tool = m.tool(&self.tool)?;
        let finish_settings = self.settings(&m, &tool, material.as_ref())?;
        let cutting = material
            .as_ref()
            .and_then(|mt| mt.cutting_for(2.0 * tool.radius()));
        let stepover = self
            .stepover
            .or(cutting
                .as_ref()
                .map(|c| Stepover::Percent(c.finish_stepover)))
            .unwrap_or(Stepover::Percent(10.0));
        let step = stepover.mm(&tool)?;
        let depth_z = relief.depth_mm + finish_settings.safe_z;
        if relief.width_mm > m.travel.x || relief.height_mm > m.travel.y || depth_z > m.travel.z {
            bail!(
                "a {:.1} x {:.1} x {:.1} mm job does not fit {}'s travel {} x {} x {} mm",
                relief.width_mm,
                relief.height_mm,
                depth_z,
                m.name,
                m.travel.x,
                m.travel.y,
                m.travel.z
            );
        }
        let hf = t.time("heightfield", || {
            HeightField::new(
                relief.heights.map(|v| *v as f64 - relief.depth_mm),
                relief.pitch_mm(),
            )
        });
        let floor = -relief.depth_mm;
        let mut ops = Vec::new();
        let mut raw_points = 0;
        if let Some(r) = &self.rough {
            let rt = m.tool(&r.tool)?;
            let settings = self.settings(&m, &rt, material.as_ref())?;
            let rc = material
                .as_ref()
                .and_then(|mt| mt.cutting_for(2.0 * rt.radius()));
            let step_down = r
                .step_down
                .or(rc.as_ref().map(|c| c.step_down))
                .unwrap_or(rt.radius());
            let rstep = r
                .stepover
                .or(rc.as_ref().map(|c| Stepover::Percent(c.rough_stepover)))
                .unwrap_or(Stepover::Percent(40.0))
                .mm(&rt)?;
            if !(step_down.is_finite() && step_down > 0.0) {
                bail!("--step-down {step_down}: must be positive");
            }
            if !(r.stock_to_leave.is_finite() && r.stock_to_leave >= 0.0) {
                bail!("--stock-to-leave {}: must be 0 or more", r.stock_to_leave);
            }
            let params = rough::Params {
                tool: rt,
                stepover: rstep,
                step_down,
                stock_to_leave: r.stock_to_leave,
                angle: self.angle,
            };
            let passes = t.time("roughing", || {
                rough::passes(&hf, relief.width_mm, relief.height_mm, floor, &params)
            })?;
            raw_points += passes.iter().map(|p| p.pts.len()).sum::<usize>();
            let passes = t.time("roughing check", || {
                passes
                    .into_iter()
                    .map(|p| Pass {
                        pts: path::verify(&hf, &rt, &path::merge(&p.pts, self.tolerance)),
                        clear_z: p.clear_z,
                    })
                    .collect()
            });
            ops.push(Op {
                title: "roughing",
                tool: rt,
                settings,
                strategy: format!(
                    "roughing, layers {step_down:.3} mm, stepover {rstep:.3} mm, \
                     stock to leave {} mm",
                    r.stock_to_leave
                ),
                passes,
            });
        }
        let safe = finish_settings.safe_z;
        let mut passes = Vec::new();
        let mut what = Vec::new();
        if self.finish != Finish::Waterline {
            let rows = raster::rows(
                relief.width_mm,
                relief.height_mm,
                self.angle,
                step,
                relief.pitch_mm(),
            );
            let tol = self.tolerance;
            let climb = self.direction == Some(Direction::Climb);
            let (main, raw) = t.time("raster", || {
                let cl = raster::drop_rows(&hf, &tool, &rows, floor);
                let main = match self.direction {
                    None => vec![raster::zigzag(&hf, &tool, &cl, floor, tol)],
                    Some(_) => raster::one_way(&cl, climb, tol),
                };
                (main, cl.iter().map(Vec::len).sum::<usize>())
            });
            raw_points += raw;
            t.time("check", || {
                passes.extend(main.iter().map(|c| Pass {
                    pts: path::check_and_refine(&hf, &tool, c, floor, tol),
                    clear_z: safe,
                }))
            });
            what.push(format!(
                "raster {}, angle {} deg, stepover {step:.4} mm",
                match self.direction {
                    None => "zigzag",
                    Some(Direction::Climb) => "one-way climb",
                    Some(Direction::Conventional) => "one-way conventional",
                },
                self.angle
            ));
        }
        if self.finish != Finish::Raster {
            let climb = self.direction != Some(Direction::Conventional);
            // beside a raster: waterlines on every slope of at least
            // GENTLEST, their levels close enough to lie at most a
            // stepover apart there
            let dz = if self.finish == Finish::RasterWaterline {
                step * waterline::GENTLEST
            } else {
                step
            };
            let loops = t.time("waterline", || {
                self.waterlines(&hf, &tool, relief, floor, dz, climb)
            });
            raw_points += loops.iter().map(Vec::len).sum::<usize>();
            passes.extend(loops.into_iter().map(|pts| Pass { pts, clear_z: safe }));
            what.push(format!(
                "waterline {}, Z step {dz:.4} mm",
                if climb { "climb" } else { "conventional" },
            ));
        }
        ops.push(Op {
            title: "finishing",
            tool,
            settings: finish_settings,
            strategy: format!("finishing, {}", what.join(" + ")),
            passes,
        });
        // emit: one file, tool changes with M0, or one file per tool
        let shift = match self.origin {
            Origin::LowerLeft => DVec3::ZERO,
            Origin::Center => DVec3::new(
                -path::snap(relief.width_mm / 2.0),
                -path::snap(relief.height_mm / 2.0),
                0.0,
            ),
        };
        let groups: Vec<(PathBuf, Vec<&Op>)> = if self.split && ops.len() > 1 {
            vec![
                (rough_out, vec![&ops[0]]),
                (self.output.clone(), vec![&ops[1]]),
            ]
        } else {
            vec![(self.output.clone(), ops.iter().collect())]
        };
        let mut out = Outputs::default();
        let (mut lines, mut time_s) = (0, 0.0);
        let mut progs = Vec::new();
        let mut written = Vec::new();
        for (file, group) in groups {
            let text = t.time("g-code", || self.emit(&group, relief, shift, &m));
            let prog = t.time("time estimate", || crate::gcode::program(&text))?;
            let secs = sim::estimate_time(&prog, &m);
            time_s += secs;
            lines += text.lines().count();
            let text = with_estimate(text, secs, &m);
            out.add(&file, text.into_bytes());
            written.push(file);
            progs.push(prog);
        }
        // the job comes first in the list
        written.rotate_right(1);
        if let Some(svg) = &self.svg {
            let doc = t.time("svg", || top_view(&progs, relief, shift));
            out.add(svg, doc.into_bytes());
            written.push(svg.clone());
        }
        if let Some(pv) = &self.preview {
            let png = t.time("preview", || simulated_preview(&progs, relief, shift))?;
            out.add(pv, png);
            written.push(pv.clone());
        }
        t.time("write", || out.commit())?;
        Ok(CamSummary {
            lines,
            raw_points,
            time_s,
            stepover_mm: step,
            written,
            timings: t,
        })
    }

    /// Feeds and speeds for `tool`: flags, else the material's entry for
    /// its diameter, else generic values; defaults are capped at the
    /// machine's limits, flags beyond them refused.
    fn settings(
        &self,
        m: &Machine,
        tool: &Tool,
        material: Option<&crate::materials::Material>,
    ) -> Result<Settings> {
        let c = material.and_then(|mt| mt.cutting_for(2.0 * tool.radius()));
        let rate = m.max_rate.x.min(m.max_rate.y);
        let s = Settings {
            feed: self
                .feed
                .unwrap_or(c.as_ref().map_or(1000.0, |c| c.feed).min(rate)),
            plunge_feed: self
                .plunge_feed
                .unwrap_or(c.as_ref().map_or(300.0, |c| c.plunge).min(m.max_rate.z)),
            rpm: self.rpm.unwrap_or(
                c.as_ref()
                    .map_or(18000.0, |c| c.rpm)
                    .clamp(m.spindle.min, m.spindle.max),
            ),
            safe_z: self.safe_z,
            dwell: 2.0,
        };
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !(positive(s.safe_z) && positive(s.feed) && positive(s.plunge_feed) && s.rpm >= 0.0) {
            bail!("--safe-z, --feed and --plunge-feed must be positive and --rpm >= 0");
        }
        if s.feed > rate || s.plunge_feed > m.max_rate.z {
            bail!(
                "feed {} / plunge {} mm/min exceed {}'s limits ({rate} XY, {} Z)",
                s.feed,
                s.plunge_feed,
                m.name,
                m.max_rate.z
            );
        }
        if s.rpm < m.spindle.min || s.rpm > m.spindle.max {
            bail!(
                "--rpm {}: outside {}'s spindle range {}..{}",
                s.rpm,
                m.name,
                m.spindle.min,
                m.spindle.max
            );
        }
        Ok(s)
    }

    /// Waterline passes `dz` apart, level by level from the top, nearest
    /// first.
    fn waterlines(
        &self,
        hf: &HeightField,
        tool: &Tool,
        relief: &Relief,
        floor: f64,
        dz: f64,
        climb: bool,
    ) -> Vec<Vec<DVec3>> {
        let g = waterline::ClGrid::new(hf, tool, relief.width_mm, relief.height_mm, floor);
        let mut out: Vec<Vec<DVec3>> = Vec::new();
        let steep_only = self.finish == Finish::RasterWaterline;
        for level in waterline::levels(&g, dz) {
            let (w, h) = (relief.width_mm, relief.height_mm);
            let keep = |p: DVec3, slope: f64| {
                (0.0..=w).contains(&p.x)
                    && (0.0..=h).contains(&p.y)
                    && (!steep_only || slope >= waterline::GENTLEST)
            };
            let cs: Vec<waterline::Contour> = waterline::contours(&g, hf, tool, level)
                .iter()
                .flat_map(|c| waterline::parts(c, keep))
                .collect();
            let mut loops: Vec<(bool, Vec<DVec3>)> = cs
                .iter()
                .map(|c| {
                    let c = waterline::refine(hf, tool, floor, c);
                    let mut pts = waterline::simplify(&c, self.tolerance);
                    if climb {
                        pts.reverse();
                    }
                    (c.closed, waterline::clear(hf, tool, &pts))
                })
                .collect();
            // nearest next: closed loops start where they are nearest
            let mut at = out
                .last()
                .and_then(|p| p.last().copied())
                .unwrap_or_default();
            while !loops.is_empty() {
                let d = |p: &DVec3| (*p - at).truncate().length_squared();
                let (k, start) = loops
                    .iter()
                    .enumerate()
                    .map(|(k, (closed, pts))| {
                        let s = if *closed {
                            (0..pts.len() - 1)
                                .min_by(|&a, &b| d(&pts[a]).total_cmp(&d(&pts[b])))
                                .unwrap_or(0)
                        } else {
                            0
                        };
                        (k, s, d(&pts[s]))
                    })
                    .min_by(|a, b| a.2.total_cmp(&b.2))
                    .map(|(k, s, _)| (k, s))
                    .unwrap();
                let (closed, mut pts) = loops.swap_remove(k);
                if closed && start > 0 {
                    pts.pop();
                    pts.rotate_left(start);
                    pts.push(pts[0]);
                }
                at = *pts.last().unwrap();
                out.push(pts);
            }
        }
        out
    }

    /// One G-code file for `ops`, tool changes between them.
    fn emit(&self, ops: &[&Op], relief: &Relief, shift: DVec3, m: &Machine) -> String {
        let header = |op: &Op| {
            vec![
                format!(
                    "tool: {} (radius {} mm) for {}",
                    op.tool.spec(),
                    op.tool.radius(),
                    op.title
                ),
                format!("strategy: {}", op.strategy),
                format!(
                    "feed {} plunge {} mm/min, {} rpm, safe Z {}",
                    op.settings.feed, op.settings.plunge_feed, op.settings.rpm, op.settings.safe_z
                ),
            ]
        };
        let mut top = vec![
            "relievo GRBL 1.1 job".to_string(),
            format!("relief: {}", self.relief_name),
            format!(
                "material: {}",
                self.material.as_deref().unwrap_or("not given")
            ),
            format!(
                "stock: {:.2} x {:.2} mm, relief depth {:.3} mm",
                relief.width_mm, relief.height_mm, relief.depth_mm
            ),
            format!(
                "origin: {}, Z0 = stock top",
                if self.origin == Origin::Center {
                    "panel centre"
                } else {
                    "panel lower-left"
                }
            ),
            format!("machine: {}", m.name),
        ];
        top.extend(header(ops[0]));
        let mut e = Emitter::new(&top, &ops[0].settings);
        for (k, op) in ops.iter().enumerate() {
            if k > 0 {
                e.tool_change(&header(op), &op.settings);
            }
            for pass in &op.passes {
                // on the G-code grid: XY as dropped, Z rounded up
                let pts: Vec<DVec3> = pass
                    .pts
                    .iter()
                    .map(|p| {
                        DVec3::new(
                            path::snap(p.x + shift.x),
                            path::snap(p.y + shift.y),
                            path::snap_up(p.z),
                        )
                    })
                    .collect();
                e.pass(&pts, &op.settings, pass.clear_z);
            }
        }
        e.finish(&ops[ops.len() - 1].settings)
    }
}

/// Insert the time estimate after the header comments.
fn with_estimate(mut text: String, secs: f64, m: &Machine) -> String {
    let mut line = String::new();
    crate::gcode::emit::comment(
        &mut line,
        &format!("estimated time: {} on {}", sim::hms(secs), m.name),
    );
    let at = text
        .lines()
        .take_while(|l| l.starts_with('('))
        .map(|l| l.len() + 1)
        .sum();
    text.insert_str(at, &line);
    text
}

/// Top view of the job(s) as SVG, in mm with Y up: cuts blue, rapids red.
fn top_view(progs: &[crate::gcode::Program], relief: &Relief, shift: DVec3) -> String {
    use crate::gcode::Kind;
    use svg::node::element::{Path as SvgPath, Rectangle};
    let (w, h) = (relief.width_mm, relief.height_mm);
    let pad = 5.0;
    let mut doc = svg::Document::new()
        .set("viewBox", (-pad, -pad, w + 2.0 * pad, h + 2.0 * pad))
        .set("width", format!("{}mm", w + 2.0 * pad))
        .set("height", format!("{}mm", h + 2.0 * pad))
        .add(
            Rectangle::new()
                .set("width", w)
                .set("height", h)
                .set("fill", "#f4efe6")
                .set("stroke", "#999")
                .set("stroke-width", 0.2),
        );
    // SVG y runs down: flip, and undo the origin shift
    let xy = |p: DVec3| (p.x - shift.x, h - (p.y - shift.y));
    for prog in progs {
        for kind in [Kind::Feed, Kind::Rapid] {
            let mut d = String::new();
            let mut last: Option<DVec3> = None;
            for s in prog.segments.iter().filter(|s| s.kind == kind) {
                if (s.b - s.a).truncate().length() < 1e-9 {
                    continue;
                }
                if last != Some(s.a) {
                    let (x, y) = xy(s.a);
                    d.push_str(&format!("M{x:.3} {y:.3}"));
                }
                let (x, y) = xy(s.b);
                d.push_str(&format!("L{x:.3} {y:.3}"));
                last = Some(s.b);
            }
            if d.is_empty() {
                continue;
            }
            let (colour, width, dash) = match kind {
                Kind::Feed => ("#1f5fbf", 0.08, "none"),
                Kind::Rapid => ("#d23c2a", 0.12, "0.8 0.5"),
            };
            doc = doc.add(
                SvgPath::new()
                    .set("d", d)
                    .set("fill", "none")
                    .set("stroke", colour)
                    .set("stroke-width", width)
                    .set("stroke-dasharray", dash),
            );
        }
    }
    doc.to_string()
}

/// The job(s) cut by the simulator at the relief's resolution, shaded as
/// the relief preview is.
fn simulated_preview(
    progs: &[crate::gcode::Program],
    relief: &Relief,
    shift: DVec3,
) -> Result<Vec<u8>> {
    let stock = sim::Stock {
        x0: shift.x,
        y0: shift.y,
        width: relief.width_mm,
        height: relief.height_mm,
        thickness: relief.depth_mm + 1.0,
        pitch: relief.pitch_mm(),
    };
    let (w, h) = stock.cells();
    let mut cut = crate::Grid::new(w, h, 0.0f32);
    for prog in progs {
        sim::cut_program(&stock, &mut cut, prog, None)?;
    }
    let carved = Relief {
        heights: cut.map(|z| (*z + relief.depth_mm as f32).max(0.0)),
        width_mm: relief.width_mm,
        height_mm: relief.height_mm,
        depth_mm: relief.depth_mm,
    };
    Ok(crate::relief::file::png8(&crate::preview::shade(&carved)))
}

/// Where `path` is the job, the roughing file beside it.
pub fn rough_path(path: &Path) -> PathBuf {
    path.with_file_name(format!(
        "{}-rough.nc",
        path.file_stem()
            .map_or("job".into(), |s| s.to_string_lossy())
    ))
}
