//! Camera: a view direction from presets plus yaw/pitch, perspective or
//! orthographic, with near/far fitted tightly around the scene. Projects
//! vertices to pixel coordinates and OpenGL-style depth h in [0,1]
//! (1 = nearest scene point, 0 = far plane = background).

use crate::bail;
use crate::error::Result;
use glam::DVec3;

/// Named view directions: where the eye sits as seen from the model.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum View {
    Front,
    Back,
    Left,
    Right,
    Top,
    Bottom,
}

impl View {
    /// (yaw, pitch) in degrees of this preset.
    pub fn angles(self) -> (f64, f64) {
        match self {
            View::Front => (0.0, 0.0),
            View::Back => (180.0, 0.0),
            View::Left => (-90.0, 0.0),
            View::Right => (90.0, 0.0),
            View::Top => (0.0, 90.0),
            View::Bottom => (0.0, -90.0),
        }
    }
}

/// Which model axis points up. Front is then the model's own front: +z for
/// y-up models (the OBJ and glTF habit), -y for z-up models (STL and CAD).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
pub enum Up {
    #[default]
    #[value(name = "y")]
    #[serde(rename = "y")]
    Y,
    #[value(name = "z")]
    #[serde(rename = "z")]
    Z,
    #[value(name = "-y")]
    #[serde(rename = "-y")]
    NegY,
    #[value(name = "-z")]
    #[serde(rename = "-z")]
    NegZ,
    #[value(name = "x")]
    #[serde(rename = "x")]
    X,
    #[value(name = "-x")]
    #[serde(rename = "-x")]
    NegX,
}

impl Up {
    /// The rotation from model coordinates to the y-up, +z-front frame the
    /// presets are defined in, as the images of the model's x, y, z axes.
    fn to_frame(self) -> [DVec3; 3] {
        let v = DVec3::new;
        match self {
            Up::Y => [DVec3::X, DVec3::Y, DVec3::Z],
            // (x, y, z) -> (x, z, -y): +z up, -y front
            Up::Z => [v(1.0, 0.0, 0.0), v(0.0, 0.0, -1.0), v(0.0, 1.0, 0.0)],
            // half a turn about z: -y up, +z front
            Up::NegY => [v(-1.0, 0.0, 0.0), v(0.0, -1.0, 0.0), DVec3::Z],
            // (x, y, z) -> (x, -z, y): -z up, +y front
            Up::NegZ => [v(1.0, 0.0, 0.0), v(0.0, 0.0, 1.0), v(0.0, -1.0, 0.0)],
            // a quarter turn about z: +x up, +z front
            Up::X => [v(0.0, 1.0, 0.0), v(-1.0, 0.0, 0.0), DVec3::Z],
            Up::NegX => [v(0.0, -1.0, 0.0), v(1.0, 0.0, 0.0), DVec3::Z],
        }
    }

    /// A vector of the preset frame in model coordinates (the inverse
    /// rotation: the transpose).
    fn to_model(self, f: DVec3) -> DVec3 {
        let [x, y, z] = self.to_frame();
        DVec3::new(x.dot(f), y.dot(f), z.dot(f))
    }

    /// The name `--up` takes.
    pub fn name(self) -> String {
        use clap::ValueEnum;
        self.to_possible_value()
            .map_or_else(String::new, |v| v.get_name().to_string())
    }
}

#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct Camera {
    pub view: View,
    /// Added to the preset's yaw (about +y), degrees.
    pub yaw: f64,
    /// Added to the preset's pitch (eye raised toward +y), degrees.
    pub pitch: f64,
    /// Full vertical/horizontal field of view in degrees; 0 = orthographic.
    pub fov: f64,
    /// The model's up axis.
    pub up: Up,
    /// Turn of the picture, counter-clockwise, degrees.
    pub roll: f64,
}

impl Default for Camera {
    fn default() -> Self {
        Camera {
            view: View::Front,
            yaw: 0.0,
            pitch: 0.0,
            fov: 20.0,
            up: Up::Y,
            roll: 0.0,
        }
    }
}

/// Vertices in pixel space of an image `w x h` pixels, with depth.
pub struct Projection {
    /// (x, y, h): x right, y down, in pixels; h in [0,1].
    pub points: Vec<[f64; 3]>,
    pub w: usize,
    pub h: usize,
    pub frame: Frame,
}

impl Camera {
    pub fn validate(&self) -> Result<()> {
        if !(0.0..=170.0).contains(&self.fov) || !self.fov.is_finite() {
            bail!(
                "--fov {}: must be between 0 (orthographic) and 170 degrees",
                self.fov
            );
        }
        if !self.yaw.is_finite() || !self.pitch.is_finite() || !self.roll.is_finite() {
            bail!("--yaw/--pitch/--roll must be finite numbers");
        }
        Ok(())
    }

