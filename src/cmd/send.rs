//! `relievo send`: stream a job to a GRBL controller.

use clap::Args;
use std::path::PathBuf;

/// What `--help` ends with.
pub const EXAMPLES: &str = "Examples:
  relievo send --port /dev/ttyUSB0 job.nc               # stream the job (asks at each tool change)
  relievo send --port COM3 --check job.nc               # GRBL's check mode first, then the cut
  relievo send --port /dev/ttyUSB0 --resume job.nc.journal job.nc";

#[derive(Args)]
pub struct SendArgs {
    /// G-code job.
    pub job: PathBuf,
    /// Serial device, e.g. /dev/ttyUSB0.
    #[arg(long)]
    pub port: String,
    #[arg(long, default_value_t = 115200)]
    pub baud: u32,
    /// Run the whole job in GRBL's check mode first; stop if any line fails.
    #[arg(long)]
    pub check: bool,
    /// Only validate the job in GRBL's check mode; run nothing.
    #[arg(long, conflicts_with_all = ["check", "resume", "resume_from"])]
    pub check_only: bool,
    /// Send one line and wait for its reply (slower; for troublesome links).
    #[arg(long)]
    pub send_response: bool,
    /// Start at this job line, re-entering safely.
    #[arg(long, conflicts_with = "resume")]
    pub resume_from: Option<usize>,
    /// Resume at the first line this journal leaves in doubt (sent, not
    /// known to have run); refused when running those again could change
    /// the cut.
    #[arg(long)]
    pub resume: Option<PathBuf>,
    /// Journal of sent, acknowledged and executed lines [default: JOB.journal].
    #[arg(long)]
    pub journal: Option<PathBuf>,
    /// Seconds without an answer from GRBL that mean the link is dead.
    #[arg(long, default_value_t = 10.0, value_name = "SECONDS")]
    pub link_timeout: f64,
    /// Seconds the machine may stay in feed hold (or with its door open)
    /// before `send` stops the spindle and gives up.
    #[arg(long, default_value_t = 600.0, value_name = "SECONDS")]
    pub hold_limit: f64,
    /// How long a controller that answers status polls but stands still
    /// and acknowledges no line is waited on before `send` holds, stops
    /// the spindle and gives up (told at half of it): `auto`, twice the
    /// planner's time for the moves GRBL holds ahead of the line it owes
    /// (at the reported overrides) plus 20 s, or seconds (beyond a dwell's
    /// own time).
    #[arg(long, default_value = "auto", value_name = "auto|SECONDS", value_parser = relievo::grbl::sender::Stall::parse)]
    pub stall_timeout: relievo::grbl::sender::Stall,
    /// At an M0 (a tool change): ask on the terminal, continue at once,
    /// touch off Z on the touch plate (--plate), or measure the new tool
    /// on the tool setter (--setter), and continue.
    #[arg(long, value_enum, default_value = "ask")]
    pub on_pause: relievo::grbl::sender::OnPause,
    /// The touch plate for --on-pause probe: its thickness and where it
    /// lies (work X, Y; without it, under the tool), mm.
    #[arg(long, value_name = "THICKNESS[@X,Y]", value_parser = relievo::grbl::sender::TouchOff::parse)]
    pub plate: Option<relievo::grbl::sender::TouchOff>,
    /// The tool setter for --on-pause setter: where it stands, machine
    /// X,Y and the Z to probe down from, mm (a machine file's [setter]).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_setter, allow_hyphen_values = true)]
    pub setter: Option<relievo::grbl::sender::Setter>,
}

/// Ctrl-C: set by the signal handler, read by the sender.
static CANCEL: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

extern "C" fn on_sigint(_: libc::c_int) {
    CANCEL.store(true, std::sync::atomic::Ordering::Relaxed);
}

pub fn run(args: SendArgs, quiet: bool) -> relievo::Result<()> {
    use relievo::grbl::port::SerialLink;
    use relievo::ops::send::SendJob;
    let job = SendJob {
        job: args.job,
        check: args.check,
        check_only: args.check_only,
        send_response: args.send_response,
        resume_from: args.resume_from,
        resume: args.resume,
        journal: args.journal,
        progress: !quiet,
        rx_buffer: 128,
        link_timeout: Some(args.link_timeout),
        hold_limit: Some(args.hold_limit),
        stall: Some(args.stall_timeout),
        on_pause: args.on_pause,
        plate: args.plate,
        setter: args.setter,
        keys: !quiet,
        remote: None,
    };
    if args.on_pause == relievo::grbl::sender::OnPause::Setter && args.setter.is_none() {
        relievo::bail!("--on-pause setter: give the tool setter with --setter X,Y,Z (machine, mm)");
    }
    if args.on_pause == relievo::grbl::sender::OnPause::Probe && args.plate.is_none() {
        relievo::bail!("--on-pause probe: give the touch plate with --plate THICKNESS[@X,Y]");
    }
    for (flag, v) in [
        ("--link-timeout", args.link_timeout),
        ("--hold-limit", args.hold_limit),
        (
            "--stall-timeout",
            match args.stall_timeout {
                relievo::grbl::sender::Stall::Seconds(s) => s,
                relievo::grbl::sender::Stall::Derived => 1.0,
            },
        ),
    ] {
        if !(v.is_finite() && (0.1..=86400.0).contains(&v)) {
            relievo::bail!("{flag} {v}: give seconds from 0.1 to 86400");
        }
    }
    // read the job before touching the machine
    relievo::grbl::sender::load_job(&job.job)?;
    let mut port = SerialLink::open(&args.port, args.baud)?;
    // SAFETY: the handler only stores to an atomic
    unsafe {
        libc::signal(
            libc::SIGINT,
            on_sigint as extern "C" fn(libc::c_int) as libc::sighandler_t,
        );
    }
    let (o, n) = job.run(&mut port, &CANCEL)?;
    if !quiet && !job.check_only {
        eprintln!(
            "{}: {n} lines sent and acknowledged in {:.1} s ({} bytes, {:.0} bytes/s)",
            job.job.display(),
            o.seconds,
            o.bytes,
            o.bytes as f64 / o.seconds.max(1e-9)
        );
    }
    Ok(())
}

/// The tool setter's machine `X,Y,Z`, mm.
fn parse_setter(s: &str) -> Result<relievo::grbl::sender::Setter, String> {
    relievo::ops::settings::parse_xyz(s).map(relievo::grbl::sender::Setter::at)
}
