//! The order passes are cut in, to keep rapid travel short: nearest next
//! (a closed loop may be entered at any of its points), then a 2-opt pass
//! that reverses stretches of the order wherever that shortens the links.

use glam::{DVec2, DVec3};

/// Grid cell for the nearest-next search, mm.
const CELL: f64 = 2.0;
/// Spacing of a loop's candidate entry points, mm.
const ENTRY_EVERY: f64 = 1.0;
/// Longest stretch 2-opt reverses, in passes.
const WINDOW: usize = 60;

fn closed(p: &[DVec3]) -> bool {
    p.len() > 2 && (p[0] - p[p.len() - 1]).length() < 1e-9
}

/// Closed loop `p` entered (and left) at its point `k`.
fn rotated(mut p: Vec<DVec3>, k: usize) -> Vec<DVec3> {
    if k == 0 || k >= p.len() - 1 {
        return p;
    }
    p.pop();
    p.rotate_left(k);
    p.push(p[0]);
    p
}

/// Passes reordered (closed loops re-entered) for short rapids, starting
/// nearest `from`. Open passes keep their direction.
pub fn tour(passes: Vec<Vec<DVec3>>, from: Option<DVec3>) -> Vec<Vec<DVec3>> {
    let n = passes.len();
    if n < 2 {
        return passes;
    }
    // candidate entries: (pass, point index) in a uniform grid
    let mut lo = DVec2::splat(f64::MAX);
    let mut hi = DVec2::splat(f64::MIN);
    for q in passes.iter().flatten() {
        lo = lo.min(q.truncate());
        hi = hi.max(q.truncate());
    }
    let gw = (((hi.x - lo.x) / CELL) as usize + 1).max(1);
    let gh = (((hi.y - lo.y) / CELL) as usize + 1).max(1);
    let cell_of = |q: DVec2| {
        (
            (((q.x - lo.x) / CELL) as usize).min(gw - 1),
            (((q.y - lo.y) / CELL) as usize).min(gh - 1),
        )
    };
    let mut grid: Vec<Vec<(u32, u32)>> = vec![Vec::new(); gw * gh];
    for (k, p) in passes.iter().enumerate() {
        let mut add = |i: usize| {
            let (cx, cy) = cell_of(p[i].truncate());
            grid[cy * gw + cx].push((k as u32, i as u32));
        };
        add(0);
        if closed(p) {
            let mut run = 0.0;
            for i in 1..p.len() - 1 {
                run += (p[i] - p[i - 1]).truncate().length();
                if run >= ENTRY_EVERY {
                    add(i);
                    run = 0.0;
                }
            }
        }
    }
    let mut taken = vec![false; n];
    let mut order: Vec<(usize, usize)> = Vec::with_capacity(n);
    let mut at = from.map_or(passes[0][0].truncate(), |p| p.truncate());
    for _ in 0..n {
        let (cx, cy) = cell_of(at);
        let mut best: Option<(f64, usize, usize)> = None;
        let mut ring = 0usize;
        loop {
            // every cell on the ring's border
            let (x0, x1) = (cx.saturating_sub(ring), (cx + ring).min(gw - 1));
            let (y0, y1) = (cy.saturating_sub(ring), (cy + ring).min(gh - 1));
            for y in y0..=y1 {
                for x in x0..=x1 {
                    if x.abs_diff(cx) != ring && y.abs_diff(cy) != ring {
                        continue;
                    }
                    let cell = &mut grid[y * gw + x];
                    cell.retain(|&(k, _)| !taken[k as usize]);
                    for &(k, i) in cell.iter() {
                        let d = (passes[k as usize][i as usize].truncate() - at).length();
                        if best.is_none_or(|b| d < b.0) {
                            best = Some((d, k as usize, i as usize));
                        }
                    }
                }
            }
            // cells beyond this ring are at least `ring * CELL` away
            let done = best.is_some_and(|b| b.0 <= ring as f64 * CELL);
            if done || (x0 == 0 && y0 == 0 && x1 == gw - 1 && y1 == gh - 1) {
                break;
            }
            ring += 1;
        }
        let Some((_, k, i)) = best else { break };
        taken[k] = true;
        order.push((k, i));
        let p = &passes[k];
        at = if closed(p) { p[i] } else { p[p.len() - 1] }.truncate();
    }
    let mut slots: Vec<Option<Vec<DVec3>>> = passes.into_iter().map(Some).collect();
    let seq: Vec<Vec<DVec3>> = order
        .into_iter()
        .map(|(k, i)| rotated(slots[k].take().unwrap(), i))
        .collect();
    two_opt(seq, from.map(|p| p.truncate()))
}

