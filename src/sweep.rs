//! A tool swept along one straight move: the lowest point of the swept
//! cutting surface over any point, in closed form (ball: the capsule of the
//! ball centre's path; flat: the disc's interval on the move; V-bit: the
//! stationary point of a convex function) or, for the tapered ball, by
//! golden-section search of the same convex function. Shared by the cut
//! simulator and the toolpath's final check.

use crate::tool::Tool;
use glam::DVec3;

/// Indices i < n of cells whose centres ((i + 0.5) pitch from the grid's
/// edge) lie in [lo, hi] (mm from that edge): the cells of one row a
/// footprint span covers, or the rows a band of Y covers.
#[inline]
pub fn cells_between(lo: f64, hi: f64, pitch: f64, n: usize) -> Option<(usize, usize)> {
    let (fl, fh) = (lo / pitch - 0.5, hi / pitch - 0.5);
    if !(fh >= 0.0 && fl <= n as f64 - 1.0) {
        return None;
    }
    // truncation is floor for the non-negative values left after clamping
    let i1 = fh.min(n as f64 - 1.0) as usize;
    let fl = fl.max(0.0);
    let i0 = fl as usize + (fl > (fl as usize) as f64) as usize;
    (i0 <= i1).then_some((i0, i1))
}

/// The lowest point of the swept tool surface over a cell at offset w from
/// the move's start (XY), or +inf when the tool does not reach it.
pub struct Sweep {
    pub a: DVec3,
    pub d: DVec3,
    /// |d_xy|^2
    pub axy: f64,
    pub r: f64,
    pub tool: Tool,
}

impl Sweep {
    pub fn new(a: DVec3, b: DVec3, tool: Tool) -> Sweep {
        let d = b - a;
        Sweep {
            a,
            d,
            axy: d.x * d.x + d.y * d.y,
            r: tool.radius(),
            tool,
        }
    }

    /// Parameter interval of the move over which the cell is within the
    /// tool's radius (None when never).
    #[inline]
    pub fn interval(&self, wx: f64, wy: f64) -> Option<(f64, f64)> {
        let w2 = wx * wx + wy * wy;
        let r2 = self.r * self.r;
        if self.axy < 1e-18 {
            return (w2 <= r2).then_some((0.0, 1.0));
        }
        let b = wx * self.d.x + wy * self.d.y;
        let disc = b * b - self.axy * (w2 - r2);
        if disc < 0.0 {
            return None;
        }
        let s = disc.sqrt();
        let (lo, hi) = (((b - s) / self.axy).max(0.0), ((b + s) / self.axy).min(1.0));
        (lo <= hi).then_some((lo, hi))
    }

    #[inline]
    pub fn rho(&self, wx: f64, wy: f64, t: f64) -> f64 {
        let (x, y) = (wx - t * self.d.x, wy - t * self.d.y);
        (x * x + y * y).sqrt()
    }

    #[inline]
    pub fn lowest(&self, wx: f64, wy: f64) -> f64 {
        let (a, d, r) = (self.a, self.d, self.r);
        match self.tool {
            Tool::Ball { .. } => {
                let z = self.sphere(wx, wy, 0.0).min(self.sphere(wx, wy, 1.0));
                z.min(self.cylinder(wx, wy))
            }
            Tool::Flat { .. } => match self.interval(wx, wy) {
                Some((lo, hi)) => a.z + d.z * if d.z < 0.0 { hi } else { lo },
                None => f64::INFINITY,
            },
            Tool::VBit { angle, .. } => {
                let Some((lo, hi)) = self.interval(wx, wy) else {
                    return f64::INFINITY;
                };
                let k = 1.0 / (angle.to_radians() / 2.0).tan();
                // a move steeper than the cone (or vertical) is lowest at
                // the end it descends to
                let t = if self.axy < 1e-18 || k * k * self.axy <= d.z * d.z {
                    if d.z < 0.0 {
                        hi
                    } else {
                        lo
                    }
                } else {
                    let b = wx * d.x + wy * d.y;
                    let h2 = (wx * wx + wy * wy - b * b / self.axy).max(0.0);
                    let s = -d.z * h2.sqrt() / (self.axy * (k * k * self.axy - d.z * d.z)).sqrt();
                    (b / self.axy + s).clamp(lo, hi)
                };
                a.z + d.z * t + k * self.rho(wx, wy, t)
            }
            Tool::TaperBall { .. } => {
                let Some((mut lo, mut hi)) = self.interval(wx, wy) else {
                    return f64::INFINITY;
                };
                let f = |t: f64| a.z + d.z * t + self.tool.profile(self.rho(wx, wy, t).min(r));
                let g = 0.5 * (5f64.sqrt() - 1.0);
                let mut best = f(lo).min(f(hi));
                for _ in 0..60 {
                    if hi - lo < 1e-12 {
                        break;
                    }
                    let (m1, m2) = (hi - g * (hi - lo), lo + g * (hi - lo));
                    if f(m1) < f(m2) {
                        hi = m2;
                    } else {
                        lo = m1;
                    }
                }
                best = best.min(f(0.5 * (lo + hi)));
                best
            }
        }
    }

