//! Pencil passes: the tool run along the concave creases of the relief,
//! where it touches both sides at once. On the tool's CL surface such a
//! crease is a valley line, sharper than any surface the tool fits into
//! smoothly; it is found on a grid of CL points (drop-cutter) and traced
//! node to node. A raster crossing a crease leaves a zigzag in it and one
//! along it a ridge; the pencil pass leaves one clean line.

use crate::cutter::dropcutter::HeightField;
use crate::tool::Tool;
use glam::DVec3;
use rayon::prelude::*;

/// The four directions a valley is looked for across, in grid steps.
const DIRS: [(isize, isize); 4] = [(1, 0), (0, 1), (1, 1), (1, -1)];

/// The valley lines of `tool`'s CL surface over `region` (x0, y0, x1,
/// y1 mm), where `keep` holds: nodes a grid step `g` apart whose CL
/// height bends upward across some direction by a curvature of at least
/// `kappa` (1/mm) and is lowest there, chained through neighbouring
/// nodes; lines shorter than the tool's diameter are left out. Points
/// are exact CL points; the moves between them are the caller's to check.
pub fn lines(
    hf: &HeightField,
    tool: &Tool,
    region: [f64; 4],
    floor: f64,
    kappa: f64,
    keep: &(dyn Fn(f64, f64) -> bool + Sync),
) -> Vec<Vec<DVec3>> {
    let g = (tool.radius() / 4.0).max(hf.pitch / 2.0);
    let nx = ((region[2] - region[0]) / g).floor() as usize + 1;
    let ny = ((region[3] - region[1]) / g).floor() as usize + 1;
    let at = |i: usize, j: usize| (region[0] + i as f64 * g, region[1] + j as f64 * g);
    let cl: Vec<f64> = (0..ny)
        .into_par_iter()
        .flat_map_iter(|j| {
            (0..nx).map(move |i| {
                let (x, y) = at(i, j);
                if keep(x, y) {
                    hf.drop(tool, x, y).unwrap_or(floor).max(floor)
                } else {
                    f64::NAN
                }
            })
        })
        .collect();
    let z = |i: isize, j: isize| {
        if i < 0 || j < 0 || i >= nx as isize || j >= ny as isize {
            f64::NAN
        } else {
            cl[j as usize * nx + i as usize]
        }
    };
    // the CL curve's upward bend (1/mm) at node (i, j) across direction
    // d over `k` steps, where the node is lowest of the three; NaN where
    // it is not, or off the region (NaN compares false)
    let bend = |i: isize, j: isize, (di, dj): (isize, isize), k: isize| {
        let (a, c, b) = (
            z(i - k * di, j - k * dj),
            z(i, j),
            z(i + k * di, j + k * dj),
        );
        let len2 = ((k * k * (di * di + dj * dj)) as f64) * g * g;
        if a >= c && b >= c {
            (a + b - 2.0 * c) / len2
        } else {
            f64::NAN
        }
    };
    // valley nodes: lowest across the direction of sharpest upward bend
    let valley: Vec<bool> = (0..nx * ny)
        .into_par_iter()
        .map(|k| {
            let (i, j) = ((k % nx) as isize, (k / nx) as isize);
            DIRS.iter().any(|&d| {
                let one = bend(i, j, d, 1);
                // a crease just short of the next node bends the CL
                // curve little over one step, much over two (the next
                // node already risen: a flat floor's nodes further out
                // are not its valley)
                one >= kappa || (one > 0.0 && bend(i, j, d, 2) >= kappa)
            })
        })
        .collect();
    // a node lies up to a grid step from the crease. Across its sharpest
    // bend the CL curve lies furthest below the chord between the nodes
    // two steps either side at the crease (a valley's bottom, a wall's
    // foot), where it turns; golden-section search for it between the
    // neighbouring nodes
    let refined = |i: usize, j: usize| -> DVec3 {
        let (x, y) = at(i, j);
        let node = DVec3::new(x, y, cl[j * nx + i]);
        let (i, j) = (i as isize, j as isize);
        let across = |&d: &(isize, isize)| bend(i, j, d, 1);
        let Some(&(di, dj)) = DIRS
            .iter()
            .filter(|d| across(d).is_finite())
            .max_by(|p, q| across(p).total_cmp(&across(q)))
        else {
            return node;
        };
        let (za, zb) = (z(i - 2 * di, j - 2 * dj), z(i + 2 * di, j + 2 * dj));
        if za.is_nan() || zb.is_nan() {
            return node;
        }
        let point = |t: f64| (x + t * di as f64 * g, y + t * dj as f64 * g);
        // CL below the chord, and the CL point (None where not to go)
        let below = |t: f64| -> Option<(f64, DVec3)> {
            let (px, py) = point(t);
            if !keep(px, py) {
                return None;
            }
            let zc = hf.drop(tool, px, py)?.max(floor);
            let chord = za + (zb - za) * (t + 2.0) / 4.0;
            Some((chord - zc, DVec3::new(px, py, zc)))
        };
        let gap = |t: f64| below(t).map_or(f64::NEG_INFINITY, |b| b.0);
        // 16 golden-section steps narrow [-1, 1] to under 1e-3
        let t = crate::cutter::golden_max(-1.0, 1.0, 16, gap);
        match below(t) {
            Some((d, p)) if d >= gap(0.0) => p,
            _ => node,
        }
    };
    trace(&valley, nx, ny, tool.working_diameter() / g)
        .into_par_iter()
        .map(|line| line.into_iter().map(|(i, j)| refined(i, j)).collect())
        .collect()
}

