//! Feeds and speeds for each tool of a job: the settings given, else the
//! material's cutting data for the tool's diameter, else generic values,
//! within the machine's limits.

use super::ToolpathJob;
use crate::bail;
use crate::error::Result;
use crate::gcode::emit::Settings;
use crate::machine::Machine;
use crate::materials::Material;
use crate::tool::Tool;

impl ToolpathJob {
    /// Feeds and speeds for `tool`: flags, else the material's entry for
    /// its diameter, else generic values; defaults are capped at the
    /// machine's limits (and `notes` says so), flags beyond them refused.
    pub(super) fn settings(
        &self,
        m: &Machine,
        tool: &Tool,
        material: Option<&Material>,
        notes: &mut Vec<String>,
    ) -> Result<Settings> {
        let c = material.and_then(|mt| mt.cutting_for(tool.working_diameter()));
        let rate = m.max_rate.x.min(m.max_rate.y);
        let mut cap = |what: &str, v: f64, lo: f64, hi: f64, unit: &str| {
            let capped = v.clamp(lo, hi);
            if capped != v {
                let n = format!(
                    "{what} {v} {unit} for {} with {} capped at {}'s {capped} {unit}",
                    self.material.as_deref().unwrap_or("generic cutting"),
                    tool.spec(),
                    m.name
                );
                if !notes.contains(&n) {
                    notes.push(n);
                }
            }
            capped
        };
        let s = Settings {
            feed: match self.feed {
                Some(f) => f,
                None => cap(
                    "feed",
                    c.as_ref().map_or(1000.0, |c| c.feed),
                    0.0,
                    rate,
                    "mm/min",
                ),
            },
            plunge_feed: match self.plunge_feed {
                Some(f) => f,
                None => cap(
                    "plunge feed",
                    c.as_ref().map_or(300.0, |c| c.plunge),
                    0.0,
                    m.max_rate.z,
                    "mm/min",
                ),
            },
            rpm: match self.rpm {
                Some(r) => r,
                None => cap(
                    "spindle speed",
                    c.as_ref().map_or(18000.0, |c| c.rpm),
                    m.spindle.min,
                    m.spindle.max,
                    "rpm",
                ),
            },
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
}
