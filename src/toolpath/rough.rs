//! Roughing: Z layers a step-down apart, each cleared by raster rows, the
//! tool kept `stock_to_leave` off the relief by dropping a tool enlarged
//! by that much (exact for a ball; for a flat end mill the enlarged
//! cylinder contains the offset tool, so it never comes closer).
//!
//! A row is cut at a layer only where material remains, that is where the
//! offset CL surface lies below the previous layer; it follows that surface
//! where it rises above the layer, so a run ends where the stock was
//! already cleared to the relief, and short gaps between runs are crossed
//! on the surface instead of by a retract.

use super::path::snap;
use super::Pass;
use crate::bail;
use crate::cutter::dropcutter::HeightField;
use crate::error::Result;
use crate::tool::Tool;
use glam::DVec3;
use rayon::prelude::*;

/// Each pass's own clearance: this far over the stock top (Z0), mm. The
/// job's stock plan (`cam::stock::Planned`) sets the travels between
/// passes from the material it knows is left, so nothing lower is
/// reckoned here.
const CLEARANCE: f64 = 1.0;

pub struct Params<'a> {
    pub tool: Tool,
    pub stepover: f64,
    pub step_down: f64,
    pub stock_to_leave: f64,
    pub angle: f64,
    /// Rows cover this rectangle of the panel: x0, y0, x1, y1 (mm).
    pub region: [f64; 4],
    /// The highest material within the tool's radius of a point, where
    /// earlier operations have cut the stock; `None`: untouched stock.
    /// Rows are cut at a layer only where material lies above it.
    pub material: Option<&'a (dyn Fn(f64, f64) -> f64 + Sync)>,
    /// The samples (i, j) of a level background that roughing cuts to
    /// its final height, leaving no stock on it; `None`: stock is left
    /// everywhere.
    pub background: Option<&'a (dyn Fn(usize, usize) -> bool + Sync)>,
}

/// `hf`'s samples with those where `background` holds lowered by `stl`,
/// and the lowest of those (None if there is none): dropping the
/// enlarged tool on them and adding `stl` back then gives, over a level
/// background, the enlarged tool's own height on the real surface (it
/// cuts the background to its level), and next to the subject the
/// subject's samples still hold it `stl` off. Every real point under the
/// real tool is one of these samples or between them, so the real tool
/// touches nothing.
fn lower_background(
    hf: &HeightField,
    stl: f64,
    background: &(dyn Fn(usize, usize) -> bool + Sync),
) -> (HeightField, Option<f64>) {
    let z = hf.samples();
    let mut low = z.clone();
    let lowest = low
        .data
        .par_chunks_mut(z.w)
        .enumerate()
        .map(|(j, row)| {
            let mut lowest = f64::INFINITY;
            for (i, v) in row.iter_mut().enumerate() {
                if background(i, j) {
                    lowest = lowest.min(*v);
                    *v -= stl;
                }
            }
            lowest
        })
        .reduce(|| f64::INFINITY, f64::min);
    (
        HeightField::new(low, hf.pitch),
        lowest.is_finite().then_some(lowest),
    )
}

