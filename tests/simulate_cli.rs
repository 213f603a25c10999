//! The cut simulator through the real binary: hand-computed grooves, rapids
//! through stock, a known-good job shifted down, malformed jobs.

mod common;
use common::*;
use std::path::{Path, PathBuf};

/// A flat relief (all at Z = 0) of `w x h` pixels, `pitch` mm, 5 mm deep.
fn flat_relief(dir: &Path, w: usize, h: usize, pitch: f64) -> PathBuf {
    let p = dir.join("flat.png");
    write_png16(&p, w, h, &vec![65535u16; w * h]);
    let side = serde_json::json!({"format": "relievo-relief/1", "width_mm": w as f64 * pitch, "height_mm": h as f64 * pitch, "depth_mm": 5.0, "pixels": [w, h]});
    std::fs::write(p.with_extension("json"), side.to_string()).unwrap();
    p
}

/// Simulate `job` on `relief` with one stock cell per relief pixel (the
/// hand-computed profiles below are read at the pixels); returns the cut
/// (w, h, Z in mm) and the report.
fn simulate(
    dir: &Path,
    relief: &Path,
    job: &str,
    tool: &str,
) -> (usize, usize, Vec<f64>, serde_json::Value) {
    let nc = dir.join("job.nc");
    std::fs::write(&nc, job).unwrap();
    let cut = dir.join("cut.png");
    let report = simulate_report(&nc, relief, &cut, &["--tool", tool, "--oversample", "1"]);
    let (w, h, mm, depth) = relief_mm(&cut);
    (w, h, mm.iter().map(|v| v - depth).collect(), report)
}

const PITCH: f64 = 0.1;

fn centre(i: usize, j: usize, h: usize) -> (f64, f64) {
    (
        (i as f64 + 0.5) * PITCH,
        h as f64 * PITCH - (j as f64 + 0.5) * PITCH,
    )
}

fn ball(r: f64, rho: f64) -> f64 {
    if rho <= r {
        r - (r * r - rho * rho).sqrt()
    } else {
        f64::INFINITY
    }
}

/// A groove cut 0.1 mm into a flat relief midway between two rows of its
/// samples: the default stock is fine enough to see its bottom, and the
/// report states its bound; with one cell per pixel, whose centres read
/// 0.080 mm, the exact measure along the moves still reads 0.100 and
/// names the move.
#[test]
fn a_groove_between_sample_rows_reads_its_full_depth() {
    let d = scratch("sim-midway");
    // 0.5 mm pixels: sample rows at Y 25.25 and 24.75, the groove at 25
    let relief = flat_relief(&d, 200, 100, 0.5);
    let nc = d.join("job.nc");
    std::fs::write(
        &nc,
        "G21 G90\nG0 Z5\nG0 X10 Y25\nG1 Z-0.1 F100\nG1 X90 F300\nG0 Z5\nM30\n",
    )
    .unwrap();
    let cut = d.join("cut.png");
    let rep = simulate_report(&nc, &relief, &cut, &["--tool", "ball:3.175"]);
    let gouge = rep["max_gouge_mm"].as_f64().unwrap();
    assert!((gouge - 0.1).abs() <= 0.002, "{gouge}");
    let (cell, between) = (
        rep["cell_mm"].as_f64().unwrap(),
        rep["between_cells_mm"].as_f64().unwrap(),
    );
    assert!(
        between <= 1e-3 && cell < 0.5,
        "cells {cell} mm, between {between} mm"
    );
    // and as one cell per pixel did, for the record
    let coarse = simulate_report(
        &nc,
        &relief,
        &cut,
        &["--tool", "ball:3.175", "--oversample", "1"],
    );
    let g1 = coarse["max_gouge_mm"].as_f64().unwrap();
    assert!((g1 - 0.1).abs() < 2e-4, "{g1}");
    assert!(coarse["gouge_exact_per_move"].as_bool().unwrap());
    // the plunge to the groove's depth (line 4) or the groove (5)
    let line = coarse["max_gouge_line"].as_u64().unwrap();
    assert!((4..=5).contains(&line), "{coarse}");
    assert!(coarse["between_cells_mm"].as_f64().unwrap() > 0.039);
    std::fs::remove_dir_all(d).unwrap();
}