    /// Ball: lowest point of the ball at parameter t (0 or 1) over the cell.
    #[inline]
    pub fn sphere(&self, wx: f64, wy: f64, t: f64) -> f64 {
        let (x, y) = (wx - t * self.d.x, wy - t * self.d.y);
        let (q, r2) = (x * x + y * y, self.r * self.r);
        if q <= r2 {
            self.a.z + t * self.d.z + self.r - (r2 - q).sqrt()
        } else {
            f64::INFINITY
        }
    }

    /// Ball: lowest point over the cell of the cylinder swept by the ball
    /// between the ends (the capsule's side), or +inf where its lowest point
    /// there is not on the side.
    #[inline]
    pub fn cylinder(&self, wx: f64, wy: f64) -> f64 {
        let len = self.d.length();
        if len == 0.0 {
            return f64::INFINITY;
        }
        let u = self.d / len;
        let aa = 1.0 - u.z * u.z;
        if aa <= 1e-12 {
            return f64::INFINITY;
        }
        let wu = wx * u.x + wy * u.y;
        let bb = -u.z * wu;
        let cc = wx * wx + wy * wy - wu * wu - self.r * self.r;
        let disc = bb * bb - aa * cc;
        if disc < 0.0 {
            return f64::INFINITY;
        }
        let zp = (-bb - disc.sqrt()) / aa;
        let s = (wu + zp * u.z) / len;
        if (0.0..=1.0).contains(&s) {
            self.a.z + self.r + zp
        } else {
            f64::INFINITY
        }
    }

    /// X range on row y of the band |n.(q - a)| <= r whose position along
    /// the move lies in [-before, |d| + after] (mm).
    pub fn strip_span(&self, y: f64, before: f64, after: f64) -> Option<(f64, f64)> {
        if self.axy <= 1e-18 {
            return None;
        }
        let len = self.axy.sqrt();
        let (ux, uy) = (self.d.x / len, self.d.y / len);
        let wy = y - self.a.y;
        // lo <= k x' + c <= hi with x' = x - a.x
        let lin = |k: f64, c: f64, lo: f64, hi: f64| -> Option<(f64, f64)> {
            if k.abs() < 1e-12 {
                return (lo..=hi)
                    .contains(&c)
                    .then_some((f64::NEG_INFINITY, f64::INFINITY));
            }
            let (p, q) = ((lo - c) / k, (hi - c) / k);
            Some((p.min(q), p.max(q)))
        };
        let (l1, h1) = lin(-uy, ux * wy, -self.r, self.r)?;
        let (l2, h2) = lin(ux, uy * wy, -before, len + after)?;
        let (l, h) = (l1.max(l2), h1.min(h2));
        (l <= h).then_some((l + self.a.x, h + self.a.x))
    }

    /// X range on row y of the disc of radius r around the point at t.
    pub fn disc_span(&self, y: f64, t: f64) -> Option<(f64, f64)> {
        let (cx, cy) = (self.a.x + t * self.d.x, self.a.y + t * self.d.y);
        let h = self.r * self.r - (y - cy) * (y - cy);
        (h >= 0.0).then(|| (cx - h.sqrt(), cx + h.sqrt()))
    }

    /// X range (mm) of the row y where the tool's XY footprint of this move
    /// lies: the capsule of radius r around the move's XY projection.
    pub fn row_span(&self, y: f64) -> Option<(f64, f64)> {
        let parts = [
            self.disc_span(y, 0.0),
            self.disc_span(y, 1.0),
            self.strip_span(y, 0.0, 0.0),
        ];
        parts
            .into_iter()
            .flatten()
            .reduce(|a, b| (a.0.min(b.0), a.1.max(b.1)))
    }
}
