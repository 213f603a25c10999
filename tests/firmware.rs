//! relievo against the machine its users own: the real GRBL 1.1h firmware
//! (see common/firmware.rs for where it comes from, and what happens
//! when it is not at hand).

mod common;

use common::firmware::{firmware, OnPty};
use common::*;
use std::path::Path;
use std::process::Command;

/// GRBL's own parser's answer to each line of `job` (run in `dir`, where it
/// keeps its EEPROM.DAT): how many it answered, and the ones it refused
/// with their answers. An M0 would wait there for a cycle start that never
/// comes, so its lines are left out (and not counted).
fn refused(validate: &Path, dir: &Path, job: &Path) -> (usize, Vec<(usize, String)>) {
    let text = std::fs::read_to_string(job).unwrap();
    let kept: Vec<&str> = text.lines().filter(|l| l.trim() != "M0").collect();
    let plain = dir.join("gvalidate-input.nc");
    std::fs::write(&plain, kept.join("\n") + "\n").unwrap();
    let out = Command::new("timeout")
        .arg("60")
        .arg(validate)
        .arg(&plain)
        .current_dir(dir)
        .stdin(std::process::Stdio::null())
        .output()
        .expect("gvalidate.exe runs");
    assert_ne!(
        out.status.code(),
        Some(124),
        "gvalidate.exe hung on {}",
        job.display()
    );
    let text = String::from_utf8_lossy(&out.stdout).replace('\r', "");
    let answers: Vec<&str> = text
        .lines()
        .filter(|l| *l == "ok" || l.starts_with("error:"))
        .collect();
    let bad = answers
        .iter()
        .enumerate()
        .filter(|(_, a)| **a != "ok")
        .map(|(k, a)| (k + 1, a.to_string()))
        .collect();
    (answers.len(), bad)
}

/// Every line of relievo's jobs (roughing, tool changes, arcs, inches,
/// V-bits, waterlines) is one GRBL 1.1h's own parser accepts.
#[test]
fn grbl_s_own_parser_accepts_every_line_relievo_writes() {
    let Some(fw) = firmware("grbl_s_own_parser_accepts_every_line_relievo_writes") else {
        return;
    };
    let d = scratch("fw-validate");
    for (name, extra) in [
        ("demo", vec![]),
        ("inch", vec!["--units", "in"]),
        (
            "vbit",
            vec!["--tool", "vbit:60", "--finish", "raster+waterline"],
        ),
        (
            "spot",
            vec!["--machine", "shapeoko", "--tool", "T2", "--rest", "ball:1"],
        ),
    ] {
        let job = d.join(format!("{name}.nc"));
        let mut args = vec![
            "carve",
            "-q",
            "--resolution",
            "96",
            "-o",
            job.to_str().unwrap(),
        ];
        let spot = fixture("spot.obj");
        if name == "spot" {
            args.insert(1, &spot);
        }
        args.extend(extra);
        ok(&run(&args));
        let text = std::fs::read_to_string(&job).unwrap();
        let lines = text.lines().filter(|l| l.trim() != "M0").count();
        let (answered, bad) = refused(&fw.validate, &d, &job);
        eprintln!(
            "{name}: GRBL's parser answered {answered} of {lines} lines, refused {}",
            bad.len()
        );
        assert_eq!(
            answered, lines,
            "{name}: GRBL's parser did not answer every line"
        );
        assert!(bad.is_empty(), "{name}: GRBL refused {bad:?}");
    }
    // the check has teeth: a line GRBL refuses is named
    let bad = d.join("bad.nc");
    std::fs::write(&bad, "G21 G90\nG1 X10 F500\nG1 X20 Q7\n").unwrap();
    assert_eq!(
        refused(&fw.validate, &d, &bad).1,
        [(3, "error:20".to_string())]
    );
    std::fs::remove_dir_all(d).unwrap();
}

