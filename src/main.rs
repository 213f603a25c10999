//! The `relievo` binary: parses flags into the library's option structs,
//! calls one library function per subcommand, prints errors once.

mod cmd;

use clap::{Parser, Subcommand};
use cmd::{carve, grbl_sim, machine, relief, send, simulate, studio, toolpath};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "relievo",
    version,
    about = "3D scenes to bas-reliefs, bas-reliefs to GRBL CNC jobs"
)]
struct Cli {
    /// Print nothing but errors.
    #[arg(long, short, global = true)]
    quiet: bool,
    /// Print stage timings and details.
    #[arg(long, short, global = true, alias = "timings")]
    verbose: bool,
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Make a bas-relief from a 3D model (OBJ, STL), a depth PNG or a
    /// normal-map PNG; without MODEL, from the built-in demo scene.
    Relief(relief::ReliefArgs),
    /// Simulate a G-code job cutting the stock and judge it against a relief.
    Simulate(simulate::SimulateArgs),
    /// Turn a relief into a GRBL job (roughing, raster/waterline finishing).
    Toolpath(toolpath::ToolpathArgs),
    /// Relief and toolpath in one call; without MODEL, the demo scene.
    Carve(Box<carve::CarveArgs>),
    /// Stream a job to a GRBL controller over a serial port.
    Send(send::SendArgs),
    /// List serial ports.
    Ports,
    /// Ask a GRBL controller for its status, unlock it or home it.
    Machine(machine::MachineArgs),
    /// Serve a simulated GRBL 1.1 machine on a pseudo-terminal (prints its path).
    GrblSim(grbl_sim::GrblSimArgs),
    /// Design a relief, check its job and download the files in a web
    /// page served on this machine.
    Studio(studio::StudioArgs),
}

fn run(cli: Cli) -> relievo::Result<()> {
    let (quiet, verbose) = (cli.quiet, cli.verbose);
    match cli.cmd {
        Cmd::Relief(args) => relief::run(args, quiet, verbose),
        Cmd::Simulate(args) => simulate::run(args, quiet, verbose),
        Cmd::Toolpath(args) => toolpath::run(args, quiet, verbose),
        Cmd::Carve(args) => carve::run(*args, quiet, verbose),
        Cmd::Send(args) => send::run(args, quiet),
        Cmd::Ports => machine::ports(),
        Cmd::Machine(args) => machine::run(args),
        Cmd::GrblSim(args) => grbl_sim::run(args),
        Cmd::Studio(args) => studio::run(args, quiet),
    }
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) if !e.use_stderr() => {
            // --help and --version
            let _ = e.print();
            return ExitCode::SUCCESS;
        }
        Err(e) => {
            // one line, like every other error
            let text = e.render().to_string();
            let mut first = text
                .lines()
                .next()
                .unwrap_or("invalid arguments")
                .trim_end()
                .to_string();
            // clap lists missing arguments on the lines after the first
            if first.ends_with(':') {
                let missing: Vec<&str> = text
                    .lines()
                    .skip(1)
                    .map(str::trim)
                    .take_while(|l| !l.is_empty())
                    .collect();
                first = format!("{first} {}", missing.join(", "));
            }
            eprintln!("{first} (see relievo --help)");
            return ExitCode::from(2);
        }
    };
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
