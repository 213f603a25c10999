//! Exact drop-cutter on the relief's continuous surface (`surface`): for
//! a tool axis at (x, y), the lowest tip Z at which the tool touches no
//! point of the two triangles per cell, i.e. the highest of
//! surface(p) - profile(|p - (x, y)|) over the points p within reach.
//!
//! On one triangle that function is concave (a plane minus a convex
//! profile), so its maximum is the facet's own contact point when that
//! lies inside the triangle, else the best of its edges, each the clamped
//! stationary point of a concave function of one variable (`Tool`'s
//! `facet_radius` and `edge_offsets`); vertices are edge ends.
//!
//! Fast for large tools: a max-pyramid of the cells' highest corners gives,
//! for any block of cells, an upper bound (block max - profile at the
//! block's nearest point) on what it can contribute; blocks that cannot
//! beat the best contact found so far are skipped whole (branch and bound).
//! For a ball, each block also keeps a plane and how far its surface rises
//! above it (`plane_bound`): on sloping ground the highest corner sits on
//! the block's uphill side while the ball meets its downhill side, and the
//! plane's bound prunes what the corner's cannot (its effect measured:
//! docs/benchmarks.md, "The plane bound").

use super::along::Bottom;
use crate::cutter::surface::Lattice;
use crate::grid::Grid;
use crate::tool::Tool;

/// Heights (Z frame, mm) of samples at centres x = (i + 0.5) p,
/// y = top - (j + 0.5) p, the surface through them, and a max-pyramid
/// over its cells.
pub struct HeightField {
    pub pitch: f64,
    /// Y of the top edge (the panel height).
    pub top: f64,
    pub lattice: Lattice,
    samples: Grid<f64>,
    /// Heights of the (w + 2) x (h + 2) lattice vertices.
    vz: Grid<f64>,
    /// levels[0] = highest corner of each cell; levels[k] = max over
    /// 2^k x 2^k blocks of cells.
    levels: Vec<Grid<f64>>,
    /// For each block of levels[k], k >= 1: a plane through it (height at
    /// the block's centre, slopes in x and y) and a bound on how far its
    /// surface rises above that plane (`plane_bound`).
    planes: Vec<Vec<[f64; 4]>>,
    /// Max over runs of ROW_BLOCK samples along each row: lets a swept
    /// move's check skip stretches of a row lying below the tool.
    row_max: Grid<f64>,
}

/// Samples per `row_max` block.
pub const ROW_BLOCK: usize = 16;

/// Work space of a drop: the branch-and-bound stack.
pub type Stack = Vec<(f64, usize, usize, usize)>;

impl HeightField {
    /// A relief's continuous surface as the tools meet it: its top at Z
    /// 0, its lower-left corner at X, Y 0 (the toolpath's frame, and the
    /// simulator's once the job's panel offset is taken off).
    pub fn of_relief(relief: &crate::relief::Relief) -> HeightField {
        HeightField::new(
            relief.heights.map(|v| *v as f64 - relief.depth_mm),
            relief.pitch_mm(),
        )
    }

    pub fn new(z: Grid<f64>, pitch: f64) -> HeightField {
        let lattice = Lattice::square(z.w, z.h, pitch);
        let top = lattice.height;
        let vz = Grid::from_vec(
            z.w + 2,
            z.h + 2,
            (0..(z.w + 2) * (z.h + 2))
                .map(|k| {
                    let (i, j) = lattice.sample(k % (z.w + 2), k / (z.w + 2));
                    *z.get(i, j)
                })
                .collect(),
        );
        let (cw, ch) = lattice.cells();
        let mut base = Grid::new(cw, ch, f64::NEG_INFINITY);
        for j in 0..ch {
            for i in 0..cw {
                let m = vz
                    .get(i, j)
                    .max(*vz.get(i + 1, j))
                    .max(vz.get(i, j + 1).max(*vz.get(i + 1, j + 1)));
                base.set(i, j, m);
            }
        }
        let mut levels = vec![base];
        while let Some(l) = levels.last() {
            if l.w <= 1 && l.h <= 1 {
                break;
            }
            let (w, h) = (l.w.div_ceil(2), l.h.div_ceil(2));
            let mut n = Grid::new(w, h, f64::NEG_INFINITY);
            for y in 0..l.h {
                for x in 0..l.w {
                    let v = n.get(x / 2, y / 2).max(*l.get(x, y));
                    n.set(x / 2, y / 2, v);
                }
            }
            levels.push(n);
        }
        let (cw, ch) = lattice.cells();
        let vx: Vec<f64> = (0..=cw).map(|i| lattice.vx(i)).collect();
        let vy: Vec<f64> = (0..=ch).map(|j| lattice.vy(j)).collect();
        let mut planes: Vec<Vec<[f64; 4]>> = vec![Vec::new()];
        for k in 1..levels.len() {
            let g = &levels[k];
            let kids = (k > 1).then(|| (&planes[k - 1][..], levels[k - 1].w));
            let p = block_planes(&lattice, (&vx, &vy), &vz, k, (g.w, g.h), kids);
            planes.push(p);
        }
        let bw = z.w.div_ceil(ROW_BLOCK);
        let row_max = Grid::from_vec(
            bw,
            z.h,
            (0..z.h)
                .flat_map(|j| {
                    let row = &z.data[j * z.w..(j + 1) * z.w];
                    row.chunks(ROW_BLOCK)
                        .map(|c| c.iter().cloned().fold(f64::NEG_INFINITY, f64::max))
                        .collect::<Vec<_>>()
                })
                .collect(),
        );
        HeightField {
            pitch,
            top,
            lattice,
            samples: z,
            vz,
            levels,
            planes,
            row_max,
        }
    }

    /// Highest sample of row block `b` (samples b*ROW_BLOCK..) of row `j`.
    #[inline]
    pub fn row_block_max(&self, b: usize, j: usize) -> f64 {
        self.row_max.data[j * self.row_max.w + b]
    }

    pub fn samples(&self) -> &Grid<f64> {
        &self.samples
    }

    /// Centre of sample (i, j).
    #[inline]
    pub fn centre(&self, i: usize, j: usize) -> (f64, f64) {
        (
            (i as f64 + 0.5) * self.pitch,
            self.top - (j as f64 + 0.5) * self.pitch,
        )
    }

    /// The extent of block (bx, by) at `level` in vertex indices: columns
    /// i0..=i1, rows j0..=j1.
    #[inline]
    fn block_vertices(&self, level: usize, bx: usize, by: usize) -> (usize, usize, usize, usize) {
        block_vertices(&self.lattice, level, bx, by)
    }

