//! Arcs as GRBL 1.1 takes and runs them: the plane's axes (G17 XY, G18
//! ZX, G19 YZ, each as GRBL orders them), the centre from I/J/K offsets or
//! from R with GRBL's refusals, and the chords GRBL's `mc_arc` cuts them
//! into (equal angles, end points on the circle, as many as `$12` arc
//! tolerance asks by GRBL's own formula). The simulator, the simulated GRBL
//! and the toolpath's arc fitting all use these chords, so what is checked
//! and judged is what the machine cuts.

use glam::DVec3;

/// GRBL's default `$12` arc tolerance (mm): the chords' sagitta target.
pub const GRBL_ARC_TOLERANCE: f64 = 0.002;

/// GRBL counts an arc's chords in a 16-bit integer.
pub const MAX_CHORDS: usize = u16::MAX as usize;

/// An arc plane: G17, G18 or G19.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Plane {
    Xy,
    Zx,
    Yz,
}

impl Plane {
    /// The G code that selects it.
    pub fn code(self) -> u8 {
        match self {
            Plane::Xy => 17,
            Plane::Zx => 18,
            Plane::Yz => 19,
        }
    }

    /// (axis 0, axis 1, linear axis) as GRBL orders them: G2 turns
    /// clockwise seen with axis 0 to the right and axis 1 up.
    pub fn axes(self) -> (usize, usize, usize) {
        match self {
            Plane::Xy => (0, 1, 2),
            Plane::Zx => (2, 0, 1),
            Plane::Yz => (1, 2, 0),
        }
    }
}

/// An arc's geometry once GRBL has accepted it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Arc {
    pub plane: Plane,
    pub clockwise: bool,
    /// Centre in the plane: (axis 0, axis 1), mm.
    pub centre: (f64, f64),
    /// Radius from the start point (GRBL's), mm.
    pub radius: f64,
}

/// GRBL's refusal codes for arcs.
pub const NO_AXIS_WORDS_IN_PLANE: u32 = 32;
pub const INVALID_TARGET: u32 = 33;
pub const ARC_RADIUS_ERROR: u32 = 34;
pub const NO_OFFSETS_IN_PLANE: u32 = 35;

/// The arc from `from` to `to` (mm) as GRBL's gc_execute_line sets it up:
/// `ijk` offsets (mm, None where the word is absent) or a radius `r`;
/// `in_plane` whether the line has an axis word of the plane. Errors are
/// GRBL's codes.
pub fn setup(
    plane: Plane,
    clockwise: bool,
    from: DVec3,
    to: DVec3,
    ijk: [Option<f64>; 3],
    r: Option<f64>,
    in_plane: bool,
) -> Result<Arc, (u32, String)> {
    let (a0, a1, _) = plane.axes();
    if !in_plane {
        return Err((
            NO_AXIS_WORDS_IN_PLANE,
            "arc with no axis word of its plane".into(),
        ));
    }
    let (x, y) = (to[a0] - from[a0], to[a1] - from[a1]);
    let (ox, oy) = match r {
        Some(r) => {
            // GRBL: the radius form; R < 0 takes the long way round
            if from == to {
                return Err((INVALID_TARGET, "R arc ending where it starts".into()));
            }
            let h = 4.0 * r * r - x * x - y * y;
            if h < 0.0 {
                return Err((
                    ARC_RADIUS_ERROR,
                    format!("arc radius R{r} is smaller than half the distance to the end point"),
                ));
            }
            let mut k = -h.sqrt() / x.hypot(y);
            if !clockwise {
                k = -k;
            }
            if r < 0.0 {
                k = -k;
            }
            (0.5 * (x - y * k), 0.5 * (y + x * k))
        }
        None => {
            if ijk[a0].is_none() && ijk[a1].is_none() {
                return Err((
                    NO_OFFSETS_IN_PLANE,
                    "arc with no offset in its plane".into(),
                ));
            }
            let (ox, oy) = (ijk[a0].unwrap_or(0.0), ijk[a1].unwrap_or(0.0));
            let start_r = ox.hypot(oy);
            let end_r = (x - ox).hypot(y - oy);
            let dr = (end_r - start_r).abs();
            if dr > 0.005 && (dr > 0.5 || dr > 0.001 * start_r) {
                return Err((
                    INVALID_TARGET,
                    format!(
                        "arc end point is not on the circle (radius {start_r:.4} at the start, \
                         {end_r:.4} at the end)"
                    ),
                ));
            }
            (ox, oy)
        }
    };
    Ok(Arc {
        plane,
        clockwise,
        centre: (from[a0] + ox, from[a1] + oy),
        radius: ox.hypot(oy),
    })
}

