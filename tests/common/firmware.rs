//! The real GRBL 1.1h firmware, built as a host program: `grbl_sim.exe`
//! (the firmware on simulated hardware, its serial port on stdin/stdout)
//! and `gvalidate.exe` (GRBL's own G-code parser). The only part of the
//! tests that may look beside the repository: `RELIEVO_GRBL_SIM` names a
//! built `grbl_sim.exe` (with `gvalidate.exe` beside it), else the sources
//! and build script in `../shared/peers/grbl` are built once per run.
//! Without either a test says what it skipped and passes, unless
//! `RELIEVO_REQUIRE_FIRMWARE=1`, when it fails.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

pub struct Firmware {
    pub sim: PathBuf,
    pub validate: PathBuf,
    /// GRBL's `doc/csv` (error, alarm and setting codes), when its sources
    /// were built here.
    pub csv: Option<PathBuf>,
}

fn find() -> Result<Firmware, String> {
    if let Some(p) = std::env::var_os("RELIEVO_GRBL_SIM") {
        let sim = PathBuf::from(p);
        let validate = sim.with_file_name("gvalidate.exe");
        return if sim.is_file() && validate.is_file() {
            // built by build.sh DEST: DEST/grbl-sim/grbl_sim.exe, DEST/src
            let csv = sim
                .parent()
                .and_then(Path::parent)
                .map(|d| d.join("src/doc/csv"));
            Ok(Firmware { sim, validate, csv })
        } else {
            Err(format!(
                "RELIEVO_GRBL_SIM={}: no grbl_sim.exe with gvalidate.exe beside it",
                sim.display()
            ))
        };
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/peers/grbl/build.sh");
    if !script.is_file() {
        return Err(
            "the GRBL 1.1h firmware is not at hand (set RELIEVO_GRBL_SIM to a built \
             grbl_sim.exe, or keep ../shared/peers/grbl beside the repository)"
                .into(),
        );
    }
    let dest = Path::new(env!("CARGO_TARGET_TMPDIR")).join("grbl-firmware");
    let fw = Firmware {
        sim: dest.join("grbl-sim/grbl_sim.exe"),
        validate: dest.join("grbl-sim/gvalidate.exe"),
        csv: Some(dest.join("src/doc/csv")),
    };
    if fw.sim.is_file() && fw.validate.is_file() {
        return Ok(fw);
    }
    let out = Command::new("bash")
        .arg(&script)
        .arg(&dest)
        .output()
        .map_err(|e| format!("{}: {e}", script.display()))?;
    if !out.status.success() {
        return Err(format!(
            "building GRBL with {} failed: {}",
            script.display(),
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    Ok(fw)
}

/// The firmware, or None after one line saying why `test` was skipped.
pub fn firmware(test: &str) -> Option<&'static Firmware> {
    static FW: OnceLock<Result<Firmware, String>> = OnceLock::new();
    match FW.get_or_init(find) {
        Ok(fw) => Some(fw),
        Err(why) if std::env::var("RELIEVO_REQUIRE_FIRMWARE").as_deref() == Ok("1") => {
            panic!("{test}: {why} (RELIEVO_REQUIRE_FIRMWARE=1)")
        }
        Err(why) => {
            // straight to stderr: the test harness shows a passing test's
            // eprintln! to nobody, and a skip must not be silent
            use std::io::Write;
            let _ = writeln!(std::io::stderr(), "skipped {test}: {why}");
            None
        }
    }
}

/// `taskset -c 0 ` where taskset is at hand. grbl_sim's receive
/// interrupt (GRBL's own `serial.c`, built -O3 for the host) publishes the
/// ring's head before it stores the byte; on an AVR nothing runs between
/// the two, but the simulator's firmware thread, spinning on another
/// core, now and then reads the slot before the byte lands and parses a
/// stale one (about one run in three of a 20,000-line check on a busy
/// 2-core host: error:1 or error:25 on a line the pty delivered intact).
/// On one core the two threads take turns, and the check comes out whole.
fn one_core() -> &'static str {
    let here = Command::new("taskset").arg("-V").output();
    if here.is_ok_and(|o| o.status.success()) {
        "taskset -c 0 "
    } else {
        ""
    }
}

/// `grbl_sim.exe` on a pseudo-terminal (socat), in its own folder (its
/// EEPROM.DAT); killed when dropped.
pub struct OnPty {
    pub tty: PathBuf,
    child: std::process::Child,
    /// One firmware at a time: both its threads spin, on one core.
    _alone: std::sync::MutexGuard<'static, ()>,
}

impl OnPty {
    pub fn start(fw: &Firmware, dir: &Path) -> OnPty {
        static ONE: std::sync::Mutex<()> = std::sync::Mutex::new(());
        let alone = ONE.lock().unwrap_or_else(|e| e.into_inner());
        let tty = dir.join("tty");
        let exec = format!(
            "EXEC:'{}{} -n -s /dev/null -b {}',pty,raw,echo=0",
            one_core(),
            fw.sim.display(),
            dir.join("blocks.log").display()
        );
        use std::os::unix::process::CommandExt;
        let child = Command::new("socat")
            .arg(format!("PTY,raw,echo=0,link={}", tty.display()))
            .arg(exec)
            .current_dir(dir)
            .process_group(0)
            .spawn()
            .expect("socat runs (apt-get install socat)");
        for _ in 0..100 {
            if tty.exists() {
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
        assert!(tty.exists(), "socat made no pty at {}", tty.display());
        // the firmware's welcome comes about a second after power-up
        std::thread::sleep(std::time::Duration::from_millis(1500));
        OnPty {
            tty,
            child,
            _alone: alone,
        }
    }
}

impl Drop for OnPty {
    fn drop(&mut self) {
        // socat and the firmware under it: its whole process group
        // SAFETY: a signal to a process group this test started
        unsafe { libc::kill(-(self.child.id() as i32), libc::SIGTERM) };
        let _ = self.child.wait();
    }
}
