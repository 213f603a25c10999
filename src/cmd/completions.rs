//! `relievo completions` and `relievo man`: shell completions and manual
//! pages, made from the same command definition as the parser.

use clap::{Args, Command};
use std::path::PathBuf;

#[derive(Args)]
pub struct CompletionsArgs {
    /// The shell to complete in.
    #[arg(value_enum)]
    pub shell: clap_complete::Shell,
}

#[derive(Args)]
pub struct ManArgs {
    /// Folder to write relievo.1 and one page per subcommand into.
    pub dir: PathBuf,
}

pub const COMPLETIONS_EXAMPLES: &str = "Examples:
  relievo completions bash > ~/.local/share/bash-completion/completions/relievo
  relievo completions zsh > ~/.zfunc/_relievo
  relievo completions fish > ~/.config/fish/completions/relievo.fish";

pub const MAN_EXAMPLES: &str = "Examples:
  relievo man ~/.local/share/man/man1 && man relievo-carve
  relievo man target/man";

/// `relievo completions SHELL`: the script on stdout.
pub fn completions(args: CompletionsArgs, mut cmd: Command) -> relievo::Result<()> {
    clap_complete::generate(args.shell, &mut cmd, "relievo", &mut std::io::stdout());
    Ok(())
}

/// `relievo man DIR`: relievo.1 and relievo-SUB.1 for each subcommand.
pub fn man(args: ManArgs, cmd: Command) -> relievo::Result<()> {
    let what =
        |p: &std::path::Path, e: std::io::Error| relievo::Error(format!("{}: {e}", p.display()));
    std::fs::create_dir_all(&args.dir).map_err(|e| what(&args.dir, e))?;
    let cmd = cmd.version(env!("CARGO_PKG_VERSION"));
    let mut pages = vec![("relievo".to_string(), cmd.clone())];
    for sub in cmd.get_subcommands().filter(|s| s.get_name() != "help") {
        let name = format!("relievo-{}", sub.get_name());
        let page_name: &'static str = Box::leak(name.clone().into_boxed_str());
        pages.push((name, sub.clone().name(page_name)));
    }
    let mut out = relievo::output::Outputs::default();
    for (name, page) in pages {
        let mut text = Vec::new();
        clap_mangen::Man::new(page)
            .render(&mut text)
            .map_err(|e| what(&args.dir, e))?;
        out.add(&args.dir.join(format!("{name}.1")), text);
    }
    out.commit()?;
    eprintln!("manual pages -> {}", args.dir.display());
    Ok(())
}
