//! Machine profiles (machines/*.toml, the shipped ones compiled in): travel,
//! rates, accelerations, spindle range, receive buffer.

use crate::bail;
use crate::error::{Context, Result};
use serde::Deserialize;
use std::path::Path;

#[derive(Deserialize, Debug, Clone, Copy, PartialEq)]
pub struct Axes {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

impl Axes {
    pub fn get(&self, k: usize) -> f64 {
        [self.x, self.y, self.z][k]
    }

    pub fn get_mut(&mut self, k: usize) -> &mut f64 {
        match k {
            0 => &mut self.x,
            1 => &mut self.y,
            _ => &mut self.z,
        }
    }
}

#[derive(Deserialize, Debug, Clone, Copy, PartialEq)]
pub struct Spindle {
    pub min: f64,
    pub max: f64,
}

#[derive(Deserialize, Debug, Clone, PartialEq)]
pub struct Machine {
    pub name: String,
    pub dialect: String,
    pub rx_buffer: usize,
    /// GRBL's junction deviation ($11), mm.
    pub junction_deviation: f64,
    /// Travel per axis, mm.
    pub travel: Axes,
    /// Maximum rate per axis, mm/min.
    pub max_rate: Axes,
    /// Acceleration per axis, mm/s^2.
    pub acceleration: Axes,
    /// Motor steps per mm ($100-$102): a move of less than a step is no
    /// move to GRBL.
    #[serde(default = "default_steps")]
    pub steps_per_mm: Axes,
    pub spindle: Spindle,
    /// The tool table: `--tool T2` finds its spec here.
    #[serde(default)]
    pub tools: std::collections::BTreeMap<String, ToolEntry>,
    /// A fixed tool-length setter, if the machine has one.
    #[serde(default)]
    pub setter: Option<Setter>,
}

/// A fixed tool-length setter: where it stands, in machine coordinates
/// (X, Y, and the Z to probe down from, clear of it), from the machine
/// file.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
pub struct Setter {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    /// How far the fast probe may go down from `z`, mm.
    #[serde(default = "setter_travel")]
    pub travel: f64,
    /// Fast probing feed, mm/min.
    #[serde(default = "setter_feed")]
    pub feed: f64,
}

fn setter_travel() -> f64 {
    50.0
}

fn setter_feed() -> f64 {
    200.0
}

impl Setter {
    /// A setter at machine `[x, y, z]`, probed at the default travel and
    /// feed.
    pub fn at([x, y, z]: [f64; 3]) -> Setter {
        Setter {
            x,
            y,
            z,
            travel: setter_travel(),
            feed: setter_feed(),
        }
    }
}

#[derive(Deserialize, Debug, Clone, PartialEq)]
pub struct ToolEntry {
    /// A tool spec as `--tool` takes it.
    pub tool: String,
    #[serde(default)]
    pub name: String,
}

/// GRBL's default $100-$102.
fn default_steps() -> Axes {
    Axes {
        x: 250.0,
        y: 250.0,
        z: 250.0,
    }
}

const BUILTIN: [(&str, &str); 3] = [
    (
        "grbl-generic",
        include_str!("../machines/grbl-generic.toml"),
    ),
    ("3018", include_str!("../machines/3018.toml")),
    ("shapeoko", include_str!("../machines/shapeoko.toml")),
];

/// The names of the shipped machine profiles.
pub fn builtin_names() -> Vec<&'static str> {
    BUILTIN.iter().map(|b| b.0).collect()
}

impl Machine {
    /// A shipped profile by name, or a TOML file by path.
    pub fn load(name_or_path: &str) -> Result<Machine> {
        if let Some((_, text)) = BUILTIN.iter().find(|(n, _)| *n == name_or_path) {
            Machine::parse(text, &format!("machines/{name_or_path}.toml"))
        } else if Path::new(name_or_path).is_file() {
            let text = crate::input::read_text(Path::new(name_or_path), crate::input::MAX_TEXT)?;
            Machine::parse(&text, name_or_path)
        } else {
            let names: Vec<&str> = BUILTIN.iter().map(|b| b.0).collect();
            bail!(
                "--machine {name_or_path}: no such profile or file; shipped: {}",
                names.join(", ")
            );
        }
    }

