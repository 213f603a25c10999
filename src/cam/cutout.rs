//! The cutout: a profile around the panel, through the stock, in layers
//! no deeper than the tool may slot, holding the panel by tabs.
//!
//! The tool runs counter-clockwise round the panel (climb milling on the
//! panel's edge with a clockwise spindle), its axis one radius outside
//! the panel's edge. Over a tab the path rises to the tab's top; its
//! flanks slope at `TAB_FLANK` degrees, so that no layer drops into
//! material steeper than that (the tab is `width` long at its top).

use crate::bail;
use crate::error::Result;
use crate::toolpath::Pass;
use glam::DVec3;

/// Slope of a tab's flanks, degrees from the horizontal.
pub const TAB_FLANK: f64 = 30.0;

/// How far below the stock's bottom the cutout goes, mm (a skim of the
/// spoilboard, so that no skin is left).
pub const BREAK_THROUGH: f64 = 0.1;

/// The user's cutout flags.
#[derive(Clone, Debug)]
pub struct Cutout {
    pub tabs: usize,
    /// Length of each tab along the edge (at its top), mm.
    pub tab_width: f64,
    /// Height of each tab over the stock's bottom, mm.
    pub tab_height: f64,
}

/// The cutout of the panel `[x0, y0, x1, y1]` (panel mm, Z 0 = stock
/// top) for a tool of radius `r` through a stock `thickness` thick, in
/// layers of at most `step`: one closed pass per layer, each starting
/// where the last ended.
pub fn passes(
    panel: [f64; 4],
    r: f64,
    thickness: f64,
    step: f64,
    c: &Cutout,
    clear_z: f64,
) -> Vec<Pass> {
    let [x0, y0, x1, y1] = panel;
    let corners = [
        (x0 - r, y0 - r),
        (x1 + r, y0 - r),
        (x1 + r, y1 + r),
        (x0 - r, y1 + r),
        (x0 - r, y0 - r),
    ];
    let sides: Vec<f64> = corners
        .windows(2)
        .map(|w| (w[1].0 - w[0].0).abs() + (w[1].1 - w[0].1).abs())
        .collect();
    let perimeter: f64 = sides.iter().sum();
    // tab centres evenly round the loop, half a spacing from its start
    let centres: Vec<f64> = (0..c.tabs)
        .map(|k| perimeter * (k as f64 + 0.5) / c.tabs as f64)
        .collect();
    // the tab's extent along the loop: its width plus the tool's
    let half = c.tab_width / 2.0 + r;
    let tab_top = -thickness + c.tab_height;
    let slope = TAB_FLANK.to_radians().tan();
    // distance along the loop from s to the nearest tab (0 on a tab)
    let off_tab = |s: f64| -> f64 {
        centres
            .iter()
            .map(|&m| {
                let d = (s - m).abs();
                let d = d.min(perimeter - d);
                (d - half).max(0.0)
            })
            .fold(f64::INFINITY, f64::min)
    };
    let at = |s: f64| -> (f64, f64) {
        let mut s = s.rem_euclid(perimeter);
        for (k, &len) in sides.iter().enumerate() {
            if s <= len || k == sides.len() - 1 {
                let t = if len > 0.0 { (s / len).min(1.0) } else { 0.0 };
                let (a, b) = (corners[k], corners[k + 1]);
                return (a.0 + (b.0 - a.0) * t, a.1 + (b.1 - a.1) * t);
            }
            s -= len;
        }
        corners[0]
    };
    let bottom = -thickness - BREAK_THROUGH;
    let n = ((-bottom / step) - 1e-9).ceil().max(1.0) as usize;
    // stations: corners, tab edges and flank feet, and every 2 mm
    let mut stations: Vec<f64> = Vec::new();
    let mut acc = 0.0;
    for len in &sides {
        stations.push(acc);
        acc += len;
    }
    let layer_z = |k: usize| -(k as f64) * (-bottom) / n as f64;
    for &m in &centres {
        // the tab's edges, and where each layer's flank meets its floor
        let feet = (1..=n).map(|k| half + (tab_top - layer_z(k)).max(0.0) / slope);
        for d in std::iter::once(half).chain(feet) {
            stations.push((m - d).rem_euclid(perimeter));
            stations.push((m + d).rem_euclid(perimeter));
        }
    }
    let fine = (perimeter / 2.0).ceil() as usize;
    stations.extend((0..fine).map(|k| perimeter * k as f64 / fine as f64));
    stations.sort_by(f64::total_cmp);
    stations.dedup_by(|a, b| (*a - *b).abs() < 1e-6);
    stations.push(perimeter);
    (1..=n)
        .map(|k| {
            let z = layer_z(k);
            let pts = stations
                .iter()
                .map(|&s| {
                    let (x, y) = at(s);
                    let lift = if c.tabs > 0 && tab_top > z {
                        (tab_top - off_tab(s) * slope).max(z)
                    } else {
                        z
                    };
                    DVec3::new(x, y, lift)
                })
                .collect();
            Pass { pts, clear_z }
        })
        .collect()
}

