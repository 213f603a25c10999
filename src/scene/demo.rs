//! The built-in demo scene: the paper's inset of two crossed tubes over a
//! plane (outlines over outlines, a crossing without contact), beside Spot
//! the cow (Keenan Crane, public domain) pressed against the same plane.

use super::mesh::{read_obj, Mesh};
use glam::{Mat4, Quat, Vec3};

const SPOT_OBJ: &str = include_str!("../../fixtures/spot.obj");

/// A closed cylinder from `a` to `b`.
pub fn tube(a: Vec3, b: Vec3, r: f32, segments: u32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let axis = (b - a).normalize();
    let u = axis.any_orthonormal_vector();
    let v = axis.cross(u);
    let mut p = vec![a, b];
    for k in 0..segments {
        let t = k as f32 / segments as f32 * std::f32::consts::TAU;
        let off = (u * t.cos() + v * t.sin()) * r;
        p.push(a + off);
        p.push(b + off);
    }
    let mut t = Vec::new();
    for k in 0..segments {
        let (i0, i1) = (2 + 2 * k, 2 + 2 * ((k + 1) % segments));
        t.push([i0, i1, i0 + 1]);
        t.push([i1, i1 + 1, i0 + 1]);
        t.push([0, i1, i0]);
        t.push([1, i0 + 1, i1 + 1]);
    }
    (p, t)
}

/// Two crossed tubes over a plane (the paper's inset), centred at x = `cx`.
pub fn crossed_tubes(cx: f32) -> Mesh {
    let mut m = Mesh::default();
    let plane = [
        Vec3::new(-2.1, -1.3, 0.0),
        Vec3::new(2.4, -1.3, 0.0),
        Vec3::new(2.4, 1.3, 0.0),
        Vec3::new(-2.1, 1.3, 0.0),
    ];
    m.push_object("plane", &plane, &[[0, 1, 2], [0, 2, 3]]);
    let r = 0.16;
    let (p, t) = tube(
        Vec3::new(cx - 0.8, -0.9, r),
        Vec3::new(cx + 0.8, 0.9, r),
        r,
        64,
    );
    m.push_object("tube_lower", &p, &t);
    // the upper tube crosses over the lower one without touching it
    let (p, t) = tube(
        Vec3::new(cx - 0.8, 0.9, 3.2 * r),
        Vec3::new(cx + 0.8, -0.9, 3.2 * r),
        r,
        64,
    );
    m.push_object("tube_upper", &p, &t);
    m
}

/// The demo scene: crossed tubes on the left, Spot on the right.
pub fn scene() -> Mesh {
    let mut m = crossed_tubes(-1.05);
    let spot = read_obj(&mut std::io::Cursor::new(SPOT_OBJ.as_bytes()), "spot.obj")
        .expect("the built-in Spot model parses");
    let mut spot = spot;
    spot.objects = vec!["spot".into()];
    // turned to show its profile, scaled, lying against the plane
    let (lo, hi) = spot.bounds();
    let turn = Mat4::from_quat(Quat::from_rotation_y(std::f32::consts::FRAC_PI_2));
    let s = 1.25;
    let centre = (lo + hi) * 0.5;
    let half_width = (hi.x - lo.x) * 0.5 * s;
    let place = Mat4::from_translation(Vec3::new(1.15, 0.0, half_width))
        * Mat4::from_scale(Vec3::splat(s))
        * turn
        * Mat4::from_translation(-centre);
    m.append(&spot, place);
    m
}

#[cfg(test)]
mod tests {
    #[test]
    fn demo_scene_is_valid() {
        let m = super::scene();
        m.validate("demo").unwrap();
        assert_eq!(m.objects, vec!["plane", "tube_lower", "tube_upper", "spot"]);
    }
}
