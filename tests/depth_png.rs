//! A depth-PNG input without bands and with a free background gives exactly
//! DESIGN.md section 2's closed form: gradients -> silhouette zeroing -> C
//! -> Neumann Poisson -> min to 0 -> scale to the depth. The reference here
//! is written independently (f64, conjugate gradients instead of the DCT).

mod common;
use common::*;

const W: usize = 60;
const H: usize = 44;

/// A dome on a raised block over a ramp, with background around it.
fn scene() -> Vec<u16> {
    let mut v = vec![0u16; W * H];
    for y in 0..H {
        for x in 0..W {
            let (fx, fy) = (x as f64, y as f64);
            let r2 = ((fx - 24.0).powi(2) + (fy - 22.0).powi(2)) / 14.0f64.powi(2);
            let mut h = 0.0;
            if (6..54).contains(&x) && (5..39).contains(&y) {
                h = 0.25 + 0.002 * fx; // the ramp
            }
            if (34..50).contains(&x) && (10..30).contains(&y) {
                h += 0.12; // a raised block: its edges are outlines
            }
            if r2 < 1.0 {
                h = h.max(0.45 + 0.3 * (1.0 - r2).sqrt());
            }
            v[y * W + x] = (h * 65535.0).round() as u16;
        }
    }
    v
}

/// The reference relief in mm.
fn closed_form(v: &[u16], alpha: f64, theta: f64, depth: f64) -> Vec<f64> {
    let n = W.max(H) as f64;
    let h: Vec<f64> = v.iter().map(|&x| x as f64 / 65535.0).collect();
    let (mut gx, mut gy) = (vec![0.0; W * H], vec![0.0; W * H]);
    for y in 0..H {
        for x in 0..W {
            let i = y * W + x;
            let mut a = if x + 1 < W {
                n * (h[i + 1] - h[i])
            } else {
                0.0
            };
            let mut b = if y + 1 < H {
                n * (h[i + W] - h[i])
            } else {
                0.0
            };
            if a.abs() > theta {
                a = 0.0;
            }
            if b.abs() > theta {
                b = 0.0;
            }
            let m = (a * a + b * b).sqrt();
            let c = if m > 0.0 {
                (1.0 + alpha * m).ln() / alpha / m
            } else {
                0.0
            };
            gx[i] = a * c / n;
            gy[i] = b * c / n;
        }
    }
    // rhs = -div g; A = -laplacian with reflecting boundary (singular: keep
    // everything mean-free)
    let mut b = vec![0.0; W * H];
    for y in 0..H {
        for x in 0..W {
            let i = y * W + x;
            let mut d = gx[i] * (x + 1 < W) as u8 as f64 + gy[i] * (y + 1 < H) as u8 as f64;
            if x > 0 {
                d -= gx[i - 1];
            }
            if y > 0 {
                d -= gy[i - W];
            }
            b[i] = -d;
        }
    }
    let apply = |u: &[f64]| -> Vec<f64> {
        let mut o = vec![0.0; W * H];
        for y in 0..H {
            for x in 0..W {
                let i = y * W + x;
                let mut s = 0.0;
                for (ok, j) in [
                    (x > 0, i.wrapping_sub(1)),
                    (x + 1 < W, i + 1),
                    (y > 0, i.wrapping_sub(W)),
                    (y + 1 < H, i + W),
                ] {
                    if ok {
                        s += u[i] - u[j];
                    }
                }
                o[i] = s;
            }
        }
        o
    };
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let mut u = vec![0.0; W * H];
    let mut r = b.clone();
    let mut p = r.clone();
    let mut rr = dot(&r, &r);
    let b2 = rr;
    for _ in 0..20000 {
        let ap = apply(&p);
        let a = rr / dot(&p, &ap);
        for i in 0..W * H {
            u[i] += a * p[i];
            r[i] -= a * ap[i];
        }
        let rr2 = dot(&r, &r);
        if rr2 < 1e-26 * b2 {
            break;
        }
        for i in 0..W * H {
            p[i] = r[i] + rr2 / rr * p[i];
        }
        rr = rr2;
    }
    let (lo, hi) = u
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    u.iter().map(|v| (v - lo) / (hi - lo) * depth).collect()
}

#[test]
fn depth_png_matches_the_closed_form() {
    let d = scratch("closed-form");
    let input = d.join("depth.png");
    let v = scene();
    write_png16(&input, W, H, &v);
    let out = d.join("r.png");
    let (alpha, theta, depth) = (3.0, 5.0, 4.0);
    ok(&run(&[
        "relief",
        input.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--alpha",
        "3",
        "--silhouette",
        "5",
        "--depth",
        "4",
        "-q",
    ]));
    let (w, h, got, _) = relief_mm(&out);
    assert_eq!((w, h), (W, H));
    let want = closed_form(&v, alpha, theta, depth);
    let err = got
        .iter()
        .zip(&want)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    eprintln!(
        "max deviation from the closed form: {err:.2e} mm ({:.4}% of the depth)",
        err / depth * 100.0
    );
    assert!(err < 0.005 * depth, "max deviation {err} mm");
    // the scene really has outlines that were zeroed
    let mut jumps = 0;
    for i in 0..W * H - 1 {
        if (v[i + 1] as f64 - v[i] as f64).abs() / 65535.0 * 60.0 > theta {
            jumps += 1;
        }
    }
    assert!(jumps > 50);
    std::fs::remove_dir_all(d).unwrap();
}
