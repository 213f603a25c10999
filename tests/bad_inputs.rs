//! Bad input: one clear error line naming the input, a non-zero exit, no
//! output file left behind, never a panic.

mod common;
use common::*;
use std::path::Path;

/// Run `relief` with `args` writing to `dir/out.png`; expect a clean failure
/// whose message contains `names`.
fn fails(dir: &Path, args: &[&str], names: &str) {
    let out = dir.join("out.png");
    let mut all = vec!["relief", "-o", out.to_str().unwrap(), "--stl", "out.stl"];
    all.extend(args);
    if !args.contains(&"--resolution") {
        all.extend(["--resolution", "64"]);
    }
    let o = bin().current_dir(dir).args(&all).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{args:?} succeeded");
    assert!(
        matches!(o.status.code(), Some(c) if c != 0),
        "{args:?}: {err}"
    );
    assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
    assert_eq!(
        err.trim_end().lines().count(),
        1,
        "{args:?}: not one line: {err}"
    );
    assert!(err.starts_with("error: "), "{err}");
    assert!(
        err.contains(names),
        "{args:?}: '{err}' does not name '{names}'"
    );
    let left: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
        .filter(|n| n.starts_with("out") || n.contains("tmp"))
        .collect();
    assert!(left.is_empty(), "{args:?} left {left:?}");
}

