//! Shop safety, judged by the simulator: the default job keeps every
//! tool within the material's depth of cut and never plunges; a job over
//! the limit is refused unless asked for; a panel is laid out to fit.

mod common;
use common::*;

/// `carve` with `args` into `dir`; (stdout, simulated report).
fn carve_judged(dir: &std::path::Path, args: &[&str]) -> (String, serde_json::Value) {
    let job = dir.join("job.nc");
    let mut a = vec!["carve", "-o", job.to_str().unwrap()];
    a.extend_from_slice(args);
    let out = run(&a);
    ok(&out);
    let rep = simulate_report(&job, &dir.join("job-relief.png"), &dir.join("cut.png"), &[]);
    (String::from_utf8_lossy(&out.stdout).to_string(), rep)
}

#[test]
fn default_jobs_stay_within_the_depth_of_cut_and_never_plunge() {
    let d = scratch("safe-default");
    for model in [
        None,
        Some(fixture("spot.obj")),
        Some(fixture("suzanne.stl")),
    ] {
        let mut args = vec!["--resolution", "200"];
        if let Some(m) = &model {
            args.insert(0, m);
        }
        let (stdout, rep) = carve_judged(&d, &args);
        let e = &rep["engagement"];
        // wood (the default): 1/8" tools may cut 1.59 mm
        for t in e["tools"].as_array().unwrap() {
            let axial = t["max_axial_mm"].as_f64().unwrap();
            eprintln!(
                "{model:?} {}: axial {axial:.3} mm, slot {:.3} mm, width {:.3} mm",
                t["tool"],
                t["max_slot_mm"].as_f64().unwrap(),
                t["max_radial_mm"].as_f64().unwrap()
            );
            assert!(axial <= 1.59 + 0.005, "{model:?} {}: {axial} mm", t["tool"]);
        }
        assert_eq!(
            e["tools"].as_array().unwrap().len(),
            2,
            "{model:?}: roughing added"
        );
        assert!(
            e["plunges"].as_array().unwrap().is_empty(),
            "{model:?}: {}",
            e["plunges"]
        );
        assert!(
            stdout.contains("roughing added with T1 (flat:3.175)"),
            "{stdout}"
        );
        assert!(rep["rapids_in_stock"].as_array().unwrap().is_empty());
        assert!(rep["max_gouge_mm"].as_f64().unwrap() < 0.001);
    }
    std::fs::remove_dir_all(d).unwrap();
}

#[test]
fn a_full_depth_pass_is_refused_unless_allowed() {
    let d = scratch("safe-deep");
    let job = d.join("job.nc");
    let args = [
        "carve",
        "--resolution",
        "120",
        "--rough",
        "T1",
        "--step-down",
        "5",
        "-o",
        job.to_str().unwrap(),
    ];
    let out = run(&args);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && !job.exists(), "{err}");
    assert!(
        err.contains("line ")
            && err.contains("flat:3.175 cuts")
            && err.contains("allowed 1.590 mm"),
        "{err}"
    );
    let mut allowed = args.to_vec();
    allowed.push("--allow-deep-cuts");
    let out = run(&allowed);
    ok(&out);
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(said.contains("--allow-deep-cuts: line"), "{said}");
    let text = std::fs::read_to_string(&job).unwrap();
    assert!(
        text.contains("(--allow-deep-cuts: line"),
        "{}",
        &text[..1500]
    );
    std::fs::remove_dir_all(d).unwrap();
}

#[test]
fn a_panel_that_fits_only_one_way_is_told_so() {
    let d = scratch("safe-rotate");
    let job = d.join("job.nc");
    let base = |extra: &[&str]| {
        let mut a = vec![
            "carve",
            "--resolution",
            "100",
            "--width",
            "250",
            "--depth",
            "3",
            "--tool",
            "ball:6",
            "--machine",
            "3018",
            "-o",
            job.to_str().unwrap(),
            "-q",
        ];
        a.extend_from_slice(extra);
        run(&a)
    };
    // the demo at 250 mm wide is about 148 mm tall: fits the 300 x 180
    let turned = base(&["--rotate", "90"]);
    let err = String::from_utf8_lossy(&turned.stderr);
    assert!(
        !turned.status.success() && err.contains("leave out --rotate"),
        "{err}"
    );
    ok(&base(&[]));
    std::fs::remove_dir_all(d).unwrap();
}