    /// Eye direction e (from scene centre toward the eye), image right r
    /// and up u, in model coordinates.
    pub fn basis(&self) -> (DVec3, DVec3, DVec3) {
        let (y0, p0) = self.view.angles();
        let yaw = (y0 + self.yaw).to_radians();
        let pitch = (p0 + self.pitch).to_radians();
        let e = DVec3::new(
            yaw.sin() * pitch.cos(),
            pitch.sin(),
            yaw.cos() * pitch.cos(),
        );
        let r = DVec3::new(yaw.cos(), 0.0, -yaw.sin());
        let u = e.cross(r);
        let (s, c) = self.roll.to_radians().sin_cos();
        let (r, u) = (r * c - u * s, r * s + u * c);
        let m = |v: DVec3| self.up.to_model(v);
        (m(e), m(r), m(u))
    }

    /// Project `positions` into an image whose long side is `long_px`
    /// pixels times `supersample`; the frame hugs the scene with a small
    /// margin of background so every outline lies inside.
    pub fn project(&self, positions: &[DVec3], long_px: usize, supersample: usize) -> Projection {
        let f = self.frame(positions, long_px, supersample);
        Projection {
            points: positions.iter().map(|p| f.screen(*p)).collect(),
            w: f.w,
            h: f.h,
            frame: f,
        }
    }

    /// The fitted frame: how any point maps to the image.
    pub fn frame(&self, positions: &[DVec3], long_px: usize, supersample: usize) -> Frame {
        let (e, r, u) = self.basis();
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        for p in positions {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
        let c = (lo + hi) * 0.5;
        let radius = positions
            .iter()
            .map(|p| (*p - c).length())
            .fold(0.0, f64::max)
            .max(1e-30);
        let persp = self.fov > 0.0;
        let dist = if persp {
            radius / (self.fov.to_radians() * 0.5).sin()
        } else {
            radius
        };
        let mut f = Frame {
            c,
            e,
            r,
            u,
            dist,
            persp,
            radius,
            x0: 0.0,
            y1: 0.0,
            margin: 0.0,
            s: 1.0,
            near: 0.0,
            far: 1.0,
            flat: false,
            w: 0,
            h: 0,
        };
        let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        let (mut near, mut far) = (f64::MAX, f64::MIN);
        for p in positions {
            let v = f.view(*p);
            x0 = x0.min(v[0]);
            x1 = x1.max(v[0]);
            y0 = y0.min(v[1]);
            y1 = y1.max(v[1]);
            near = near.min(v[2]);
            far = far.max(v[2]);
        }
        let span = (x1 - x0).max(y1 - y0).max(1e-30);
        let margin = span * (0.02f64).max(2.5 / long_px as f64);
        let (ex, ey) = (x1 - x0 + 2.0 * margin, y1 - y0 + 2.0 * margin);
        let scale = long_px as f64 / ex.max(ey);
        let w = ((ex * scale).round() as usize).max(1);
        let h = ((ey * scale).round() as usize).max(1);
        f.x0 = x0;
        f.y1 = y1;
        f.margin = margin;
        f.s = scale * supersample as f64;
        f.near = near;
        f.far = far;
        f.flat = far - near <= 1e-9 * radius;
        f.w = w * supersample;
        f.h = h * supersample;
        f
    }
}

/// How the camera maps the scene to the image.
#[derive(Clone, Copy, Debug)]
pub struct Frame {
    c: DVec3,
    e: DVec3,
    r: DVec3,
    u: DVec3,
    dist: f64,
    persp: bool,
    /// Radius of the scene about its centre.
    pub radius: f64,
    x0: f64,
    y1: f64,
    margin: f64,
    s: f64,
    near: f64,
    far: f64,
    flat: bool,
    pub w: usize,
    pub h: usize,
}

impl Frame {
    /// (screen x, screen y, distance along the view axis).
    fn view(&self, p: DVec3) -> [f64; 3] {
        let d = p - self.c;
        let z = self.dist - d.dot(self.e);
        let (x, y) = (d.dot(self.r), d.dot(self.u));
        if self.persp {
            [x / z, y / z, z]
        } else {
            [x, y, z]
        }
    }

    /// (x right, y down, in pixels; depth h in [0,1], 1 = nearest).
    pub fn screen(&self, p: DVec3) -> [f64; 3] {
        let q = self.screen_unclamped(p);
        [q[0], q[1], q[2].clamp(0.0, 1.0)]
    }

    fn screen_unclamped(&self, p: DVec3) -> [f64; 3] {
        let v = self.view(p);
        let depth = if self.flat {
            1.0
        } else if self.persp {
            (1.0 / v[2] - 1.0 / self.far) / (1.0 / self.near - 1.0 / self.far)
        } else {
            (self.far - v[2]) / (self.far - self.near)
        };
        [
            (v[0] - self.x0 + self.margin) * self.s,
            (self.y1 + self.margin - v[1]) * self.s,
            depth,
        ]
    }