/// Reverse stretches of the order (each pass keeps its own direction)
/// wherever that shortens the links between passes.
fn two_opt(mut seq: Vec<Vec<DVec3>>, from: Option<DVec2>) -> Vec<Vec<DVec3>> {
    let n = seq.len();
    // (entry, exit) of each pass in order; a reversal of the order only
    // reverses this list too
    let mut e: Vec<(DVec2, DVec2)> = seq
        .iter()
        .map(|p| (p[0].truncate(), p[p.len() - 1].truncate()))
        .collect();
    for _ in 0..4 {
        let mut improved = false;
        for i in 0..n.saturating_sub(1) {
            let prev = if i == 0 { from } else { Some(e[i - 1].1) };
            let before_in = prev.map_or(0.0, |p| (e[i].0 - p).length());
            let mut internal = 0.0; // change of the links inside i..=j
            let mut best: Option<(f64, usize)> = None;
            for j in i + 1..n.min(i + WINDOW) {
                internal += (e[j].1 - e[j - 1].0).length() - (e[j - 1].1 - e[j].0).length();
                let after_in = prev.map_or(0.0, |p| (e[j].0 - p).length());
                let (before_out, after_out) = match e.get(j + 1) {
                    Some(nx) => ((nx.0 - e[j].1).length(), (nx.0 - e[i].1).length()),
                    None => (0.0, 0.0),
                };
                let delta = after_in + after_out + internal - before_in - before_out;
                if delta < -1e-6 && best.is_none_or(|b| delta < b.0) {
                    best = Some((delta, j));
                }
            }
            if let Some((_, j)) = best {
                seq[i..=j].reverse();
                e[i..=j].reverse();
                improved = true;
            }
        }
        if !improved {
            break;
        }
    }
    seq
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(x: f64, y: f64) -> Vec<DVec3> {
        [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0), (0.0, 0.0)]
            .iter()
            .map(|&(a, b)| DVec3::new(x + a, y + b, -1.0))
            .collect()
    }

    fn rapids(seq: &[Vec<DVec3>]) -> f64 {
        seq.windows(2)
            .map(|w| (w[1][0] - w[0][w[0].len() - 1]).truncate().length())
            .sum()
    }

    #[test]
    fn tour_visits_every_pass_once_and_shortens_rapids() {
        // loops scattered on a 10 x 10 lattice, listed row by row across
        // the panel and back in an order that zigzags badly
        let mut passes = Vec::new();
        for k in 0..100 {
            let (a, b) = ((k * 37) % 100 / 10, (k * 37) % 10);
            passes.push(square(a as f64 * 10.0, b as f64 * 10.0));
        }
        let before = rapids(&passes);
        let t = tour(passes.clone(), None);
        assert_eq!(t.len(), 100);
        for p in &passes {
            // the same loop, perhaps entered elsewhere
            assert!(t.iter().any(|q| q.len() == p.len()
                && p.iter()
                    .all(|a| q.iter().any(|b| (*a - *b).length() < 1e-12))));
        }
        let after = rapids(&t);
        assert!(after < before / 3.0, "{before} -> {after}");
    }
}