/// `relievo send` on the firmware over a serial line: a job checked in
/// GRBL's check mode, one with a bad line refused at that line, one with
/// a tool change checked to its end, and a
/// small job run to its end with the machine idle where the job left it.
#[test]
fn send_streams_a_job_to_the_firmware() {
    let Some(fw) = firmware("send_streams_a_job_to_the_firmware") else {
        return;
    };
    let d = scratch("fw-send");
    let relief = d.join("coin.png");
    let coin = fixture("suzanne.stl");
    ok(&run(&[
        "relief",
        &coin,
        "--up",
        "y",
        "--width",
        "6",
        "--depth",
        "0.3",
        "--resolution",
        "24",
        "-q",
        "-o",
        relief.to_str().unwrap(),
    ]));
    let job = d.join("coin.nc");
    ok(&run(&[
        "toolpath",
        relief.to_str().unwrap(),
        "--tool",
        "ball:3",
        "--stepover",
        "60%",
        "--safe-z",
        "1",
        "-q",
        "-o",
        job.to_str().unwrap(),
    ]));
    let text = std::fs::read_to_string(&job).unwrap();
    assert!(!text.contains("\nM0"), "the small job needs one tool");
    let grbl = OnPty::start(fw, &d);
    let tty = grbl.tty.to_str().unwrap().to_string();
    let send = |args: &[&str]| {
        let mut a = vec!["60", env!("CARGO_BIN_EXE_relievo"), "send", "--port", &tty];
        a.extend_from_slice(args);
        Command::new("timeout").args(&a).output().unwrap()
    };
    let out = send(&["--check-only", job.to_str().unwrap()]);
    ok(&out);
    let said =
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    assert!(said.contains("check passed"), "{said}");

    let bad = d.join("bad.nc");
    std::fs::write(&bad, format!("{text}G1 X1 Q7\n")).unwrap();
    let out = send(&["--check-only", bad.to_str().unwrap()]);
    assert!(!out.status.success());
    let said = String::from_utf8_lossy(&out.stderr);
    let n = text.lines().count() + 1;
    assert!(
        said.contains(&format!("line {n}")) && said.contains("error:20"),
        "{said}"
    );

    // a job with a tool change checks to its end: GRBL's check mode does
    // not pause at M0, and the sender does not wait for it to
    let changes = d.join("changes.nc");
    ok(&run(&[
        "carve",
        "-q",
        "--resolution",
        "32",
        "-o",
        changes.to_str().unwrap(),
    ]));
    assert!(std::fs::read_to_string(&changes).unwrap().contains("\nM0"));
    let out = send(&["--check-only", changes.to_str().unwrap()]);
    ok(&out);
    assert!(String::from_utf8_lossy(&out.stderr).contains("check passed"));

    let start = std::time::Instant::now();
    let out = send(&["--on-pause", "continue", job.to_str().unwrap()]);
    ok(&out);
    eprintln!(
        "the job ran on the firmware in {:.1} s",
        start.elapsed().as_secs_f64()
    );
    let status = Command::new("timeout")
        .args([
            "20",
            env!("CARGO_BIN_EXE_relievo"),
            "machine",
            "status",
            "--port",
            &tty,
        ])
        .output()
        .unwrap();
    ok(&status);
    let said = String::from_utf8_lossy(&status.stdout);
    assert!(said.starts_with("<Idle|"), "{said}");
    // the firmware executed every motion block of the job
    let blocks = std::fs::read_to_string(d.join("blocks.log")).unwrap_or_default();
    assert!(blocks.lines().count() > 10, "{blocks}");
    drop(grbl);
    std::fs::remove_dir_all(d).unwrap();
}

/// A short job with a tool change (11 lines, ending at work X3 Y1 Z5).
const TOOL_CHANGE_JOB: &str = "G21 G90 G94\nG0 Z2\nG1 X2 Y1 F600\nG0 Z5\nM5\n\
    M0 (fit the 1 mm ball)\nG0 X1 Y1\nG1 Z0 F300\nG1 X3 F600\nG0 Z5\nM2\n";