#[test]
fn each_bad_input_fails_cleanly() {
    let d = scratch("bad");
    let w = |name: &str, bytes: &[u8]| {
        std::fs::write(d.join(name), bytes).unwrap();
        d.join(name).display().to_string()
    };
    let tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
    let missing = d.join("missing.obj").display().to_string();
    fails(&d, &[&missing], "missing.obj");
    let empty = w("empty.obj", b"# nothing here\n");
    fails(&d, &[&empty], "empty.obj");
    let nan = w("nan.obj", format!("{tri}v nan 1 1\nf 1 2 4\n").as_bytes());
    fails(&d, &[&nan], "nan.obj");
    let range = w("range.obj", format!("{tri}f 1 2 7\n").as_bytes());
    fails(&d, &[&range], "range.obj");
    let garbage: Vec<u8> = (0..5000u32)
        .map(|i| (i.wrapping_mul(2654435761) >> 13) as u8)
        .collect();
    let gobj = w("garbage.obj", &garbage);
    fails(&d, &[&gobj], "garbage.obj");
    let gstl = w("garbage.stl", &garbage);
    fails(&d, &[&gstl], "garbage.stl");
    let gpng = w("garbage.png", &garbage);
    fails(&d, &[&gpng], "garbage.png");
    let gext = w("garbage.bin", &garbage);
    fails(&d, &[&gext], "garbage.bin");
    let spot = fixture("spot.obj");
    fails(&d, &[&spot, "--resolution", "0"], "--resolution 0");
    fails(
        &d,
        &[&spot, "--resolution", "100000"],
        "--resolution 100000",
    );
    fails(&d, &[&spot, "--resolution", "-3"], "--resolution");
    // within the long-side limit but past the pixel limit (16384 px of the
    // demo took 10 GB): refused before rendering, with the size that fits
    fails(
        &d,
        &["--resolution", "16384"],
        "--resolution 16384: the relief would be 16384 x 9732 = 159.4 million pixels, \
         more than the 67.1 million allowed (memory); use --resolution 10628 or less",
    );
    fails(&d, &[&spot, "--bands", "2,x"], "--bands");
    fails(&d, &[&spot, "--material", "unobtainium"], "unobtainium");
    fails(&d, &[&spot, "--depth", "-1"], "--depth");
    fails(&d, &[&spot, "--fov", "190"], "--fov");
    fails(&d, &[&spot, "--steps", "9", "--depth", "3"], "--steps");
    // unwritable output: a directory that does not exist, and a read-only one
    let o = run(&[
        "relief",
        &spot,
        "--resolution",
        "32",
        "-o",
        d.join("no/such/dir/r.png").to_str().unwrap(),
    ]);
    assert!(
        !o.status.success() && String::from_utf8_lossy(&o.stderr).contains("no/such/dir/r.png")
    );
    let ro = d.join("ro");
    std::fs::create_dir(&ro).unwrap();
    let mut perm = std::fs::metadata(&ro).unwrap().permissions();
    perm.set_readonly(true);
    std::fs::set_permissions(&ro, perm).unwrap();
    let target = ro.join("r.png");
    let o = run(&[
        "relief",
        &spot,
        "--resolution",
        "32",
        "-o",
        target.to_str().unwrap(),
    ]);
    let is_root = std::fs::write(ro.join("probe"), b"x").is_ok();
    if !is_root {
        assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("r.png"));
        assert!(
            std::fs::read_dir(&ro).unwrap().next().is_none(),
            "left files in a read-only dir"
        );
    }
    // one good output and one unwritable: neither is left behind
    let o = run(&[
        "relief",
        &spot,
        "--resolution",
        "32",
        "-o",
        d.join("good.png").to_str().unwrap(),
        "--preview",
        d.join("nodir/p.png").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(!d.join("good.png").exists() && !d.join("good.json").exists());
    let mut perm = std::fs::metadata(&ro).unwrap().permissions();
    #[allow(clippy::permissions_set_readonly_false)]
    perm.set_readonly(false);
    std::fs::set_permissions(&ro, perm).unwrap();
    std::fs::remove_dir_all(d).unwrap();
}

/// `relievo ARGS` fails with one error line containing `names`, no panic.
fn fails_with(args: &[&str], names: &str) {
    let o = run(args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{args:?} succeeded");
    assert!(!err.contains("panicked"), "{args:?}: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
    assert!(err.contains(names), "{args:?}: '{err}' lacks '{names}'");
}

/// Bad toolpath flags: one error line naming the flag, exit != 0, no job,
/// no roughing file, no SVG left behind.
#[test]
fn bad_toolpath_flags_fail_cleanly() {
    let d = scratch("bad-cam");
    let relief = d.join("r.png");
    demo_relief(&relief, "48");
    let job = d.join("job.nc");
    let svg = d.join("job.svg");
    for (args, names) in [
        (vec!["--rough", "vbit:60"], "--rough vbit:60"),
        (vec!["--rough", "flat:3", "--step-down", "0"], "--step-down"),
        (
            vec!["--rough", "flat:3", "--stock-to-leave", "-1"],
            "--stock-to-leave",
        ),
        (
            vec!["--rough", "flat:3", "--stock-to-leave", "5"],
            "--stock-to-leave",
        ),
        (vec!["--rough", "T7", "--split"], "T7"),
        (vec!["--finish", "spiral"], "spiral"),
        (vec!["--climb", "--conventional"], "--conventional"),
        (vec!["--split"], "--rough"),
        (vec!["--tool", "ball:3", "--scallop", "2"], "--scallop"),
        (vec!["--material", "cheese"], "cheese"),
        (vec!["--rpm", "99999"], "--rpm"),
        // hostile numbers (issue 14): a panic, a hang, an abort before
        (vec!["--angle", "nan"], "--angle"),
        (vec!["--stepover", "1e-320"], "stepover"),
        (
            vec!["--finish", "waterline", "--stepover", "1e-9"],
            "stepover",
        ),
        (vec!["--stepover", "0.001"], "raise --stepover"),
        (vec!["--tile", "0x10"], "--tile"),
        (vec!["--cutout", "--tab-height", "50"], "--cutout"),
        (vec!["--boundary", "subject"], "--boundary subject"),
        (vec!["--z-zero", "bottom"], "--stock"),
    ] {
        let mut all = vec![
            "toolpath",
            relief.to_str().unwrap(),
            "-o",
            job.to_str().unwrap(),
            "--svg",
            svg.to_str().unwrap(),
        ];
        all.extend(args.iter());
        fails_with(&all, names);
        let left: Vec<_> = std::fs::read_dir(&d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
            .filter(|n| n.starts_with("job"))
            .collect();
        assert!(left.is_empty(), "{args:?} left {left:?}");
    }
    std::fs::remove_dir_all(d).unwrap();
}

/// Hostile numbers in files (issue 14): a sidecar's width of 5e-324, a
/// machine profile's NaN spindle maximum, a 1e308 mm stock, arcs of a
/// kilometre's radius: each one clean error naming the input, no panic,
/// no hang.
#[test]
fn hostile_numbers_in_files_fail_cleanly() {
    let d = scratch("bad-numbers");
    let relief = d.join("r.png");
    demo_relief(&relief, "48");
    let job = d.join("job.nc");
    ok(&run(&[
        "toolpath",
        relief.to_str().unwrap(),
        "-o",
        job.to_str().unwrap(),
        "-q",
    ]));
    let tiny = d.join("tiny.png");
    std::fs::copy(&relief, &tiny).unwrap();
    let side = std::fs::read_to_string(d.join("r.json")).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&side).unwrap();
    v["width_mm"] = serde_json::json!(5e-324);
    std::fs::write(d.join("tiny.json"), v.to_string()).unwrap();
    let profile =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("machines/3018.toml"))
            .unwrap();
    let nan = d.join("nan.toml");
    let text: String = profile
        .lines()
        .map(|l| {
            if l.starts_with("max = ") {
                "max = nan"
            } else {
                l
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    assert!(text.contains("max = nan"));
    std::fs::write(&nan, text).unwrap();
    // 300 near-full circles a kilometre round (they hung the simulator)
    let arcs = d.join("arcs.nc");
    let mut text = String::from("G21 G90 G17\nG0 Z1\nG1 Z-0.5 F100\n");
    for k in 0..300 {
        text.push_str(&format!("G2 X{} Y0 R-1000000\n", ((k + 1) % 2) * 10));
    }
    std::fs::write(&arcs, text).unwrap();
    let out = d.join("out.nc");
    let cut = d.join("out.png");
    for (args, names) in [
        (
            vec![
                "simulate",
                arcs.to_str().unwrap(),
                "--relief",
                relief.to_str().unwrap(),
                "--tool",
                "ball:3",
                "-o",
                cut.to_str().unwrap(),
            ],
            "arcs.nc: line 4: arc radius 1000000.0 mm",
        ),
        (
            vec![
                "toolpath",
                tiny.to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
            ],
            "tiny.png: width 5e-324",
        ),
        (
            vec![
                "toolpath",
                relief.to_str().unwrap(),
                "--machine",
                nan.to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
            ],
            "nan.toml: spindle",
        ),
        (
            vec![
                "simulate",
                job.to_str().unwrap(),
                "--relief",
                relief.to_str().unwrap(),
                "--stock",
                "1e308x1e308x1",
                "-o",
                cut.to_str().unwrap(),
            ],
            "--stock",
        ),
        (
            vec![
                "carve",
                "--resolution",
                "32",
                "--angle",
                "nan",
                "-o",
                out.to_str().unwrap(),
            ],
            "--angle",
        ),
        // an oversampled stock past the cells taken
        (
            vec![
                "simulate",
                job.to_str().unwrap(),
                "--relief",
                relief.to_str().unwrap(),
                "--stock",
                "9000x9000x10",
                "--oversample",
                "15",
                "-o",
                cut.to_str().unwrap(),
            ],
            "cells, more than the 128 million taken",
        ),
    ] {
        fails_with(&args, names);
        assert!(!out.exists() && !cut.exists());
    }
    std::fs::remove_dir_all(d).unwrap();
}

/// A 60 MB binary STL of 1.2 million triangles (it took more than 30 s to
/// make a 64 px relief) makes a 512 px relief; its speed is measured by
/// `bench/large-stl` (0.7 s), here only that it finishes.
#[test]
fn a_million_triangle_stl_makes_a_relief() {
    let d = scratch("big-stl");
    let stl = d.join("big.stl");
    // a wavy 775 x 775 vertex sheet: 2 x 774 x 774 = 1,198,152 triangles
    let n = 775usize;
    let p = |i: usize, j: usize| {
        let (x, y) = (
            i as f32 / (n - 1) as f32 * 2.0 - 1.0,
            j as f32 / (n - 1) as f32 * 2.0 - 1.0,
        );
        [x, y, 0.3 * (3.0 * x).cos() * (2.0 * y).sin()]
    };
    let count = 2 * (n - 1) * (n - 1);
    let mut b = Vec::with_capacity(84 + 50 * count);
    b.extend([0u8; 80]);
    b.extend((count as u32).to_le_bytes());
    for i in 0..n - 1 {
        for j in 0..n - 1 {
            let (a, bb, c, e) = (p(i, j), p(i + 1, j), p(i, j + 1), p(i + 1, j + 1));
            for t in [[a, bb, c], [bb, e, c]] {
                b.extend([0u8; 12]);
                t.iter().flatten().for_each(|v| b.extend(v.to_le_bytes()));
                b.extend([0u8; 2]);
            }
        }
    }
    assert_eq!(b.len(), 84 + 50 * count);
    std::fs::write(&stl, &b).unwrap();
    let out = d.join("r.png");
    ok(&run(&[
        "relief",
        stl.to_str().unwrap(),
        "--view",
        "top",
        "--resolution",
        "512",
        "-o",
        out.to_str().unwrap(),
        "-q",
    ]));
    // seen from above the sheet fills the picture
    let (w, h, v) = read_png16(&out);
    assert_eq!(w.max(h), 512);
    assert!(v.iter().filter(|&&x| x > 0).count() > w * h / 2);
    std::fs::remove_dir_all(d).unwrap();
}

/// `carve` refuses a bad job flag before it makes the relief: one error
/// line naming the flag (not the mesh's up axis and the relief's warnings
/// first), and no relief nor job left.
#[test]
fn carve_refuses_job_flags_before_the_relief() {
    let d = scratch("bad-carve");
    let bunny = fixture("stanford-bunny.obj");
    let job = d.join("job.nc");
    for (args, names) in [
        (vec!["--tool", "ball:0"], "--tool ball:0"),
        (vec!["--rough", "flat:0"], "--rough flat:0"),
        (vec!["--rest", "vbit:500"], "--rest vbit:500"),
        (vec!["--tool", "T9"], "--tool T9"),
        (vec!["--machine", "nosuch"], "--machine nosuch"),
        (vec!["--angle", "nan"], "--angle"),
        (vec!["--tolerance", "5"], "--tolerance"),
        (vec!["--stepover", "0"], "stepover"),
    ] {
        let mut all = vec![
            "carve",
            bunny.as_str(),
            "--resolution",
            "48",
            "-o",
            job.to_str().unwrap(),
        ];
        all.extend(args.iter());
        fails_with(&all, names);
        let left: Vec<_> = std::fs::read_dir(&d).unwrap().collect();
        assert!(left.is_empty(), "{args:?} left {left:?}");
    }
    std::fs::remove_dir_all(d).unwrap();
}

/// A pile of random triangles, each a sizeable part of the picture (a
/// broken export, a point cloud read as a mesh): the render costs what the
/// picture shows, not triangles times their area, and gives a relief.
/// 1.2 million such triangles at 512 px took over 120 s before; the
/// figures are in docs/benchmarks.md, here only that it finishes.
#[test]
fn a_pile_of_random_triangles_makes_a_relief() {
    let d = scratch("random-pile");
    let stl = d.join("pile.stl");
    let count = 200_000u32;
    let mut seed = 7u64;
    let mut rnd = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut b = Vec::with_capacity(84 + 50 * count as usize);
    b.extend([0u8; 80]);
    b.extend(count.to_le_bytes());
    for _ in 0..count {
        b.extend([0u8; 12]);
        for _ in 0..9 {
            b.extend(rnd().to_le_bytes());
        }
        b.extend([0u8; 2]);
    }
    std::fs::write(&stl, &b).unwrap();
    let out = d.join("r.png");
    ok(&run(&[
        "relief",
        stl.to_str().unwrap(),
        "--resolution",
        "256",
        "-o",
        out.to_str().unwrap(),
        "-q",
    ]));
    let (w, h, v) = read_png16(&out);
    assert_eq!(w.max(h), 256);
    assert!(v.iter().filter(|&&x| x > 0).count() > w * h / 2);
    std::fs::remove_dir_all(d).unwrap();
}
