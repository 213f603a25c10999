//! Outputs that cannot clobber the system or each other (issue 15, part):
//! only regular files are replaced, a relief's PNG and sidecar are checked
//! as a pair, an interrupted `carve` leaves nothing.

mod common;
use common::*;
use std::path::Path;
use std::process::Stdio;

fn relief_to(out: &Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec![
        "relief",
        "--resolution",
        "24",
        "-q",
        "-o",
        out.to_str().unwrap(),
    ];
    args.extend(extra);
    run(&args)
}

/// A device or FIFO as `-o` is refused and left as it was (renaming a
/// temporary file over /dev/null, as root, replaced the device node).
#[test]
fn devices_and_fifos_are_not_replaced() {
    let d = scratch("out-devices");
    for dev in ["/dev/null", "/dev/full"] {
        let o = relief_to(Path::new(dev), &[]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{dev}: {err}");
        assert!(err.contains("not a regular file"), "{dev}: {err}");
        use std::os::unix::fs::FileTypeExt;
        assert!(std::fs::metadata(dev).unwrap().file_type().is_char_device());
    }
    let fifo = d.join("fifo.png");
    let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
    // SAFETY: a plain mkfifo(3) call on a NUL-terminated path
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o644) }, 0);
    let o = relief_to(&fifo, &[]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("not a regular file"));
    use std::os::unix::fs::FileTypeExt;
    assert!(std::fs::metadata(&fifo).unwrap().file_type().is_fifo());
    std::fs::remove_dir_all(d).unwrap();
}

/// Two runs writing one `-o` at once (different views, so different
/// PNGs): whatever pair is left, a reader either gets the PNG its sidecar
/// was written with (byte for byte the PNG that view makes alone) or
/// refuses it, and no temporary file remains. `RELIEVO_RACES` sets the
/// number of races (40 by default).
#[test]
fn concurrent_runs_never_leave_a_mismatched_pair() {
    let d = scratch("out-race");
    let out = d.join("r.png");
    let job = d.join("j.nc");
    let alone = |view: &str| {
        let p = d.join(format!("{view}.png"));
        ok(&relief_to(&p, &["--view", view]));
        std::fs::read(&p).unwrap()
    };
    let (front, left) = (alone("front"), alone("left"));
    assert_ne!(front, left);
    let races: usize = std::env::var("RELIEVO_RACES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(40);
    let (mut accepted, mut refused) = (0, 0);
    for _ in 0..races {
        let spawn = |view: &str| {
            bin()
                .args(["relief", "--resolution", "24", "-q", "--view", view, "-o"])
                .arg(&out)
                .stderr(Stdio::null())
                .spawn()
                .unwrap()
        };
        let (mut a, mut b) = (spawn("front"), spawn("left"));
        let (sa, sb) = (a.wait().unwrap(), b.wait().unwrap());
        assert!(sa.success() && sb.success());
        let o = run(&[
            "toolpath",
            out.to_str().unwrap(),
            "-o",
            job.to_str().unwrap(),
            "--finish",
            "raster",
            "--tool",
            "ball:6",
            "-q",
        ]);
        let err = String::from_utf8_lossy(&o.stderr);
        if o.status.success() {
            accepted += 1;
            // the pair read is one run's: the PNG is what the sidecar's
            // view makes
            let side = sidecar(&out);
            let png = std::fs::read(&out).unwrap();
            let want = match side["params"]["camera"]["view"].as_str() {
                Some("front") => &front,
                Some("left") => &left,
                v => panic!("sidecar view {v:?}"),
            };
            assert!(
                &png == want,
                "a PNG beside another run's sidecar was accepted"
            );
        } else {
            assert!(err.contains("not the PNG its sidecar"), "{err}");
            refused += 1;
        }
    }
    let left: Vec<_> = std::fs::read_dir(&d)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
        .filter(|n| n.ends_with(".tmp"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
    eprintln!("{races} races: {accepted} pairs consistent, {refused} refused as mismatched");
    std::fs::remove_dir_all(d).unwrap();
}

/// A PNG swapped under its sidecar (same size, other content) is refused.
#[test]
fn a_png_that_is_not_its_sidecars_is_refused() {
    let d = scratch("out-swap");
    let (a, b) = (d.join("a.png"), d.join("b.png"));
    assert!(relief_to(&a, &["--view", "front"]).status.success());
    assert!(relief_to(&b, &["--view", "front", "--alpha", "1"])
        .status
        .success());
    std::fs::copy(&b, &a).unwrap();
    let o = run(&[
        "toolpath",
        a.to_str().unwrap(),
        "-o",
        d.join("j.nc").to_str().unwrap(),
        "-q",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("a.png: not the PNG its sidecar"),
        "{err}"
    );
    std::fs::remove_dir_all(d).unwrap();
}

/// `carve` interrupted while it plans the job leaves neither relief nor
/// job (the relief was written before the job is planned).
#[test]
fn an_interrupted_carve_leaves_nothing() {
    let d = scratch("out-carve-int");
    let job = d.join("job.nc");
    let mut child = bin()
        .args([
            "carve",
            "--resolution",
            "400",
            "-q",
            "--finish",
            "raster+waterline",
            "-o",
        ])
        .arg(&job)
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let relief = d.join("job-relief.png");
    let t = std::time::Instant::now();
    while !relief.exists() && t.elapsed().as_secs() < 60 {
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    assert!(relief.exists(), "the relief was never written");
    // SAFETY: signalling our own child process
    unsafe { libc::kill(child.id() as i32, libc::SIGINT) };
    let status = child.wait().unwrap();
    assert!(!status.success());
    let left: Vec<_> = std::fs::read_dir(&d)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
        .collect();
    assert!(left.is_empty(), "an interrupted carve left {left:?}");
    std::fs::remove_dir_all(d).unwrap();
}