/// The studio's Machine panel's connection on the firmware: it reads
/// GRBL's own status reports (work offset, overrides, buffer), jogs and
/// zeroes, tells a refusal's meaning, and lends its port to the sender
/// for a job with a tool change, which pauses for the page and runs to
/// its end when told to go on.
#[test]
fn the_machine_panel_s_session_drives_the_firmware() {
    use relievo::grbl::port::SerialLink;
    use relievo::grbl::session::{jog_line, zero_line, JobRun, Readout, Session};
    use relievo::ops::send::SendJob;
    let Some(fw) = firmware("the_machine_panel_s_session_drives_the_firmware") else {
        return;
    };
    let d = scratch("fw-session");
    let grbl = OnPty::start(fw, &d);
    let tty = grbl.tty.to_str().unwrap().to_string();
    let s = std::sync::Arc::new(Session::open(
        Box::new(SerialLink::open(&tty, 115200).unwrap()),
        &tty,
    ));
    let wait = |what: &str, secs: f64, f: &dyn Fn(&Readout) -> bool| -> Readout {
        let t = std::time::Instant::now();
        let mut r = s.shared.now();
        while !f(&r) {
            assert!(t.elapsed().as_secs_f64() < secs, "{what}: {r:?}");
            r = s.shared.after(r.seq, 0.2);
        }
        r
    };
    let r = wait("Idle with its offsets", 10.0, &|r| {
        r.state.as_deref() == Some("Idle") && r.wco.is_some() && r.overrides.is_some()
    });
    assert_eq!(r.overrides, Some([100, 100, 100]));
    // (GRBL's default $10=1 leaves the buffer out of its reports)
    s.line(&jog_line([Some(5.0), None, None], 1000.0).unwrap())
        .unwrap();
    wait("jogged 5 mm", 20.0, &|r| {
        r.state.as_deref() == Some("Idle") && r.mpos.is_some_and(|p| (p[0] - 5.0).abs() < 1e-3)
    });
    s.line(&zero_line("x").unwrap()).unwrap();
    let r = wait("work X zeroed", 10.0, &|r| {
        r.wpos.is_some_and(|p| p[0].abs() < 1e-3)
    });
    assert!((r.mpos.unwrap()[0] - 5.0).abs() < 1e-3);
    s.line("G1 X1 Q7").unwrap();
    let r = wait("the refusal", 10.0, &|r| {
        r.console.iter().any(|c| c.text == "error:20")
    });
    let e = r.console.iter().find(|c| c.text == "error:20").unwrap();
    assert!(e.meaning.is_some_and(|m| m.contains("unsupported")));

    // a short job with a tool change, lent the port like the page's Run
    let job = d.join("change.nc");
    std::fs::write(&job, TOOL_CHANGE_JOB).unwrap();
    let run = SendJob {
        job: job.clone(),
        rx_buffer: 128,
        remote: Some(s.remote()),
        ..SendJob::default()
    };
    let shared = s.shared.clone();
    s.lend(
        JobRun::default(),
        Box::new(move |port| {
            let ran = run.run(port, &std::sync::atomic::AtomicBool::new(false));
            match ran {
                Ok((_, n)) => shared.end_job(format!("done: {n}"), true, false),
                Err(e) => shared.end_job(e.0, false, false),
            }
        }),
    )
    .unwrap();
    let r = wait("the pause", 30.0, &|r| {
        r.job.as_ref().is_some_and(|j| j.paused.is_some())
    });
    let pause = r.job.unwrap().paused.unwrap();
    assert!(pause.contains("fit the 1 mm ball"), "{pause}");
    // stopped before the M0, the machine stands Idle: the carver jogs
    // (and would probe) there, and going on puts it back where the job was
    let r = wait("Idle at the change", 20.0, &|r| {
        r.state.as_deref() == Some("Idle")
    });
    let z = r.wpos.unwrap()[2];
    s.line(&jog_line([None, None, Some(-3.0)], 600.0).unwrap())
        .unwrap();
    wait("jogged down at the change", 20.0, &|r| {
        r.state.as_deref() == Some("Idle")
            && r.wpos.is_some_and(|p| (p[2] - (z - 3.0)).abs() < 1e-3)
    });
    s.go_on();
    let r = wait("the job's end", 60.0, &|r| {
        r.job.as_ref().is_some_and(|j| j.outcome.is_some())
    });
    let j = r.job.unwrap();
    assert_eq!(j.outcome.as_deref(), Some("done: 11"), "{j:?}");
    let r = wait("the end position", 20.0, &|r| {
        r.state.as_deref() == Some("Idle") && r.wpos.is_some_and(|p| (p[0] - 3.0).abs() < 1e-3)
    });
    eprintln!("the session on the firmware: {:?}", r.wpos);
    drop(s);
    drop(grbl);
    std::fs::remove_dir_all(d).unwrap();
}

