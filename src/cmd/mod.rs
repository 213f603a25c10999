//! The subcommands, one file each: flags parsed into the library's
//! option structs, one library call, a summary printed.

pub mod carve;
pub mod completions;
pub mod config;
pub mod grbl_sim;
pub mod machine;
pub mod relief;
pub mod send;
pub mod simulate;
pub mod studio;
pub mod toolpath;

/// Run `work` under a spinner saying `what` (a long toolpath shows that it
/// is alive and for how long).
pub fn with_spinner<T>(quiet: bool, what: &str, work: impl FnOnce() -> T) -> T {
    let progress = relievo::progress::Progress::on_terminal(quiet);
    progress.stage(what);
    let out = work();
    progress.finish();
    out
}

/// Files written, as a summary names them: `a.png, a.json`.
pub fn paths(list: &[std::path::PathBuf]) -> String {
    let names: Vec<String> = list.iter().map(|p| p.display().to_string()).collect();
    names.join(", ")
}

/// Stage timings for --verbose.
pub fn print_timings(t: &relievo::timing::Timings) {
    eprintln!(
        "stage timings ({} threads):\n{}",
        rayon::current_num_threads(),
        t.report()
    );
}
