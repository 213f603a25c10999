//! `relievo machine` and `relievo ports`: talk to a controller outside a job.

use clap::Args;

/// What `--help` ends with.
pub const EXAMPLES: &str = "Examples:
  relievo machine status --port /dev/ttyUSB0
  relievo machine jog --port /dev/ttyUSB0 --x 10 --feed 800
  relievo machine zero --port /dev/ttyUSB0 --axes z";

#[derive(Args)]
pub struct MachineArgs {
    #[arg(value_enum)]
    pub action: MachineAction,
    #[arg(long)]
    pub port: String,
    #[arg(long, default_value_t = 115200)]
    pub baud: u32,
    /// jog: distance along X, mm (relative to where the tool is).
    #[arg(long, allow_negative_numbers = true)]
    pub x: Option<f64>,
    /// jog: distance along Y, mm.
    #[arg(long, allow_negative_numbers = true)]
    pub y: Option<f64>,
    /// jog: distance along Z, mm.
    #[arg(long, allow_negative_numbers = true)]
    pub z: Option<f64>,
    /// jog: feed, mm/min.
    #[arg(long, default_value_t = 500.0)]
    pub feed: f64,
    /// zero: the axes whose work zero is set where the tool is.
    #[arg(long, default_value = "xyz")]
    pub axes: String,
    /// probe: the touch plate's thickness and where it lies (work X, Y;
    /// without it, under the tool), mm.
    #[arg(long, value_name = "THICKNESS[@X,Y]", value_parser = relievo::grbl::sender::TouchOff::parse)]
    pub plate: Option<relievo::grbl::sender::TouchOff>,
}

#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum MachineAction {
    /// The machine's state, read-only (never resets it).
    Status,
    /// $X: leave an alarm.
    Unlock,
    /// $H: home.
    Home,
    /// $$: the machine's settings.
    Settings,
    /// $J=: move by --x/--y/--z at --feed.
    Jog,
    /// G10 L20: work zero on --axes where the tool is.
    Zero,
    /// A Z touch-off on the plate (--plate): work Z0 on the stock under it.
    Probe,
    /// 0x18 soft reset: stops everything at once (a machine in motion
    /// loses its position: ALARM:3), then waits for GRBL's welcome.
    Reset,
}

pub fn run(args: MachineArgs) -> relievo::Result<()> {
    use relievo::grbl::{port::SerialLink, sender::Replies, session};
    let mut port = SerialLink::open(&args.port, args.baud)?;
    let mut r = Replies::new(&mut port);
    let lines = match args.action {
        // read-only: no handshake, so no soft reset of a board that is
        // running or holding; '?' again until a report comes (a board
        // that resets on connection answers once it has booted), then
        // until the work offset and the overrides have come, which GRBL
        // sends only every few reports
        MachineAction::Status => {
            let mut got: Vec<String> = Vec::new();
            let until = r.port.now() + 2.5;
            let mut asked = f64::MIN;
            let has =
                |got: &[String], f: &str| got.iter().any(|l| l.starts_with('<') && l.contains(f));
            while r.port.now() < until && !(has(&got, "|WCO:") && has(&got, "|Ov:")) {
                let gap = if has(&got, "") { 0.05 } else { 0.5 };
                if r.port.now() - asked >= gap {
                    r.port.write_all(b"?")?;
                    asked = r.port.now();
                }
                if let Some(l) = r.next(0.05)? {
                    got.push(l);
                }
            }
            let Some(whole) = relievo::grbl::sender::whole_report(got.iter().map(String::as_str))
            else {
                relievo::bail!("{}: no status report within 2.5 s of '?'", args.port);
            };
            got.retain(|l| !l.starts_with('<'));
            got.push(whole);
            got
        }
        MachineAction::Reset => {
            r.port.write_all(&[relievo::grbl::SOFT_RESET])?;
            r.handshake(2.5)?;
            r.command("$G", 5.0)?
        }
        action => {
            r.handshake(2.5)?;
            match action {
                MachineAction::Unlock => r.command("$X", 5.0)?,
                MachineAction::Home => r.command("$H", 120.0)?,
                MachineAction::Settings => r.command("$$", 5.0)?,
                MachineAction::Jog => {
                    let line = session::jog_line([args.x, args.y, args.z], args.feed)
                        .map_err(|e| relievo::Error(format!("machine {e}")))?;
                    r.command(&line, 5.0)?
                }
                MachineAction::Zero => {
                    let line = session::zero_line(&args.axes)
                        .map_err(|e| relievo::Error(format!("--axes: {e}")))?;
                    r.command(&line, 5.0)?
                }
                MachineAction::Probe => {
                    let Some(plate) = args.plate else {
                        relievo::bail!(
                            "machine probe: give the plate with --plate THICKNESS[@X,Y]"
                        );
                    };
                    relievo::grbl::sender::touch_off(&mut r, &plate, None)?;
                    r.command("$#", 5.0)?
                }
                MachineAction::Status | MachineAction::Reset => Vec::new(),
            }
        }
    };
    // the answers, without the welcome and the oks
    for l in lines
        .iter()
        .filter(|l| *l != "ok" && !l.starts_with("Grbl "))
    {
        println!("{l}");
    }
    if let Some(e) = lines.iter().find(|l| l.starts_with("error:")) {
        let code: u32 = e[6..].parse().unwrap_or(0);
        relievo::bail!(
            "{}: {e} ({})",
            args.port,
            relievo::grbl::error_meaning(code)
        );
    }
    Ok(())
}

/// `relievo ports`: the serial ports this machine has.
pub fn ports() -> relievo::Result<()> {
    let ports = serialport::available_ports()
        .map_err(|e| relievo::Error(format!("listing serial ports: {e}")))?;
    if ports.is_empty() {
        eprintln!("no serial ports found");
    }
    for p in ports {
        println!("{}", p.port_name);
    }
    Ok(())
}