    /// Direction from `p` toward the eye.
    pub fn to_eye(&self, p: DVec3) -> DVec3 {
        if self.persp {
            self.c + self.e * self.dist - p
        } else {
            self.e
        }
    }

    /// The depth slope (h per pixel, x and y) of the plane through `p`
    /// with normal `n`, as the image sees it; `None` where the plane is
    /// seen edge-on or from behind.
    pub fn plane_slope(&self, p: DVec3, n: DVec3) -> Option<[f64; 2]> {
        let eye = self.to_eye(p);
        if self.flat || n.dot(eye) <= 1e-6 * n.length() * eye.length() {
            return None;
        }
        let n = n.normalize();
        let t1 = n.any_orthonormal_vector();
        let t2 = n.cross(t1);
        let eps = 1e-4 * self.radius;
        let q0 = self.screen_unclamped(p);
        let q1 = self.screen_unclamped(p + t1 * eps);
        let q2 = self.screen_unclamped(p + t2 * eps);
        let (dx1, dy1, dh1) = (q1[0] - q0[0], q1[1] - q0[1], q1[2] - q0[2]);
        let (dx2, dy2, dh2) = (q2[0] - q0[0], q2[1] - q0[1], q2[2] - q0[2]);
        let det = dx1 * dy2 - dx2 * dy1;
        let scale = (dx1 * dx1 + dy1 * dy1).max(dx2 * dx2 + dy2 * dy2);
        if det.abs() <= 1e-6 * scale {
            return None;
        }
        Some([(dh1 * dy2 - dh2 * dy1) / det, (dx1 * dh2 - dx2 * dh1) / det])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_are_orthonormal_and_right_handed() {
        for v in [
            View::Front,
            View::Back,
            View::Left,
            View::Right,
            View::Top,
            View::Bottom,
        ] {
            let cam = Camera {
                view: v,
                ..Default::default()
            };
            let (e, r, u) = cam.basis();
            assert!((e.length() - 1.0).abs() < 1e-12 && (r.length() - 1.0).abs() < 1e-12);
            assert!(e.dot(r).abs() < 1e-12 && e.dot(u).abs() < 1e-12 && r.dot(u).abs() < 1e-12);
            assert!((r.cross(u) - e).length() < 1e-12);
        }
        let (e, _, u) = Camera {
            view: View::Top,
            ..Default::default()
        }
        .basis();
        assert!((e - DVec3::Y).length() < 1e-12 && (u + DVec3::Z).length() < 1e-12);
    }

    #[test]
    fn up_axes_put_the_model_front_before_the_eye() {
        let cam = |up, roll| Camera {
            up,
            roll,
            ..Default::default()
        };
        // z-up: the eye on -y, the picture's up along +z
        let (e, r, u) = cam(Up::Z, 0.0).basis();
        assert!((e + DVec3::Y).length() < 1e-12 && (u - DVec3::Z).length() < 1e-12);
        assert!((r - DVec3::X).length() < 1e-12);
        for up in [Up::Y, Up::Z, Up::NegY, Up::NegZ, Up::X, Up::NegX] {
            let (e, r, u) = cam(up, 0.0).basis();
            assert!((r.cross(u) - e).length() < 1e-12, "{up:?} is a reflection");
            let axis = match up {
                Up::Y => DVec3::Y,
                Up::Z => DVec3::Z,
                Up::NegY => -DVec3::Y,
                Up::NegZ => -DVec3::Z,
                Up::X => DVec3::X,
                Up::NegX => -DVec3::X,
            };
            assert!((u - axis).length() < 1e-12, "{up:?}: picture up {u}");
        }
        // a quarter roll counter-clockwise: what was at the right is now on top
        let (_, r0, _) = cam(Up::Y, 0.0).basis();
        let (_, _, u1) = cam(Up::Y, 90.0).basis();
        assert!((u1 - r0).length() < 1e-12);
    }

    #[test]
    fn perspective_depth_is_one_at_nearest_zero_at_farthest() {
        let pts = [
            DVec3::new(0.0, 0.0, 1.0),
            DVec3::new(1.0, 1.0, -1.0),
            DVec3::ZERO,
        ];
        let pr = Camera::default().project(&pts, 64, 1);
        assert!((pr.points[0][2] - 1.0).abs() < 1e-12);
        assert!(pr.points[1][2].abs() < 1e-12);
        assert!(pr.points[2][2] > 0.0 && pr.points[2][2] < 1.0);
        assert_eq!(pr.w.max(pr.h), 64);
    }
}
