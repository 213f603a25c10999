//! The `toolpath` command as one library call: a relief in, a GRBL job out
//! (ball-end raster finishing with exact tool compensation, so far).

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
use crate::toolpath::{path, raster};
use glam::DVec3;
use std::path::PathBuf;

/// Where the job's X0 Y0 is on the panel.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Origin {
    LowerLeft,
    Center,
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
    pub tool: Tool,
    pub stepover: Stepover,
    pub angle: f64,
    /// Merge tolerance, mm.
    pub tolerance: f64,
    /// Cutting feed, mm/min; `None` = 1000 within the machine's XY limit.
    pub feed: Option<f64>,
    /// Plunge feed, mm/min; `None` = 300 within the machine's Z limit.
    pub plunge_feed: Option<f64>,
    /// Spindle speed; `None` = 18000 within the machine's range.
    pub rpm: Option<f64>,
    /// Travel height above the stock top, mm.
    pub safe_z: f64,
    pub machine: String,
    pub origin: Origin,
    pub output: PathBuf,
    /// Name of the relief in the header.
    pub relief_name: String,
}

pub struct CamSummary {
    pub lines: usize,
    /// CL points before merging (one line each if unmerged).
    pub raw_points: usize,
    pub time_s: f64,
    pub stepover_mm: f64,
    pub timings: Timings,
}

impl ToolpathJob {
    pub fn run(&self, relief: &Relief) -> Result<CamSummary> {
        let mut t = Timings::default();
        check_writable(&self.output)?;
        if !(self.tolerance > 0.0 && self.tolerance <= 1.0) {
            bail!("--tolerance {}: must be in (0, 1] mm", self.tolerance);
        }
        let m = Machine::load(&self.machine)?;
        let settings = Settings {
            feed: self
                .feed
                .unwrap_or(m.max_rate.x.min(m.max_rate.y).min(1000.0)),
            plunge_feed: self.plunge_feed.unwrap_or(m.max_rate.z.min(300.0)),
            rpm: self
                .rpm
                .unwrap_or(18000f64.clamp(m.spindle.min, m.spindle.max)),
            safe_z: self.safe_z,
            dwell: 2.0,
        };
        let s = &settings;
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !(positive(s.safe_z) && positive(s.feed) && positive(s.plunge_feed) && s.rpm >= 0.0) {
            bail!("--safe-z, --feed and --plunge-feed must be positive and --rpm >= 0");
        }
        // refuse what the machine cannot do, before any work
        let rate = m.max_rate.x.min(m.max_rate.y);
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
        if relief.width_mm > m.travel.x
            || relief.height_mm > m.travel.y
            || relief.depth_mm + s.safe_z > m.travel.z
        {
            bail!(
                "a {:.1} x {:.1} x {:.1} mm job does not fit {}'s travel {} x {} x {} mm",
                relief.width_mm,
                relief.height_mm,
                relief.depth_mm + s.safe_z,
                m.name,
                m.travel.x,
                m.travel.y,
                m.travel.z
            );
        }
        let step = self.stepover.mm(&self.tool)?;
        let hf = t.time("heightfield", || {
            HeightField::new(
                relief.heights.map(|v| *v as f64 - relief.depth_mm),
                relief.pitch_mm(),
            )
        });
        let floor = -relief.depth_mm;
        let rows = raster::rows(
            relief.width_mm,
            relief.height_mm,
            self.angle,
            step,
            relief.pitch_mm(),
        );
        let cl = t.time("drop-cutter", || {
            raster::zigzag(&hf, &self.tool, &rows, floor)
        });
        let raw_points = cl.len();
        let merged = t.time("merge", || path::merge(&cl, self.tolerance));
        let merged = t.time("check", || path::verify(&hf, &self.tool, &merged));
        let shift = match self.origin {
            Origin::LowerLeft => DVec3::ZERO,
            Origin::Center => DVec3::new(
                -path::snap(relief.width_mm / 2.0),
                -path::snap(relief.height_mm / 2.0),
                0.0,
            ),
        };
        // on the G-code grid: XY as dropped, Z rounded up
        let pts: Vec<DVec3> = merged
            .iter()
            .map(|p| {
                DVec3::new(
                    path::snap(p.x + shift.x),
                    path::snap(p.y + shift.y),
                    path::snap_up(p.z),
                )
            })
            .collect();
        let header = vec![
            "relievo GRBL 1.1 job".to_string(),
            format!(
                "tool: {} (radius {} mm)",
                self.tool.spec(),
                self.tool.radius()
            ),
            format!(
                "strategy: raster finishing, zigzag, angle {} deg, stepover {:.4} mm",
                self.angle, step
            ),
            format!("relief: {}", self.relief_name),
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
            format!(
                "feed {} plunge {} mm/min, {} rpm, safe Z {}",
                s.feed, s.plunge_feed, s.rpm, s.safe_z
            ),
        ];
        let mut text = t.time("g-code", || {
            let mut e = Emitter::new(&header, s);
            e.pass(&pts, s);
            e.finish()
        });
        // the time estimate reads the job back, as the simulator would
        let prog = t.time("time estimate", || crate::gcode::program(&text))?;
        let time_s = sim::estimate_time(&prog, &m);
        let mut line = String::new();
        crate::gcode::emit::comment(
            &mut line,
            &format!("estimated time: {} on {}", sim::hms(time_s), m.name),
        );
        let at = text.lines().take(header.len()).map(|l| l.len() + 1).sum();
        text.insert_str(at, &line);
        let mut out = Outputs::default();
        let lines = text.lines().count();
        out.add(&self.output, text.into_bytes());
        t.time("write", || out.commit())?;
        Ok(CamSummary {
            lines,
            raw_points,
            time_s,
            stepover_mm: step,
            timings: t,
        })
    }
}
