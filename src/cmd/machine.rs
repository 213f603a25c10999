//! `relievo machine` and `relievo ports`: talk to a controller outside a job.

use clap::Args;

#[derive(Args)]
pub struct MachineArgs {
    #[arg(value_enum)]
    pub action: MachineAction,
    #[arg(long)]
    pub port: String,
    #[arg(long, default_value_t = 115200)]
    pub baud: u32,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum MachineAction {
    Status,
    Unlock,
    Home,
}

pub fn run(args: MachineArgs) -> relievo::Result<()> {
    use relievo::grbl::{port::SerialLink, sender::Replies};
    let mut port = SerialLink::open(&args.port, args.baud)?;
    let mut r = Replies::new(&mut port);
    let lines = match args.action {
        // read-only: no handshake, so no soft reset of a board that is
        // running or holding; '?' again until a report comes (a board
        // that resets on connection answers once it has booted)
        MachineAction::Status => {
            let mut got = Vec::new();
            let until = r.port.now() + 2.5;
            let mut asked = f64::MIN;
            while r.port.now() < until && !got.iter().any(|l: &String| l.starts_with('<')) {
                if r.port.now() - asked >= 0.5 {
                    r.port.write_all(b"?")?;
                    asked = r.port.now();
                }
                if let Some(l) = r.next(0.1)? {
                    got.push(l);
                }
            }
            if !got.iter().any(|l| l.starts_with('<')) {
                relievo::bail!("{}: no status report within 2.5 s of '?'", args.port);
            }
            got
        }
        action => {
            r.handshake(2.5)?;
            match action {
                MachineAction::Unlock => r.command("$X", 5.0)?,
                _ => r.command("$H", 120.0)?,
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