    /// A profile from its TOML text, every number checked; `name_or_path`
    /// names it in errors.
    pub fn parse(text: &str, name_or_path: &str) -> Result<Machine> {
        let m: Machine = toml::from_str(text).ctx(name_or_path)?;
        let pos = |v: f64| v.is_finite() && v > 0.0;
        for k in 0..3 {
            if !pos(m.travel.get(k))
                || !pos(m.max_rate.get(k))
                || !pos(m.acceleration.get(k))
                || !pos(m.steps_per_mm.get(k))
            {
                bail!(
                    "{name_or_path}: travel, max_rate, acceleration and steps_per_mm must be \
                     positive on every axis"
                );
            }
        }
        if !(m.spindle.min.is_finite() && m.spindle.min >= 0.0 && pos(m.spindle.max))
            || m.spindle.min > m.spindle.max
        {
            bail!(
                "{name_or_path}: spindle min {} and max {} rpm must be finite, 0 <= min <= max",
                m.spindle.min,
                m.spindle.max
            );
        }
        if !pos(m.junction_deviation) || m.rx_buffer < 16 {
            bail!("{name_or_path}: junction_deviation must be positive and rx_buffer at least 16");
        }
        for (k, t) in &m.tools {
            crate::tool::Tool::parse(&t.tool).ctx(format!("{name_or_path}: tool {k}"))?;
        }
        Ok(m)
    }

    /// The flat end mill in the tool table to rough with ahead of
    /// `finish`: the largest up to 1/4 in, so that it clears fast and still
    /// reaches between the relief's forms. (name, spec)
    pub fn roughing_tool(&self, finish: &crate::tool::Tool) -> Option<(String, String)> {
        if finish.is_flat() {
            return None;
        }
        self.largest(|t| t.is_flat())
    }

    /// The ball in the tool table to finish with ahead of a smaller
    /// `tool` (then a rest tool): the largest up to 1/4 in. (name, spec)
    pub fn finishing_ball(&self, tool: &crate::tool::Tool) -> Option<(String, String)> {
        self.largest(|t| t.is_ball() && t.radius() > tool.radius())
    }

    /// The largest tool up to 1/4 in of the table that `pick` takes.
    fn largest(&self, pick: impl Fn(&crate::tool::Tool) -> bool) -> Option<(String, String)> {
        self.tools
            .iter()
            .filter_map(|(k, e)| {
                let t = crate::tool::Tool::parse(&e.tool).ok()?;
                let d = t.working_diameter();
                (pick(&t) && d <= 6.35 + 1e-9).then(|| (d, k.clone(), e.tool.clone()))
            })
            .max_by(|a, b| a.0.total_cmp(&b.0))
            .map(|(_, k, s)| (k, s))
    }

    /// `tool` for the flag that named it: its errors start with the flag
    /// and the spec ("--rough flat:0: size or angle out of range").
    pub fn tool_for(&self, flag: &str, spec: &str) -> Result<crate::tool::Tool> {
        self.tool(spec)
            .map_err(|e| crate::error::Error(format!("{flag} {}", e.0)))
    }

    /// A tool from the table by name (case-insensitive), else a spec.
    pub fn tool(&self, spec: &str) -> Result<crate::tool::Tool> {
        let hit = self
            .tools
            .iter()
            .find(|(k, _)| k.eq_ignore_ascii_case(spec));
        match hit {
            Some((_, t)) => crate::tool::Tool::parse(&t.tool),
            None if !spec.contains(':') && !self.tools.is_empty() => bail!(
                "{spec}: not a tool spec (ball:D, flat:D, ...) nor in {}'s tool table ({})",
                self.name,
                self.tools.keys().cloned().collect::<Vec<_>>().join(", ")
            ),
            None => crate::tool::Tool::parse(spec),
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn shipped_profiles_load() {
        for n in ["grbl-generic", "3018", "shapeoko"] {
            let m = super::Machine::load(n).unwrap();
            assert_eq!(m.rx_buffer, 128);
            assert!(m.tools.len() >= 3, "{n}");
            assert_eq!(m.tool("t1").unwrap(), m.tool(&m.tools["T1"].tool).unwrap());
            assert!(m.tool("T99").unwrap_err().0.contains("T1"));
        }
        assert!(super::Machine::load("nonesuch").is_err());
    }
}
