//! Shop safety, judged by the simulator: the default job keeps every
//! tool within the material's depth of cut and never plunges; a job over
//! the limit is refused unless asked for; a panel is laid out to fit.

mod common;
use common::*;

/// `carve` with `args` into `dir`; (stdout, simulated report).
fn carve_judged(dir: &std::path::Path, args: &[&str]) -> (String, serde_json::Value) {
    carve_simulated(dir, args, &[])
}

/// `carve_judged` with `simulate` given `sim` besides.
fn carve_simulated(
    dir: &std::path::Path,
    args: &[&str],
    sim: &[&str],
) -> (String, serde_json::Value) {
    let job = dir.join("job.nc");
    let mut a = vec!["carve", "-o", job.to_str().unwrap()];
    a.extend_from_slice(args);
    let out = run(&a);
    ok(&out);
    // the simulator's own fine cells (a cut hides at most 1 um between
    // them), three per relief pixel here, not the cells the job was
    // planned on: the rim of a row's cut falling between those used to
    // hide material under a roughing pass going steeply down a wall
    let rep = simulate_report(&job, &dir.join("job-relief.png"), &dir.join("cut.png"), sim);
    (String::from_utf8_lossy(&out.stdout).to_string(), rep)
}

/// A simulated job plunges nowhere into material and gouges less than 1 um.
fn no_plunge_nor_gouge(rep: &serde_json::Value) {
    let plunges = &rep["engagement"]["plunges"];
    assert!(plunges.as_array().unwrap().is_empty(), "{plunges}");
    assert!(rep["max_gouge_mm"].as_f64().unwrap() < 0.001);
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
        // carve judges on simulate's own cells: the figures it prints
        // are the ones simulate finds in the written job
        for t in e["tools"].as_array().unwrap() {
            let said = format!(
                "{}: depth of cut up to {:.3} mm (line {})",
                t["tool"].as_str().unwrap(),
                t["max_axial_mm"].as_f64().unwrap(),
                t["axial_line"]
            );
            assert!(
                stdout.contains(&said),
                "{model:?}: '{said}' not in {stdout}"
            );
        }
        assert!(rep["rapids_in_stock"].as_array().unwrap().is_empty());
        assert!(rep["max_gouge_mm"].as_f64().unwrap() < 0.001);
        // the time by tool, as the header states it and simulate finds it
        let by_tool: Vec<(String, f64)> = rep["time_by_tool"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| (p[0].as_str().unwrap().to_string(), p[1].as_f64().unwrap()))
            .collect();
        let total = rep["time_s"].as_f64().unwrap();
        let sum: f64 = by_tool.iter().map(|p| p.1).sum();
        assert!((sum - total).abs() < 1e-6, "{by_tool:?} vs {total}");
        let header = std::fs::read_to_string(d.join("job.nc")).unwrap();
        let est: String = header
            .lines()
            .skip_while(|l| !l.starts_with("(estimated time:"))
            .take_while(|l| l.starts_with('('))
            .map(|l| l.trim_matches(|c| c == '(' || c == ')').trim())
            .collect::<Vec<_>>()
            .join(" ");
        eprintln!("{model:?}: {est}");
        let parts: Vec<(String, f64)> = est
            .split_once(": ")
            .and_then(|(_, rest)| rest.split_once(": "))
            .expect("the estimate split by op")
            .1
            .split(", ")
            .map(|p| {
                let (name, time) = p.split_once(' ').unwrap();
                let (tool, time) = time.split_once(' ').unwrap();
                (format!("{name} {tool}"), hms_secs(time))
            })
            .collect();
        let names: Vec<&str> = parts.iter().map(|p| p.0.as_str()).collect();
        assert_eq!(names, ["roughing flat:3.175", "finishing ball:3.175"]);
        for ((_, h), (tool, s)) in parts.iter().zip(&by_tool) {
            assert!((h - s).abs() <= 1.0, "{tool}: header {h} s, simulate {s} s");
            assert!(*s > 60.0, "{tool}: {s} s");
        }
    }
    std::fs::remove_dir_all(d).unwrap();
}

/// Seconds of "1h 02m 03s" or "2m 03s".
fn hms_secs(t: &str) -> f64 {
    t.split(' ')
        .map(|p| {
            let (n, unit) = p.split_at(p.len() - 1);
            let n: f64 = n.parse().unwrap();
            match unit {
                "h" => 3600.0 * n,
                "m" => 60.0 * n,
                _ => n,
            }
        })
        .sum()
}