    /// An upper bound on what block (bx, by) at `level` >= 1 can hold a
    /// ball of radius `r` at (x, y) to: its surface lies at most e above
    /// its plane P, so the contact is at most e over the highest of P less
    /// the ball's profile, taken over the block's rectangle with the
    /// profile's parabola d^2 / 2r below it (separable: the best point is
    /// the unconstrained one, x + r P', clamped), and over the whole plane
    /// with the sphere itself (the ball's contact with P). On sloping
    /// ground it is far tighter than the block's highest corner, which sits
    /// on its uphill side while the ball meets its downhill side.
    #[inline]
    fn plane_bound(&self, level: usize, bx: usize, by: usize, x: f64, y: f64, r: f64) -> f64 {
        let p = self.block_plane(level, bx, by);
        let (x0, x1, yt, yb) = p.rect;
        let qx = (x + r * p.ax).clamp(x0, x1);
        let qy = (y + r * p.ay).clamp(yb, yt);
        let (dx, dy) = (qx - x, qy - y);
        let parabola = p.at(qx, qy) - (dx * dx + dy * dy) / (2.0 * r);
        let sphere = p.at(x, y) + p.ball_lift(r);
        parabola.min(sphere) + p.e
    }

    /// Block (bx, by)'s plane at `level` >= 1, with its rectangle.
    #[inline]
    fn block_plane(&self, level: usize, bx: usize, by: usize) -> BlockPlane {
        let [z0, ax, ay, e] = self.planes[level][by * self.levels[level].w + bx];
        let (i0, i1, j0, j1) = self.block_vertices(level, bx, by);
        let l = &self.lattice;
        let rect = (l.vx(i0), l.vx(i1), l.vy(j0), l.vy(j1));
        BlockPlane {
            rect,
            centre: (0.5 * (rect.0 + rect.1), 0.5 * (rect.2 + rect.3)),
            z0,
            ax,
            ay,
            e,
        }
    }

    /// Squared distance from (x, y) to the rectangle of block (bx, by) at `level`,
    /// or less: the rectangle is taken unclamped to the panel (wider at
    /// its edges), which is cheaper and still a bound.
    #[inline]
    fn block_distance(&self, level: usize, bx: usize, by: usize, x: f64, y: f64) -> f64 {
        let s = (1usize << level) as f64 * self.pitch;
        let (x0, yt) = (
            bx as f64 * s - 0.5 * self.pitch,
            self.top + 0.5 * self.pitch - by as f64 * s,
        );
        let dx = (x0 - x).max(0.0).max(x - (x0 + s));
        let dy = (yt - s - y).max(0.0).max(y - yt);
        dx * dx + dy * dy
    }

    /// Exact drop-cutter at (x, y); None when no point of the panel lies
    /// within reach.
    pub fn drop(&self, tool: &Tool, x: f64, y: f64) -> Option<f64> {
        self.drop_from(tool, x, y, None, &mut Vec::new())
            .map(|c| c.0)
    }

    /// What cell (i, j) holds the tool at (x, y) to, if in reach: the
    /// highest contact over its two triangles.
    #[inline]
    pub fn contribution(&self, tool: &Tool, i: usize, j: usize, x: f64, y: f64) -> Option<f64> {
        let z = self.cell_contact(tool, tool.radius(), i, j, x, y, f64::NEG_INFINITY);
        z.is_finite().then_some(z)
    }

    /// The cells of the block of `side` x `side` cells (1 or 2) from cell
    /// `first`, each first bounded cheaply (its highest corner minus the
    /// profile at its nearest point); the corners' contacts of a cell that
    /// passes are computed (once per block) and bound it closely: inside
    /// a triangle whose corners are all in reach the tool can sink below
    /// the best corner by at most the Jensen gap of its profile, curvature
    /// x diameter^2 / 8. Only a cell that may still beat `best` gets its
    /// exact contact.
    #[allow(clippy::too_many_arguments)]
    fn cells(
        &self,
        tool: &Tool,
        r: f64,
        first: (usize, usize),
        side: usize,
        (x, y): (f64, f64),
        best: &mut f64,
        contact: &mut (usize, usize),
    ) {
        let (cw, ch) = self.lattice.cells();
        let (i0, j0) = first;
        let (ni, nj) = ((cw - i0).min(side), (ch - j0).min(side));
        let l = &self.lattice;
        let w = self.vz.w;
        let r2 = r * r;
        // (distance^2, contact) of the corners, computed when first
        // needed (NaN until then); -inf out of reach
        let mut v = [[(f64::NAN, f64::NEG_INFINITY); 3]; 3];
        let mut corner = |ai: usize, bj: usize| -> (f64, f64) {
            let c = &mut v[bj][ai];
            if c.0.is_nan() {
                let (dx, dy) = (l.vx(i0 + ai) - x, l.vy(j0 + bj) - y);
                let d2 = dx * dx + dy * dy;
                c.0 = d2;
                if d2 <= r2 {
                    c.1 = self.vz.data[(j0 + bj) * w + i0 + ai] - tool.profile_sq(d2);
                }
            }
            *c
        };
        for bj in 0..nj {
            for ai in 0..ni {
                let (i, j) = (i0 + ai, j0 + bj);
                let (x0, x1, yt, yb) = (l.vx(i), l.vx(i + 1), l.vy(j), l.vy(j + 1));
                let dx = (x0 - x).max(0.0).max(x - x1);
                let dy = (yb - y).max(0.0).max(y - yt);
                let near2 = dx * dx + dy * dy;
                let high = *self.levels[0].get(i, j);
                if near2 > r2 || high - tool.profile_below(near2) <= *best {
                    continue;
                }
                let cs = [
                    corner(ai, bj),
                    corner(ai + 1, bj),
                    corner(ai, bj + 1),
                    corner(ai + 1, bj + 1),
                ];
                let top = cs.iter().fold(f64::NEG_INFINITY, |m, c| m.max(c.1));
                let far2 = cs.iter().fold(0.0f64, |m, c| m.max(c.0));
                if top > *best {
                    (*best, *contact) = (top, (i, j));
                }
                let bound = if far2 <= r2 {
                    let diam2 = (x1 - x0) * (x1 - x0) + (yt - yb) * (yt - yb);
                    top + tool.curvature_bound(near2.sqrt(), far2.sqrt()) * diam2 / 8.0
                } else {
                    high - tool.profile_sq(near2)
                };
                if bound > *best {
                    let z = self.cell_contact(tool, r, i, j, x, y, *best);
                    if z > *best {
                        (*best, *contact) = (z, (i, j));
                    }
                }
            }
        }
    }

