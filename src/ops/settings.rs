//! The settings the command line and the studio share, each defined once:
//! a field of `ReliefSettings` or `CutSettings` with its flag, help text,
//! parser and default (clap). The command line flattens them into its
//! commands; the studio's page sends them as JSON under the same names,
//! and `Given` reads them with the same definition, so a setting added
//! here appears in both, with one parser, one default and one error.
//! Files the command line reads or writes stay in its own flags: a page
//! names none on this machine.

use crate::cam::ToolpathJob;
use crate::error::Result;
use crate::ops::relief::ReliefJob;
use crate::relief::{Background, Method};
use crate::scene::{Camera, Up, View};
use clap::{ArgAction, Args, CommandFactory, FromArgMatches, Parser};
use serde_json::Value;
use std::path::PathBuf;

/// The relief settings: how the scene is seen and made a relief.
#[derive(Args, Clone, Debug, PartialEq)]
pub struct ReliefSettings {
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
    /// Base thickness under the relief in the STL, mm.
    #[arg(long, default_value_t = 2.0, allow_negative_numbers = true)]
    pub base: f64,
}

pub fn parse_emphasis(s: &str) -> std::result::Result<(String, f64), String> {
    let (name, gain) = s
        .split_once('=')
        .ok_or_else(|| format!("'{s}': expected NAME=GAIN"))?;
    let gain: f64 = gain
        .parse()
        .map_err(|_| format!("'{s}': GAIN must be a number"))?;
    Ok((name.to_string(), gain))
}

impl ReliefSettings {
    /// The relief job for `model` (`None` = the demo scene) writing
    /// `output`; files only the command line names (a stencil, an STL, the
    /// depth buffer) are set on it there.
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
            material: self.material,
            mirror: self.mirror,
            invert: self.invert,
            method: self.method,
            smooth: (!self.faceted).then_some(self.smooth),
            fade: self.fade,
            tilt: self.tilt,
            output,
            base_mm: self.base,
            ..ReliefJob::default()
        }
    }
}

