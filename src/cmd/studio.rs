//! `relievo studio`: serve the design page on this machine.

use clap::Args;
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::path::PathBuf;

/// What `--help` ends with.
pub const EXAMPLES: &str = "Examples:
  relievo studio --open                                 # the demo scene, in the browser
  relievo studio bunny.obj --port 8080";

#[derive(Args)]
pub struct StudioArgs {
    /// Model to open (OBJ, STL or PNG); without it, the demo scene.
    pub model: Option<PathBuf>,
    /// Port to listen on (0 = any free port).
    #[arg(long, default_value_t = 7171)]
    pub port: u16,
    /// Address to listen on. Anything but this machine's loopback lets
    /// others on the network use the studio and read its files.
    #[arg(long, default_value_t = IpAddr::V4(Ipv4Addr::LOCALHOST))]
    pub host: IpAddr,
    /// Open the page in the default browser.
    #[arg(long)]
    pub open: bool,
}

/// `relievo studio`.
pub fn run(args: StudioArgs, quiet: bool) -> relievo::Result<()> {
    if let Some(m) = &args.model {
        if !m.is_file() {
            return Err(relievo::Error(format!("{}: no such file", m.display())));
        }
    }
    if !args.host.is_loopback() {
        eprintln!(
            "warning: listening on {}: anyone who reaches it can use the studio and download its files",
            args.host
        );
    }
    let open = args.open;
    relievo::studio::serve(
        args.model.as_deref(),
        SocketAddr::new(args.host, args.port),
        |at| {
            let url = format!("http://{at}/");
            // the one line a script waits for, even with --quiet
            println!("relievo studio on {url}");
            if !quiet {
                eprintln!("(Ctrl-C stops it)");
            }
            if open {
                let tried = std::process::Command::new("xdg-open").arg(&url).spawn();
                if tried.is_err() {
                    eprintln!("could not start a browser (xdg-open): open {url} yourself");
                }
            }
        },
    )
}
