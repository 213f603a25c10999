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
