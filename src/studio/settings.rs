//! What the page sends: the relief and cutting settings, as the library's
//! jobs and as the `relievo` command line that makes the same files. The
//! flags are the CLI's own names, so the line shown reproduces the studio.

use crate::bail;
use crate::cam::{self, Finish, Origin, Stepover, ToolpathJob};
use crate::error::Result;
use crate::ops::relief::ReliefJob;
use crate::relief::{Background, Method};
use crate::scene::{Camera, Up, View};
use clap::ValueEnum;
use serde::Deserialize;
use std::path::PathBuf;

/// The relief flags the page sets (the rest keep their CLI defaults).
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct ReliefSettings {
    pub view: String,
    /// `None` = the model's file type decides.
    pub up: Option<String>,
    pub yaw: f64,
    pub pitch: f64,
    pub roll: f64,
    pub fov: f64,
    pub resolution: usize,
    pub width: f64,
    pub depth: Option<f64>,
    pub alpha: Option<f64>,
    pub silhouette: f64,
    pub steps: Option<f64>,
    pub background: Background,
    pub bands: Option<Vec<f64>>,
    pub emphasize: Vec<(String, f64)>,
    pub material: Option<String>,
    pub mirror: bool,
    pub invert: bool,
    pub smooth: Option<f64>,
    pub fade: Option<String>,
    pub tilt: Option<String>,
    pub method: String,
}

impl Default for ReliefSettings {
    fn default() -> Self {
        let j = ReliefJob::default();
        ReliefSettings {
            view: "front".into(),
            up: None,
            yaw: j.camera.yaw,
            pitch: j.camera.pitch,
            roll: j.camera.roll,
            fov: j.camera.fov,
            resolution: j.resolution,
            width: j.width_mm,
            depth: None,
            alpha: None,
            silhouette: j.silhouette,
            steps: None,
            background: j.background,
            bands: None,
            emphasize: Vec::new(),
            material: None,
            mirror: false,
            invert: false,
            smooth: j.smooth,
            fade: None,
            tilt: None,
            method: "gradient".into(),
        }
    }
}

/// A clap value enum from its flag name, or an error naming the flag.
fn value<T: ValueEnum>(flag: &str, s: &str) -> Result<T> {
    match T::from_str(s, true) {
        Ok(v) => Ok(v),
        Err(_) => {
            let names: Vec<String> = T::value_variants()
                .iter()
                .filter_map(|v| v.to_possible_value().map(|p| p.get_name().to_string()))
                .collect();
            bail!("--{flag} {s}: expected one of {}", names.join(", "))
        }
    }
}

/// A number as the command line writes it: the shortest text that reads
/// back as the same f64.
fn num(x: f64) -> String {
    format!("{x}")
}

/// A word for a shell: quoted when it holds anything but plain characters.
pub fn shell_word(s: &str) -> String {
    let plain = !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_./:=,%+@".contains(c));
    if plain {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', r"'\''"))
    }
}

/// Flags and values pushed onto a command line.
struct Line(Vec<String>);

impl Line {
    fn flag(&mut self, name: &str, value: impl Into<String>) {
        self.0.push(format!("--{name}"));
        self.0.push(value.into());
    }
    fn switch(&mut self, name: &str, on: bool) {
        if on {
            self.0.push(format!("--{name}"));
        }
    }
    fn num(&mut self, name: &str, x: f64, default: f64) {
        if x != default {
            self.flag(name, num(x));
        }
    }
    fn opt(&mut self, name: &str, x: Option<f64>) {
        if let Some(x) = x {
            self.flag(name, num(x));
        }
    }
    fn text(&mut self, name: &str, s: &Option<String>) {
        if let Some(s) = s {
            self.flag(name, s.clone());
        }
    }
}