    /// The corners of cell (i, j): upper left, upper right, lower left,
    /// lower right, as (x, y, z). Its triangles are a b c and b c d.
    #[inline]
    fn corners(&self, i: usize, j: usize) -> [[f64; 3]; 4] {
        let l = &self.lattice;
        let (x0, x1, yt, yb) = (l.vx(i), l.vx(i + 1), l.vy(j), l.vy(j + 1));
        let w = self.vz.w;
        let k = j * w + i;
        let z = &self.vz.data;
        [
            [x0, yt, z[k]],
            [x1, yt, z[k + 1]],
            [x0, yb, z[k + w]],
            [x1, yb, z[k + w + 1]],
        ]
    }

    /// The highest contact of the tool at (x, y) with the two triangles
    /// of cell (i, j); -inf when they are out of reach. A triangle that
    /// cannot beat `floor` is skipped: its facet's contact with its whole
    /// plane bounds it, and is its contact when that lies inside it;
    /// otherwise its edges hold the tool.
    #[allow(clippy::too_many_arguments)]
    fn cell_contact(
        &self,
        tool: &Tool,
        r: f64,
        i: usize,
        j: usize,
        x: f64,
        y: f64,
        floor: f64,
    ) -> f64 {
        let [a, b, c, d] = self.corners(i, j);
        let ([x0, yt, za], [x1, yb, zd]) = (a, d);
        let (zb, zc) = (b[2], c[2]);
        let (cw, chh) = (x1 - x0, yt - yb);
        let mut best = f64::NEG_INFINITY;
        let mut diag = None;
        // upper-left triangle a b c (u + v <= 1), then lower-right b c d
        for upper in [true, false] {
            let (gx, gy, o) = if upper {
                ((zb - za) / cw, (za - zc) / chh, a)
            } else {
                ((zd - zc) / cw, (zb - zd) / chh, d)
            };
            let at_axis = o[2] + gx * (x - o[0]) + gy * (y - o[1]);
            let (px, py, plane) = if let Tool::Ball { d } = *tool {
                // touches where the sphere's normal is the plane's: R
                // (gx, gy) / q from the axis, q = sqrt(1 + g^2), and the
                // tip sits R (q - 1) above the plane at the axis
                let q = (1.0 + gx * gx + gy * gy).sqrt();
                let k = 0.5 * d / q;
                (x + k * gx, y + k * gy, at_axis + 0.5 * d * (q - 1.0))
            } else {
                let g = (gx * gx + gy * gy).sqrt();
                let rf = tool.facet_radius(g);
                if g > 0.0 {
                    let (px, py) = (x + rf * gx / g, y + rf * gy / g);
                    (px, py, at_axis + g * rf - tool.profile(rf))
                } else {
                    (x, y, at_axis - tool.profile(0.0))
                }
            };
            if plane <= floor.max(best) {
                continue;
            }
            // where the facet's contact lies: beyond which edges (at most
            // two). The triangle's contact is on an edge facing it: from
            // any point inside, the way to the facet's contact climbs.
            let (u, v) = ((px - x0) / cw, (yt - py) / chh);
            let (beyond_diag, beyond_x, beyond_y) = if upper {
                (u + v > 1.0, u < 0.0, v < 0.0)
            } else {
                (u + v < 1.0, u > 1.0, v > 1.0)
            };
            if !(beyond_diag || beyond_x || beyond_y) {
                best = best.max(plane);
                continue;
            }
            let e = if upper { a } else { d };
            if beyond_diag {
                best = best.max(*diag.get_or_insert_with(|| edge(tool, r, x, y, b, c)));
            }
            if beyond_x {
                // the edge of constant x: a-c, or b-d
                best = best.max(edge(tool, r, x, y, e, if upper { c } else { b }));
            }
            if beyond_y {
                best = best.max(edge(tool, r, x, y, e, if upper { b } else { c }));
            }
        }
        best
    }

    /// Drop-cutter that starts from a `hint` cell (the previous point's
    /// contact, usually close to this one's) and reuses `stack`; returns
    /// the CL height and the contact cell.
    pub fn drop_from(
        &self,
        tool: &Tool,
        x: f64,
        y: f64,
        hint: Option<(usize, usize)>,
        stack: &mut Stack,
    ) -> Option<(f64, (usize, usize))> {
        self.drop_above(tool, x, y, f64::NEG_INFINITY, hint, stack)
    }