/// Steep walls: the demo with a flat field and 0.5 mm steps (outline walls
/// the raster runs down) and its roughing at the panel's edge. A surface
/// pass down a wall in steps just over 45 degrees used to be cut into
/// one-point pieces, each entered straight down from above (33 plunges at
/// 200 px), and a clearing pass at the foot of a steep rise was ramped
/// into down that rise.
#[test]
fn steep_walls_are_not_entered_by_plunging() {
    let d = scratch("safe-walls");
    let (_, rep) = carve_judged(
        &d,
        &["--resolution", "200", "--flat-background", "--steps", "0.5"],
    );
    let e = &rep["engagement"];
    assert!(
        e["plunges"].as_array().unwrap().is_empty(),
        "{}",
        e["plunges"]
    );
    assert!(rep["rapids_in_stock"].as_array().unwrap().is_empty());
    assert!(rep["max_gouge_mm"].as_f64().unwrap() < 0.001);
    std::fs::remove_dir_all(d).unwrap();
}

/// A travel between two pieces of a pass clears every cell any part of
/// which lies within the tool's reach, not only those whose centres do:
/// Suzanne's finish alone at 400 px with the field held flat hopped from
/// a row split at the panel's edge 1 mm over the cut, 0.93 mm under an
/// uncut row beside it (the cell's centre had been cut).
#[test]
fn travels_clear_uncut_stock_at_the_edge_of_a_cut() {
    let d = scratch("safe-hop");
    let suzanne = fixture("suzanne.stl");
    let (_, rep) = carve_judged(
        &d,
        &[
            &suzanne,
            "--up",
            "y",
            "--resolution",
            "400",
            "--width",
            "60",
            "--depth",
            "3",
            "--tool",
            "ball:2",
            "--flat-background",
            "--allow-deep-cuts",
        ],
    );
    let rapids = &rep["rapids_in_stock"];
    assert!(rapids.as_array().unwrap().is_empty(), "{rapids}");
    no_plunge_nor_gouge(&rep);
    std::fs::remove_dir_all(d).unwrap();
}

/// A sharp tool's tip between the planning cells' centres meets the
/// material of the cell it is in: a V-bit finishing the roughed demo and
/// Spot ramps in where it starts in the stock left on the relief (at 160
/// px it went straight down into it 56 and 70 times, its tip between
/// centres that stood 0.25 mm above it; Spot's last one on the panel's
/// corner, exactly half a cell's diagonal from the nearest centre).
#[test]
fn a_v_bit_ramps_into_the_stock_roughing_left() {
    let d = scratch("safe-vbit");
    let spot = fixture("spot.obj");
    for model in [None, Some(spot.as_str())] {
        let mut a = vec!["--resolution", "160", "--tool", "vbit:60:6"];
        a.extend(model);
        let (_, rep) = carve_judged(&d, &a);
        no_plunge_nor_gouge(&rep);
    }
    std::fs::remove_dir_all(d).unwrap();
}

/// A flat end mill's moves are checked exactly along them against the
/// relief's surface, where its rim meets an edge or a sample: the 160 px
/// demo's flat:2 finish cut 0.0134 mm into the surface between probes at
/// the axis' crossings alone, 0.0016 mm with probes where the rim met
/// samples and edges; now under 0.001 mm, on cells a fifth of a sample
/// and by the simulator's exact measure along every move.
#[test]
fn a_flat_end_mill_s_rim_keeps_off_the_surface_between_samples() {
    let d = scratch("safe-flat-rim");
    let (_, rep) = carve_simulated(
        &d,
        &["--resolution", "160", "--tool", "flat:2"],
        &["--oversample", "5"],
    );
    let gouge = rep["max_gouge_mm"].as_f64().unwrap();
    assert!(
        gouge < 0.001,
        "gouge {gouge} mm at {} {}",
        rep["max_gouge_at_mm"],
        rep["max_gouge_line"]
    );
    assert!(rep["gouge_exact_per_move"].as_bool().unwrap());
    std::fs::remove_dir_all(d).unwrap();
}