/// The roughing passes over `p.region` of a relief whose background is
/// `floor`.
pub fn passes(hf: &HeightField, floor: f64, p: &Params) -> Result<Vec<Pass>> {
    let stl = p.stock_to_leave;
    let lowered = p.background.map(|bg| lower_background(hf, stl, bg));
    let (hf, background) = match &lowered {
        Some((low, z)) => (low, *z),
        None => (hf, None),
    };
    let big = match p.tool.grown(stl) {
        _ if stl == 0.0 => p.tool,
        Some(t) => t,
        None => bail!(
            "--rough {}: roughing takes a flat or ball end mill",
            p.tool.spec()
        ),
    };
    let bottom = background.unwrap_or(floor + stl);
    if bottom >= 0.0 {
        bail!(
            "--stock-to-leave {stl}: leaves nothing to rough in a relief {:.3} mm deep",
            -floor
        );
    }
    let n = (-bottom / p.step_down - 1e-9).ceil().max(1.0) as usize;
    let layer = |k: isize| {
        if k < 0 {
            0.0
        } else {
            -(k + 1) as f64 * -bottom / n as f64
        }
    };
    // the offset CL surface along every row, once for all layers
    let rows = super::raster::rows_in(p.region, p.angle, p.stepover, hf.pitch);
    let cl: Vec<Vec<DVec3>> = rows
        .par_iter()
        .map(|row| {
            let mut stack = Vec::new();
            let mut hint = None;
            row.iter()
                .map(|&(x, y)| {
                    let (x, y) = (snap(x), snap(y));
                    let z = match hf.drop_from(&big, x, y, hint, &mut stack) {
                        Some((z, c)) => {
                            hint = Some(c);
                            (z + stl).max(bottom)
                        }
                        None => bottom,
                    };
                    DVec3::new(x, y, z)
                })
                .collect()
        })
        .collect();
    // the material over each row point, if earlier operations cut some
    let top: Option<Vec<Vec<f64>>> = p.material.map(|f| {
        cl.par_iter()
            .map(|row| row.iter().map(|q| f(q.x, q.y)).collect())
            .collect()
    });
    let gap_max = (4.0 * p.tool.radius() / hf.pitch).ceil() as usize;
    let mut out = Vec::new();
    for k in 0..n as isize {
        let (z, above) = (layer(k), layer(k - 1));
        for (r, row) in cl.iter().enumerate() {
            // material remains where the surface is below the last layer
            let active: Vec<bool> = row
                .iter()
                .enumerate()
                .map(|(i, q)| q.z < above - 1e-4 && top.as_ref().is_none_or(|t| t[r][i] > z + 1e-3))
                .collect();
            let mut runs: Vec<(usize, usize)> = Vec::new();
            let mut i = 0;
            while i < row.len() {
                if !active[i] {
                    i += 1;
                    continue;
                }
                let s = i;
                while i < row.len() && active[i] {
                    i += 1;
                }
                let (a, b) = (s.saturating_sub(1), i.min(row.len() - 1));
                match runs.last_mut() {
                    Some(last) if a <= last.1 + gap_max => last.1 = b,
                    _ => runs.push((a, b)),
                }
            }
            if r % 2 == 1 {
                runs.reverse();
            }
            for (a, b) in runs {
                let mut pts: Vec<DVec3> = row[a..=b]
                    .iter()
                    .map(|q| DVec3::new(q.x, q.y, q.z.max(z)))
                    .collect();
                if r % 2 == 1 {
                    pts.reverse();
                }
                let top = match &top {
                    Some(t) => {
                        let i = if r % 2 == 1 { b } else { a };
                        t[r][i].min(above).max(pts[0].z)
                    }
                    None => above.max(pts[0].z),
                };
                let pts = super::path::ramp(&pts, top, p.tool.radius());
                out.push(Pass {
                    pts,
                    clear_z: CLEARANCE,
                });
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramp_descends_gently_and_ends_at_the_start() {
        let pts: Vec<DVec3> = (0..50)
            .map(|i| DVec3::new(i as f64 * 0.2, 0.0, -2.0))
            .collect();
        let r = super::super::path::ramp(&pts, 0.0, 1.5);
        assert_eq!(r[0], DVec3::new(0.0, 0.0, 0.0));
        let k = r.len() - pts.len();
        assert_eq!(&r[k..], &pts[..]);
        for w in r.windows(2) {
            let dz = w[0].z - w[1].z;
            let dxy = (w[1] - w[0]).truncate().length();
            assert!(
                dz <= dxy * super::super::path::RAMP_DEG.to_radians().tan() + 1e-9,
                "{w:?}"
            );
        }
        assert!(r[..k].iter().all(|q| q.z >= -2.0));
    }

    /// A dome on a level field, roughed with the background cut to its
    /// level: the last layer runs on the level away from the dome, nothing
    /// goes below the real tool's CL surface, and next to the dome the
    /// tool keeps the stock to leave off it.
    #[test]
    fn a_level_background_is_cut_to_its_height() {
        use crate::grid::Grid;
        let (n, pitch, level) = (60, 0.5, -3.0);
        let mut z = Grid::new(n, n, level);
        for j in 0..n {
            for i in 0..n {
                let r2 = (i as f64 - 30.0).powi(2) + (j as f64 - 30.0).powi(2);
                if r2 < 100.0 {
                    z.set(i, j, level + 0.02 * (100.0 - r2));
                }
            }
        }
        let dome = z.map(|v| *v > level);
        let hf = HeightField::new(z, pitch);
        let (tool, stl) = (Tool::Flat { d: 3.0 }, 0.3);
        let field = |i: usize, j: usize| !*dome.get(i, j);
        let p = Params {
            tool,
            stepover: 1.2,
            step_down: 1.0,
            stock_to_leave: stl,
            angle: 0.0,
            region: [0.0, 0.0, 30.0, 30.0],
            material: None,
            background: Some(&field),
        };
        let passes = passes(&hf, level, &p).unwrap();
        // the dome alone, its field sunk far below
        let only = HeightField::new(
            hf.samples()
                .map(|v| if *v > level { *v } else { level - 100.0 }),
            pitch,
        );
        let big = Tool::Flat { d: 3.0 + 2.0 * stl };
        let (mut on_level, mut near_dome) = (0, 0);
        for q in passes.iter().flat_map(|p| &p.pts) {
            let real = hf.drop(&tool, q.x, q.y).unwrap_or(level);
            assert!(q.z >= real - 1e-9, "{q:?} below the CL surface {real}");
            let offset = only.drop(&big, q.x, q.y).unwrap_or(f64::MIN);
            if offset > level {
                // the enlarged tool meets the dome: stock is left on it
                assert!(q.z >= offset + stl - 1e-9, "{q:?}");
                near_dome += 1;
            } else if q.z == level {
                on_level += 1;
            }
        }
        assert!(on_level > 100 && near_dome > 10, "{on_level} {near_dome}");
    }
}