    /// The drop-cutter as a test: the CL height and contact at (x, y) if
    /// the CL lies above `floor`, else None. Far cheaper than a drop when
    /// it does not (a tool checked at a point of its own path): everything
    /// that cannot rise above `floor` is pruned from the start.
    pub fn drop_above(
        &self,
        tool: &Tool,
        x: f64,
        y: f64,
        floor: f64,
        hint: Option<(usize, usize)>,
        stack: &mut Stack,
    ) -> Option<(f64, (usize, usize))> {
        let r = tool.radius();
        let r2 = r * r;
        // the profile's lower bound, for a ball without its division
        let inv_d = match *tool {
            Tool::Ball { d } => 1.0 / d,
            _ => f64::NAN,
        };
        let ball = matches!(tool, Tool::Ball { .. });
        let below = |d2: f64| {
            if inv_d.is_nan() {
                tool.profile_below(d2)
            } else {
                d2 * inv_d
            }
        };
        let mut best = floor;
        let mut contact = (usize::MAX, 0);
        let (cw, ch) = self.lattice.cells();
        if let Some((i, j)) = hint.filter(|&(i, j)| i < cw && j < ch) {
            // usually the contact again, or next to it: a close lower
            // bound to prune with from the start
            let z = self.cell_contact(tool, r, i, j, x, y, best);
            if z > best {
                (best, contact) = (z, (i, j));
            }
        }
        // start at the level whose blocks are about the footprint's size,
        // with the (few) blocks the footprint's bounding box touches
        let reach = (2.0 * r / self.pitch).max(1.0);
        let start = (reach.log2().ceil() as usize).min(self.levels.len() - 1);
        let base = &self.levels[start];
        let l = &self.lattice;
        let (i0, i1) = (l.cell_x(x - r) >> start, l.cell_x(x + r) >> start);
        let (j0, j1) = (l.cell_y(y + r) >> start, l.cell_y(y - r) >> start);
        stack.clear();
        for by in j0..=j1.min(base.h - 1) {
            for bx in i0..=i1.min(base.w - 1) {
                let d2 = self.block_distance(start, bx, by, x, y);
                if d2 <= r * r {
                    let mut b = base.get(bx, by) - tool.profile_below(d2);
                    if ball && start >= 1 && b > best {
                        b = b.min(self.plane_bound(start, bx, by, x, y, r));
                    }
                    stack.push((b, start, bx, by));
                }
            }
        }
        stack.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        while let Some((bound, level, bx, by)) = stack.pop() {
            if bound <= best {
                continue;
            }
            if level <= 1 {
                let first = (bx << level, by << level);
                self.cells(tool, r, first, 1 << level, (x, y), &mut best, &mut contact);
                continue;
            }
            // children, most promising last so they are searched first;
            // their distances from the axis along x and y, two each
            let child = &self.levels[level - 1];
            let s = (1usize << (level - 1)) as f64 * self.pitch;
            let xl = (2 * bx) as f64 * s - 0.5 * self.pitch;
            let yt = self.top + 0.5 * self.pitch - (2 * by) as f64 * s;
            let dxs = [
                (xl - x).max(0.0).max(x - (xl + s)),
                (xl + s - x).max(0.0).max(x - (xl + 2.0 * s)),
            ];
            let dys = [
                (yt - s - y).max(0.0).max(y - yt),
                (yt - 2.0 * s - y).max(0.0).max(y - (yt - s)),
            ];
            let mut kids = [(0.0f64, 0usize, 0usize, 0usize); 4];
            let mut nk = 0;
            for (k, (cx, cy)) in [
                (2 * bx, 2 * by),
                (2 * bx + 1, 2 * by),
                (2 * bx, 2 * by + 1),
                (2 * bx + 1, 2 * by + 1),
            ]
            .into_iter()
            .enumerate()
            {
                if cx >= child.w || cy >= child.h {
                    continue;
                }
                let d2 = dxs[k & 1] * dxs[k & 1] + dys[k >> 1] * dys[k >> 1];
                if d2 > r2 {
                    continue;
                }
                let mut b = child.data[cy * child.w + cx] - below(d2);
                if ball && level >= 2 && b > best {
                    b = b.min(self.plane_bound(level - 1, cx, cy, x, y, r));
                }
                if b > best {
                    kids[nk] = (b, level - 1, cx, cy);
                    nk += 1;
                }
            }
            kids[..nk].sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
            stack.extend_from_slice(&kids[..nk]);
        }
        (contact.0 != usize::MAX && best.is_finite()).then_some((best, contact))
    }

    /// A ball or flat end mill moved straight from tip a to tip b: the
    /// highest the exact CL surface rises over the move (how deep the move
    /// would cut), if more than `floor`, else None. Branch and bound as
    /// for a drop, a block bounded by its highest corner less the tool's
    /// lowest over the block's nearest point to the move's path, and less
    /// the path's lower end; every cell that may beat the best found gets
    /// its features' exact rises (`along`).
    pub fn rise_along(
        &self,
        bottom: Bottom,
        a: glam::DVec3,
        b: glam::DVec3,
        floor: f64,
    ) -> Option<f64> {
        let path = super::along::Path { a, d: b - a };
        let r = bottom.radius();
        let below = |d2: f64| bottom.below(d2);
        let p = self.pitch;
        let (dx, dy) = (b.x - a.x, b.y - a.y);
        let len2 = dx * dx + dy * dy;
        let reach_t = if len2 > 0.0 { r / len2.sqrt() } else { 0.0 };
        // for the rectangle of block (bx, by) at `level` (unclamped, as
        // `block_distance`): the squared distance from the move's path
        // (XY), and the move's lowest tip where the ball can reach it
        let near = |level: usize, bx: usize, by: usize| {
            let s = (1usize << level) as f64 * p;
            let x0 = bx as f64 * s - 0.5 * p;
            let y1 = self.top + 0.5 * p - by as f64 * s;
            let d2 = segment_rect_d2((a.x, a.y), (b.x, b.y), (x0, y1 - s, x0 + s, y1));
            let (lo, hi) = if len2 > 0.0 {
                let t = |x: f64, y: f64| ((x - a.x) * dx + (y - a.y) * dy) / len2;
                let ts = [t(x0, y1 - s), t(x0 + s, y1 - s), t(x0, y1), t(x0 + s, y1)];
                let lo = ts.iter().cloned().fold(f64::INFINITY, f64::min) - reach_t;
                let hi = ts.iter().cloned().fold(f64::NEG_INFINITY, f64::max) + reach_t;
                (lo.clamp(0.0, 1.0), hi.clamp(0.0, 1.0))
            } else {
                (0.0, 1.0)
            };
            let z = |t: f64| a.z + (b.z - a.z) * t;
            (d2, z(lo).min(z(hi)), (lo, hi))
        };
        // a block at level >= 1 holds the ball at most its plane's contact
        // with it plus its rise above the plane (`plane_bound`): along the
        // move, less the tip's height, that is linear in t, so highest at
        // an end of the stretch where the ball reaches the block
        let plane_rise = |level: usize, bx: usize, by: usize, (lo, hi): (f64, f64)| {
            let pl = self.block_plane(level, bx, by);
            let at = |t: f64| {
                let q = path.a + path.d * t;
                pl.at(q.x, q.y) - q.z
            };
            at(lo).max(at(hi)) + bottom.lift(pl.ax * pl.ax + pl.ay * pl.ay) + pl.e
        };
        let mut best = floor;
        let reach = (2.0 * r / p).max(1.0);
        let start = (reach.log2().ceil() as usize).min(self.levels.len() - 1);
        let base = &self.levels[start];
        let l = &self.lattice;
        let (xl, xh) = (a.x.min(b.x) - r, a.x.max(b.x) + r);
        let (yl, yh) = (a.y.min(b.y) - r, a.y.max(b.y) + r);
        let (i0, i1) = (l.cell_x(xl) >> start, l.cell_x(xh) >> start);
        let (j0, j1) = (l.cell_y(yh) >> start, l.cell_y(yl) >> start);
        let mut stack: Vec<(f64, usize, usize, usize)> = Vec::new();
        for by in j0..=j1.min(base.h - 1) {
            for bx in i0..=i1.min(base.w - 1) {
                let (d2, low, span) = near(start, bx, by);
                if d2 <= r * r {
                    let mut k = base.get(bx, by) - below(d2) - low;
                    if start >= 1 && k > best {
                        k = k.min(plane_rise(start, bx, by, span));
                    }
                    stack.push((k, start, bx, by));
                }
            }
        }
        stack.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        while let Some((bound, level, bx, by)) = stack.pop() {
            if bound <= best {
                continue;
            }
            if level == 0 {
                let (d2, low, _) = near(0, bx, by);
                let high = *self.levels[0].get(bx, by);
                best = best.max(self.cell_rise(&path, bottom, bx, by, (d2, low, high), best));
                continue;
            }
            let child = &self.levels[level - 1];
            let mut kids = [(0.0f64, 0usize, 0usize, 0usize); 4];
            let mut nk = 0;
            for (cx, cy) in [
                (2 * bx, 2 * by),
                (2 * bx + 1, 2 * by),
                (2 * bx, 2 * by + 1),
                (2 * bx + 1, 2 * by + 1),
            ] {
                if cx >= child.w || cy >= child.h {
                    continue;
                }
                let (d2, low, span) = near(level - 1, cx, cy);
                if d2 > r * r {
                    continue;
                }
                let mut k = child.data[cy * child.w + cx] - below(d2) - low;
                if level >= 2 && k > best {
                    k = k.min(plane_rise(level - 1, cx, cy, span));
                }
                if k > best {
                    kids[nk] = (k, level - 1, cx, cy);
                    nk += 1;
                }
            }
            kids[..nk].sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
            stack.extend_from_slice(&kids[..nk]);
        }
        (best > floor).then_some(best)
    }