impl super::ToolpathJob {
    /// The cutout stage, when asked for: with the job's roughing tool,
    /// else the machine's largest flat end mill up to 1/4 in, else the
    /// finishing tool; in layers no deeper than it may slot.
    pub(super) fn cutout_stage(&self, w: &mut super::setup::Work) -> Result<Option<super::Op>> {
        use super::Op;
        let Some(c) = &self.cutout else {
            return Ok(None);
        };
        let (m, relief, plan, limits) = (&w.machine, &w.relief, &w.plan, &w.limits);
        let name = match &w.rough {
            Some(r) => Some(r.asked.tool.clone()),
            None => m.roughing_tool(&w.tool).map(|(n, _)| n),
        };
        let ct = match &name {
            Some(n) => m.tool(n)?,
            None => w.tool,
        };
        let d = ct.working_diameter();
        let (pw, ph) = (relief.width_mm, relief.height_mm);
        let (sw, sh, st) = plan.stock;
        let (ax, ay) = plan.panel_at;
        let room = ax.min(ay).min(sw - pw - ax).min(sh - ph - ay);
        if room < d - 1e-9 {
            bail!(
                "--cutout: {} needs {d:.2} mm of stock round the panel, there is {room:.2} mm; \
                 give a larger --stock or a --margin",
                ct.spec()
            );
        }
        let ok_tab = c.tab_width.is_finite() && c.tab_width > 0.0;
        if !(ok_tab && c.tab_height.is_finite() && c.tab_height > 0.0 && c.tab_height < st) {
            bail!(
                "--tab-width {} / --tab-height {}: must be positive, the height below the \
                 stock's {st} mm",
                c.tab_width,
                c.tab_height
            );
        }
        let (dc, slot) = limits.material_of(&ct);
        let step = if dc.min(slot).is_finite() {
            dc.min(slot)
        } else {
            ct.radius()
        };
        let settings = self.settings(m, &ct, w.material.as_ref(), &mut w.notes)?;
        let passes = passes(
            [0.0, 0.0, pw, ph],
            ct.radius(),
            st,
            step,
            c,
            settings.safe_z,
        );
        let layers = passes.len();
        w.notes.push(format!(
            "cutout with {}: {layers} layers of {:.2} mm through {:.2} mm, {} tabs {} mm long, \
             {} mm high",
            ct.spec(),
            (st + BREAK_THROUGH) / layers as f64,
            st + BREAK_THROUGH,
            c.tabs,
            c.tab_width,
            c.tab_height
        ));
        let passes = w.planned.ramp_and_cut(passes, ct, true);
        Ok(Some(Op {
            title: "cutout",
            tool: ct,
            zero: String::new(),
            settings,
            strategy: format!(
                "cutout round the panel, {:.2} mm deep in {layers} layers, {} tabs {} mm long \
                 and {} mm high",
                st + BREAK_THROUGH,
                c.tabs,
                c.tab_width,
                c.tab_height
            ),
            passes,
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layers_go_through_and_rise_over_the_tabs_only() {
        let c = Cutout {
            tabs: 4,
            tab_width: 6.0,
            tab_height: 2.0,
        };
        let p = passes([0.0, 0.0, 100.0, 60.0], 1.5, 8.0, 1.5, &c, 5.0);
        // 8.1 mm in layers of at most 1.5: 6 layers
        assert_eq!(p.len(), 6);
        let last = &p[5].pts;
        assert!((last.iter().map(|q| q.z).fold(0.0, f64::min) + 8.1).abs() < 1e-9);
        // closed, counter-clockwise (positive area)
        assert_eq!(last[0].truncate(), last[last.len() - 1].truncate());
        let area: f64 = last
            .windows(2)
            .map(|w| w[0].x * w[1].y - w[1].x * w[0].y)
            .sum();
        assert!(area > 0.0);
        // four runs at the tab top (-6), each 6 + 3 mm long along the loop
        let mut runs = Vec::new();
        let mut len = 0.0;
        for w in last.windows(2) {
            let on = (w[0].z + 6.0).abs() < 1e-9 && (w[1].z + 6.0).abs() < 1e-9;
            if on {
                len += (w[1] - w[0]).truncate().length();
            } else if len > 0.0 {
                runs.push(len);
                len = 0.0;
            }
        }
        assert_eq!(runs.len(), 4, "{runs:?}");
        assert!(runs.iter().all(|l| (l - 9.0).abs() < 1e-6), "{runs:?}");
        // no move steeper than the flank
        for w in last.windows(2) {
            let dz = (w[1].z - w[0].z).abs();
            let dxy = (w[1] - w[0]).truncate().length();
            assert!(dz <= dxy * TAB_FLANK.to_radians().tan() + 1e-9, "{w:?}");
        }
    }
}