/// The cutting settings: tools, strategy, feeds, stock and layout.
#[derive(Args, Clone, Debug, PartialEq)]
pub struct CutSettings {
    /// Finishing tool: ball:D, flat:D, vbit:ANGLE[:D],
    /// taperball:TIP_RADIUS:HALF_ANGLE[:D], or a name from the machine's
    /// tool table (T1, T2, ...).
    #[arg(long, default_value = "ball:3.175")]
    pub tool: String,
    /// Finishing strategy.
    #[arg(long, value_enum, default_value_t = crate::cam::Finish::Raster)]
    pub finish: crate::cam::Finish,
    /// Distance between rows (and waterline levels): MM or PERCENT% of the
    /// tool diameter [default: the material's, else 10%].
    #[arg(long, value_parser = crate::cam::Stepover::parse)]
    pub stepover: Option<crate::cam::Stepover>,
    /// Scallop height in mm; sets the stepover for a ball.
    #[arg(long)]
    pub scallop: Option<f64>,
    /// Raster angle in degrees.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub angle: f64,
    /// Climb milling: one-way rows, waterlines with the material on the
    /// right [default: zigzag rows, climb waterlines].
    #[arg(long, conflicts_with = "conventional")]
    pub climb: bool,
    /// Conventional milling: one-way rows, waterlines the other way round.
    #[arg(long)]
    pub conventional: bool,
    /// Rough first with this tool (flat:D or ball:D, or a tool-table name).
    #[arg(long)]
    pub rough: Option<String>,
    /// Roughing layer depth, mm [default: the material's, else the tool radius].
    #[arg(long, requires = "rough")]
    pub step_down: Option<f64>,
    /// Roughing stepover, MM or PERCENT% [default: the material's, else 40%].
    #[arg(long, requires = "rough", value_parser = crate::cam::Stepover::parse)]
    pub rough_stepover: Option<crate::cam::Stepover>,
    /// Material roughing leaves on the relief for the finish, mm.
    #[arg(
        long,
        default_value_t = 0.3,
        requires = "rough",
        allow_negative_numbers = true
    )]
    pub stock_to_leave: f64,
    /// After the finish, a smaller tool (ball:D, ... or a tool-table name)
    /// only where the finish left more than --rest-threshold, as the
    /// simulated cut shows: creases the finishing tool cannot reach.
    #[arg(long)]
    pub rest: Option<String>,
    /// Material left over the relief (mm) that calls for the rest tool.
    #[arg(long, default_value_t = crate::cam::rest::THRESHOLD, requires = "rest")]
    pub rest_threshold: f64,
    /// Write the roughing to NAME-rough.nc instead of one job with an M0
    /// tool change.
    #[arg(long, requires = "rough")]
    pub split: bool,
    /// Merge dropped points into moves that pass within this distance above
    /// them (never below), mm.
    #[arg(long, default_value_t = 0.005)]
    pub tolerance: f64,
    /// Arcs: G2/G3 where a circle fits within the tolerance, for
    /// waterlines in XY (G17) and, from a tolerance of 0.006 mm, for raster
    /// rows along X or Y in their vertical plane (G18/G19), as the very
    /// chords GRBL cuts them into with its default $12 arc tolerance
    /// (0.002 mm).
    #[arg(long, value_enum, default_value_t = OnOff::On)]
    pub arcs: OnOff,
    /// Cutting feed, mm/min [default: the material's, else 1000; within the machine's limit].
    #[arg(long)]
    pub feed: Option<f64>,
    /// Plunge feed, mm/min [default: the material's, else 300].
    #[arg(long)]
    pub plunge_feed: Option<f64>,
    /// Spindle speed [default: the material's, else 18000; within the machine's range].
    #[arg(long)]
    pub rpm: Option<f64>,
    /// Travel height above the stock top, mm.
    #[arg(long, default_value_t = 5.0)]
    pub safe_z: f64,
    /// Machine profile: grbl-generic, 3018, shapeoko, or a TOML file.
    #[arg(long, default_value = "grbl-generic")]
    pub machine: String,
    /// Job origin on the panel.
    #[arg(long, value_enum, default_value_t = crate::cam::Origin::LowerLeft)]
    pub origin: crate::cam::Origin,
    /// Light of the preview: azimuth (clockwise from the panel's top
    /// edge) and elevation, degrees [default: 315,35].
    #[arg(long, value_parser = parse_pair, allow_negative_numbers = true)]
    pub light: Option<(f64, f64)>,
    /// Write cuts deeper than the material allows the tool (the header and
    /// the summary say where).
    #[arg(long)]
    pub allow_deep_cuts: bool,
    /// Where Z0 is set: the stock top (roughing leaves a touch-off pad
    /// for the next tool) or the stock's bottom, the spoilboard (needs
    /// --stock).
    #[arg(long, value_enum, default_value_t = crate::cam::ZZero::Top)]
    pub z_zero: crate::cam::ZZero,
    /// Units of the G-code (flags stay in mm).
    #[arg(long, value_enum, default_value_t = crate::cam::Units::Mm)]
    pub units: crate::cam::Units,
    /// Stock width x height x thickness, mm [default: the panel plus
    /// margins, the relief's depth + 3 mm thick]; the panel is centred on
    /// it unless --margin places it.
    #[arg(long, value_parser = parse_stock)]
    pub stock: Option<(f64, f64, f64)>,
    /// Stock around the panel, mm (the panel sits this far from the
    /// stock's lower-left corner).
    #[arg(long)]
    pub margin: Option<f64>,
    /// Where the finishing tool works: the whole panel, or the subject
    /// and a tool's diameter round it (the roughing tool then clears the
    /// background at its own level).
    #[arg(long, value_enum, default_value_t = crate::cam::Boundary::Panel)]
    pub boundary: crate::cam::Boundary,
    /// Cut a panel larger than the machine's travel in tiles of at most
    /// WIDTHxHEIGHT mm, one job each (NAME-tileC-R.nc), the stock moved
    /// between them as each job's header says.
    #[arg(long, value_parser = parse_size)]
    pub tile: Option<(f64, f64)>,
    /// Cut the panel out of the stock at the end: a profile round it,
    /// through the stock, holding it by tabs (needs stock round the
    /// panel: --stock or --margin).
    #[arg(long)]
    pub cutout: bool,
    /// Tabs holding the panel in the cutout.
    #[arg(long, default_value_t = 4, requires = "cutout")]
    pub tabs: usize,
    /// Length of each tab along the panel's edge, mm.
    #[arg(long, default_value_t = 6.0, requires = "cutout")]
    pub tab_width: f64,
    /// Height of each tab over the stock's bottom, mm.
    #[arg(long, default_value_t = 2.0, requires = "cutout")]
    pub tab_height: f64,
    /// Turn the panel a quarter (90 degrees counter-clockwise) on the machine.
    #[arg(long, value_parser = parse_rotation)]
    pub rotate: Option<bool>,
}

