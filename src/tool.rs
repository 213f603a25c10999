//! Cutting tools. On a heightfield every axisymmetric tool is its radial
//! profile z(r): the height of the cutting surface above the tip at
//! distance r from the axis, for r up to the cutting radius.

use crate::bail;
use crate::error::Result;

#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
#[serde(tag = "shape", rename_all = "lowercase")]
pub enum Tool {
    /// Ball end of diameter d.
    Ball { d: f64 },
    /// Flat end of diameter d.
    Flat { d: f64 },
    /// Tapered ball nose: tip radius, half angle of the taper (degrees),
    /// cutting diameter at the top of the flutes.
    TaperBall { tip_r: f64, half_angle: f64, d: f64 },
    /// V-bit of included angle (degrees) and cutting diameter.
    VBit { angle: f64, d: f64 },
}

/// Sine, cosine and tangent of an angle.
#[derive(Clone, Copy)]
struct Trig {
    sin: f64,
    cos: f64,
    tan: f64,
}

/// `Trig` of `deg` degrees. A job asks a V's or tapered ball's profile
/// millions of times with one angle (the trigonometry took a fifth of a
/// tapered ball's toolpath), so each thread keeps the last answer.
fn trig(deg: f64) -> Trig {
    use std::cell::Cell;
    thread_local! {
        static LAST: Cell<(u64, Trig)> = const {
            Cell::new((0, Trig { sin: 0.0, cos: 1.0, tan: 0.0 }))
        };
    }
    LAST.with(|last| {
        let (key, t) = last.get();
        if key == deg.to_bits() {
            return t;
        }
        let a = deg.to_radians();
        let t = Trig {
            sin: a.sin(),
            cos: a.cos(),
            tan: a.tan(),
        };
        last.set((deg.to_bits(), t));
        t
    })
}

/// Default cutting diameter of V-bits and tapered tools (1/4" shank).
pub const DEFAULT_SHANK: f64 = 6.35;

impl Tool {
    /// Parse `ball:D`, `flat:D`, `taperball:TIP_RADIUS:HALF_ANGLE[:D]`,
    /// `vbit:ANGLE[:D]` (mm, degrees).
    pub fn parse(spec: &str) -> Result<Tool> {
        let parts: Vec<&str> = spec.split(':').collect();
        let nums: Vec<f64> = match parts[1..]
            .iter()
            .map(|p| p.trim().parse::<f64>())
            .collect::<std::result::Result<_, _>>()
        {
            Ok(v) => v,
            Err(_) => bail!("{spec}: numbers expected after the shape, e.g. ball:3.175"),
        };
        let ok = |v: f64, lo: f64, hi: f64| v.is_finite() && v > lo && v < hi;
        let tool = match (parts[0].to_ascii_lowercase().as_str(), nums.as_slice()) {
            ("ball", [d]) => Tool::Ball { d: *d },
            ("flat", [d]) => Tool::Flat { d: *d },
            ("taperball", [r, a]) => Tool::TaperBall { tip_r: *r, half_angle: *a, d: DEFAULT_SHANK },
            ("taperball", [r, a, d]) => Tool::TaperBall { tip_r: *r, half_angle: *a, d: *d },
            ("vbit", [a]) => Tool::VBit { angle: *a, d: DEFAULT_SHANK },
            ("vbit", [a, d]) => Tool::VBit { angle: *a, d: *d },
            _ => bail!("{spec}: expected ball:D, flat:D, taperball:TIP_RADIUS:HALF_ANGLE[:D] or vbit:ANGLE[:D]"),
        };
        let valid = match tool {
            Tool::Ball { d } | Tool::Flat { d } => ok(d, 0.0, 100.0),
            Tool::TaperBall {
                tip_r,
                half_angle,
                d,
            } => ok(tip_r, 0.0, d / 2.0) && ok(half_angle, 0.0, 60.0) && ok(d, 0.0, 100.0),
            Tool::VBit { angle, d } => ok(angle, 0.0, 180.0) && ok(d, 0.0, 100.0),
        };
        if !valid {
            bail!("{spec}: size or angle out of range");
        }
        Ok(tool)
    }