impl Arc {
    /// The signed angle GRBL travels from `from` to `to` (radians;
    /// negative clockwise), a full turn when they coincide.
    pub fn travel(&self, from: DVec3, to: DVec3) -> f64 {
        let (a0, a1, _) = self.plane.axes();
        let (r0, r1) = (from[a0] - self.centre.0, from[a1] - self.centre.1);
        let (t0, t1) = (to[a0] - self.centre.0, to[a1] - self.centre.1);
        let mut t = (r0 * t1 - r1 * t0).atan2(r0 * t0 + r1 * t1);
        const EPS: f64 = 5e-7; // GRBL's ARC_ANGULAR_TRAVEL_EPSILON
        if self.clockwise {
            if t >= -EPS {
                t -= std::f64::consts::TAU;
            }
        } else if t <= EPS {
            t += std::f64::consts::TAU;
        }
        t
    }

    /// How many chords GRBL cuts the arc into with arc tolerance `tol`
    /// (at least one).
    pub fn chords(&self, travel: f64, tol: f64) -> usize {
        let r = self.radius;
        let n = (0.5 * travel.abs() * r / (tol * (2.0 * r - tol)).max(1e-300).sqrt()).floor();
        (n.max(1.0) as usize).min(MAX_CHORDS)
    }

    /// The points GRBL moves through after `from`: chord ends on the
    /// circle at equal angles (the linear axis in equal steps), `to` last.
    pub fn points(&self, from: DVec3, to: DVec3, tol: f64) -> Vec<DVec3> {
        let (a0, a1, lin) = self.plane.axes();
        let travel = self.travel(from, to);
        let n = self.chords(travel, tol);
        let (r0, r1) = (from[a0] - self.centre.0, from[a1] - self.centre.1);
        let mut out = Vec::with_capacity(n);
        for k in 1..n {
            let t = travel * k as f64 / n as f64;
            let (s, c) = t.sin_cos();
            let mut p = from;
            p[a0] = self.centre.0 + r0 * c - r1 * s;
            p[a1] = self.centre.1 + r0 * s + r1 * c;
            p[lin] = from[lin] + (to[lin] - from[lin]) * k as f64 / n as f64;
            out.push(p);
        }
        out.push(to);
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn planes_turn_as_grbl_turns_them() {
        // G18: axis 0 is Z, axis 1 is X. From (X0, Z0) round the centre
        // (X5, Z0) to (X10, Z0): clockwise in (Z, X) passes through Z < 0
        let (a, b) = (DVec3::ZERO, DVec3::new(10.0, 0.0, 0.0));
        let arc = setup(
            Plane::Zx,
            true,
            a,
            b,
            [Some(5.0), None, Some(0.0)],
            None,
            true,
        )
        .unwrap();
        let pts = arc.points(a, b, GRBL_ARC_TOLERANCE);
        let mid = pts[pts.len() / 2];
        assert!(mid.z < -4.9 && (mid.x - 5.0).abs() < 0.3, "{mid:?}");
        // G17 clockwise from +x to -y about the origin
        let (a, b) = (DVec3::new(10.0, 0.0, 0.0), DVec3::new(0.0, -10.0, 0.0));
        let arc = setup(
            Plane::Xy,
            true,
            a,
            b,
            [Some(-10.0), Some(0.0), None],
            None,
            true,
        )
        .unwrap();
        assert!((arc.travel(a, b) + std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        // R form agrees with the offsets
        let by_r = setup(Plane::Xy, true, a, b, [None; 3], Some(10.0), true).unwrap();
        assert!((by_r.centre.0).abs() < 1e-9 && (by_r.centre.1).abs() < 1e-9);
    }

    #[test]
    fn chords_follow_grbls_formula() {
        let (a, b) = (DVec3::new(10.0, 0.0, 0.0), DVec3::new(-10.0, 0.0, -1.0));
        let arc = setup(
            Plane::Xy,
            false,
            a,
            b,
            [Some(-10.0), Some(0.0), None],
            None,
            true,
        )
        .unwrap();
        let pts = arc.points(a, b, 0.002);
        // floor(0.5 * pi * 10 / sqrt(0.002 * (20 - 0.002))) = 78
        assert_eq!(pts.len(), 78);
        let mut prev = a;
        for p in &pts {
            let m = (prev + *p) * 0.5;
            let sag = 10.0 - m.truncate().length();
            assert!((0.0..=0.0021).contains(&sag), "sagitta {sag}");
            prev = *p;
        }
        assert_eq!(*pts.last().unwrap(), b);
        assert!((pts[38].z + 0.5).abs() < 0.02, "helical: Z in equal steps");
    }

    #[test]
    fn refusals_carry_grbls_codes() {
        let (a, b) = (DVec3::ZERO, DVec3::new(10.0, 0.0, 0.0));
        let code = |p, ijk, r, inp| setup(p, true, a, b, ijk, r, inp).unwrap_err().0;
        assert_eq!(code(Plane::Xy, [None, None, Some(1.0)], None, true), 35);
        assert_eq!(code(Plane::Xy, [Some(1.0), None, None], None, true), 33);
        assert_eq!(code(Plane::Xy, [None; 3], Some(4.0), true), 34);
        assert_eq!(code(Plane::Xy, [Some(5.0), None, None], None, false), 32);
        assert_eq!(
            setup(Plane::Xy, true, a, a, [None; 3], Some(4.0), true)
                .unwrap_err()
                .0,
            33
        );
    }
}