/// Chains of marked nodes: each walk starts at an end (a node with at
/// most one marked neighbour) where there is one, goes on to the
/// neighbour that turns least, and claims the nodes beside it (a valley
/// two nodes wide is one line). Chains of fewer than `min_len` steps are
/// dropped.
fn trace(marked: &[bool], nx: usize, ny: usize, min_len: f64) -> Vec<Vec<(usize, usize)>> {
    let mut free: Vec<bool> = marked.to_vec();
    let neighbours = |k: usize| {
        let (i, j) = ((k % nx) as isize, (k / nx) as isize);
        (-1isize..=1)
            .flat_map(move |dj| (-1isize..=1).map(move |di| (di, dj)))
            .filter(|&d| d != (0, 0))
            .filter_map(move |(di, dj)| {
                let (a, b) = (i + di, j + dj);
                (a >= 0 && b >= 0 && a < nx as isize && b < ny as isize)
                    .then(|| b as usize * nx + a as usize)
            })
    };
    let degree = |k: usize| neighbours(k).filter(|&n| marked[n]).count();
    // ends first, then whatever is left (closed loops)
    let mut starts: Vec<usize> = (0..nx * ny).filter(|&k| marked[k]).collect();
    starts.sort_by_key(|&k| degree(k) > 1);
    let mut out = Vec::new();
    for s in starts {
        if !free[s] {
            continue;
        }
        free[s] = false;
        let mut chain = vec![s];
        let mut dir: Option<(f64, f64)> = None;
        loop {
            let k = chain[chain.len() - 1];
            let (i, j) = ((k % nx) as f64, (k / nx) as f64);
            let next = neighbours(k).filter(|&n| free[n]).min_by(|&a, &b| {
                let turn = |n: usize| {
                    let d = ((n % nx) as f64 - i, (n / nx) as f64 - j);
                    let l = (d.0 * d.0 + d.1 * d.1).sqrt();
                    dir.map_or(l, |(u, v)| 1.0 - (d.0 * u + d.1 * v) / l)
                };
                turn(a).total_cmp(&turn(b))
            });
            let Some(n) = next else { break };
            // the other free nodes beside this one belong to this line
            for m in neighbours(k) {
                free[m] = false;
            }
            let d = ((n % nx) as f64 - i, (n / nx) as f64 - j);
            let l = (d.0 * d.0 + d.1 * d.1).sqrt();
            dir = Some((d.0 / l, d.1 / l));
            chain.push(n);
        }
        let steps: f64 = chain
            .windows(2)
            .map(|w| {
                let diagonal = w[0] % nx != w[1] % nx && w[0] / nx != w[1] / nx;
                if diagonal {
                    std::f64::consts::SQRT_2
                } else {
                    1.0
                }
            })
            .sum();
        if steps >= min_len {
            out.push(chain.into_iter().map(|k| (k % nx, k / nx)).collect());
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::Grid;

    /// A relief 10 x 6 mm at 0.1 mm samples, its height a function of x.
    fn across_x(f: impl Fn(f64) -> f64) -> HeightField {
        let pitch = 0.1;
        let (w, h) = (100, 60);
        let z = (0..w * h).map(|k| f(((k % w) as f64 + 0.5) * pitch));
        HeightField::new(Grid::from_vec(w, h, z.collect()), pitch)
    }

    /// A V groove along Y at x = 5 (walls 30 degrees up): the pencil line
    /// runs its length, at its bottom.
    #[test]
    fn a_groove_gives_one_line_along_its_bottom() {
        let hf = across_x(|x| -2.0 + (x - 5.0).abs() * 30f64.to_radians().tan());
        let tool = Tool::Ball { d: 1.0 };
        // (the nodes, 0.125 mm apart, straddle the bottom)
        let ls = lines(&hf, &tool, [1.05, 1.0, 9.0, 5.0], -3.0, 1.0, &|_, _| true);
        assert_eq!(ls.len(), 1, "{} lines", ls.len());
        let l = &ls[0];
        let len = (l[0] - l[l.len() - 1]).truncate().length();
        assert!(len > 3.5, "the line is {len} mm long");
        for p in l {
            assert!((p.x - 5.0).abs() < 0.01, "off the groove at {p}");
            let want = hf.drop(&tool, p.x, p.y).unwrap();
            assert!((p.z - want).abs() < 1e-9);
        }
    }

    /// At the foot of a 60 degree wall rising from a floor the line runs
    /// where the tool touches both: the last CL point on the floor.
    #[test]
    fn a_wall_s_foot_gives_its_corner() {
        let hf = across_x(|x| -2.0 + (x - 5.0).max(0.0) * 60f64.to_radians().tan());
        let tool = Tool::Ball { d: 1.0 };
        // the corner, by a scan of the CL surface across it
        let corner = (0..2000)
            .map(|k| 3.0 + k as f64 * 0.001)
            .take_while(|&x| hf.drop(&tool, x, 3.0).unwrap() < -2.0 + 1e-9)
            .last()
            .unwrap();
        // nodes 0.125 mm apart: one 0.036 mm short of the corner, then
        // one 0.003 mm past it (the node short of it then barely bends)
        for x0 in [1.05, corner + 0.003 - 29.0 * 0.125] {
            let ls = lines(&hf, &tool, [x0, 1.0, 9.0, 5.0], -3.0, 1.0, &|_, _| true);
            assert_eq!(ls.len(), 1, "{} lines", ls.len());
            for p in &ls[0] {
                assert!(
                    (p.x - corner).abs() < 0.005,
                    "{p} off the corner at x = {corner}"
                );
            }
        }
    }

    /// A smooth bowl the tool fits into has no pencil line.
    #[test]
    fn a_wide_bowl_gives_none() {
        let pitch = 0.1;
        let (w, h) = (80, 80);
        let z = Grid::from_vec(
            w,
            h,
            (0..w * h)
                .map(|k| {
                    let x = ((k % w) as f64 + 0.5) * pitch - 4.0;
                    let y = ((k / w) as f64 + 0.5) * pitch - 4.0;
                    -1.0 + 0.05 * (x * x + y * y)
                })
                .collect(),
        );
        let hf = HeightField::new(z, pitch);
        let tool = Tool::Ball { d: 1.0 };
        let ls = lines(&hf, &tool, [0.0, 0.0, 8.0, 8.0], -3.0, 1.0, &|_, _| true);
        assert!(ls.is_empty(), "{} lines", ls.len());
    }
}