impl ReliefSettings {
    /// The relief job for `model` (`None` = the demo scene).
    pub fn job(&self, model: Option<PathBuf>, output: PathBuf) -> Result<ReliefJob> {
        let view: View = value("view", &self.view)?;
        let up: Option<Up> = self.up.as_deref().map(|u| value("up", u)).transpose()?;
        let method: Method = value("method", &self.method)?;
        Ok(ReliefJob {
            model,
            camera: Camera {
                view,
                yaw: self.yaw,
                pitch: self.pitch,
                fov: self.fov,
                up: Up::Y,
                roll: self.roll,
            },
            up,
            resolution: self.resolution,
            width_mm: self.width,
            depth_mm: self.depth,
            alpha: self.alpha,
            silhouette: self.silhouette,
            steps_mm: self.steps,
            background: self.background,
            bands: self.bands.clone(),
            emphasize: self.emphasize.clone(),
            material: self.material.clone(),
            mirror: self.mirror,
            invert: self.invert,
            method,
            smooth: self.smooth,
            fade: self.fade.clone(),
            tilt: self.tilt.clone(),
            output,
            ..ReliefJob::default()
        })
    }

    /// The flags that differ from the CLI's defaults.
    pub fn args(&self) -> Vec<String> {
        let d = ReliefSettings::default();
        let mut l = Line(Vec::new());
        if self.view != d.view {
            l.flag("view", self.view.clone());
        }
        l.text("up", &self.up);
        l.num("yaw", self.yaw, d.yaw);
        l.num("pitch", self.pitch, d.pitch);
        l.num("roll", self.roll, d.roll);
        l.num("fov", self.fov, d.fov);
        if self.resolution != d.resolution {
            l.flag("resolution", self.resolution.to_string());
        }
        l.num("width", self.width, d.width);
        l.text("material", &self.material);
        l.opt("depth", self.depth);
        l.opt("alpha", self.alpha);
        l.num("silhouette", self.silhouette, d.silhouette);
        l.opt("steps", self.steps);
        l.switch("flat-background", self.background == Background::Flat);
        l.switch("free-background", self.background == Background::Free);
        if let Some(b) = &self.bands {
            let b: Vec<String> = b.iter().map(|x| num(*x)).collect();
            l.flag("bands", b.join(","));
        }
        for (name, gain) in &self.emphasize {
            l.flag("emphasize", format!("{name}={}", num(*gain)));
        }
        l.switch("mirror", self.mirror);
        l.switch("invert", self.invert);
        match self.smooth {
            None => l.switch("faceted", true),
            Some(a) => l.num("smooth", a, crate::ops::relief::DEFAULT_CREASE),
        }
        l.text("fade", &self.fade);
        l.text("tilt", &self.tilt);
        if self.method != d.method {
            l.flag("method", self.method.clone());
        }
        l.0
    }
}

/// The cutting flags the page sets.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct CutSettings {
    pub machine: String,
    pub tool: String,
    pub finish: String,
    /// MM or PERCENT%; `None` = the material's, else 10%.
    pub stepover: Option<String>,
    pub angle: f64,
    pub rough: Option<String>,
    pub stock_to_leave: f64,
    pub rest: Option<String>,
    pub tolerance: f64,
    pub arcs: bool,
    pub feed: Option<f64>,
    pub rpm: Option<f64>,
    pub origin: String,
}

impl Default for CutSettings {
    fn default() -> Self {
        CutSettings {
            machine: "grbl-generic".into(),
            tool: "ball:3.175".into(),
            finish: "raster".into(),
            stepover: None,
            angle: 0.0,
            rough: None,
            stock_to_leave: 0.3,
            rest: None,
            tolerance: 0.005,
            arcs: true,
            feed: None,
            rpm: None,
            origin: "lower-left".into(),
        }
    }
}