pub fn parse_rotation(s: &str) -> std::result::Result<bool, String> {
    match s.trim() {
        "90" => Ok(true),
        "0" => Ok(false),
        _ => Err(format!("'{s}': 0 or 90 (degrees)")),
    }
}

impl CutSettings {
    /// The toolpath job writing `output` for the relief `relief_name`
    /// made with `material`; the views only the command line names (SVG,
    /// preview) are set on it there.
    pub fn job(
        self,
        output: PathBuf,
        relief_name: String,
        material: Option<String>,
    ) -> ToolpathJob {
        use crate::cam::{Direction, Roughing, Stepover};
        let direction = match (self.climb, self.conventional) {
            (true, _) => Some(Direction::Climb),
            (_, true) => Some(Direction::Conventional),
            _ => None,
        };
        ToolpathJob {
            tool: self.tool,
            finish: self.finish,
            direction,
            stepover: self.scallop.map(Stepover::Scallop).or(self.stepover),
            angle: self.angle,
            tolerance: self.tolerance,
            arcs: self.arcs == OnOff::On,
            feed: self.feed,
            plunge_feed: self.plunge_feed,
            rpm: self.rpm,
            safe_z: self.safe_z,
            machine: self.machine,
            material,
            origin: self.origin,
            rough: self.rough.map(|tool| Roughing {
                tool,
                step_down: self.step_down,
                stepover: self.rough_stepover,
                stock_to_leave: self.stock_to_leave,
            }),
            rest: self.rest.map(|tool| crate::cam::rest::Rest {
                tool,
                threshold: self.rest_threshold,
            }),
            split: self.split,
            output,
            allow_deep_cuts: self.allow_deep_cuts,
            z_zero: self.z_zero,
            units: self.units,
            layout: crate::cam::layout::Layout {
                stock: self.stock,
                margin: self.margin,
                rotate: self.rotate.unwrap_or(false),
                tile: self.tile,
            },
            boundary: self.boundary,
            cutout: self.cutout.then_some(crate::cam::cutout::Cutout {
                tabs: self.tabs,
                tab_width: self.tab_width,
                tab_height: self.tab_height,
            }),
            svg: None,
            preview: None,
            light: self.light,
            relief_name,
        }
    }
}

/// A switch set on or off.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum OnOff {
    On,
    Off,
}

/// `N` sizes in mm written `AxB[xC]`, each within 0.001..10000 mm (up to
/// 10 m: a panel, not a number that overflows the stock grid).
fn parse_sizes<const N: usize>(s: &str, shape: &str) -> std::result::Result<[f64; N], String> {
    let v: Vec<f64> = s
        .split(['x', 'X'])
        .map(|p| p.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| format!("'{s}': expected {shape} in mm"))?;
    let v: [f64; N] = v
        .try_into()
        .map_err(|_| format!("'{s}': expected {shape} in mm"))?;
    if !v.iter().all(|x| (0.001..=1e4).contains(x)) {
        return Err(format!("'{s}': each size must be within 0.001..10000 mm"));
    }
    Ok(v)
}