/// The Machine panel in Chromium on the real firmware, the flow of the
/// studio test without the probe: connect, jog, zero, a job file brought
/// to the page, checked in GRBL's check mode, run to its tool change
/// (the machine Idle, jogged there), continued to its end.
#[test]
fn the_page_drives_the_firmware() {
    use common::browser::{connect, lines_past, make_job, run_to_end, Browser, Studio};
    let Some(fw) = firmware("the_page_drives_the_firmware") else {
        return;
    };
    let d = scratch("fw-page");
    let Some(b) = Browser::start(&d) else {
        return;
    };
    let grbl = OnPty::start(fw, &d);
    let studio = Studio::start(&[]);
    let text = |css: &str, what: &str, secs: u64, f: &dyn Fn(&str) -> bool| -> String {
        b.wait(what, secs, || {
            let t = b.text(css);
            f(&t).then_some(t)
        })
    };
    b.goto(&studio.url);
    // the studio's own job, small enough for the firmware's real time: an
    // 8 mm relief, roughed with a flat and finished with a ball
    let summary = make_job(
        &b,
        &[
            ("#width", "8"),
            ("#depth", "1"),
            ("#resolution", "48"),
            ("#stepover", "2"),
            ("#rough", "flat:3.175"),
            ("[data-more=cut][data-name=rough_stepover]", "2.5"),
            ("[data-more=cut][data-name=safe_z]", "2"),
        ],
    );
    assert!(summary.contains("roughing flat:3.175"), "{summary}");
    connect(&b, &grbl.tty);
    b.script("document.getElementById('m-step').value = '10'");
    b.click("[data-jog='x+']");
    text("#m-mx", "machine X 10", 30, &|t| t == "10.000");
    b.click("[data-zero='x']");
    text("#m-wx", "work X 0", 20, &|t| t == "0.000");

    b.click("#m-check");
    let checked = text("#m-jobtext", "the check", 120, &|t| {
        t.contains("check passed") || t.contains("error") || t.contains("stopped")
    });
    assert!(checked.contains("check passed"), "{checked}");
    // run, stopped midway (hold, spindle off, reset), unlocked, resumed
    // from the journal through the tool change to the end
    b.click("#m-run");
    lines_past(&b, 40, 120);
    b.click("#m-stop");
    let stopped = text("#m-jobtext", "the stop", 60, &|t| t.contains("stopped"));
    assert!(stopped.contains("resume"), "{stopped}");
    // as a carver would: Unlock, and again if the firmware was still in
    // its reset when the first $X came (on a loaded host it can be)
    let idle = (0..3).any(|_| {
        b.click("#m-unlock");
        let t0 = std::time::Instant::now();
        while t0.elapsed().as_secs() < 15 {
            if b.text("#m-state") == "Idle" {
                return true;
            }
            std::thread::sleep(std::time::Duration::from_millis(200));
        }
        false
    });
    assert!(idle, "unlocked: {}", b.text("#m-state"));
    b.click("#m-resume");
    let pause = text("#m-pausetext", "the tool change", 180, &|t| {
        t.contains("M0")
    });
    assert!(pause.contains("ball:3.175"), "{pause}");
    text("#m-state", "Idle at the change", 30, &|t| t == "Idle");
    let z = b.text("#m-wz").parse::<f64>().unwrap();
    b.click("[data-jog='z+']");
    text("#m-wz", "jogged up", 30, &|t| {
        t.parse::<f64>().ok() == Some(z + 10.0)
    });
    b.shot("#machine-panel")
        .save(d.join("firmware-change.png"))
        .unwrap();
    let done = run_to_end(&b, "the job's end");
    assert!(done.starts_with("done"), "{done}");
    b.shot("#machine-panel")
        .save(d.join("firmware-panel.png"))
        .unwrap();
    eprintln!(
        "the page on the firmware: {checked}; {stopped}; {done}; {}",
        d.join("firmware-panel.png").display()
    );
    drop(grbl);
}

/// Every error and alarm code GRBL 1.1h documents (its own `doc/csv`) is
/// told with its meaning, never as unknown.
#[test]
fn every_grbl_error_and_alarm_code_is_told_with_its_meaning() {
    let Some(fw) = firmware("every_grbl_error_and_alarm_code_is_told_with_its_meaning") else {
        return;
    };
    let Some(csv) = fw.csv.as_ref().filter(|c| c.is_dir()) else {
        let why =
            "GRBL's doc/csv is not beside the built firmware (build.sh DEST puts it in DEST/src)";
        assert!(
            std::env::var("RELIEVO_REQUIRE_FIRMWARE").as_deref() != Ok("1"),
            "{why} (RELIEVO_REQUIRE_FIRMWARE=1)"
        );
        use std::io::Write;
        let _ = writeln!(std::io::stderr(), "skipped the code check: {why}");
        return;
    };
    let codes = |file: &str| -> Vec<u32> {
        std::fs::read_to_string(csv.join(file))
            .unwrap()
            .lines()
            .skip(1)
            .filter_map(|l| l.split(',').next()?.trim_matches('"').parse().ok())
            .collect()
    };
    let errors = codes("error_codes_en_US.csv");
    let alarms = codes("alarm_codes_en_US.csv");
    assert!(
        errors.len() >= 30 && alarms.len() >= 9,
        "{errors:?} {alarms:?}"
    );
    for e in &errors {
        let m = relievo::grbl::error_meaning(*e);
        assert!(!m.starts_with("unknown"), "error:{e} has no meaning");
    }
    for a in &alarms {
        let m = relievo::grbl::alarm_meaning(*a);
        assert!(!m.starts_with("unknown"), "ALARM:{a} has no meaning");
    }
    eprintln!(
        "GRBL 1.1h documents {} error and {} alarm codes; each is told with its meaning",
        errors.len(),
        alarms.len()
    );
}