    /// Cutting radius (mm).
    pub fn radius(&self) -> f64 {
        match *self {
            Tool::Ball { d }
            | Tool::Flat { d }
            | Tool::TaperBall { d, .. }
            | Tool::VBit { d, .. } => d / 2.0,
        }
    }

    /// Height of the cutting surface above the tip at distance r (mm);
    /// infinite beyond the cutting radius.
    pub fn profile(&self, r: f64) -> f64 {
        if r > self.radius() {
            return f64::INFINITY;
        }
        match *self {
            Tool::Ball { d } => {
                let rr = d / 2.0;
                rr - (rr * rr - r * r).max(0.0).sqrt()
            }
            Tool::Flat { .. } => 0.0,
            Tool::VBit { angle, .. } => r / trig(angle / 2.0).tan,
            Tool::TaperBall {
                tip_r, half_angle, ..
            } => {
                let a = trig(half_angle);
                let r0 = tip_r * a.cos;
                if r <= r0 {
                    tip_r - (tip_r * tip_r - r * r).max(0.0).sqrt()
                } else {
                    tip_r * (1.0 - a.sin) + (r - r0) / a.tan
                }
            }
        }
    }

    /// How far from its axis the tool's cutting surface stays within `h`
    /// of its tip (the farthest distance whose profile is at most h, a
    /// hair more); None when h < 0, where it reaches nothing.
    pub fn reach(&self, h: f64) -> Option<f64> {
        if h < 0.0 {
            return None;
        }
        let r = self.radius();
        if self.profile(r) <= h {
            return Some(r);
        }
        let rho = match *self {
            Tool::Ball { d } => (h * (d - h)).max(0.0).sqrt(),
            Tool::Flat { .. } => r,
            Tool::VBit { angle, .. } => h * trig(angle / 2.0).tan,
            Tool::TaperBall {
                tip_r, half_angle, ..
            } => {
                // the tip sphere up to r0, then the cone (`profile`)
                let a = trig(half_angle);
                let (r0, h0) = (tip_r * a.cos, tip_r * (1.0 - a.sin));
                if h <= h0 {
                    (h * (2.0 * tip_r - h)).max(0.0).sqrt()
                } else {
                    r0 + (h - h0) * a.tan
                }
            }
        };
        Some((rho * (1.0 + 1e-9) + 1e-9).min(r))
    }

    /// A V's or tapered ball's cone: its slope k (rise per mm out), the
    /// radius r0 where a tapered ball's tip sphere meets it, and c0, so
    /// that past r0 the profile is c0 + k rho (None for a ball or flat).
    pub fn cone(&self) -> Option<(f64, f64, f64)> {
        match *self {
            Tool::VBit { angle, .. } => Some((1.0 / trig(angle / 2.0).tan, 0.0, 0.0)),
            Tool::TaperBall {
                tip_r, half_angle, ..
            } => {
                let a = trig(half_angle);
                let (k, r0) = (1.0 / a.tan, tip_r * a.cos);
                Some((k, r0, tip_r * (1.0 - a.sin) - r0 * k))
            }
            _ => None,
        }
    }

    /// The profile at sqrt(d2) from the axis (infinite beyond the
    /// radius): for a ball one square root instead of two.
    #[inline]
    pub fn profile_sq(&self, d2: f64) -> f64 {
        match *self {
            Tool::Ball { d } => {
                let rr = d / 2.0;
                if d2 > rr * rr {
                    f64::INFINITY
                } else {
                    rr - (rr * rr - d2).sqrt()
                }
            }
            _ => self.profile(d2.sqrt()),
        }
    }

    /// A lower bound of the profile at sqrt(d2) from the axis, cheap
    /// enough for pruning: for a ball its osculating paraboloid, which
    /// lies inside the sphere.
    #[inline]
    pub fn profile_below(&self, d2: f64) -> f64 {
        match *self {
            Tool::Ball { d } => d2 / d,
            Tool::Flat { .. } => 0.0,
            _ => self.profile(d2.sqrt()),
        }
    }