#[test]
fn straight_grooves_have_the_exact_profile() {
    let d = scratch("sim-grooves");
    let relief = flat_relief(&d, 200, 100, PITCH);
    let job = "G21 G90\nG0 Z5\nG0 X2 Y5\nG1 Z-1 F100\nG1 X18 F300\nG0 Z5\nM30\n";
    for (tool, profile) in [
        (
            "ball:3",
            Box::new(|rho: f64| ball(1.5, rho)) as Box<dyn Fn(f64) -> f64>,
        ),
        (
            "flat:3",
            Box::new(|rho: f64| if rho <= 1.5 { 0.0 } else { f64::INFINITY }),
        ),
        (
            "vbit:90:4",
            Box::new(|rho: f64| if rho <= 2.0 { rho } else { f64::INFINITY }),
        ),
    ] {
        let (w, h, z, report) = simulate(&d, &relief, job, tool);
        let mut checked = 0;
        let mut width = 0.0;
        for j in 0..h {
            let i = w / 2;
            let (_, y) = centre(i, j, h);
            let rho = (y - 5.0).abs();
            if (rho - 1.5).abs() < 0.06 && tool != "vbit:90:4" {
                continue; // the rim of a flat end: a jump, either side is right
            }
            let want = (-1.0 + profile(rho)).min(0.0);
            assert!(
                (z[j * w + i] - want).abs() < 1e-3,
                "{tool}: y {y:.2}: {} vs {want}",
                z[j * w + i]
            );
            if z[j * w + i] < -1e-6 {
                width += PITCH;
            }
            checked += 1;
        }
        assert!(checked > 90);
        let want_width = match tool {
            "ball:3" => 2.0 * (1.5f64 * 1.5 - 0.5 * 0.5).sqrt(),
            "flat:3" => 3.0,
            _ => 2.0,
        };
        assert!(
            (width - want_width).abs() <= 2.0 * PITCH,
            "{tool}: groove {width} mm wide, want {want_width}"
        );
        assert_eq!(report["rapids_in_stock"].as_array().unwrap().len(), 0);
        assert!(report["max_gouge_mm"].as_f64().unwrap() > 0.9);
        assert_eq!(report["lines"].as_u64(), Some(7));
    }
    std::fs::remove_dir_all(d).unwrap();
}

#[test]
fn arc_grooves_with_ij_and_r_and_a_plunge() {
    let d = scratch("sim-arcs");
    let relief = flat_relief(&d, 240, 240, PITCH);
    let h = 240;
    for arc in ["G2 X4 Y12 I-6 J0", "G2 X4 Y12 R6", "g2x4y12r6"] {
        let job = format!("G0 Z5\nG0 X16 Y12\nG1 Z-1 F100\n{arc} F400\nG0 Z5\n");
        let (w, _, z, _) = simulate(&d, &relief, &job, "ball:3");
        let mut checked = 0;
        for j in 0..h {
            for i in 0..w {
                let (x, y) = centre(i, j, h);
                if y > 11.0 {
                    continue; // the arc is the lower half circle; skip its ends
                }
                // GRBL cuts the arc as chords with their ends on the
                // circle, sagging inward up to its $12 (0.002 mm)
                let at = |r: f64| {
                    let rho = (((x - 10.0).powi(2) + (y - 12.0).powi(2)).sqrt() - r).abs();
                    (-1.0 + ball(1.5, rho)).min(0.0)
                };
                let (a, b) = (at(6.0), at(6.0 - 0.0021));
                let got = z[j * w + i];
                assert!(
                    got > a.min(b) - 1e-3 && got < a.max(b) + 1e-3,
                    "{arc}: ({x:.2},{y:.2}): {got} vs {a}..{b}"
                );
                checked += 1;
            }
        }
        assert!(checked > 10000);
    }
    // plunges: a flat end leaves a flat-bottomed hole, a ball a spherical dimple
    for (tool, depth_at) in [
        (
            "flat:4",
            Box::new(|r: f64| if r < 2.0 { -2.0 } else { 0.0 }) as Box<dyn Fn(f64) -> f64>,
        ),
        ("ball:4", Box::new(|r: f64| (-2.0 + ball(2.0, r)).min(0.0))),
    ] {
        let (w, _, z, _) = simulate(&d, &relief, "G0 X10 Y10 Z3\nG1 Z-2 F50\nG0 Z3\n", tool);
        for j in 0..h {
            for i in 0..w {
                let (x, y) = centre(i, j, h);
                let r = ((x - 10.0).powi(2) + (y - 10.0).powi(2)).sqrt();
                if (r - 2.0).abs() < 0.05 {
                    continue;
                }
                assert!(
                    (z[j * w + i] - depth_at(r)).abs() < 1e-3,
                    "{tool} plunge at r {r}"
                );
            }
        }
    }
    std::fs::remove_dir_all(d).unwrap();
}