/// A coarse relief (the 48 px demo, 60 mm wide, 3 mm deep: 1.25 mm
/// samples) is judged as `simulate` sees it with its default fine cells:
/// no tool cuts deeper than the material allows, and the job's own
/// figures agree with the simulator's. (Beside the touch-off pad a strip
/// a roughing stepover wide used to stand at the stock top, and the
/// finish met it 1.817 mm deep where the judge's coarse cells saw 0.70.)
#[test]
fn a_coarse_relief_is_judged_as_the_simulator_sees_it() {
    let d = scratch("safe-coarse");
    let (relief, job) = (d.join("r.png"), d.join("job.nc"));
    demo_relief(&relief, "48");
    let out = run(&[
        "toolpath",
        relief.to_str().unwrap(),
        "-o",
        job.to_str().unwrap(),
    ]);
    ok(&out);
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    let text = std::fs::read_to_string(&job).unwrap();
    assert!(text.contains("(touch-off pad: "), "{}", &text[..1500]);
    let rep = simulate_report(&job, &relief, &d.join("cut.png"), &[]);
    let e = &rep["engagement"];
    for t in e["tools"].as_array().unwrap() {
        let (name, axial) = (
            t["tool"].as_str().unwrap(),
            t["max_axial_mm"].as_f64().unwrap(),
        );
        // the job's own figure: "ball:3.175: depth of cut up to 0.750 mm"
        let own: f64 = stdout
            .lines()
            .find_map(|l| l.strip_prefix(&format!("{name}: depth of cut up to ")))
            .and_then(|l| l.split(' ').next())
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("{name} in {stdout}"));
        eprintln!("{name}: simulated {axial:.3} mm, judged {own:.3} mm");
        assert!(axial <= 1.59 + 0.005, "{name}: {axial} mm");
        assert!(
            (axial - own).abs() <= 0.1,
            "{name}: {axial} simulated, {own} judged"
        );
    }
    // (a layer's ramp, run backwards over a step its pass climbs, used to
    // plunge 0.1 mm)
    no_plunge_nor_gouge(&rep);
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
    // the lines named are the written file's, comments put in after the
    // judging counted: `simulate` on its default cells, the ones the job
    // was judged on, names the very same lines and figures
    let sim = run(&[
        "simulate",
        job.to_str().unwrap(),
        "--relief",
        d.join("job-relief.png").to_str().unwrap(),
        "-o",
        d.join("cut.png").to_str().unwrap(),
    ]);
    ok(&sim);
    let engaged = |s: &str| -> Vec<String> {
        s.lines()
            .filter(|l| l.contains("depth of cut up to") || l.starts_with("plunges into"))
            .map(String::from)
            .collect()
    };
    let simulated = format!(
        "{}{}",
        String::from_utf8_lossy(&sim.stdout),
        String::from_utf8_lossy(&sim.stderr)
    );
    assert_eq!(engaged(&said), engaged(&simulated), "{said}\n{simulated}");
    assert!(engaged(&said).len() >= 2);
    let n: usize = said
        .split("--allow-deep-cuts: line ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|v| v.parse().ok())
        .unwrap();
    let named = text.lines().nth(n - 1).unwrap();
    assert!(
        named.starts_with('X') || named.starts_with("G1"),
        "line {n}: {named}"
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

/// The touch-off pad's centre and side from a job header's
/// `(touch-off pad: S mm square at Xx Yy, ...)` line.
fn pad_of(job: &std::path::Path) -> (f64, f64, f64) {
    let text = std::fs::read_to_string(job).unwrap();
    let line = text
        .lines()
        .find(|l| l.starts_with("(touch-off pad:"))
        .unwrap_or_else(|| panic!("{}: no pad line", job.display()));
    let num = |after: &str| -> f64 {
        let rest = &line[line.find(after).unwrap() + after.len()..];
        let end = rest
            .find(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-'))
            .unwrap_or(rest.len());
        rest[..end].parse().unwrap()
    };
    (num(" at X"), num(" Y"), num("pad: "))
}

/// A simulated cut (as a relief PNG: stock top = depth) with the job
/// coordinates of each cell's centre.
fn cut_cells(png: &std::path::Path) -> Vec<(f64, f64, f64)> {
    let (w, h, v, _) = relief_mm(png);
    let side = sidecar(png);
    let p = side["width_mm"].as_f64().unwrap() / w as f64;
    let x0 = side["params"]["x0_mm"].as_f64().unwrap();
    let top = side["params"]["y0_mm"].as_f64().unwrap() + side["height_mm"].as_f64().unwrap();
    (0..w * h)
        .map(|k| {
            let (i, j) = (k % w, k / w);
            (x0 + (i as f64 + 0.5) * p, top - (j as f64 + 0.5) * p, v[k])
        })
        .collect()
}

/// Heights of the cells within `half` mm of (x, y).
fn near(cells: &[(f64, f64, f64)], (x, y, half): (f64, f64, f64)) -> Vec<f64> {
    cells
        .iter()
        .filter(|c| (c.0 - x).abs() <= half && (c.1 - y).abs() <= half)
        .map(|c| c.2)
        .collect()
}

/// Acceptance 3: roughing leaves the pad at the stock top, the finishing
/// file cuts it; Z0 on the spoilboard cuts the same surface as Z0 on top.
#[test]
fn the_pad_stands_through_roughing_and_z0_bottom_cuts_the_same() {
    let d = scratch("safe-pad");
    let job = d.join("job.nc");
    let rough = d.join("job-rough.nc");
    let relief = d.join("job-relief.png");
    let common = [
        "carve",
        "--resolution",
        "150",
        "--rough",
        "T1",
        "--stock",
        "100x60x8",
        "-q",
    ];
    let carve = |extra: &[&str]| {
        let mut a = common.to_vec();
        a.extend_from_slice(extra);
        a.extend(["-o", job.to_str().unwrap()]);
        ok(&run(&a));
    };
    carve(&["--split"]);
    let (px, py, side) = pad_of(&rough);
    let (_, _, _, depth) = relief_mm(&relief);
    let pitch = 100.0 / 150.0;
    let panel_h = sidecar(&relief)["height_mm"].as_f64().unwrap();
    let cut = d.join("cut.png");
    let rep = simulate_report(&rough, &relief, &cut, &[]);
    assert!(rep["frame"].as_str().unwrap().contains("T8"), "{rep}");
    let pad = near(&cut_cells(&cut), (px, py, side / 2.0 - pitch));
    assert!(!pad.is_empty());
    let lowest = pad.iter().cloned().fold(f64::INFINITY, f64::min);
    eprintln!(
        "pad {side} mm at X{px} Y{py}: {} cells, lowest {:.4} mm below the top after roughing",
        pad.len(),
        depth - lowest
    );
    assert!(lowest >= depth - 1e-4, "roughing cut the pad");
    // roughing and finishing in turn: the pad cut down to the relief
    let both = simulate_report(&rough, &relief, &cut, &[job.to_str().unwrap()]);
    let top_cut = cut_cells(&cut);
    let gouge = both["max_gouge_mm"].as_f64().unwrap();
    let residual = both["max_residual_mm"].as_f64().unwrap();
    // the relief under the pad, from the panel's place in the frame
    let frame = relievo::cam::layout::Frame::find(&std::fs::read_to_string(&job).unwrap())
        .unwrap()
        .unwrap();
    let (ox, oy) = frame.panel;
    let (rw, rh, rv, _) = relief_mm(&relief);
    let relief_cells: Vec<(f64, f64, f64)> = (0..rw * rh)
        .map(|k| {
            let (i, j) = (k % rw, k / rw);
            let (x, y) = ((i as f64 + 0.5) * pitch, panel_h - (j as f64 + 0.5) * pitch);
            (x + ox, y + oy, rv[k])
        })
        .collect();
    // cell by cell over the pad: the cut at the relief within the
    // residual, where roughing had left the stock top
    let half = side / 2.0 - pitch;
    let (mut n, mut worst, mut deepest) = (0, 0.0f64, 0.0f64);
    for c in top_cut
        .iter()
        .filter(|c| (c.0 - px).abs() <= half && (c.1 - py).abs() <= half)
    {
        let r = relief_cells
            .iter()
            .find(|r| (r.0 - c.0).abs() < pitch / 2.0 && (r.1 - c.1).abs() < pitch / 2.0)
            .unwrap();
        worst = worst.max(c.2 - r.2);
        deepest = deepest.max(depth - c.2);
        n += 1;
    }
    eprintln!(
        "rough + finish: gouge {gouge:.4} mm, residual max {residual:.4} mm; over the pad's \
         {n} cells the cut lies up to {worst:.4} mm above the relief and up to {deepest:.3} mm \
         below the stock top"
    );
    assert!(gouge < 0.001 && residual < 0.15, "{both}");
    // (cells against the nearest relief sample, not the surface between
    // samples the simulator measures: within the merge tolerance)
    assert!(n > 50 && worst <= residual + 0.005 && deepest > 0.3);

    // Z0 on the spoilboard with roughing: no pad, no gouge
    carve(&["--z-zero", "bottom"]);
    let text = std::fs::read_to_string(&job).unwrap();
    assert!(text.contains("Z0 bottom") && !text.contains("touch-off pad"));
    let rep = simulate_report(&job, &relief, &cut, &[]);
    assert!(rep["max_gouge_mm"].as_f64().unwrap() < 0.001, "{rep}");
    assert!(rep["max_residual_mm"].as_f64().unwrap() < 0.15, "{rep}");
    // the same job zeroed on top and on the spoilboard cuts the same
    // surface (a relief the finishing tool cuts in one pass: no pad)
    let mut cuts = Vec::new();
    for z0 in ["top", "bottom"] {
        ok(&run(&[
            "carve",
            "--resolution",
            "150",
            "--depth",
            "1.2",
            "--stock",
            "104x64x6",
            "--z-zero",
            z0,
            "-o",
            job.to_str().unwrap(),
            "-q",
        ]));
        simulate_report(&job, &relief, &cut, &[]);
        cuts.push(cut_cells(&cut));
    }
    let worst = cuts[0]
        .iter()
        .zip(&cuts[1])
        .map(|(a, b)| (a.2 - b.2).abs())
        .fold(0.0, f64::max);
    eprintln!(
        "Z0 bottom vs top: {} cells, largest difference {worst:.6} mm",
        cuts[0].len()
    );
    assert!(worst < 0.001, "{worst}");
    std::fs::remove_dir_all(d).unwrap();
}

/// Acceptance 4: a G20 job cuts what the mm job cuts (within 1 um), and
/// the simulated GRBL runs every line of it.
#[test]
fn an_inch_job_cuts_what_the_mm_job_cuts() {
    use relievo::grbl::{port::MemPort, sim::SimGrbl};
    use relievo::ops::send::SendJob;
    let d = scratch("safe-inch");
    let (mm, inch) = (d.join("mm.nc"), d.join("in.nc"));
    let relief = d.join("mm-relief.png");
    for (job, units) in [(&mm, "mm"), (&inch, "in")] {
        ok(&run(&[
            "carve",
            "--resolution",
            "120",
            "--units",
            units,
            "-o",
            job.to_str().unwrap(),
            "-q",
        ]));
    }
    let text = std::fs::read_to_string(&inch).unwrap();
    assert!(
        text.contains("G20") && !text.contains("G21"),
        "not a G20 job"
    );
    let cut = |job: &std::path::Path, name: &str| {
        let png = d.join(name);
        let rep = simulate_report(job, &relief, &png, &[]);
        assert!(rep["max_gouge_mm"].as_f64().unwrap() < 0.001, "{rep}");
        relief_mm(&png).2
    };
    let (a, b) = (cut(&mm, "cut-mm.png"), cut(&inch, "cut-in.png"));
    let worst = a
        .iter()
        .zip(&b)
        .map(|(p, q)| (p - q).abs())
        .fold(0.0, f64::max);
    eprintln!(
        "inch vs mm job: largest difference {worst:.6} mm over {} cells",
        a.len()
    );
    // within one Z step of the grbl-generic profile (its 250 steps/mm):
    // the writer fits a move shorter than a step to the machine's steps
    // (left out, or a whole step up), and mm and inch numbers round to
    // the step grid differently
    assert!(worst < 0.004 + 1e-6, "{worst}");
    // GRBL's parser (the simulated machine's) takes every line
    let machine = relievo::machine::Machine::load("grbl-generic").unwrap();
    let mut port = MemPort::new(SimGrbl::new(&machine), 115200);
    let send = SendJob {
        job: inch.clone(),
        rx_buffer: 128,
        // the job's tool change (M0): continue at once
        on_pause: relievo::grbl::sender::OnPause::Continue,
        ..Default::default()
    };
    let (_, n) = send
        .run(&mut port, &std::sync::atomic::AtomicBool::new(false))
        .unwrap();
    // acknowledged is queued: let the machine finish its planner
    port.sim.advance(1e9);
    assert_eq!(port.sim.log.len(), n);
    assert!(port.sim.log.iter().any(|l| l.starts_with("G20")));
    std::fs::remove_dir_all(d).unwrap();
}

/// Acceptance 6: `--cutout --tabs 4`: simulated, the panel is cut free
/// along its outline but for four tabs of the stated size.
#[test]
fn the_cutout_goes_through_but_for_four_tabs() {
    let d = scratch("safe-cutout");
    let relief = d.join("relief.png");
    let job = d.join("job.nc");
    ok(&run(&[
        "relief",
        "--resolution",
        "200",
        "--depth",
        "5",
        "-o",
        relief.to_str().unwrap(),
        "-q",
    ]));
    let (pw, ph) = (
        sidecar(&relief)["width_mm"].as_f64().unwrap(),
        sidecar(&relief)["height_mm"].as_f64().unwrap(),
    );
    // 5.5 mm stock under a 5 mm relief: the simulated cut (drawn down to
    // the relief's depth) shows the tabs' tops, 2 mm over the bottom, at
    // 1.5 mm, and a cut through at 0
    let stock = format!("{}x{}x5.5", pw + 10.0, ph + 10.0);
    let out = run(&[
        "toolpath",
        relief.to_str().unwrap(),
        "--stock",
        &stock,
        "--margin",
        "5",
        "--cutout",
        "--tabs",
        "4",
        "--tab-width",
        "6",
        "--tab-height",
        "2",
        "-o",
        job.to_str().unwrap(),
    ]);
    ok(&out);
    let said = String::from_utf8_lossy(&out.stdout);
    let cut = d.join("cut.png");
    // one cell per pixel: read below at the relief's pixels
    let rep = simulate_report(&job, &relief, &cut, &["--oversample", "1"]);
    assert!(rep["max_gouge_mm"].as_f64().unwrap() < 0.001, "{rep}");
    assert!(rep["engagement"]["plunges"].as_array().unwrap().is_empty());
    let cells = cut_cells(&cut);
    let pitch = pw / 200.0;
    // the slot's centre line, one tool radius (1/8" flat) outside the panel
    let r = 3.175 / 2.0;
    let (x0, y0, x1, y1) = (5.0 - r, 5.0 - r, 5.0 + pw + r, 5.0 + ph + r);
    let corners = [(x0, y0), (x1, y0), (x1, y1), (x0, y1), (x0, y0)];
    let mut ring = Vec::new();
    for w in corners.windows(2) {
        let len = ((w[1].0 - w[0].0).abs() + (w[1].1 - w[0].1).abs()) / pitch;
        for k in 0..len as usize {
            let t = k as f64 / len;
            let (x, y) = (
                w[0].0 + (w[1].0 - w[0].0) * t,
                w[0].1 + (w[1].1 - w[0].1) * t,
            );
            let c = cells
                .iter()
                .min_by(|a, b| {
                    let da = (a.0 - x).powi(2) + (a.1 - y).powi(2);
                    let db = (b.0 - x).powi(2) + (b.1 - y).powi(2);
                    da.total_cmp(&db)
                })
                .unwrap();
            ring.push(c.2);
        }
    }
    let through = ring.iter().filter(|&&h| h < 1e-3).count();
    // runs at the tab's top, 1.5 mm over the relief's floor
    let mut runs = Vec::new();
    let mut n = 0;
    for &h in ring.iter().chain(std::iter::once(&0.0)) {
        if (h - 1.5).abs() < 0.02 {
            n += 1;
        } else if n > 0 {
            runs.push(n as f64 * pitch);
            n = 0;
        }
    }
    eprintln!(
        "cutout: {} of {} ring cells cut through; tabs at the top {runs:?} mm long\n{said}",
        through,
        ring.len()
    );
    assert_eq!(runs.len(), 4, "{runs:?}");
    assert!(runs.iter().all(|l| (l - 6.0).abs() <= 2.0 * pitch + 1e-9));
    // all but the tabs and their 30-degree flanks cut through
    let flanks = 4.0 * (6.0 + 2.0 * 2.1 / 30f64.to_radians().tan()) / pitch;
    assert!(through as f64 >= ring.len() as f64 - flanks - 8.0);
    assert!(said.contains("cutout"), "{said}");
    std::fs::remove_dir_all(d).unwrap();
}

/// Acceptance 5 (tiles): a 600 x 400 mm stock on the 3018 (travel 300 x
/// 180) in tiles that each fit; their simulated cuts put together equal
/// the one big job's (on a machine large enough) within 1 um.
#[test]
fn tiles_fit_the_machine_and_cut_what_the_big_job_cuts() {
    let d = scratch("safe-tiles");
    let relief = d.join("big.png");
    ok(&run(&[
        "relief",
        "--resolution",
        "600",
        "--width",
        "600",
        "-o",
        relief.to_str().unwrap(),
        "-q",
    ]));
    // the 3018 with room for the whole panel
    let big = d.join("big.toml");
    let profile = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("machines/3018.toml"),
    )
    .unwrap();
    std::fs::write(
        &big,
        profile.replacen("x = 300.0\ny = 180.0", "x = 1000.0\ny = 1000.0", 1),
    )
    .unwrap();
    let toolpath = |machine: &str, out: &std::path::Path, extra: &[&str]| {
        let mut a = vec![
            "toolpath",
            relief.to_str().unwrap(),
            "--machine",
            machine,
            "--z-zero",
            "bottom",
            "--stock",
            "600x400x8",
            "--stepover",
            "1.5",
            "-o",
            out.to_str().unwrap(),
        ];
        a.extend_from_slice(extra);
        run(&a)
    };
    // the big job does not fit the 3018, and says to tile it
    let one = d.join("one.nc");
    let refused = toolpath("3018", &one, &[]);
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success() && err.contains("--tile"), "{err}");
    ok(&toolpath(big.to_str().unwrap(), &one, &[]));
    let tiled = d.join("t.nc");
    let out = toolpath("3018", &tiled, &["--tile", "280x170"]);
    ok(&out);
    let mut tiles: Vec<std::path::PathBuf> = std::fs::read_dir(&d)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.to_string_lossy().contains("t-tile"))
        .collect();
    tiles.sort();
    assert_eq!(tiles.len(), 9, "{tiles:?}");
    for t in &tiles {
        let text = std::fs::read_to_string(t).unwrap();
        assert!(text.contains("(tile "), "{}", t.display());
        let prog = relievo::gcode::program(&text).unwrap();
        let (lo, hi) = prog.bounds();
        let span = hi - lo;
        eprintln!(
            "{}: moves span {:.1} x {:.1} mm",
            t.display(),
            span.x,
            span.y
        );
        assert!(span.x <= 300.0 && span.y <= 180.0);
    }
    let c1 = d.join("c1.png");
    let r1 = simulate_report(&one, &relief, &c1, &["--machine", big.to_str().unwrap()]);
    let c2 = d.join("c2.png");
    let names: Vec<&str> = tiles.iter().map(|p| p.to_str().unwrap()).collect();
    let mut extra = vec!["--machine", "3018"];
    extra.extend(&names[1..]);
    let r2 = simulate_report(&tiles[0], &relief, &c2, &extra);
    let (a, b) = (relief_mm(&c1), relief_mm(&c2));
    assert_eq!((a.0, a.1), (b.0, b.1));
    let worst =
        a.2.iter()
            .zip(&b.2)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0, f64::max);
    eprintln!(
        "9 tiles vs one job: largest difference {worst:.6} mm over {} cells; removed {} / {} mm3; \
         out of travel: {}",
        a.2.len(),
        r1["removed_mm3"],
        r2["removed_mm3"],
        r2["out_of_travel"]
    );
    // (both within the merge tolerance of the same CL surface; tiles
    // are clipped, so their chords end elsewhere)
    assert!(worst < 0.002, "{worst}");
    assert!(r2["out_of_travel"].as_array().unwrap().is_empty());
    assert!(r2["max_gouge_mm"].as_f64().unwrap() < 0.001);
    std::fs::remove_dir_all(d).unwrap();
}