    /// Distance from the axis at which the tool, lowered onto a plane
    /// rising `g` (mm per mm), touches it first: where the profile's slope
    /// equals g, else the rim. The profile is convex, so this is the one
    /// maximum of plane - profile along the plane's steepest direction.
    #[inline]
    pub fn facet_radius(&self, g: f64) -> f64 {
        let r = self.radius();
        match *self {
            Tool::Ball { .. } => r * g / (1.0 + g * g).sqrt(),
            Tool::Flat { .. } => {
                if g > 0.0 {
                    r
                } else {
                    0.0
                }
            }
            Tool::VBit { angle, .. } => {
                if g > 1.0 / trig(angle / 2.0).tan {
                    r
                } else {
                    0.0
                }
            }
            Tool::TaperBall {
                tip_r, half_angle, ..
            } => {
                if g <= 1.0 / trig(half_angle).tan {
                    tip_r * g / (1.0 + g * g).sqrt()
                } else {
                    r
                }
            }
        }
    }

    /// Where along a straight edge the tool touches it first: the edge
    /// passes `d` from the axis and rises `m` (mm per mm); the answer is
    /// the offset from the edge's nearest point to the axis, +-inf for
    /// "at the end of the reach". Two candidates (a tapered ball's sphere
    /// and cone regimes; the others repeat one); the caller clamps them to
    /// the edge and keeps the higher contact.
    #[inline]
    pub fn edge_offsets(&self, m: f64, d: f64) -> [f64; 2] {
        let sphere = |rr: f64| m * (rr * rr - d * d).max(0.0).sqrt() / (1.0 + m * m).sqrt();
        let cone = |k: f64| {
            if m.abs() < k {
                m * d / (k * k - m * m).sqrt()
            } else {
                m.signum() * f64::INFINITY
            }
        };
        match *self {
            Tool::Ball { d: dia } => {
                let u = sphere(dia / 2.0);
                [u, u]
            }
            Tool::Flat { .. } => {
                let u = if m == 0.0 {
                    0.0
                } else {
                    m.signum() * f64::INFINITY
                };
                [u, u]
            }
            Tool::VBit { angle, .. } => {
                let u = cone(1.0 / trig(angle / 2.0).tan);
                [u, u]
            }
            Tool::TaperBall {
                tip_r, half_angle, ..
            } => [sphere(tip_r), cone(1.0 / trig(half_angle).tan)],
        }
    }

    /// Largest curvature (Hessian norm of profile(|p - axis|) over p) of
    /// the cutting surface between `lo` and `hi` from the axis (both
    /// within the radius); +inf at a V point. Bounds how far the tool can
    /// sink into a triangle below what its corners hold it at.
    #[inline]
    pub fn curvature_bound(&self, lo: f64, hi: f64) -> f64 {
        let sphere = |rr: f64, h: f64| {
            let q = (rr * rr - h * h).max(0.0);
            rr * rr / (q * q.sqrt())
        };
        match *self {
            Tool::Ball { d } => sphere(d / 2.0, hi),
            Tool::Flat { .. } => 0.0,
            Tool::VBit { angle, .. } => 1.0 / (trig(angle / 2.0).tan * lo),
            Tool::TaperBall {
                tip_r, half_angle, ..
            } => {
                let a = trig(half_angle);
                let r0 = tip_r * a.cos;
                let s = if lo <= r0 {
                    sphere(tip_r, hi.min(r0))
                } else {
                    0.0
                };
                let c = if hi >= r0 {
                    1.0 / (a.tan * lo.max(r0))
                } else {
                    0.0
                };
                s.max(c)
            }
        }
    }