#[test]
fn a_rapid_through_stock_is_reported_with_its_line() {
    let d = scratch("sim-rapid");
    let relief = flat_relief(&d, 100, 100, PITCH);
    let job = "G0 Z5\nG0 X1 Y1\nG0 Z-0.5\n(oops: rapid across)\nG0 X9 Y9\nG0 Z5\nG0 X1\n";
    let (_, _, _, report) = simulate(&d, &relief, job, "flat:2");
    assert_eq!(report["rapids_in_stock"], serde_json::json!([3, 5]));
    std::fs::remove_dir_all(d).unwrap();
}

/// A known-good ball-end job (brute-force drop-cutter on a dense sampling
/// of the relief's continuous surface: two triangles per cell, flat to the
/// panel's edges), then the same job shifted down by 0.1 mm.
#[test]
fn a_known_good_cut_shifted_down_gouges_by_the_shift() {
    let d = scratch("sim-shift");
    let relief = d.join("waves.png");
    let (w, h) = (64usize, 48usize);
    let v: Vec<u16> = (0..w * h)
        .map(|k| {
            let (x, y) = ((k % w) as f64 * 0.5, (k / w) as f64 * 0.5);
            let z = 0.5 + 0.3 * (x / 5.0).sin() * (y / 4.0).cos() + 0.1 * (x / 3.0 + y / 7.0).cos();
            (z.clamp(0.0, 1.0) * 65535.0).round() as u16
        })
        .collect();
    write_png16(&relief, w, h, &v);
    let side = serde_json::json!({"format": "relievo-relief/1", "width_mm": 32.0, "height_mm": 24.0, "depth_mm": 3.0, "pixels": [w, h]});
    std::fs::write(relief.with_extension("json"), side.to_string()).unwrap();
    let (w, h, mm, depth) = relief_mm(&relief);
    let p = 32.0 / w as f64;
    let (pw, ph) = (w as f64 * p, h as f64 * p);
    let r = 1.0;
    // the surface: sample heights joined by the triangles a-b-c and
    // b-c-d of each cell (a top-left, d bottom-right), flat to the edges
    let sample = |i: isize, j: isize| {
        let (i, j) = (
            i.clamp(0, w as isize - 1) as usize,
            j.clamp(0, h as isize - 1) as usize,
        );
        mm[j * w + i] - depth
    };
    let surface = |x: f64, y: f64| {
        let (fx, fy) = (x / p - 0.5, (ph - y) / p - 0.5);
        let (i, j) = (fx.floor() as isize, fy.floor() as isize);
        let (u, v) = (fx - i as f64, fy - j as f64);
        let (za, zb, zc, zd) = (
            sample(i, j),
            sample(i + 1, j),
            sample(i, j + 1),
            sample(i + 1, j + 1),
        );
        if u + v <= 1.0 {
            za + u * (zb - za) + v * (zc - za)
        } else {
            zd + (1.0 - u) * (zc - zd) + (1.0 - v) * (zb - zd)
        }
    };
    // every 1/16 mm: a ball held by these points sinks at most
    // 1 - sqrt(1 - 0.022^2) = 0.25 um between them
    let q = 1.0 / 16.0;
    let dense: Vec<Vec<f64>> = (0..=(ph / q) as usize)
        .map(|b| {
            (0..=(pw / q) as usize)
                .map(|a| surface(a as f64 * q, b as f64 * q))
                .collect()
        })
        .collect();
    let cl = |x: f64, y: f64| {
        let mut z = f64::MIN;
        let (a0, a1) = (
            ((x - r) / q).ceil().max(0.0) as usize,
            ((x + r) / q).floor().min(pw / q) as usize,
        );
        let (b0, b1) = (
            ((y - r) / q).ceil().max(0.0) as usize,
            ((y + r) / q).floor().min(ph / q) as usize,
        );
        for (b, row) in dense.iter().enumerate().take(b1 + 1).skip(b0) {
            for (a, s) in row.iter().enumerate().take(a1 + 1).skip(a0) {
                let rho = ((a as f64 * q - x).powi(2) + (b as f64 * q - y).powi(2)).sqrt();
                if rho <= r {
                    z = z.max(s - ball(r, rho));
                }
            }
        }
        z
    };
    let job = |shift: f64| {
        let mut s = String::from("(tool: ball:2)\nG21 G90\nG0 Z2\n");
        // CL points every 1/8 sample: the chords between them dip below the
        // CL surface's creases by little
        let step = p / 8.0;
        let rows = (h as f64 * p / (p / 2.0)) as usize;
        for row in 0..=rows {
            let y = row as f64 * p / 2.0;
            s += &format!("G0 X0 Y{y:.4}\n");
            let n = (32.0 / step) as usize;
            for k in 0..=n {
                let x = k as f64 * step;
                let z = cl(x, y) + shift;
                s += &format!("G1 X{x:.4} Y{y:.4} Z{z:.5} F1000\n");
            }
            s += "G0 Z2\n";
        }
        s
    };
    let nc = d.join("good.nc");
    let cut = d.join("cut.png");
    for (shift, name) in [(0.0, "good"), (-0.1, "shifted")] {
        std::fs::write(&nc, job(shift)).unwrap();
        let report = simulate_report(&nc, &relief, &cut, &[]);
        let gouge = report["max_gouge_mm"].as_f64().unwrap();
        eprintln!(
            "{name}: gouge {gouge:.5} mm, residual max {:.4}",
            report["max_residual_mm"]
        );
        if shift == 0.0 {
            assert!(gouge < 0.002, "known-good job gouges {gouge}");
        } else {
            assert!((gouge - 0.1).abs() <= 0.005, "shifted job gouges {gouge}");
        }
        assert!(report["time_s"].as_f64().unwrap() > 0.0);
    }
    std::fs::remove_dir_all(d).unwrap();
}

