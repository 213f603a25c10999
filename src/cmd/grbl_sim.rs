//! `relievo grbl-sim`: a simulated GRBL 1.1 machine on a pseudo-terminal.

use clap::Args;
use std::path::PathBuf;

/// What `--help` ends with.
pub const EXAMPLES: &str = "Examples:
  relievo grbl-sim --link sim-port &                    # a simulated GRBL at ./sim-port
  relievo grbl-sim --machine shapeoko --speed 20 --plate 10";

#[derive(Args)]
pub struct GrblSimArgs {
    /// Machine profile for travel, rates and buffer size.
    #[arg(long, default_value = "grbl-generic")]
    pub machine: String,
    /// Simulated motion runs this many times faster than real time.
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// Append every executed line to this file.
    #[arg(long)]
    pub log: Option<PathBuf>,
    /// Fault: reply error:CODE (default 20) to the Nth G-code line.
    #[arg(long, value_name = "N[:CODE]")]
    pub error_at: Option<String>,
    /// Fault: raise ALARM:CODE (default 1) at the Nth G-code line.
    #[arg(long, value_name = "N[:CODE]")]
    pub alarm_at: Option<String>,
    /// Fault: cut the link after this many bytes, as a pulled cable does
    /// (the machine runs on; replies are lost). When the host closes the
    /// port and opens it again, the board resets, as an Arduino does.
    #[arg(long)]
    pub disconnect_after: Option<usize>,
    /// Fault: a feed hold at the Nth G-code line that cycle start does not
    /// release (a stuck hold button, an open door), until a reset.
    #[arg(long, value_name = "N")]
    pub hold_at: Option<usize>,
    /// Fault: at the Nth G-code line the machine freezes: it answers
    /// status polls (Run) but neither moves nor takes another line.
    #[arg(long, value_name = "N")]
    pub freeze_at: Option<usize>,
    /// Fault: after the welcome, answer nothing and print [MSG:] lines.
    #[arg(long)]
    pub chatty: bool,
    /// Fault: probability of noise bytes in a reply line.
    #[arg(long, default_value_t = 0.0)]
    pub garble: f64,
    /// A touch plate on the stock: its thickness and where it lies
    /// (machine X, Y; 50 mm square), mm.
    #[arg(long, value_name = "THICKNESS[@X,Y]", value_parser = relievo::grbl::sim::Plate::parse)]
    pub plate: Option<relievo::grbl::sim::Plate>,
    /// Each tool's length in turn (the next one goes in at each M0, or
    /// when the process gets SIGUSR1: the operator's hand at a change the
    /// machine does not see), mm: a job that does not touch off again
    /// after a change cuts that much off.
    #[arg(long, value_name = "L1,L2,...", value_delimiter = ',')]
    pub tool_lengths: Vec<f64>,
    /// Also reach the machine at this path (a symbolic link to its
    /// pseudo-terminal), a name that stays the same from run to run.
    #[arg(long, value_name = "PATH")]
    pub link: Option<PathBuf>,
}

pub fn parse_fault(
    s: &Option<String>,
    default: u32,
    what: &str,
) -> relievo::Result<Option<(usize, u32)>> {
    let Some(s) = s else { return Ok(None) };
    let (n, c) = s.split_once(':').unwrap_or((s, ""));
    let n = n
        .parse()
        .map_err(|_| relievo::Error(format!("{what} {s}: expected N[:CODE]")))?;
    let c = if c.is_empty() {
        default
    } else {
        c.parse()
            .map_err(|_| relievo::Error(format!("{what} {s}: expected N[:CODE]")))?
    };
    Ok(Some((n, c)))
}