pub fn parse_stock(s: &str) -> std::result::Result<(f64, f64, f64), String> {
    parse_sizes::<3>(s, "WxHxT").map(|[w, h, t]| (w, h, t))
}

pub fn parse_size(s: &str) -> std::result::Result<(f64, f64), String> {
    parse_sizes::<2>(s, "WxH").map(|[w, h]| (w, h))
}

pub fn parse_pair(s: &str) -> std::result::Result<(f64, f64), String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| format!("'{s}': expected X,Y"))?;
    match v[..] {
        [a, b] => Ok((a, b)),
        _ => Err(format!("'{s}': expected X,Y")),
    }
}

/// `X,Y,Z`, mm (finite).
pub fn parse_xyz(s: &str) -> std::result::Result<[f64; 3], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|v| v.trim().parse::<f64>().ok().filter(|v| v.is_finite()))
        .collect::<Option<_>>()
        .ok_or_else(|| format!("'{s}': expected X,Y,Z in mm"))?;
    match v[..] {
        [x, y, z] => Ok([x, y, z]),
        _ => Err(format!("'{s}': expected X,Y,Z in mm")),
    }
}

/// Settings that change which files a job makes (roughing in a file of its
/// own, one file per tile): the command line's, not a page's, which offers
/// one job file.
pub const FILE_MAKING: &[&str] = &["split", "tile"];

/// The settings of one kind alone, as a command line of their own.
#[derive(Parser)]
#[command(no_binary_name = true)]
struct Only<T: Args> {
    #[command(flatten)]
    settings: T,
}

/// Settings as given: typed, and as the flags that differ from the
/// defaults, in the definition's order (what a command line needs to make
/// the same files).
#[derive(Clone, Debug, PartialEq)]
pub struct Given<T> {
    pub settings: T,
    pub flags: Vec<String>,
}

impl<T> std::ops::Deref for Given<T> {
    type Target = T;
    fn deref(&self) -> &T {
        &self.settings
    }
}

impl Default for ReliefSettings {
    fn default() -> Self {
        Given::defaults().settings
    }
}

impl Default for CutSettings {
    fn default() -> Self {
        Given::defaults().settings
    }
}

impl<T: Args + FromArgMatches> Given<T> {
    /// Every setting at its default.
    pub fn defaults() -> Given<T> {
        Given::from_json(&Value::Object(Default::default())).expect("the defaults parse")
    }

    /// The settings a page sends: a JSON object keyed by the settings'
    /// names (the fields, `stock_to_leave`), null or absent for a default.
    /// Read as the command line reads its flags; an error names the flag.
    pub fn from_json(v: &Value) -> Result<Given<T>> {
        let Value::Object(map) = v else {
            crate::bail!("settings: expected a JSON object");
        };
        let cmd = Only::<T>::command();
        for key in map.keys() {
            if !cmd.get_arguments().any(|a| a.get_id() == key.as_str()) {
                crate::bail!("unknown setting '{key}'");
            }
        }
        let mut flags = Vec::new();
        for arg in cmd.get_arguments() {
            if let Some(v) = map.get(arg.get_id().as_str()) {
                flags.extend(words(arg, v)?);
            }
        }
        let parsed = Only::<T>::try_parse_from(&flags).map_err(|e| crate::Error(one_line(&e)))?;
        Ok(Given {
            settings: parsed.settings,
            flags,
        })
    }

    /// Every setting as a page shows it: its name, flag, help, default,
    /// the values it takes (when they are few) and whether it is a switch;
    /// `page` false for one that makes files a page does not offer.
    pub fn describe() -> Vec<Value> {
        Only::<T>::command()
            .get_arguments()
            .map(|a| {
                let name = a.get_id().to_string();
                serde_json::json!({
                    "name": name,
                    "flag": format!("--{}", a.get_long().unwrap_or(&name)),
                    "help": a.get_help().map(|h| h.to_string()).unwrap_or_default(),
                    "default": a.get_default_values().first().map(|d| d.to_string_lossy().into_owned()),
                    "values": a.get_possible_values().iter().map(|v| v.get_name().to_string()).collect::<Vec<_>>(),
                    "switch": matches!(a.get_action(), ArgAction::SetTrue),
                    "page": !FILE_MAKING.contains(&name.as_str()),
                })
            })
            .collect()
    }

