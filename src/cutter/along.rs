//! A ball's or flat end mill's exact drop-cutter along a straight move,
//! one surface feature at a time: how far the CL surface rises over the
//! move's tip path p(t) = a + t (b - a), t in [0, 1], at its highest.
//!
//! Over one feature that rise is concave in t (for a ball a sphere about
//! a vertex, a cylinder about an edge, a plane offset from a facet, each
//! seen along a line; for a flat a vertex's height, the edge's highest
//! point inside the disc, linear plus the square root of a concave
//! quadratic, or a facet's highest point on the rim; minus the move's
//! own straight rise), so its highest is the stationary point where that
//! lies on the feature, found in closed form, else at an end of the
//! stretch where the feature holds the tool; an edge's stretch ends where
//! its contact reaches a vertex, whose own rise covers that.
//! `HeightField::rise_along` takes the highest over every feature of
//! every cell the tool reaches.

use crate::tool::Tool;
use glam::DVec3;

/// The tools whose rise along a move is found exactly here: a ball's
/// sphere or a flat's disc, of radius r.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Bottom {
    Ball(f64),
    Flat(f64),
}

impl Bottom {
    pub fn of(tool: &Tool) -> Option<Bottom> {
        match *tool {
            Tool::Ball { d } => Some(Bottom::Ball(d / 2.0)),
            Tool::Flat { d } => Some(Bottom::Flat(d / 2.0)),
            _ => None,
        }
    }

    pub fn radius(self) -> f64 {
        match self {
            Bottom::Ball(r) | Bottom::Flat(r) => r,
        }
    }

    /// How much lower than its tip the tool is at distance sqrt(d2)
    /// from its axis, at least (a ball's parabola; a flat's disc is level).
    #[inline]
    pub fn below(self, d2: f64) -> f64 {
        match self {
            Bottom::Ball(r) => d2 / (2.0 * r),
            Bottom::Flat(_) => 0.0,
        }
    }

    /// How far above a plane of slope sqrt(g2), at its axis, the tool's
    /// tip sits when it touches the plane.
    #[inline]
    pub fn lift(self, g2: f64) -> f64 {
        match self {
            Bottom::Ball(r) => r * ((1.0 + g2).sqrt() - 1.0),
            Bottom::Flat(r) => r * g2.sqrt(),
        }
    }
}

/// The move's tip path: start and direction (b - a).
#[derive(Clone, Copy)]
pub struct Path {
    pub a: DVec3,
    pub d: DVec3,
}

impl Path {
    /// The ball's rise over the path at vertex v, at its highest: with
    /// rho(t) the axis' distance from v, the tip is held at v.z - r +
    /// sqrt(r^2 - rho^2) while rho <= r.
    pub fn vertex(&self, r: f64, v: [f64; 3]) -> f64 {
        let (wx, wy) = (self.a.x - v[0], self.a.y - v[1]);
        let (dx, dy, m) = (self.d.x, self.d.y, self.d.z);
        let alpha = dx * dx + dy * dy;
        let rise = |t: f64| {
            let (x, y) = (wx + t * dx, wy + t * dy);
            let s = r * r - x * x - y * y;
            if s < 0.0 {
                f64::NEG_INFINITY
            } else {
                v[2] - r + s.sqrt() - (self.a.z + m * t)
            }
        };
        if alpha < 1e-18 {
            return rise(0.0).max(rise(1.0));
        }
        // the rise is stationary at t0 - m r' / sqrt(alpha (alpha + m^2))
        let Some((t0, r1, lo, hi)) = self.in_reach(r, v) else {
            return f64::NEG_INFINITY;
        };
        let t = (t0 - m * r1.sqrt() / (alpha * (alpha + m * m)).sqrt()).clamp(lo, hi);
        rise(t)
    }

