//! A ball's exact drop-cutter along a straight move, one surface feature
//! at a time: how far the CL surface rises over the move's tip path
//! p(t) = a + t (b - a), t in [0, 1], at its highest.
//!
//! Over one feature that rise is concave in t (a sphere about a vertex,
//! a cylinder about an edge, a plane offset from a facet, each seen along
//! a line, minus the move's own straight rise), so its highest is the
//! stationary point where that lies on the feature, found in closed
//! form, else at an end of the stretch where the feature holds the ball;
//! an edge's stretch ends where its contact reaches a vertex, whose own
//! rise covers that. `HeightField::rise_along` takes the highest over
//! every feature of every cell the ball reaches.

use glam::DVec3;

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
        // rho^2 = alpha (t - t0)^2 + rho0^2; in reach while
        // |t - t0| <= half, and the rise is stationary at t0 - m r' /
        // sqrt(alpha (alpha + m^2)), r'^2 = r^2 - rho0^2
        let t0 = -(wx * dx + wy * dy) / alpha;
        let rho0 = (wx + t0 * dx).powi(2) + (wy + t0 * dy).powi(2);
        let r1 = r * r - rho0;
        if r1 < 0.0 {
            return f64::NEG_INFINITY;
        }
        let half = (r1 / alpha).sqrt();
        let (lo, hi) = ((t0 - half).max(0.0), (t0 + half).min(1.0));
        if lo > hi {
            return f64::NEG_INFINITY;
        }
        let t = (t0 - m * r1.sqrt() / (alpha * (alpha + m * m)).sqrt()).clamp(lo, hi);
        rise(t)
    }

    /// The ball's rise over the path at the edge p -> q (not vertical),
    /// at its highest where its contact lies between p and q (beyond
    /// them, the vertices hold the ball).
    pub fn edge(&self, r: f64, p: [f64; 3], q: [f64; 3]) -> f64 {
        let (ex, ey, ez) = (q[0] - p[0], q[1] - p[1], q[2] - p[2]);
        let a2 = ex * ex + ey * ey;
        if a2 < 1e-18 {
            return f64::NEG_INFINITY;
        }
        let l2 = a2 + ez * ez;
        let (w0x, w0y) = (self.a.x - p[0], self.a.y - p[1]);
        let (dx, dy, m) = (self.d.x, self.d.y, self.d.z);
        // the ball's centre at height p.z + h over the axis at t touches
        // the edge's line where A h^2 - 2 B(t) h + C(t) = 0, B = ez s,
        // s = w . e (w from p to the axis), C = l2 |w|^2 - s^2 - r^2 l2
        let (s0, s1) = (w0x * ex + w0y * ey, dx * ex + dy * ey);
        let (q0, q1, q2) = (
            w0x * w0x + w0y * w0y,
            w0x * dx + w0y * dy,
            dx * dx + dy * dy,
        );
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

    /// The ball's rise over the path at the facet through o with slopes
    /// (gx, gy), where its contact lies inside the triangle: `inside`
    /// gives the triangle's three edge functions at a point, each >= 0
    /// inside and affine in the point.
    pub fn facet(
        &self,
        r: f64,
        o: [f64; 3],
        (gx, gy): (f64, f64),
        inside: impl Fn(f64, f64) -> [f64; 3],
    ) -> f64 {
        let q = (1.0 + gx * gx + gy * gy).sqrt();
        let k = r / q;
        // the contact and the tip's rise over the path, both affine in t
        let contact = |t: f64| {
            (
                self.a.x + t * self.d.x + k * gx,
                self.a.y + t * self.d.y + k * gy,
            )
        };
        let rise = |t: f64| {
            let (x, y) = (self.a.x + t * self.d.x, self.a.y + t * self.d.y);
            o[2] + gx * (x - o[0]) + gy * (y - o[1]) + r * (q - 1.0) - (self.a.z + t * self.d.z)
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