pub fn run(args: GrblSimArgs) -> relievo::Result<()> {
    use relievo::grbl::sim::{Faults, SimGrbl};
    use std::io::{Read, Write};
    let m = relievo::machine::Machine::load(&args.machine)?;
    if !(args.speed.is_finite() && args.speed > 0.0) {
        relievo::bail!("--speed {}: must be positive", args.speed);
    }
    let mut sim = SimGrbl::new(&m);
    if args.tool_lengths.iter().any(|l| !l.is_finite()) {
        relievo::bail!("--tool-lengths: give lengths in mm");
    }
    sim.plate = args.plate;
    sim.tool_lengths = args.tool_lengths.clone();
    sim.faults = Faults {
        error_at: parse_fault(&args.error_at, 20, "--error-at")?,
        alarm_at: parse_fault(&args.alarm_at, 1, "--alarm-at")?,
        disconnect_after: args.disconnect_after,
        garble: args.garble,
        hold_at: args.hold_at,
        freeze_at: args.freeze_at,
        chatty: args.chatty,
        ..Faults::default()
    };
    let (mut master, slave) = serialport::TTYPort::pair()
        .map_err(|e| relievo::Error(format!("grbl-sim: no pseudo-terminal: {e}")))?;
    let name = serialport::SerialPort::name(&slave).unwrap_or_default();
    // the host's side is closed here, so that the master sees when the
    // host closes the port (reads fail with EIO) and opens it again
    drop(slave);
    if let Some(link) = &args.link {
        make_link(link, &name)?;
    }
    println!("{name}");
    std::io::stdout().flush().ok();
    let mut log = match &args.log {
        Some(p) => Some(
            std::fs::File::create(p)
                .map_err(|e| relievo::Error(format!("{}: {e}", p.display())))?,
        ),
        None => None,
    };
    let mut logged = 0;
    serialport::SerialPort::set_timeout(&mut master, std::time::Duration::from_millis(2))
        .map_err(|e| relievo::Error(format!("grbl-sim: {e}")))?;
    fitted::watch();
    let start = std::time::Instant::now();
    let mut buf = [0u8; 1024];
    // whether the host has the port open
    let mut open = false;
    loop {
        if fitted::take() {
            sim.fit_next_tool();
        }
        let n = match master.read(&mut buf) {
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => 0,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => 0,
            Err(e)
                if e.raw_os_error() == Some(libc::EIO)
                    || e.kind() == std::io::ErrorKind::BrokenPipe =>
            {
                // nobody has the port open: the machine runs on unheard
                open = false;
                std::thread::sleep(std::time::Duration::from_millis(2));
                0
            }
            Err(e) => relievo::bail!("grbl-sim: {e}"),
        };
        let t = start.elapsed().as_secs_f64() * args.speed;
        sim.advance(t);
        let reopened = !open && (n > 0 || poll_open(&master));
        if reopened {
            open = true;
            if sim.disconnected {
                // a new connection after a cut: the board resets (DTR)
                sim.reconnect();
            }
        }
        for &b in &buf[..n] {
            sim.receive(b);
        }
        if !open {
            // a host that is not there hears nothing; the welcome from
            // power-up waits for the first one
            if sim.disconnected {
                sim.take_output();
            }
        } else {
            let out = sim.take_output();
            match master.write_all(&out) {
                Ok(()) => {}
                // the host closed the port between the read and this
                // write: what was said goes unheard, as above
                Err(e)
                    if e.raw_os_error() == Some(libc::EIO)
                        || e.kind() == std::io::ErrorKind::BrokenPipe =>
                {
                    open = false;
                }
                Err(e) => relievo::bail!("grbl-sim: {e}"),
            }
        }
        if let Some(f) = log.as_mut() {
            for l in &sim.log[logged..] {
                writeln!(f, "{l}").map_err(|e| relievo::Error(format!("grbl-sim log: {e}")))?;
            }
            logged = sim.log.len();
        }
        if sim.overflow > 0 {
            relievo::bail!(
                "grbl-sim: receive buffer overflow ({} bytes lost)",
                sim.overflow
            );
        }
    }
}

/// A symbolic link at `link` to the pseudo-terminal `pty`; an old link
/// there is replaced, anything else is left alone.
fn make_link(link: &std::path::Path, pty: &str) -> relievo::Result<()> {
    let what = |e: std::io::Error| relievo::Error(format!("--link {}: {e}", link.display()));
    match std::fs::symlink_metadata(link) {
        Ok(m) if m.file_type().is_symlink() => std::fs::remove_file(link).map_err(what)?,
        Ok(_) => relievo::bail!(
            "--link {}: a file is there; give a new path",
            link.display()
        ),
        Err(_) => {}
    }
    std::os::unix::fs::symlink(pty, link).map_err(what)
}

/// Whether the host side of the pseudo-terminal is open: the master
/// polls as hung up (and reads fail) while it is not.
fn poll_open(master: &serialport::TTYPort) -> bool {
    use std::os::fd::AsRawFd;
    let mut p = libc::pollfd {
        fd: master.as_raw_fd(),
        events: libc::POLLIN,
        revents: 0,
    };
    // SAFETY: one valid pollfd, no timeout
    let r = unsafe { libc::poll(&mut p, 1, 0) };
    r >= 0 && p.revents & libc::POLLHUP == 0
}

/// SIGUSR1: the operator fitted the next tool.
mod fitted {
    use std::sync::atomic::{AtomicBool, Ordering};

    static FITTED: AtomicBool = AtomicBool::new(false);

    extern "C" fn on_signal(_: libc::c_int) {
        FITTED.store(true, Ordering::SeqCst);
    }

    pub fn watch() {
        // SAFETY: the handler only stores to an atomic
        unsafe {
            libc::signal(libc::SIGUSR1, on_signal as *const () as libc::sighandler_t);
        }
    }

    pub fn take() -> bool {
        FITTED.swap(false, Ordering::SeqCst)
    }
}