    /// Where the axis passes within r of vertex v: with rho^2 = alpha
    /// (t - t0)^2 + rho0^2, the closest t0, r'^2 = r^2 - rho0^2, and the
    /// stretch [lo, hi] of [0, 1] in reach, where |t - t0| is at most
    /// r' / sqrt(alpha). A move with no XY travel is in reach all along
    /// or nowhere.
    fn in_reach(&self, r: f64, v: [f64; 3]) -> Option<(f64, f64, f64, f64)> {
        let (wx, wy) = (self.a.x - v[0], self.a.y - v[1]);
        let (dx, dy) = (self.d.x, self.d.y);
        let alpha = dx * dx + dy * dy;
        if alpha < 1e-18 {
            let r1 = r * r - wx * wx - wy * wy;
            return (r1 >= 0.0).then_some((0.0, r1, 0.0, 1.0));
        }
        let t0 = -(wx * dx + wy * dy) / alpha;
        let rho0 = (wx + t0 * dx).powi(2) + (wy + t0 * dy).powi(2);
        let r1 = r * r - rho0;
        if r1 < 0.0 {
            return None;
        }
        let half = (r1 / alpha).sqrt();
        let (lo, hi) = ((t0 - half).max(0.0), (t0 + half).min(1.0));
        (lo <= hi).then_some((t0, r1, lo, hi))
    }

    /// The ball's rise over the path at the edge p -> q (not vertical),
    /// at its highest where its contact lies between p and q (beyond
    /// them, the vertices hold the ball).
    pub fn edge(&self, r: f64, p: [f64; 3], q: [f64; 3]) -> f64 {
        let Some(e) = self.edge_view(p, q) else {
            return f64::NEG_INFINITY;
        };
        let (ez, a2, (s0, s1), (q0, q1, q2)) = (e.ez, e.a2, e.s, e.w2);
        let l2 = a2 + ez * ez;
        let m = self.d.z;
        // the ball's centre at height p.z + h over the axis at t touches
        // the edge's line where A h^2 - 2 B(t) h + C(t) = 0, B = ez s,
        // s = w . e (w from p to the axis), C = l2 |w|^2 - s^2 - r^2 l2
        let (c0, c1, c2) = (
            l2 * q0 - s0 * s0 - r * r * l2,
            2.0 * (l2 * q1 - s0 * s1),
            l2 * q2 - s1 * s1,
        );
        // the upper root at t, if the ball reaches the line there and
        // touches it between p and q
        let height = |t: f64| -> Option<f64> {
            let b = ez * (s0 + s1 * t);
            let c = c0 + t * (c1 + t * c2);
            let disc = b * b - a2 * c;
            if disc < 0.0 {
                return None;
            }
            let h = (b + disc.sqrt()) / a2;
            let u = (s0 + s1 * t + h * ez) / l2;
            (0.0..=1.0).contains(&u).then_some(h)
        };
        let rise = |t: f64, h: f64| p[2] + h - r - (self.a.z + m * t);
        let mut best = f64::NEG_INFINITY;
        for t in [0.0, 1.0] {
            if let Some(h) = height(t) {
                best = best.max(rise(t, h));
            }
        }
        // stationary: F_t + m F_h = 0, which makes h linear in t,
        // h (m A - ez s1) = k0 + k1 t; then F = 0 is a quadratic in t
        let den = m * a2 - ez * s1;
        let k0 = m * ez * s0 - 0.5 * c1;
        let k1 = m * ez * s1 - c2;
        let mut ts = [f64::NAN; 2];
        if den.abs() < 1e-15 {
            if k1.abs() > 1e-15 {
                ts[0] = -k0 / k1;
            }
        } else {
            let (h0, h1) = (k0 / den, k1 / den);
            let qa = a2 * h1 * h1 - 2.0 * ez * s1 * h1 + c2;
            let qb = 2.0 * a2 * h0 * h1 - 2.0 * ez * (s0 * h1 + s1 * h0) + c1;
            let qc = a2 * h0 * h0 - 2.0 * ez * s0 * h0 + c0;
            ts = quadratic(qa, qb, qc);
        }
        for t in ts {
            if (0.0..=1.0).contains(&t) {
                if let Some(h) = height(t) {
                    best = best.max(rise(t, h));
                }
            }
        }
        best
    }

