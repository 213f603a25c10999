//! The `relief` command on real models, through the real binary.

mod common;
use common::*;

/// `--depth D` gives max - min = D; materials give the paper's ratios.
#[test]
fn depth_and_material_ratios() {
    let d = scratch("depth");
    let out = d.join("r.png");
    let o = out.to_str().unwrap();
    ok(&run(&[
        "relief",
        &fixture("spot.obj"),
        "-o",
        o,
        "--resolution",
        "96",
        "--depth",
        "7.5",
        "-q",
    ]));
    let (_, _, mm, depth) = relief_mm(&out);
    let (lo, hi) = mm
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    assert_eq!(depth, 7.5);
    assert!(((hi - lo) - 7.5).abs() <= 0.005 * 7.5, "range {}", hi - lo);
    for (mat, want) in [("silver", 0.88), ("wood", 3.2), ("marble", 4.2)] {
        ok(&run(&[
            "relief",
            &fixture("spot.obj"),
            "-o",
            o,
            "--resolution",
            "64",
            "--width",
            "100",
            "--material",
            mat,
            "-q",
        ]));
        let (_, _, mm, depth) = relief_mm(&out);
        let (lo, hi) = mm
            .iter()
            .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
        assert!((depth - want).abs() < 1e-9, "{mat}: {depth}");
        assert!(
            ((hi - lo) - want).abs() <= 0.005 * want,
            "{mat}: range {}",
            hi - lo
        );
        assert_eq!(sidecar(&out)["width_mm"].as_f64(), Some(100.0));
    }
    std::fs::remove_dir_all(d).unwrap();
}

/// The same flags at 256 and 1024 px agree within 3% of the depth (RMS)
/// once the 1024 result is brought down to 256.
#[test]
fn resolution_independence() {
    let d = scratch("resolution");
    let (a, b) = (d.join("a.png"), d.join("b.png"));
    let flags = ["--depth", "5", "--alpha", "4", "--silhouette", "8", "-q"];
    for (p, res) in [(&a, "256"), (&b, "1024")] {
        let mut args = vec!["relief", "--resolution", res, "-o", p.to_str().unwrap()];
        args.extend(flags);
        ok(&run(&args));
    }
    let (w, h, lo, depth) = relief_mm(&a);
    let (bw, bh, hi, _) = relief_mm(&b);
    assert_eq!((w, bw), (256, 1024));
    let mut sum = 0.0;
    for y in 0..h {
        for x in 0..w {
            let (mut s, mut n) = (0.0, 0.0);
            for yy in 4 * y..(4 * y + 4).min(bh) {
                for xx in 4 * x..4 * x + 4 {
                    s += hi[yy * bw + xx];
                    n += 1.0;
                }
            }
            sum += (s / n - lo[y * w + x]).powi(2);
        }
    }
    let rms = (sum / (w * h) as f64).sqrt();
    eprintln!(
        "256 vs 1024 px: RMS {rms:.4} mm = {:.2}% of the depth",
        rms / depth * 100.0
    );
    assert!(rms < 0.03 * depth, "RMS {rms} mm of {depth} mm");
    std::fs::remove_dir_all(d).unwrap();
}

/// Every output: relief PNG + sidecar, STL, preview, depth buffer; an STL
/// input (ASCII) and mirror/invert behave.
#[test]
fn outputs_and_options() {
    let d = scratch("outputs");
    let p = |n: &str| d.join(n).display().to_string();
    ok(&run(&[
        "relief",
        &fixture("suzanne.stl"),
        "--up",
        "y",
        "-o",
        &p("s.png"),
        "--resolution",
        "80",
        "--stl",
        &p("s.stl"),
        "--preview",
        &p("prev.png"),
        "--depth-out",
        &p("depth.png"),
        "--base",
        "1.5",
        "--bands",
        "2,1.5,1",
        "-q",
    ]));
    let side = sidecar(&d.join("s.png"));
    assert_eq!(side["format"], "relievo-relief/1");
    assert_eq!(side["pixels"][0].as_u64(), Some(80));
    let stl = std::fs::read(d.join("s.stl")).unwrap();
    let mesh = stl_io::read_stl(&mut std::io::Cursor::new(&stl)).unwrap();
    let zmin = mesh.vertices.iter().map(|v| v[2]).fold(f32::MAX, f32::min);
    assert!((zmin + 5.0 + 1.5).abs() < 1e-4, "bottom at {zmin}");
    assert!(image::open(d.join("prev.png")).is_ok());
    let (dw, _, dv) = read_png16(&d.join("depth.png"));
    assert_eq!(dw, 80);
    assert!(dv.iter().any(|&v| v > 30000));

    // mirror flips columns; invert turns the relief upside down
    ok(&run(&[
        "relief",
        &fixture("suzanne.stl"),
        "--up",
        "y",
        "-o",
        &p("m.png"),
        "--resolution",
        "80",
        "--bands",
        "2,1.5,1",
        "--mirror",
        "--invert",
        "-q",
    ]));
    let (w, h, a) = read_png16(&d.join("s.png"));
    let (_, _, b) = read_png16(&d.join("m.png"));
    for y in 0..h {
        for x in 0..w {
            let (u, v) = (a[y * w + x] as i32, b[y * w + (w - 1 - x)] as i32);
            assert!((u + v - 65535).abs() <= 1, "({x},{y}): {u} + {v}");
        }
    }
    std::fs::remove_dir_all(d).unwrap();
}