    /// Width of the cutting surface at `depth` above the tip (mm): the
    /// widest cut the tool makes that deep.
    pub fn width_at(&self, depth: f64) -> f64 {
        let r = self.radius();
        if self.profile(r) <= depth || depth.is_nan() {
            return 2.0 * r;
        }
        let (mut lo, mut hi) = (0.0, r);
        for _ in 0..40 {
            let mid = 0.5 * (lo + hi);
            if self.profile(mid) > depth {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        2.0 * lo
    }

    /// Diameter the stepover, the scallop and the cutting data go by: the
    /// tip's for a tapered ball (its shank never touches a finished
    /// surface), the cutting diameter otherwise.
    pub fn working_diameter(&self) -> f64 {
        match *self {
            Tool::TaperBall { tip_r, .. } => 2.0 * tip_r,
            t => 2.0 * t.radius(),
        }
    }

    /// A ball end mill.
    pub fn is_ball(&self) -> bool {
        matches!(self, Tool::Ball { .. })
    }

    /// A flat end mill.
    pub fn is_flat(&self) -> bool {
        matches!(self, Tool::Flat { .. })
    }

    /// A V-bit: a sharp point, its CL surface creased.
    pub fn is_vbit(&self) -> bool {
        matches!(self, Tool::VBit { .. })
    }

    /// The radius of a rounded tip (a ball's, a tapered ball's), which
    /// leaves scallops and a CL surface without creases; None for a flat
    /// end or a V-bit.
    pub fn tip_radius(&self) -> Option<f64> {
        match *self {
            Tool::Ball { d } => Some(d / 2.0),
            Tool::TaperBall { tip_r, .. } => Some(tip_r),
            _ => None,
        }
    }

    /// The same kind of end mill, `by` mm wider all round (a roughing
    /// tool that leaves stock to the finish); None for a tool other than a
    /// flat or ball end mill.
    pub fn grown(&self, by: f64) -> Option<Tool> {
        match *self {
            Tool::Flat { d } => Some(Tool::Flat { d: d + 2.0 * by }),
            Tool::Ball { d } => Some(Tool::Ball { d: d + 2.0 * by }),
            _ => None,
        }
    }

    /// The spec string that parses back to this tool.
    pub fn spec(&self) -> String {
        match *self {
            Tool::Ball { d } => format!("ball:{d}"),
            Tool::Flat { d } => format!("flat:{d}"),
            Tool::TaperBall {
                tip_r,
                half_angle,
                d,
            } => format!("taperball:{tip_r}:{half_angle}:{d}"),
            Tool::VBit { angle, d } => format!("vbit:{angle}:{d}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `reach` is the profile's inverse: a micron nearer the axis the
    /// profile is at most h, a micron farther out above it (unless the
    /// whole tool is within h); nothing below the tip.
    #[test]
    fn reach_inverts_the_profile() {
        for s in [
            "ball:3.175",
            "flat:6",
            "taperball:0.25:5:3.175",
            "taperball:0.5:10",
            "vbit:60:6.35",
            "vbit:90:3",
        ] {
            let t = Tool::parse(s).unwrap();
            assert_eq!(t.reach(-1e-9), None);
            for k in 0..=400 {
                let h = 0.05 * k as f64;
                let rho = t.reach(h).unwrap();
                if rho >= 1e-6 {
                    assert!(t.profile(rho - 1e-6) <= h, "{s} h {h}: reach {rho} long");
                }
                if rho < t.radius() {
                    assert!(t.profile(rho + 1e-6) > h, "{s} h {h}: reach {rho} short");
                }
            }
        }
    }

    #[test]
    fn specs_round_trip_and_profiles_are_continuous() {
        for s in [
            "ball:3.175",
            "flat:6",
            "taperball:0.25:5:3.175",
            "vbit:60:6.35",
        ] {
            let t = Tool::parse(s).unwrap();
            assert_eq!(Tool::parse(&t.spec()).unwrap(), t);
            let mut prev = t.profile(0.0);
            assert_eq!(prev, 0.0);
            for k in 1..=1000 {
                let z = t.profile(t.radius() * k as f64 / 1000.0);
                assert!(z >= prev - 1e-12 && z - prev < 0.2, "{s} at {k}");
                prev = z;
            }
        }
        assert!(
            Tool::parse("ball").is_err()
                && Tool::parse("ball:-1").is_err()
                && Tool::parse("drill:3").is_err()
        );
    }
}