    /// Every setting's name, in the definition's order.
    pub fn names() -> Vec<String> {
        Only::<T>::command()
            .get_arguments()
            .map(|a| a.get_id().to_string())
            .collect()
    }
}

/// The command line's words for setting `arg` given as `v`: none for a
/// default (null, false, or the default's own text), else the flag and its
/// value. A list is one comma-separated value where the flag takes one,
/// else the flag again for each item; an item that is a pair is
/// `NAME=VALUE`; true and false are `on` and `off` where the flag takes a
/// value.
fn words(arg: &clap::Arg, v: &Value) -> Result<Vec<String>> {
    let flag = format!("--{}", arg.get_long().unwrap_or(arg.get_id().as_str()));
    let switch = matches!(arg.get_action(), ArgAction::SetTrue);
    let bad = || crate::Error(format!("{flag}: {v} is not a value for it"));
    let scalar = |v: &Value| -> Result<String> {
        Ok(match v {
            Value::String(s) => s.clone(),
            Value::Number(n) => match n.as_f64() {
                Some(x) if n.is_f64() => format!("{x}"),
                _ => n.to_string(),
            },
            Value::Bool(b) => if *b { "on" } else { "off" }.into(),
            Value::Array(pair) if pair.len() == 2 => {
                let (Value::String(name), Value::Number(n)) = (&pair[0], &pair[1]) else {
                    return Err(bad());
                };
                format!("{name}={}", n.as_f64().ok_or_else(bad)?)
            }
            _ => return Err(bad()),
        })
    };
    let out = match v {
        Value::Null => Vec::new(),
        Value::Bool(b) if switch => {
            if *b {
                vec![flag]
            } else {
                Vec::new()
            }
        }
        Value::Array(items) if arg.get_value_delimiter().is_some() => {
            let parts: Vec<String> = items.iter().map(scalar).collect::<Result<_>>()?;
            vec![flag, parts.join(",")]
        }
        Value::Array(items) => {
            let mut out = Vec::new();
            for item in items {
                out.extend([flag.clone(), scalar(item)?]);
            }
            out
        }
        _ if switch => return Err(bad()),
        v => {
            let text = scalar(v)?;
            let default = arg.get_default_values();
            if default.len() == 1 && default[0] == text.as_str() {
                Vec::new()
            } else {
                vec![flag, text]
            }
        }
    };
    Ok(out)
}