    /// The rise over the path at vertex v of a ball (`vertex`) or a flat
    /// (`flat_vertex`).
    pub fn vertex_by(&self, bottom: Bottom, v: [f64; 3]) -> f64 {
        match bottom {
            Bottom::Ball(r) => self.vertex(r, v),
            Bottom::Flat(r) => self.flat_vertex(r, v),
        }
    }

    /// The rise over the path at the edge p -> q of a ball (`edge`) or a
    /// flat (`flat_edge`).
    pub fn edge_by(&self, bottom: Bottom, p: [f64; 3], q: [f64; 3]) -> f64 {
        match bottom {
            Bottom::Ball(r) => self.edge(r, p, q),
            Bottom::Flat(r) => self.flat_edge(r, p, q),
        }
    }

    /// A flat's rise over the path at vertex v: the tip is held at v.z
    /// while the axis is within r of v, so the rise is linear there and
    /// highest at an end of that stretch.
    pub fn flat_vertex(&self, r: f64, v: [f64; 3]) -> f64 {
        match self.in_reach(r, v) {
            // v.z - (a.z + m t) falls as t grows where the move climbs
            Some((_, _, lo, hi)) => {
                v[2] - (self.a.z + self.d.z * if self.d.z > 0.0 { lo } else { hi })
            }
            None => f64::NEG_INFINITY,
        }
    }

    /// A flat's rise over the path at the edge p -> q, where the edge's
    /// highest point inside the disc lies between p and q (else a vertex
    /// holds the tool). With w(t) the axis less p and e = q - p in XY,
    /// the disc holds the edge's line for u in (s -+ sqrt(D)) / |e|^2,
    /// s = w . e, D = s^2 - |e|^2 (|w|^2 - r^2), a concave quadratic in
    /// t; the highest point is the uphill end, so the tip is held at
    /// p.z + ez (s + sign(ez) sqrt(D)) / |e|^2: linear plus a concave
    /// root, highest where its derivative vanishes (a quadratic) or at
    /// an end of its stretch (t = 0, 1, or D = 0 on a level edge).
    pub fn flat_edge(&self, r: f64, p: [f64; 3], q: [f64; 3]) -> f64 {
        let Some(e) = self.edge_view(p, q) else {
            return f64::NEG_INFINITY;
        };
        let (ez, a2, (s0, s1), (q0, q1, q2)) = (e.ez, e.a2, e.s, e.w2);
        let m = self.d.z;
        let (d0, d1, d2) = (
            s0 * s0 - a2 * (q0 - r * r),
            2.0 * (s0 * s1 - a2 * q1),
            (s1 * s1 - a2 * q2).min(0.0),
        );
        let sign = if ez < 0.0 { -1.0 } else { 1.0 };
        // the rise at t, if the disc reaches the line and its uphill end
        // lies between p and q; `on_rim`: D is 0 there by construction
        let rise = |t: f64, on_rim: bool| -> f64 {
            if !(0.0..=1.0).contains(&t) {
                return f64::NEG_INFINITY;
            }
            let d = if on_rim { 0.0 } else { d0 + t * (d1 + t * d2) };
            if d < 0.0 {
                return f64::NEG_INFINITY;
            }
            let s = s0 + s1 * t;
            let u = (s + sign * d.sqrt()) / a2;
            if !(0.0..=1.0).contains(&u) {
                return f64::NEG_INFINITY;
            }
            p[2] + ez * u - (self.a.z + m * t)
        };
        let mut best = rise(0.0, false).max(rise(1.0, false));
        for t in quadratic(d2, d1, d0) {
            best = best.max(rise(t, true));
        }
        // f = L t + K sqrt(D) + const: f' = 0 where K^2 D'^2 = 4 L^2 D
        let (l, k) = (ez * s1 / a2 - m, ez.abs() / a2);
        let (k2, l2) = (k * k, l * l);
        let ts = quadratic(
            4.0 * d2 * (k2 * d2 - l2),
            4.0 * d1 * (k2 * d2 - l2),
            k2 * d1 * d1 - 4.0 * l2 * d0,
        );
        for t in ts {
            best = best.max(rise(t, false));
        }
        best
    }

