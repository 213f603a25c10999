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
}

#[derive(Deserialize)]
struct File {
    materials: BTreeMap<String, Material>,
}

/// All built-in materials by name.
pub fn builtin() -> BTreeMap<String, Material> {
    toml::from_str::<File>(BUILTIN)
        .ctx("machines/materials.toml")
        .expect("built-in materials parse")
        .materials
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
        assert!(super::find("cheese")
            .unwrap_err()
            .0
            .contains("known: acrylic"));
    }
}