/// Selective scaling by object name raises that object's relief.
#[test]
fn emphasize_an_object() {
    let d = scratch("emphasize");
    let (a, b) = (d.join("a.png"), d.join("b.png"));
    ok(&run(&[
        "relief",
        "--resolution",
        "128",
        "-o",
        a.to_str().unwrap(),
        "-q",
    ]));
    ok(&run(&[
        "relief",
        "--resolution",
        "128",
        "--emphasize",
        "spot=3",
        "-o",
        b.to_str().unwrap(),
        "-q",
    ]));
    let (w, h, ra, _) = relief_mm(&a);
    let (_, _, rb, _) = relief_mm(&b);
    // the cow is in the right half of the demo, the tubes in the left: the
    // cow's relief grows against the tubes'
    let span = |r: &[f64], x0: usize, x1: usize| {
        let v: Vec<f64> = (0..h)
            .flat_map(|y| (x0..x1).map(move |x| r[y * w + x]))
            .collect();
        v.iter().cloned().fold(f64::MIN, f64::max) - v.iter().cloned().fold(f64::MAX, f64::min)
    };
    let ratio = |r: &[f64]| span(r, w * 6 / 10, w * 9 / 10) / span(r, w / 10, w * 4 / 10);
    assert!(
        ratio(&rb) > 1.5 * ratio(&ra),
        "{} vs {}",
        ratio(&rb),
        ratio(&ra)
    );
    let e = run(&[
        "relief",
        "--resolution",
        "64",
        "--emphasize",
        "horse=2",
        "-o",
        a.to_str().unwrap(),
    ]);
    assert!(!e.status.success());
    assert!(String::from_utf8_lossy(&e.stderr).contains("horse"));
    std::fs::remove_dir_all(d).unwrap();
}

/// The flat background stays exactly flat (one value) around the object.
#[test]
fn flat_background_is_flat() {
    let d = scratch("flat");
    let a = d.join("a.png");
    ok(&run(&[
        "relief",
        &fixture("spot.obj"),
        "--resolution",
        "128",
        "--flat-background",
        "-o",
        a.to_str().unwrap(),
        "-q",
    ]));
    let (w, h, v) = read_png16(&a);
    // the frame's margin is background: every border pixel has one value
    let border: Vec<u16> = (0..w)
        .flat_map(|x| [v[x], v[(h - 1) * w + x]])
        .chain((0..h).flat_map(|y| [v[y * w], v[y * w + w - 1]]))
        .collect();
    assert!(border.iter().all(|&b| b == border[0]), "border not flat");
    assert!(v.iter().any(|&x| x > border[0] + 30000));
    std::fs::remove_dir_all(d).unwrap();
}

/// A normal map and the depth PNG of the same surface give the same relief.
#[test]
fn normal_map_matches_depth_png() {
    let d = scratch("normals");
    let (w, h) = (96usize, 64usize);
    let n = w as f64;
    // a smooth bump, heights in pixels (isotropic with x and y)
    let z = |x: f64, y: f64| {
        6.0 * (-((x - 40.0).powi(2) + (y - 30.0).powi(2)) / 300.0).exp() + 0.05 * x
    };
    let mut depth = vec![0u16; w * h];
    let mut rgb = vec![0u8; w * h * 3];
    for y in 0..h {
        for x in 0..w {
            let (fx, fy) = (x as f64, y as f64);
            depth[y * w + x] = ((0.2 + z(fx, fy) / n) * 65535.0).round() as u16;
            let (dx, drow) = (
                z(fx + 0.5, fy) - z(fx - 0.5, fy),
                z(fx, fy + 0.5) - z(fx, fy - 0.5),
            );
            let len = (dx * dx + drow * drow + 1.0).sqrt();
            // tangent space, +Y up: n = (-dz/dx, +dz/drow, 1) / len
            for (k, c) in [-dx / len, drow / len, 1.0 / len].into_iter().enumerate() {
                rgb[(y * w + x) * 3 + k] = ((c + 1.0) / 2.0 * 255.0).round() as u8;
            }
        }
    }
    write_png16(&d.join("depth.png"), w, h, &depth);
    image::RgbImage::from_raw(w as u32, h as u32, rgb)
        .unwrap()
        .save(d.join("normals.png"))
        .unwrap();
    for src in ["depth", "normals"] {
        let input = d.join(format!("{src}.png"));
        ok(&run(&[
            "relief",
            input.to_str().unwrap(),
            "-o",
            d.join(format!("r-{src}.png")).to_str().unwrap(),
            "--depth",
            "4",
            "-q",
        ]));
    }
    let (_, _, a, depth_mm) = relief_mm(&d.join("r-depth.png"));
    let (_, _, b, _) = relief_mm(&d.join("r-normals.png"));
    let rms = (a.iter().zip(&b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / a.len() as f64).sqrt();
    eprintln!("normal map vs depth PNG: RMS {rms:.4} mm of {depth_mm} mm");
    assert!(rms < 0.05 * depth_mm, "RMS {rms}");
    std::fs::remove_dir_all(d).unwrap();
}

/// The relief's own binary STL is a valid model to relieve again.
#[test]
fn binary_stl_round_trip() {
    let d = scratch("stl-in");
    let (r, s) = (d.join("r.png"), d.join("r.stl"));
    ok(&run(&[
        "relief",
        &fixture("spot.obj"),
        "--resolution",
        "48",
        "-o",
        r.to_str().unwrap(),
        "--stl",
        s.to_str().unwrap(),
        "-q",
    ]));
    let bytes = std::fs::read(&s).unwrap();
    assert!(!bytes.starts_with(b"solid"), "expected a binary STL");
    ok(&run(&[
        "relief",
        s.to_str().unwrap(),
        "--view",
        "top",
        "--resolution",
        "48",
        "-o",
        d.join("again.png").to_str().unwrap(),
        "-q",
    ]));
    std::fs::remove_dir_all(d).unwrap();
}
