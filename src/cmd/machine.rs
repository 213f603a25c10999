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
    r.handshake(2.5)?;
    let lines = match args.action {
        MachineAction::Status => {
            r.port.write_all(b"?")?;
            // a bounded wait, however chatty the device
            let mut got = Vec::new();
            let until = r.port.now() + 2.0;
            while r.port.now() < until {
                let Some(l) = r.next(0.25)? else { continue };
                let status = l.starts_with('<');
                got.push(l);
                if status {
                    break;
                }
            }
            if !got.iter().any(|l| l.starts_with('<')) {
                relievo::bail!("{}: no status report within 2 s of '?'", args.port);
            }
            got
        }
        MachineAction::Unlock => r.command("$X", 5.0)?,
        MachineAction::Home => r.command("$H", 120.0)?,
    };
    for l in &lines {
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