impl CutSettings {
    /// The toolpath job writing `output` (and its SVG) for a relief made
    /// with `material`.
    pub fn job(
        &self,
        output: PathBuf,
        svg: PathBuf,
        relief_name: String,
        material: Option<String>,
    ) -> Result<ToolpathJob> {
        let finish: Finish = value("finish", &self.finish)?;
        let origin: Origin = value("origin", &self.origin)?;
        let stepover = self
            .stepover
            .as_deref()
            .map(Stepover::parse)
            .transpose()
            .map_err(|e| crate::Error(format!("--stepover {e}")))?;
        Ok(ToolpathJob {
            tool: self.tool.clone(),
            finish,
            direction: None,
            stepover,
            angle: self.angle,
            tolerance: self.tolerance,
            arcs: self.arcs,
            feed: self.feed,
            plunge_feed: None,
            rpm: self.rpm,
            safe_z: 5.0,
            machine: self.machine.clone(),
            material,
            origin,
            rough: self.rough.clone().map(|tool| cam::Roughing {
                tool,
                step_down: None,
                stepover: None,
                stock_to_leave: self.stock_to_leave,
            }),
            rest: self.rest.clone().map(|tool| cam::rest::Rest {
                tool,
                threshold: cam::rest::THRESHOLD,
            }),
            split: false,
            allow_deep_cuts: false,
            z_zero: cam::ZZero::Top,
            units: cam::Units::Mm,
            layout: cam::layout::Layout::default(),
            cutout: None,
            boundary: cam::Boundary::Panel,
            output,
            svg: Some(svg),
            preview: None,
            light: None,
            relief_name,
        })
    }

    /// The flags that differ from the CLI's defaults.
    pub fn args(&self) -> Vec<String> {
        let d = CutSettings::default();
        let mut l = Line(Vec::new());
        if self.machine != d.machine {
            l.flag("machine", self.machine.clone());
        }
        if self.tool != d.tool {
            l.flag("tool", self.tool.clone());
        }
        if self.finish != d.finish {
            l.flag("finish", self.finish.clone());
        }
        l.text("stepover", &self.stepover);
        l.num("angle", self.angle, d.angle);
        l.text("rough", &self.rough);
        if self.rough.is_some() {
            l.num("stock-to-leave", self.stock_to_leave, d.stock_to_leave);
        }
        l.text("rest", &self.rest);
        l.num("tolerance", self.tolerance, d.tolerance);
        if !self.arcs {
            l.flag("arcs", "off");
        }
        l.opt("feed", self.feed);
        l.opt("rpm", self.rpm);
        if self.origin != d.origin {
            l.flag("origin", self.origin.clone());
        }
        l.0
    }
}

/// `relievo relief MODEL FLAGS -o relief.png`, ready for a shell.
pub fn relief_command(model: Option<&str>, r: &ReliefSettings) -> String {
    command("relief", model, r.args(), "relief.png")
}

/// `relievo carve MODEL RELIEF-FLAGS CUT-FLAGS -o job.nc`.
pub fn carve_command(model: Option<&str>, r: &ReliefSettings, c: &CutSettings) -> String {
    let mut args = r.args();
    args.extend(c.args());
    command("carve", model, args, "job.nc")
}

fn command(sub: &str, model: Option<&str>, args: Vec<String>, out: &str) -> String {
    let mut words = vec!["relievo".to_string(), sub.to_string()];
    words.extend(model.map(shell_word));
    words.extend(args.iter().map(|a| shell_word(a)));
    words.push("-o".into());
    words.push(out.into());
    words.join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_say_nothing_and_changes_are_flags() {
        assert_eq!(
            relief_command(None, &ReliefSettings::default()),
            "relievo relief -o relief.png"
        );
        let r = ReliefSettings {
            depth: Some(2.5),
            yaw: -12.25,
            emphasize: vec![("tea pot".into(), 2.0)],
            background: Background::Free,
            ..Default::default()
        };
        assert_eq!(
            relief_command(Some("my model.obj"), &r),
            "relievo relief 'my model.obj' --yaw -12.25 --depth 2.5 --free-background \
             --emphasize 'tea pot=2' -o relief.png"
        );
        let c = CutSettings {
            stepover: Some("8%".into()),
            arcs: false,
            ..Default::default()
        };
        assert_eq!(
            carve_command(None, &ReliefSettings::default(), &c),
            "relievo carve --stepover 8% --arcs off -o job.nc"
        );
    }

    #[test]
    fn bad_names_are_refused_with_their_flag() {
        let r = ReliefSettings {
            view: "sideways".into(),
            ..Default::default()
        };
        let e = r.job(None, "r.png".into()).unwrap_err().to_string();
        assert!(
            e.starts_with("--view sideways: expected one of front"),
            "{e}"
        );
        let c = CutSettings {
            finish: "spiral".into(),
            ..Default::default()
        };
        assert!(c.job("a".into(), "b".into(), String::new(), None).is_err());
    }
}