/// `--boundary subject`: the finishing tool stays on the subject and a
/// tool's diameter round it; the flat roughing tool clears the level
/// background; the cut is the relief, without gouge. A free (not level)
/// background is refused with the figures; the default holds it flat.
#[test]
fn the_finishing_tool_keeps_to_the_subject() {
    let d = scratch("safe-boundary");
    let job = d.join("job.nc");
    let spot = fixture("spot.obj");
    let carve = |extra: &[&str]| {
        let mut a = vec![
            "carve",
            spot.as_str(),
            "--resolution",
            "150",
            "--boundary",
            "subject",
            "-o",
            job.to_str().unwrap(),
        ];
        a.extend_from_slice(extra);
        run(&a)
    };
    let free = carve(&["--free-background"]);
    let err = String::from_utf8_lossy(&free.stderr);
    assert!(
        !free.status.success() && err.contains("without --free-background"),
        "{err}"
    );
    // Spot's picture has a background: held flat by default
    let out = carve(&[]);
    ok(&out);
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(said.contains("finishing over the subject"), "{said}");
    let relief = d.join("job-relief.png");
    let rep = simulate_report(&job, &relief, &d.join("cut.png"), &[]);
    assert!(rep["max_gouge_mm"].as_f64().unwrap() < 0.001, "{rep}");
    assert!(rep["max_residual_mm"].as_f64().unwrap() < 0.15, "{rep}");
    // the finishing tool's cutting moves: over the subject (off the
    // level background) or within its diameter of it
    let (w, h, v, _) = relief_mm(&relief);
    let side = sidecar(&relief);
    let (pw, ph) = (
        side["width_mm"].as_f64().unwrap(),
        side["height_mm"].as_f64().unwrap(),
    );
    let p = pw / w as f64;
    let subject: Vec<(f64, f64)> = (0..w * h)
        .filter(|&k| v[k] > 0.01)
        .map(|k| {
            (
                (k % w) as f64 * p + p / 2.0,
                ph - ((k / w) as f64 * p + p / 2.0),
            )
        })
        .collect();
    let text = std::fs::read_to_string(&job).unwrap();
    let from = text
        .lines()
        .position(|l| l.contains("for finishing)"))
        .unwrap();
    let prog = relievo::gcode::program(&text).unwrap();
    let mut far = 0.0f64;
    for s in prog
        .segments
        .iter()
        .filter(|s| s.line > from && s.kind == relievo::gcode::Kind::Feed)
        .step_by(7)
    {
        let nearest = subject
            .iter()
            .map(|q| ((q.0 - s.b.x).powi(2) + (q.1 - s.b.y).powi(2)).sqrt())
            .fold(f64::INFINITY, f64::min);
        far = far.max(nearest);
    }
    eprintln!("finishing moves lie within {far:.2} mm of the subject\n{said}");
    assert!(far <= 3.175 + 2.0 * p, "{far}");
    // and the job is shorter than finishing the whole panel: roughing cuts
    // the background to its level, so nothing goes over it twice
    let subject_s = rep["time_s"].as_f64().unwrap();
    let panel_job = d.join("panel.nc");
    ok(&run(&[
        "toolpath",
        relief.to_str().unwrap(),
        "--boundary",
        "panel",
        "-o",
        panel_job.to_str().unwrap(),
        "-q",
    ]));
    let panel_s = simulate_report(&panel_job, &relief, &d.join("cut.png"), &[])["time_s"]
        .as_f64()
        .unwrap();
    eprintln!("estimated {subject_s:.0} s on the subject, {panel_s:.0} s over the panel");
    assert!(subject_s < panel_s, "{subject_s} s against {panel_s} s");
    std::fs::remove_dir_all(d).unwrap();
}