    /// The highest rise over `path` of a ball or flat held by cell (i, j):
    /// its four vertices, then, unless they settle that the cell cannot
    /// beat `best`, its five edges and two facets. `(d2, low, high)`: the
    /// cell's squared distance from the path, the path's lowest tip in
    /// reach of it, and its highest corner.
    ///
    /// A flat: no point of the cell holds the tip above the cell's highest
    /// corner. A ball: while every corner lies within F = R / 2 of the
    /// axis, a triangle holds the ball at most the Jensen gap of its
    /// profile, curvature R^2 / (R^2 - F^2)^1.5 times diameter^2 / 8,
    /// above its best corner; while one lies farther, the whole cell lies
    /// at least F - diameter from the axis, where the ball is that much
    /// higher.
    fn cell_rise(
        &self,
        path: &super::along::Path,
        bottom: Bottom,
        i: usize,
        j: usize,
        (d2, low, high): (f64, f64, f64),
        best: f64,
    ) -> f64 {
        let [a, b, c, d] = self.corners(i, j);
        let (cw, ch) = (d[0] - a[0], a[1] - d[1]);
        let corners = [a, b, c, d]
            .iter()
            .map(|v| path.vertex_by(bottom, *v))
            .fold(f64::NEG_INFINITY, f64::max);
        // the most an edge or facet can rise
        let most = match bottom {
            Bottom::Ball(r) => {
                let diam2 = cw * cw + ch * ch;
                let f = 0.5 * r;
                let gap = r * r / (r * r - f * f).powf(1.5) * diam2 / 8.0;
                let rim = (f - diam2.sqrt()).max(d2.sqrt()).min(r);
                (corners + gap).max(high - (r - (r * r - rim * rim).sqrt()) - low)
            }
            Bottom::Flat(_) => high - low,
        };
        if most <= best.max(corners) {
            return corners;
        }
        let mut best = corners;
        for (p, q) in [(a, b), (a, c), (b, c), (b, d), (c, d)] {
            best = best.max(path.edge_by(bottom, p, q));
        }
        if cw > 0.0 && ch > 0.0 {
            best = best.max(self.facets_rise(path, bottom, i, j));
        }
        best
    }

    /// The highest rise of the cell's two facets over `path`.
    fn facets_rise(&self, path: &super::along::Path, bottom: Bottom, i: usize, j: usize) -> f64 {
        let [a, b, c, d] = self.corners(i, j);
        let ([x0, yt, za], [x1, yb, zd]) = (a, d);
        let (zb, zc) = (b[2], c[2]);
        let (cw, ch) = (x1 - x0, yt - yb);
        let uv = |x: f64, y: f64| ((x - x0) / cw, (yt - y) / ch);
        let upper = path.facet(bottom, a, ((zb - za) / cw, (za - zc) / ch), |x, y| {
            let (u, v) = uv(x, y);
            [u, v, 1.0 - u - v]
        });
        let lower = path.facet(bottom, d, ((zd - zc) / cw, (zb - zd) / ch), |x, y| {
            let (u, v) = uv(x, y);
            [1.0 - u, 1.0 - v, u + v - 1.0]
        });
        upper.max(lower)
    }

    /// Every cell in turn, no pruning (checks the branch and bound).
    pub fn drop_brute(&self, tool: &Tool, x: f64, y: f64) -> Option<f64> {
        let (cw, ch) = self.lattice.cells();
        let r = tool.radius();
        let best = (0..ch)
            .flat_map(|j| (0..cw).map(move |i| (i, j)))
            .map(|(i, j)| self.cell_contact(tool, r, i, j, x, y, f64::NEG_INFINITY))
            .fold(f64::NEG_INFINITY, f64::max);
        best.is_finite().then_some(best)
    }
}

/// A block's plane from `HeightField::planes`, with the block's
/// rectangle (x0, x1, y top, y bottom) and centre.
struct BlockPlane {
    rect: (f64, f64, f64, f64),
    centre: (f64, f64),
    z0: f64,
    ax: f64,
    ay: f64,
    /// How far the block's surface may rise above the plane.
    e: f64,
}

impl BlockPlane {
    /// The plane's height at (x, y).
    #[inline]
    fn at(&self, x: f64, y: f64) -> f64 {
        self.z0 + self.ax * (x - self.centre.0) + self.ay * (y - self.centre.1)
    }

    /// How far above the plane at its axis a ball of radius `r` touching
    /// it sits: r (sqrt(1 + slope^2) - 1).
    #[inline]
    fn ball_lift(&self, r: f64) -> f64 {
        r * ((1.0 + self.ax * self.ax + self.ay * self.ay).sqrt() - 1.0)
    }
}

/// The vertex columns i0..=i1 and rows j0..=j1 of block (bx, by) at
/// `level` (its cells bx 2^level.. and by 2^level.., within the lattice).
#[inline]
fn block_vertices(l: &Lattice, level: usize, bx: usize, by: usize) -> (usize, usize, usize, usize) {
    let (cw, ch) = l.cells();
    let i0 = (bx << level).min(cw);
    let j0 = (by << level).min(ch);
    (
        i0,
        ((bx + 1) << level).min(cw),
        j0,
        ((by + 1) << level).min(ch),
    )
}