#[test]
fn malformed_jobs_fail_with_the_line_and_leave_nothing() {
    let d = scratch("sim-bad");
    let relief = flat_relief(&d, 50, 50, PITCH);
    for (job, want) in [
        ("G0 Z5\nG1 X1 Y1 Z-1 F100\nG1 X2 Q7\n", "line 3"),
        ("G0 Z5\nG1 X1\n", "line 2"),
        ("G0 Z5\n\n\nG2 X1 Y1 I5 J5 F100\n", "line 4"),
        ("G0 Z5\nG38.2 Z-3\n", "line 2"),
        ("G0 X1 %\n", "line 1: GRBL error:1"),
    ] {
        let nc = d.join("bad.nc");
        std::fs::write(&nc, job).unwrap();
        let o = run(&[
            "simulate",
            nc.to_str().unwrap(),
            "--relief",
            relief.to_str().unwrap(),
            "--tool",
            "ball:1",
            "-o",
            d.join("out.png").to_str().unwrap(),
            "--report",
            d.join("out.json").to_str().unwrap(),
            "--deviation",
            d.join("outdev.png").to_str().unwrap(),
        ]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{job:?} succeeded");
        assert!(
            err.contains(want) && err.contains("bad.nc"),
            "{job:?}: {err}"
        );
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
        for f in ["out.png", "out.json", "outdev.png"] {
            assert!(!d.join(f).exists(), "{f} left behind");
        }
    }
    // no tool anywhere
    let nc = d.join("notool.nc");
    std::fs::write(&nc, "G0 Z5\n").unwrap();
    let o = run(&[
        "simulate",
        nc.to_str().unwrap(),
        "--relief",
        relief.to_str().unwrap(),
        "-o",
        d.join("out.png").to_str().unwrap(),
    ]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("tool"));
    std::fs::remove_dir_all(d).unwrap();
}

/// `--deviation`: the map has its scale under it, and the scallops of a
/// raster whose stepover (0.37 mm) beats with the cells (0.1 mm) do not
/// show as bands: the residual is drawn as its envelope over a stepover.
#[test]
fn the_deviation_map_has_a_scale_and_no_bands() {
    let d = scratch("sim-map");
    // a flat 0.5 mm below the stock top
    let relief = d.join("flat.png");
    write_png16(&relief, 300, 100, &vec![0u16; 300 * 100]);
    let side = serde_json::json!({"format": "relievo-relief/1", "width_mm": 30.0,
        "height_mm": 10.0, "depth_mm": 0.5, "pixels": [300, 100]});
    std::fs::write(relief.with_extension("json"), side.to_string()).unwrap();
    let nc = d.join("job.nc");
    ok(&run(&[
        "toolpath",
        relief.to_str().unwrap(),
        "--stepover",
        "0.37",
        "-o",
        nc.to_str().unwrap(),
        "-q",
    ]));
    let map = d.join("dev.png");
    let report = simulate_report(
        &nc,
        &relief,
        &d.join("cut.png"),
        &["--oversample", "1", "--deviation", map.to_str().unwrap()],
    );
    let left = report["max_residual_mm"].as_f64().unwrap();
    let img = image::open(&map).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (300, 130));
    // the scallops: 0.37^2 / (8 x 1.5875) = 0.0108 mm, blue on a 0.02 scale
    assert!((left - 0.0108).abs() < 0.002, "residual {left}");
    // grey (199) to blue takes the red channel down to 25 at the scale:
    // the raw scallops would span 199..105 here
    let reds: Vec<u8> = (20..80)
        .flat_map(|y| (20..280).map(move |x| (x, y)))
        .map(|(x, y)| img.get_pixel(x, y)[0])
        .collect();
    let (lo, hi) = (*reds.iter().min().unwrap(), *reds.iter().max().unwrap());
    eprintln!("red over the flat: {lo}..{hi}");
    assert!(hi - lo <= 15, "bands: red {lo}..{hi}");
    assert!(
        img.get_pixel(150, 50)[0] < 150,
        "the scallops are not shown"
    );
    // the legend: red to blue, and its figures in white
    assert!(img.get_pixel(9, 108)[0] > 200 && img.get_pixel(290, 108)[2] > 200);
    let white = (115..130)
        .flat_map(|y| (0..300).map(move |x| (x, y)))
        .filter(|&(x, y)| img.get_pixel(x, y).0 == [255, 255, 255])
        .count();
    assert!(white > 50, "no figures under the bar");
}

/// `--tool` takes a name from the machine's tool table as `toolpath` does:
/// T2 on the generic profile is its 1/8 in ball, and cuts as `ball:3.175`;
/// a name the table lacks is refused with the table's names.
#[test]
fn tool_table_names_work_in_simulate() {
    let d = scratch("sim-tool-table");
    let relief = flat_relief(&d, 200, 100, PITCH);
    let job = "G21 G90\nG0 Z5\nG0 X2 Y5\nG1 Z-1 F100\nG1 X18 F300\nG0 Z5\nM30\n";
    let (_, _, by_name, _) = simulate(&d, &relief, job, "T2");
    let (_, _, by_spec, _) = simulate(&d, &relief, job, "ball:3.175");
    assert_eq!(by_name, by_spec);
    let nc = d.join("job.nc");
    let out = run(&[
        "simulate",
        nc.to_str().unwrap(),
        "--relief",
        relief.to_str().unwrap(),
        "--tool",
        "T9",
        "-o",
        d.join("x.png").to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(1));
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(
        said.contains("--tool T9: not a tool spec") && said.contains("T1, T2"),
        "{said}"
    );
    std::fs::remove_dir_all(d).unwrap();
}