/// clap's error as one line: what is wrong, and the values it takes.
fn one_line(e: &clap::Error) -> String {
    e.to_string()
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with("For more information"))
        .map(|l| l.trim_start_matches("error: "))
        .collect::<Vec<_>>()
        .join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    /// Each setting read from a page by its name, from a sample that is not
    /// its default (with what it needs beside it): it becomes its flag, and
    /// that command line parsed again gives the same settings. A setting
    /// added without a sample here fails, so every one is seen both ways.
    fn each_setting_both_ways<T>(samples: Value)
    where
        T: Args + FromArgMatches + Default + PartialEq + std::fmt::Debug,
    {
        for name in Given::<T>::names() {
            let sample = samples
                .get(&name)
                .unwrap_or_else(|| panic!("no sample for the setting '{name}'"));
            let given = Given::<T>::from_json(sample).unwrap_or_else(|e| panic!("{name}: {e}"));
            let flag = format!("--{}", name.replace('_', "-"));
            assert!(given.flags.contains(&flag), "{name}: {:?}", given.flags);
            assert_ne!(
                given.settings,
                T::default(),
                "{name}: the sample is the default"
            );
            let again = Only::<T>::try_parse_from(&given.flags).unwrap().settings;
            assert_eq!(again, given.settings, "{name}");
        }
    }

    #[test]
    fn every_relief_setting_reads_from_a_page_as_from_the_command_line() {
        let one = |k: &str, v: Value| (k.to_string(), json!({ k: v }));
        let samples: serde_json::Map<String, Value> = [
            one("view", json!("left")),
            one("up", json!("-z")),
            one("roll", json!(-15.5)),
            one("yaw", json!(30)),
            one("pitch", json!(10)),
            one("fov", json!(0)),
            one("resolution", json!(256)),
            one("width", json!(80)),
            one("depth", json!(3.5)),
            one("alpha", json!(8)),
            one("silhouette", json!(12)),
            one("steps", json!(0.3)),
            one("flat_background", json!(true)),
            one("free_background", json!(true)),
            one("bands", json!([2, 1.5, 1])),
            one("emphasize", json!([["head", 2], ["tail", 0.5]])),
            one("material", json!("oak")),
            one("mirror", json!(true)),
            one("invert", json!(true)),
            one("smooth", json!(30)),
            one("faceted", json!(true)),
            one("fade", json!("bottom:0.5")),
            one("tilt", json!("2:top")),
            one("method", json!("linear")),
            one("base", json!(3)),
        ]
        .into_iter()
        .collect();
        each_setting_both_ways::<ReliefSettings>(samples.into());
    }

    #[test]
    fn every_cut_setting_reads_from_a_page_as_from_the_command_line() {
        let one = |k: &str, v: Value| (k.to_string(), json!({ k: v }));
        let rough = |k: &str, v: Value| (k.to_string(), json!({"rough": "flat:3.175", k: v}));
        let samples: serde_json::Map<String, Value> = [
            one("tool", json!("ball:1")),
            one("finish", json!("raster+waterline")),
            one("stepover", json!("8%")),
            one("scallop", json!(0.01)),
            one("angle", json!(45)),
            one("climb", json!(true)),
            one("conventional", json!(true)),
            one("rough", json!("T1")),
            rough("step_down", json!(1.5)),
            rough("rough_stepover", json!("50%")),
            rough("stock_to_leave", json!(0.5)),
            one("rest", json!("ball:1")),
            (
                "rest_threshold".into(),
                json!({"rest": "ball:1", "rest_threshold": 0.05}),
            ),
            rough("split", json!(true)),
            one("tolerance", json!(0.01)),
            one("arcs", json!(false)),
            one("feed", json!(1500)),
            one("plunge_feed", json!(200)),
            one("rpm", json!(12000)),
            one("safe_z", json!(8)),
            one("machine", json!("shapeoko")),
            one("origin", json!("center")),
            one("light", json!("270,40")),
            one("allow_deep_cuts", json!(true)),
            one("z_zero", json!("bottom")),
            one("units", json!("in")),
            one("stock", json!("120x90x12")),
            one("margin", json!(10)),
            one("boundary", json!("subject")),
            one("tile", json!("50x40")),
            one("cutout", json!(true)),
            ("tabs".into(), json!({"cutout": true, "tabs": 6})),
            ("tab_width".into(), json!({"cutout": true, "tab_width": 8})),
            (
                "tab_height".into(),
                json!({"cutout": true, "tab_height": 1.5}),
            ),
            one("rotate", json!("90")),
        ]
        .into_iter()
        .collect();
        each_setting_both_ways::<CutSettings>(samples.into());
    }

    #[test]
    fn defaults_are_the_command_lines() {
        let r = ReliefSettings::default();
        assert_eq!(
            (r.view, r.fov, r.resolution, r.smooth),
            (View::Front, 20.0, 512, 45.0)
        );
        let c = CutSettings::default();
        assert_eq!(
            (c.tool.as_str(), c.stock_to_leave, c.arcs),
            ("ball:3.175", 0.3, OnOff::On)
        );
        assert!(Given::<ReliefSettings>::defaults().flags.is_empty());
    }
}