/// Each block's plane at `level` (w x h blocks): through its corners'
/// mean at its centre, with their mean slopes, and how far the surface
/// rises above it: its vertices' highest rise at level 1, above that a
/// bound from the four children (each lies within its own rise above its
/// plane, which departs from this one linearly, so by most at a corner).
/// `vx`, `vy`: the lattice's vertex X and Y.
fn block_planes(
    l: &Lattice,
    (vx, vy): (&[f64], &[f64]),
    vz: &Grid<f64>,
    level: usize,
    (w, h): (usize, usize),
    children: Option<(&[[f64; 4]], usize)>,
) -> Vec<[f64; 4]> {
    use rayon::prelude::*;
    (0..w * h)
        .into_par_iter()
        .map(|k| {
            let (bx, by) = (k % w, k / w);
            let (i0, i1, j0, j1) = block_vertices(l, level, bx, by);
            let z = |i: usize, j: usize| vz.data[j * vz.w + i];
            let (cx, cy) = (0.5 * (vx[i0] + vx[i1]), 0.5 * (vy[j0] + vy[j1]));
            let (a, b, c, d) = (z(i0, j0), z(i1, j0), z(i0, j1), z(i1, j1));
            let z0 = 0.25 * (a + b + c + d);
            let wx = vx[i1] - vx[i0];
            let wy = vy[j0] - vy[j1];
            let ax = if wx > 0.0 {
                0.5 * (b + d - a - c) / wx
            } else {
                0.0
            };
            let ay = if wy > 0.0 {
                0.5 * (a + b - c - d) / wy
            } else {
                0.0
            };
            let plane = |x: f64, y: f64| z0 + ax * (x - cx) + ay * (y - cy);
            let mut e = f64::NEG_INFINITY;
            match children {
                Some((kids, kw)) => {
                    let kh = kids.len() / kw;
                    for ky in 2 * by..(2 * by + 2).min(kh) {
                        for kx in 2 * bx..(2 * bx + 2).min(kw) {
                            let [kz, kax, kay, ke] = kids[ky * kw + kx];
                            let (ki0, ki1, kj0, kj1) = block_vertices(l, level - 1, kx, ky);
                            let (kcx, kcy) = (0.5 * (vx[ki0] + vx[ki1]), 0.5 * (vy[kj0] + vy[kj1]));
                            for (x, y) in [
                                (vx[ki0], vy[kj0]),
                                (vx[ki1], vy[kj0]),
                                (vx[ki0], vy[kj1]),
                                (vx[ki1], vy[kj1]),
                            ] {
                                e = e
                                    .max(ke + kz + kax * (x - kcx) + kay * (y - kcy) - plane(x, y));
                            }
                        }
                    }
                }
                None => {
                    for (j, &y) in vy.iter().enumerate().take(j1 + 1).skip(j0) {
                        for (i, &x) in vx.iter().enumerate().take(i1 + 1).skip(i0) {
                            e = e.max(z(i, j) - plane(x, y));
                        }
                    }
                }
            }
            // rounding: the bound must stay above the surface
            [z0, ax, ay, e + 1e-9 * (1.0 + z0.abs())]
        })
        .collect()
}

