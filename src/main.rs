//! The `relievo` binary: parses flags into the library's option structs,
//! calls one library function per subcommand, prints errors once.

mod cmd;

use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};
use cmd::{
    carve, completions, config, grbl_sim, machine, relief, send, simulate, studio, toolpath,
};
use relievo::settings::{Settings, KEYS};
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
    #[command(after_help = relief::EXAMPLES)]
    Relief(relief::ReliefArgs),
    /// Simulate a G-code job cutting the stock and judge it against a relief.
    #[command(after_help = simulate::EXAMPLES)]
    Simulate(simulate::SimulateArgs),
    /// Turn a relief into a GRBL job (roughing, raster/waterline finishing).
    #[command(after_help = toolpath::EXAMPLES)]
    Toolpath(toolpath::ToolpathArgs),
    /// Relief and toolpath in one call; without MODEL, the demo scene.
    #[command(after_help = carve::EXAMPLES)]
    Carve(Box<carve::CarveArgs>),
    /// Stream a job to a GRBL controller over a serial port.
    #[command(after_help = send::EXAMPLES)]
    Send(send::SendArgs),
    /// List serial ports.
    #[command(after_help = "Examples:
  relievo ports                            # the serial ports this machine has
  relievo config set port /dev/ttyUSB0     # remember which one is the mill's")]
    Ports,
    /// Ask a GRBL controller for its status, unlock it or home it.
    #[command(after_help = machine::EXAMPLES)]
    Machine(machine::MachineArgs),
    /// Serve a simulated GRBL 1.1 machine on a pseudo-terminal (prints its path).
    #[command(after_help = grbl_sim::EXAMPLES)]
    GrblSim(grbl_sim::GrblSimArgs),
    /// Design a relief, check its job and download the files in a web
    /// page served on this machine.
    #[command(after_help = studio::EXAMPLES)]
    Studio(studio::StudioArgs),
    /// Your own defaults (machine, material, units, tool, port, studio
    /// port); a flag on the command line still wins.
    #[command(after_help = config::EXAMPLES)]
    Config(config::ConfigArgs),
    /// Print shell completions (bash, zsh, fish, powershell, elvish).
    #[command(after_help = completions::COMPLETIONS_EXAMPLES)]
    Completions(completions::CompletionsArgs),
    /// Write manual pages (relievo.1, relievo-SUB.1) into a folder.
    #[command(after_help = completions::MAN_EXAMPLES)]
    Man(completions::ManArgs),
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
        Cmd::Config(args) => config::run(args),
        Cmd::Completions(args) => completions::completions(args, Cli::command()),
        Cmd::Man(args) => completions::man(args, Cli::command()),
    }
}

/// The command line, with the user's settings as the defaults of the flags
/// they stand in for (a flag given still wins).
fn command(settings: &Settings) -> clap::Command {
    let mut cmd = Cli::command();
    for key in KEYS {
        let Some(value) = settings.get(key.name) else {
            continue;
        };
        // the parser keeps its defaults for the life of the process
        let value: &'static str = Box::leak(value.to_string().into_boxed_str());
        for &(sub, arg) in key.flags {
            cmd = cmd.mut_subcommand(sub, |c| {
                if c.get_arguments().any(|a| a.get_id() == arg) {
                    c.mut_arg(arg, |a| a.default_value(value).required(false))
                } else {
                    c
                }
            });
        }
    }
    cmd
}

/// With -v: where each setting in force for this command comes from.
fn say_sources(m: &clap::ArgMatches, settings: &Settings) {
    let Some((sub, m)) = m.subcommand() else {
        return;
    };
    for key in KEYS {
        for &(_, arg) in key.flags.iter().filter(|(s, _)| *s == sub) {
            let v = m
                .get_raw(arg)
                .and_then(|mut v| v.next())
                .map_or("(none)".into(), |v| v.to_string_lossy());
            let from = match m.value_source(arg) {
                Some(clap::parser::ValueSource::CommandLine) => "command line".to_string(),
                _ if settings.get(key.name).is_some() => {
                    format!("settings file {}", settings.path.display())
                }
                _ => "built-in default".to_string(),
            };
            eprintln!("{} = {v} ({from})", key.name);
        }
    }
}

fn main() -> ExitCode {
    // `config` must work whatever the file holds: it is how to mend it
    let configuring = std::env::args()
        .skip(1)
        .find(|a| !a.starts_with('-'))
        .is_some_and(|a| a == "config");
    let settings = match Settings::load() {
        Ok(s) => s,
        Err(_) if configuring => Settings::default(),
        Err(e) => {
            eprintln!("error: {e} (mend or remove the settings file)");
            return ExitCode::FAILURE;
        }
    };
    let parsed = command(&settings)
        .try_get_matches()
        .and_then(|m| Cli::from_arg_matches(&m).map(|c| (c, m)));
    let cli = match parsed {
        Ok((c, m)) => {
            if c.verbose {
                say_sources(&m, &settings);
            }
            c
        }
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