    /// The tool's rise over the path at the facet through o with slopes
    /// (gx, gy), where its contact lies inside the triangle: `inside`
    /// gives the triangle's three edge functions at a point, each >= 0
    /// inside and affine in the point. A ball touches a plane r / q
    /// uphill of its axis (q = sqrt(1 + g^2)), a flat on its rim (at its
    /// axis where the plane is level).
    pub fn facet(
        &self,
        bottom: Bottom,
        o: [f64; 3],
        (gx, gy): (f64, f64),
        inside: impl Fn(f64, f64) -> [f64; 3],
    ) -> f64 {
        let g2 = gx * gx + gy * gy;
        let k = match bottom {
            Bottom::Ball(r) => r / (1.0 + g2).sqrt(),
            Bottom::Flat(r) if g2 > 0.0 => r / g2.sqrt(),
            Bottom::Flat(_) => 0.0,
        };
        let lift = bottom.lift(g2);
        // the contact and the tip's rise over the path, both affine in t
        let contact = |t: f64| {
            (
                self.a.x + t * self.d.x + k * gx,
                self.a.y + t * self.d.y + k * gy,
            )
        };
        let rise = |t: f64| {
            let (x, y) = (self.a.x + t * self.d.x, self.a.y + t * self.d.y);
            o[2] + gx * (x - o[0]) + gy * (y - o[1]) + lift - (self.a.z + t * self.d.z)
        };
        // clip [0, 1] to where all three edge functions stay >= 0
        let (e0, e1) = (contact(0.0), contact(1.0));
        let (f0, f1) = (inside(e0.0, e0.1), inside(e1.0, e1.1));
        let (mut lo, mut hi) = (0.0f64, 1.0f64);
        for k in 0..3 {
            let (u, v) = (f0[k], f1[k]);
            if u < 0.0 && v < 0.0 {
                return f64::NEG_INFINITY;
            }
            if u < 0.0 {
                lo = lo.max(u / (u - v));
            } else if v < 0.0 {
                hi = hi.min(u / (u - v));
            }
        }
        if lo > hi {
            return f64::NEG_INFINITY;
        }
        rise(lo).max(rise(hi))
    }
}

/// An edge p -> q (e = q - p) seen from a path: with w(t) the axis less
/// p in XY, s(t) = w . e = s.0 + s.1 t and |w|^2 = w2.0 + 2 w2.1 t +
/// w2.2 t^2.
struct EdgeView {
    ez: f64,
    /// |e|^2 in XY.
    a2: f64,
    s: (f64, f64),
    w2: (f64, f64, f64),
}

impl Path {
    /// None for an edge with no XY extent (the lattice has none).
    fn edge_view(&self, p: [f64; 3], q: [f64; 3]) -> Option<EdgeView> {
        let (ex, ey, ez) = (q[0] - p[0], q[1] - p[1], q[2] - p[2]);
        let a2 = ex * ex + ey * ey;
        if a2 < 1e-18 {
            return None;
        }
        let (wx, wy) = (self.a.x - p[0], self.a.y - p[1]);
        let (dx, dy) = (self.d.x, self.d.y);
        Some(EdgeView {
            ez,
            a2,
            s: (wx * ex + wy * ey, dx * ex + dy * ey),
            w2: (wx * wx + wy * wy, wx * dx + wy * dy, dx * dx + dy * dy),
        })
    }
}

/// The real roots of a t^2 + b t + c (NaN where there are none).
fn quadratic(a: f64, b: f64, c: f64) -> [f64; 2] {
    if a.abs() < 1e-300 {
        return if b.abs() > 0.0 {
            [-c / b, f64::NAN]
        } else {
            [f64::NAN; 2]
        };
    }
    let disc = b * b - 4.0 * a * c;
    if disc < 0.0 {
        return [f64::NAN; 2];
    }
    // the stable pair: one root from the larger-magnitude sum
    let s = -0.5 * (b + b.signum() * disc.sqrt());
    if s == 0.0 {
        return [0.0, 0.0];
    }
    [s / a, c / s]
}
