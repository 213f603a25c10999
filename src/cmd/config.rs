//! `relievo config`: the user's own defaults (see the library's
//! `settings`): where they are kept, what they are, set and unset.

use clap::{Args, Subcommand};
use relievo::settings::{self, Settings, KEYS};

#[derive(Args)]
pub struct ConfigArgs {
    #[command(subcommand)]
    pub action: ConfigAction,
}

#[derive(Subcommand)]
pub enum ConfigAction {
    /// Print where the settings file is (RELIEVO_CONFIG overrides it).
    Path,
    /// Print every setting, its value and where the value comes from.
    Show,
    /// Keep a default: machine, material, units, tool, port, studio-port.
    Set { key: String, value: String },
    /// Forget a default (the built-in one applies again).
    Unset { key: String },
}

pub const EXAMPLES: &str = "Examples:
  relievo config set machine shapeoko     # every job for the Shapeoko unless --machine says otherwise
  relievo config set port /dev/ttyUSB0    # send and machine find the controller there
  relievo config show                     # what is in force and where it comes from";

/// `relievo config`.
pub fn run(args: ConfigArgs) -> relievo::Result<()> {
    match args.action {
        ConfigAction::Path => println!("{}", settings::path()?.display()),
        ConfigAction::Show => {
            let s = Settings::load()?;
            println!("# {}", s.path.display());
            for k in KEYS {
                match s.get(k.name) {
                    Some(v) => println!("{} = {v}    (settings file)", k.name),
                    None => println!("{} unset    ({}; built-in default)", k.name, k.what),
                }
            }
        }
        ConfigAction::Set { key, value } => {
            let mut s = Settings::load()?;
            s.set(&key, &value)?;
            s.save()?;
            eprintln!("{key} = {value} -> {}", s.path.display());
        }
        ConfigAction::Unset { key } => {
            let mut s = Settings::load()?;
            if s.unset(&key)? {
                s.save()?;
                eprintln!("{key} unset -> {}", s.path.display());
            } else {
                eprintln!("{key} was not set in {}", s.path.display());
            }
        }
    }
    Ok(())
}
