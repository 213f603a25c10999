//! Material presets (machines/materials.toml, compiled in): relief depth
//! ratio, feature-band gains and compression per material.

use crate::bail;
use crate::error::{Context, Result};
use serde::Deserialize;
use std::collections::BTreeMap;

const BUILTIN: &str = include_str!("../machines/materials.toml");

#[derive(Deserialize, Debug, Clone)]
pub struct Material {
    pub description: String,
    /// Relief height in mm per 100 mm of panel width.
    pub depth_per_100mm: f64,
    /// Feature-band gains, finest first.
    #[serde(default)]
    pub bands: Vec<f64>,
    pub alpha: Option<f64>,
    /// Feeds and speeds by tool diameter.
    #[serde(default)]
    pub cutting: Vec<Cutting>,
}

/// Cutting data for one tool diameter.
#[derive(Deserialize, Debug, Clone, PartialEq)]
pub struct Cutting {
    /// Tool diameter, mm.
    pub d: f64,
    /// mm/min.
    pub feed: f64,
    /// mm/min.
    pub plunge: f64,
    pub rpm: f64,
    /// Deepest cut at partial width (the roughing layer), mm.
    pub step_down: f64,
    /// Deepest full-width (slotting) cut, mm.
    pub slot_depth: f64,
    /// Percent of the diameter.
    pub rough_stepover: f64,
    /// Percent of the diameter.
    pub finish_stepover: f64,
}

impl Material {
    /// The entry nearest diameter `d` (by ratio), step-down and slotting
    /// depth scaled to `d`.
    pub fn cutting_for(&self, d: f64) -> Option<Cutting> {
        let c = self.cutting.iter().min_by(|a, b| {
            let ka = (a.d / d).ln().abs();
            let kb = (b.d / d).ln().abs();
            ka.total_cmp(&kb)
        })?;
        Some(Cutting {
            step_down: c.step_down * d / c.d,
            slot_depth: c.slot_depth * d / c.d,
            ..c.clone()
        })
    }
}

#[derive(Deserialize)]
struct File {
    materials: BTreeMap<String, Material>,
}

/// All built-in materials by name.
pub fn builtin() -> BTreeMap<String, Material> {
    parse(BUILTIN, "machines/materials.toml").expect("built-in materials parse")
}

/// Materials from TOML text, every number checked to be finite and in
/// range; `what` names the text in errors.
pub fn parse(text: &str, what: &str) -> Result<BTreeMap<String, Material>> {
    let all = toml::from_str::<File>(text).ctx(what)?.materials;
    let within = |v: f64, lo: f64, hi: f64| v.is_finite() && v >= lo && v <= hi;
    for (name, m) in &all {
        let ok = within(m.depth_per_100mm, 0.01, 100.0)
            && m.bands.len() <= 16
            && m.bands.iter().all(|&g| within(g, 0.0, 100.0))
            && m.alpha.is_none_or(|a| within(a, 0.0, 1e6));
        if !ok {
            bail!(
                "{what}: material {name}: depth_per_100mm must be within 0.01..100, \
                 at most 16 bands within 0..100, alpha within 0..1e6"
            );
        }
        for c in &m.cutting {
            let ok = within(c.d, 0.01, 100.0)
                && [c.feed, c.plunge, c.rpm]
                    .iter()
                    .all(|&v| within(v, 1e-3, 1e6))
                && [c.step_down, c.slot_depth]
                    .iter()
                    .all(|&v| within(v, 1e-3, 100.0))
                && [c.rough_stepover, c.finish_stepover]
                    .iter()
                    .all(|&v| within(v, 0.1, 100.0));
            if !ok {
                bail!(
                    "{what}: material {name}: cutting entry for d = {} mm: d within 0.01..100 mm, \
                     feed, plunge and rpm within 0.001..1e6, step_down and slot_depth within \
                     0.001..100 mm, stepovers within 0.1..100 %",
                    c.d
                );
            }
        }
    }
    Ok(all)
}

/// One material by name (case-insensitive; "aluminum" is accepted).
pub fn find(name: &str) -> Result<Material> {
    let all = builtin();
    let key = name.to_ascii_lowercase().replace("aluminum", "aluminium");
    match all.get(&key) {
        Some(m) => Ok(m.clone()),
        None => bail!(
            "--material {name}: unknown material; known: {}",
            all.keys().cloned().collect::<Vec<_>>().join(", ")
        ),
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn paper_ratios() {
        assert_eq!(super::find("wood").unwrap().depth_per_100mm, 3.2);
        assert_eq!(super::find("Silver").unwrap().depth_per_100mm, 0.88);
        assert_eq!(super::find("marble").unwrap().depth_per_100mm, 4.2);
        let c = super::find("hardwood").unwrap().cutting_for(3.0).unwrap();
        assert_eq!(c.d, 3.175);
        for m in super::builtin().values() {
            assert_eq!(m.cutting.len(), 3, "{}", m.description);
        }
        assert!(super::find("cheese")
            .unwrap_err()
            .0
            .contains("known: acrylic"));
    }
}