/// Squared distance from the segment a -> b to the rectangle (x0, y0,
/// x1, y1): 0 where they meet, else the least over the segment's ends and
/// the rectangle's corners.
fn segment_rect_d2(a: (f64, f64), b: (f64, f64), (x0, y0, x1, y1): (f64, f64, f64, f64)) -> f64 {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    if crate::cutter::sweep::clip_to_rect(a, (dx, dy), [x0, y0, x1, y1]).is_some() {
        return 0.0;
    }
    let to_rect = |x: f64, y: f64| {
        let ex = (x0 - x).max(0.0).max(x - x1);
        let ey = (y0 - y).max(0.0).max(y - y1);
        ex * ex + ey * ey
    };
    let len2 = dx * dx + dy * dy;
    let to_segment = |x: f64, y: f64| {
        let t = if len2 > 0.0 {
            (((x - a.0) * dx + (y - a.1) * dy) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let (ex, ey) = (a.0 + t * dx - x, a.1 + t * dy - y);
        ex * ex + ey * ey
    };
    [
        to_rect(a.0, a.1),
        to_rect(b.0, b.1),
        to_segment(x0, y0),
        to_segment(x1, y0),
        to_segment(x0, y1),
        to_segment(x1, y1),
    ]
    .into_iter()
    .fold(f64::INFINITY, f64::min)
}

/// The highest contact of the tool at (x, y) with the edge a -> b, within
/// reach `r`; -inf when out of reach.
#[inline]
fn edge(tool: &Tool, r: f64, x: f64, y: f64, a: [f64; 3], b: [f64; 3]) -> f64 {
    let (ex, ey) = (b[0] - a[0], b[1] - a[1]);
    let len = (ex * ex + ey * ey).sqrt();
    let (ux, uy) = (ex / len, ey / len);
    let (wx, wy) = (x - a[0], y - a[1]);
    let s0 = wx * ux + wy * uy;
    let d2 = (wx * wx + wy * wy - s0 * s0).max(0.0);
    if d2 > r * r {
        return f64::NEG_INFINITY;
    }
    let c = (r * r - d2).sqrt();
    let (lo, hi) = ((s0 - c).max(0.0), (s0 + c).min(len));
    if lo > hi {
        return f64::NEG_INFINITY;
    }
    let m = (b[2] - a[2]) / len;
    if let Tool::Ball { .. } = *tool {
        // the ball's section in the edge's vertical plane is a circle of
        // radius c: touching at offset m c / q (q = sqrt(1 + m^2)) it
        // holds the tip c q - r above the edge's height at the foot
        let q = (1.0 + m * m).sqrt();
        let s = s0 + m * c / q;
        if (lo..=hi).contains(&s) {
            return a[2] + m * s0 + c * q - r;
        }
        let s = s.clamp(lo, hi);
        let u = s - s0;
        return a[2] + m * s + (c * c - u * u).max(0.0).sqrt() - r;
    }
    let [u1, u2] = tool.edge_offsets(m, d2.sqrt());
    let at = |u: f64| {
        let s = (s0 + u).clamp(lo, hi);
        let rho = (d2 + (s - s0) * (s - s0)).sqrt().min(r);
        a[2] + m * s - tool.profile(rho)
    };
    if u1 == u2 {
        at(u1)
    } else {
        at(u1).max(at(u2))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::testing::rng;

    /// Smooth waves, noise, and a raised disc whose rim is a step one
    /// sample wide (an outline with `--steps`).
    fn field(w: usize, h: usize, pitch: f64, seed: u64, rough: bool) -> HeightField {
        let mut rnd = rng(seed);
        let z: Vec<f64> = (0..w * h)
            .map(|k| {
                let (x, y) = ((k % w) as f64, (k / w) as f64);
                let smooth = -2.0 + 0.8 * (x / 7.0).sin() * (y / 5.0).cos();
                let (cx, cy) = (x - w as f64 * 0.6, y - h as f64 * 0.4);
                let step = if cx * cx + cy * cy < (w as f64 * 0.2).powi(2) {
                    0.7
                } else {
                    0.0
                };
                smooth + step + if rough { 0.6 } else { 0.01 } * rnd()
            })
            .collect();
        HeightField::new(Grid::from_vec(w, h, z), pitch)
    }

    /// Golden-section search for the maximum of a concave function on
    /// [lo, hi]: (argmax, max).
    fn golden(lo: f64, hi: f64, f: impl Fn(f64) -> f64) -> (f64, f64) {
        let mid = crate::cutter::golden_max(lo, hi, 64, &f);
        [(lo, f(lo)), (hi, f(hi)), (mid, f(mid))].into_iter().fold(
            (lo, f64::NEG_INFINITY),
            |m, p| if p.1 > m.1 { p } else { m },
        )
    }

    /// The independent reference: over every triangle of the surface (as
    /// the STL export writes it, plus the flat strips to the panel's
    /// edges), the maximum of plane - profile by nested golden-section
    /// search, exact for a concave function; no contact formula. Beyond
    /// the reach the profile goes on as a steep cone (still convex), and a
    /// maximum found out there means the triangle is out of reach.
    fn reference(hf: &HeightField, tool: &Tool, x: f64, y: f64) -> Option<f64> {
        let r = tool.radius();
        let l = &hf.lattice;
        let (cw, ch) = l.cells();
        let prof = |rho: f64| {
            if rho <= r {
                tool.profile(rho)
            } else {
                tool.profile(r) + 1e6 * (rho - r)
            }
        };
        let z = |i: usize, j: usize| {
            let (a, b) = l.sample(i, j);
            *hf.samples().get(a, b)
        };
        let mut best = f64::NEG_INFINITY;
        for j in 0..ch {
            for i in 0..cw {
                let p = |i: usize, j: usize| [l.vx(i), l.vy(j), z(i, j)];
                let (a, b, c, d) = (p(i, j), p(i + 1, j), p(i, j + 1), p(i + 1, j + 1));
                // pruned only by a bound: the highest corner minus the
                // profile at the cell's nearest point
                let dx = (a[0] - x).max(0.0).max(x - b[0]);
                let dy = (c[1] - y).max(0.0).max(y - a[1]);
                let near = (dx * dx + dy * dy).sqrt();
                let top = a[2].max(b[2]).max(c[2]).max(d[2]);
                if near > r || top - tool.profile(near) <= best {
                    continue;
                }
                for t in [[a, b, c], [d, c, b]] {
                    let e1 = [t[1][0] - t[0][0], t[1][1] - t[0][1], t[1][2] - t[0][2]];
                    let e2 = [t[2][0] - t[0][0], t[2][1] - t[0][1], t[2][2] - t[0][2]];
                    let n = [
                        e1[1] * e2[2] - e1[2] * e2[1],
                        e1[2] * e2[0] - e1[0] * e2[2],
                        e1[0] * e2[1] - e1[1] * e2[0],
                    ];
                    let plane = |px: f64, py: f64| {
                        t[0][2] - (n[0] * (px - t[0][0]) + n[1] * (py - t[0][1])) / n[2]
                    };
                    let f = |px: f64, py: f64| {
                        plane(px, py) - prof(((px - x).powi(2) + (py - y).powi(2)).sqrt())
                    };
                    // the triangle's Y range at X: where its edges cross X
                    let yrange = |px: f64| {
                        let (mut lo, mut hi) = (f64::MAX, f64::MIN);
                        for k in 0..3 {
                            let (p, q) = (t[k], t[(k + 1) % 3]);
                            if px < p[0].min(q[0]) || px > p[0].max(q[0]) {
                                continue;
                            }
                            let ys = if p[0] == q[0] {
                                [p[1], q[1]]
                            } else {
                                let yy = p[1] + (q[1] - p[1]) * (px - p[0]) / (q[0] - p[0]);
                                [yy, yy]
                            };
                            lo = lo.min(ys[0].min(ys[1]));
                            hi = hi.max(ys[0].max(ys[1]));
                        }
                        (lo, hi)
                    };
                    let xl = t.iter().map(|v| v[0]).fold(f64::MAX, f64::min);
                    let xh = t.iter().map(|v| v[0]).fold(f64::MIN, f64::max);
                    let (px, _) = golden(xl, xh, |px| {
                        let (lo, hi) = yrange(px);
                        golden(lo, hi, |py| f(px, py)).1
                    });
                    let (lo, hi) = yrange(px);
                    let (py, v) = golden(lo, hi, |py| f(px, py));
                    if ((px - x).powi(2) + (py - y).powi(2)).sqrt() <= r + 1e-9 {
                        best = best.max(v);
                    }
                }
            }
        }
        best.is_finite().then_some(best)
    }

    #[test]
    fn every_tool_matches_an_independent_reference() {
        let tools = [
            "ball:1.5",
            "ball:3.175",
            "flat:0.8",
            "flat:3.3",
            "taperball:0.2:8:2.4",
            "vbit:60:2",
            "vbit:90:3",
            // smaller than a sample: the search starts at single cells
            "ball:0.08",
            "flat:0.09",
        ];
        // reliefs of 128 to 512 px with waves, noise and a step outline
        for (w, h, pitch, seed, rough) in [(128, 96, 0.1, 1, true), (512, 40, 0.05, 2, false)] {
            let hf = field(w, h, pitch, seed, rough);
            let (pw, ph) = (w as f64 * pitch, h as f64 * pitch);
            let mut rnd = rng(seed * 77);
            for spec in tools {
                let tool = Tool::parse(spec).unwrap();
                for _ in 0..25 {
                    let (x, y) = (-0.5 + (pw + 1.0) * rnd(), -0.5 + (ph + 1.0) * rnd());
                    let a = hf.drop(&tool, x, y);
                    let b = reference(&hf, &tool, x, y);
                    // a hint (right or wrong) never changes the answer
                    let hinted = hf
                        .drop_from(&tool, x, y, Some((7, 9)), &mut Vec::new())
                        .map(|c| c.0);
                    // (the same contact, reached through a neighbouring
                    // cell, may round differently)
                    let same = |p: Option<f64>, q: Option<f64>| match (p, q) {
                        (Some(p), Some(q)) => (p - q).abs() <= 1e-12,
                        (p, q) => p == q,
                    };
                    assert!(same(a, hinted) && same(a, hf.drop_brute(&tool, x, y)));
                    match (a, b) {
                        (Some(a), Some(b)) => {
                            assert!((a - b).abs() <= 1e-7, "{spec} at ({x},{y}): {a} vs {b}")
                        }
                        (a, b) => assert_eq!(a, b, "{spec} at ({x},{y})"),
                    }
                }
            }
        }
    }

    /// A block's plane bound is never below what any of its cells holds
    /// the ball to, on smooth, noisy and stepped fields, at every level:
    /// the drop-cutter may prune a block by it.
    #[test]
    fn plane_bounds_hold_every_cell_of_their_block() {
        let mut rnd = rng(7);
        let mut worst = f64::INFINITY;
        for (seed, rough) in [(1, false), (2, true), (3, false)] {
            let hf = field(90, 70, 0.1, seed, rough);
            let (cw, ch) = hf.lattice.cells();
            for r in [0.5, 1.5875] {
                let tool = Tool::Ball { d: 2.0 * r };
                for _ in 0..300 {
                    let (x, y) = (rnd() * 9.0, rnd() * 7.0);
                    for level in 1..hf.levels.len() {
                        let g = &hf.levels[level];
                        let (bx, by) =
                            ((rnd() * g.w as f64) as usize, (rnd() * g.h as f64) as usize);
                        let (i0, i1, j0, j1) = hf.block_vertices(level, bx, by);
                        let held = (j0..j1.min(ch))
                            .flat_map(|j| (i0..i1.min(cw)).map(move |i| (i, j)))
                            .filter_map(|(i, j)| hf.contribution(&tool, i, j, x, y))
                            .fold(f64::NEG_INFINITY, f64::max);
                        if held.is_finite() {
                            let bound = hf.plane_bound(level, bx, by, x, y, r);
                            assert!(bound >= held, "level {level}: bound {bound} < {held}");
                            worst = worst.min(bound - held);
                        }
                    }
                }
            }
        }
        assert!(worst < 1e-3, "bounds never tight: {worst}");
    }

    #[test]
    fn a_ball_on_a_flat_field_does_not_ripple() {
        let hf = HeightField::new(Grid::new(40, 30, -1.0), 0.5);
        let tool = Tool::parse("ball:3.175").unwrap();
        for k in 0..200 {
            let (x, y) = (2.0 + k as f64 * 0.0731, 7.3);
            assert_eq!(hf.drop(&tool, x, y), Some(-1.0), "at x {x}");
        }
    }

    /// The rise along a move against the drop-cutter itself: dense drops
    /// along the move, and a golden-section search round the highest
    /// (the highest of concave pieces lies inside one of them): the
    /// exact rise is never below it and at most 1e-7 mm above, for level,
    /// rising and falling moves over waves, noise and a one-sample step,
    /// including moves clear of the surface and ones cutting deep. A
    /// flat's CL surface steps where a sample enters its disc, so its
    /// highest may lie at such a step, between drops: there the exact
    /// rise may exceed the drops by what the move climbs between two.
    #[test]
    fn the_rise_along_a_move_matches_dense_drops() {
        for (seed, rough) in [(3, false), (8, true)] {
            let hf = field(60, 48, 0.25, seed, rough);
            let mut rnd = rng(seed + 100);
            for (r, n) in [(1.5875, 60), (0.5, 60)] {
                for tool in [Tool::Ball { d: 2.0 * r }, Tool::Flat { d: 2.0 * r }] {
                    let bottom = Bottom::of(&tool).unwrap();
                    for _ in 0..n {
                        let (x, y) = (2.5 + 10.0 * rnd(), 2.5 + 7.0 * rnd());
                        let (len, ang) = (0.05 + 2.0 * rnd(), std::f64::consts::TAU * rnd());
                        let (bx, by) = (x + len * ang.cos(), y + len * ang.sin());
                        let za = hf.drop(&tool, x, y).unwrap() + 0.3 * (rnd() - 0.6);
                        let zb = match (rnd() * 3.0) as usize {
                            0 => za,
                            _ => hf.drop(&tool, bx, by).unwrap() + 0.3 * (rnd() - 0.6),
                        };
                        let (a, b) = (glam::DVec3::new(x, y, za), glam::DVec3::new(bx, by, zb));
                        let rise = |t: f64| {
                            let q = a + (b - a) * t;
                            hf.drop(&tool, q.x, q.y).unwrap_or(f64::NEG_INFINITY) - q.z
                        };
                        let m = 8000;
                        let (k, top) = (0..=m)
                            .map(|k| (k, rise(k as f64 / m as f64)))
                            .fold((0, f64::NEG_INFINITY), |b, p| if p.1 > b.1 { p } else { b });
                        let lo = (k.max(1) - 1) as f64 / m as f64;
                        let hi = ((k + 1).min(m)) as f64 / m as f64;
                        let reference = top.max(golden(lo, hi, rise).1);
                        let exact = hf
                            .rise_along(bottom, a, b, f64::NEG_INFINITY)
                            .unwrap_or_else(|| {
                                panic!("none: {tool:?} {a} -> {b}, dense {reference}")
                            });
                        let between = match tool {
                            Tool::Flat { .. } => (zb - za).abs() / m as f64,
                            _ => 0.0,
                        };
                        assert!(
                            exact >= reference - 1e-9 && exact <= reference + 1e-7 + between,
                            "{tool:?}, {a} -> {b}: exact {exact}, dense {reference}"
                        );
                        // with a floor: None exactly when it is not passed
                        let floor = reference - 1e-3;
                        assert_eq!(hf.rise_along(bottom, a, b, floor).is_some(), exact > floor);
                        assert!(hf.rise_along(bottom, a, b, exact + 1e-6).is_none());
                    }
                }
            }
        }
    }
}
