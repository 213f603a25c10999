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

/// `N` sizes in mm written `AxB[xC]`, each within 0.001..10000 mm (up to
/// 10 m: a panel, not a number that overflows the stock grid).
fn parse_sizes<const N: usize>(s: &str, shape: &str) -> Result<[f64; N], String> {
    let v: Vec<f64> = s
        .split(['x', 'X'])
        .map(|p| p.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("'{s}': expected {shape} in mm"))?;
    let v: [f64; N] = v
        .try_into()
        .map_err(|_| format!("'{s}': expected {shape} in mm"))?;
    if !v.iter().all(|x| (0.001..=1e4).contains(x)) {
        return Err(format!("'{s}': each size must be within 0.001..10000 mm"));
    }
    Ok(v)
}

pub fn parse_stock(s: &str) -> Result<(f64, f64, f64), String> {
    parse_sizes::<3>(s, "WxHxT").map(|[w, h, t]| (w, h, t))
}

pub fn parse_size(s: &str) -> Result<(f64, f64), String> {
    parse_sizes::<2>(s, "WxH").map(|[w, h]| (w, h))
}

pub fn parse_pair(s: &str) -> Result<(f64, f64), String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("'{s}': expected X,Y"))?;
    match v[..] {
        [a, b] => Ok((a, b)),
        _ => Err(format!("'{s}': expected X,Y")),
    }
}

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