/// Acceptance 7 (at test size): the armadillo's raster+waterline job
/// draws an SVG that rsvg-convert renders, in paths of at most 2000
/// moves, and its rapids are a small part of its travel.
#[test]
fn the_armadillo_svg_opens_and_its_rapids_are_short() {
    let d = scratch("safe-svg");
    let job = d.join("job.nc");
    let svg = d.join("job.svg");
    let out = run(&[
        "carve",
        &fixture("armadillo.obj"),
        "--resolution",
        "400",
        "--finish",
        "raster+waterline",
        "--allow-deep-cuts",
        "--svg",
        svg.to_str().unwrap(),
        "-o",
        job.to_str().unwrap(),
    ]);
    ok(&out);
    let said = String::from_utf8_lossy(&out.stdout);
    // "rapids R m, cutting C m; ..."
    let line = said.lines().find(|l| l.starts_with("rapids ")).unwrap();
    let m = |key: &str| -> f64 {
        let rest = &line[line.find(key).unwrap() + key.len()..];
        rest.split_whitespace().next().unwrap().parse().unwrap()
    };
    let (rapid, cut) = (m("rapids "), m("cutting "));
    eprintln!("armadillo 400 px, raster+waterline: rapids {rapid} m, cutting {cut} m");
    assert!(rapid < 0.2 * cut, "{said}");
    let text = std::fs::read_to_string(&svg).unwrap();
    for path in text.split("<path").skip(1) {
        let moves = path.matches('L').count();
        assert!(moves <= 2000, "a path of {moves} moves");
    }
    let rsvg = std::process::Command::new("rsvg-convert")
        .args(["-w", "800", "-o"])
        .arg(d.join("svg.png"))
        .arg(&svg)
        .output();
    match rsvg {
        Ok(o) => {
            assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
            let (w, _, v) = read_png16(&d.join("svg.png"));
            assert_eq!(w, 800);
            // drawn: not one colour
            assert!(v.iter().any(|&p| p != v[0]));
        }
        Err(_) if std::env::var("RELIEVO_REQUIRE_RSVG").is_err() => {
            eprintln!("rsvg-convert not installed: SVG not rendered (.ci/run installs it)")
        }
        Err(e) => panic!("rsvg-convert: {e}"),
    }
    std::fs::remove_dir_all(d).unwrap();
}

/// A refused job's advice fits the operation that cuts too deep, told by
/// the op the line belongs to, not by its tool: the Cornell box's back
/// view with a flat field and 2 mm steps has strips ~2.5 mm wide between
/// the box and the panel's edges, 2 mm deep, that a 3.175 mm flat cannot
/// rough (with 0.5 mm steps they were deep enough only while a subject
/// dipping below the field was lifted whole). With
/// the same flat roughing and finishing, the finish is the one over (it
/// used to be told to lower --step-down); with a roughing layer of 3 mm,
/// roughing is.
#[test]
fn refusals_advise_for_the_operation_that_cuts_too_deep() {
    let d = scratch("safe-advice");
    let model = fixture("cornell_box.obj");
    let job = d.join("job.nc");
    let base = [
        "carve",
        model.as_str(),
        "--view",
        "back",
        "--flat-background",
        "--steps",
        "2",
        "--resolution",
        "256",
        "-o",
        job.to_str().unwrap(),
    ];
    for (extra, advice) in [
        (
            &["--tool", "flat:3.175", "--rough", "flat:3.175"][..],
            "flat:3.175 cannot reach there, nor can the finishing tool's layers be entered",
        ),
        (
            &["--rough", "flat:3.175", "--step-down", "3"][..],
            "lower --step-down, or pass --allow-deep-cuts",
        ),
    ] {
        let mut args = base.to_vec();
        args.extend_from_slice(extra);
        let out = run(&args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{extra:?}: written");
        assert!(err.contains(advice), "{extra:?}: {err}");
        assert!(!job.exists(), "{extra:?}: a job left behind");
    }
    std::fs::remove_dir_all(d).unwrap();
}

/// A small finishing tool on the default job: roughing, then the 1 mm
/// ball's own layers wherever more is left than it may cut, and the
/// finish. Rows just outside the strip the finish keeps off round the
/// touch-off pad used to reach into material the layers had not cleared
/// (they kept off the same strip): the 160 px demo was refused at 0.534 mm
/// where 0.5 mm is allowed.
#[test]
fn a_small_finishing_tool_keeps_within_its_depth_of_cut() {
    let d = scratch("safe-small-ball");
    let (stdout, rep) = carve_judged(&d, &["--resolution", "160", "--tool", "ball:1"]);
    assert!(stdout.contains("ball:1 steps down in layers"), "{stdout}");
    // and, its layers taking most of the job, the faster plan is named
    assert!(
        stdout.contains("finishing with T2 (ball:3.175) and --rest ball:1"),
        "{stdout}"
    );
    let e = &rep["engagement"];
    for t in e["tools"].as_array().unwrap() {
        let axial = t["max_axial_mm"].as_f64().unwrap();
        let limit = if t["tool"] == "ball:1" { 0.5 } else { 1.59 };
        eprintln!("{}: axial {axial:.3} mm (limit {limit})", t["tool"]);
        assert!(axial <= limit + 0.005, "{}: {axial} mm", t["tool"]);
    }
    no_plunge_nor_gouge(&rep);
    std::fs::remove_dir_all(d).unwrap();
}
