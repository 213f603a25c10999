//! The command line and the studio share one definition of each relief
//! and cutting setting (`ops::settings`): every setting the studio reads
//! by name is a flag of the real binary's commands, and the studio reads
//! every flag of those commands that is not a file.

mod common;

use relievo::ops::settings::{CutSettings, Given, ReliefSettings};

fn help(sub: &str) -> String {
    let out = common::run(&[sub, "--help"]);
    assert!(out.status.success());
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The long flags a command's help lists (one per option line).
fn flags(help: &str) -> Vec<String> {
    help.lines()
        .map(str::trim_start)
        .filter(|l| l.starts_with('-'))
        .filter_map(|l| l.split_whitespace().find(|w| w.starts_with("--")))
        .map(|w| w.split(['=', '[', '<']).next().unwrap().to_string())
        .collect()
}

#[test]
fn every_setting_is_a_flag_and_every_flag_not_a_file_is_a_setting() {
    let relief = Given::<ReliefSettings>::names();
    let cut = Given::<CutSettings>::names();
    let flag = |n: &String| format!("--{}", n.replace('_', "-"));
    // the files and outputs a command line names, and the general flags
    let files = [
        "--output",
        "--preview",
        "--stencil",
        "--stencil-gain",
        "--stl",
        "--depth-out",
        "--svg",
        "--width",
        "--depth",
        "--material",
        "--quiet",
        "--verbose",
        "--help",
    ];
    for (sub, sets) in [
        ("relief", vec![&relief]),
        ("toolpath", vec![&cut]),
        ("carve", vec![&relief, &cut]),
    ] {
        let h = help(sub);
        let listed = flags(&h);
        let names: Vec<String> = sets.iter().flat_map(|s| s.iter().map(flag)).collect();
        for n in &names {
            assert!(listed.contains(n), "relievo {sub}: no {n} in its help");
        }
        for f in listed
            .iter()
            .filter(|f| f.chars().nth(2).is_some_and(|c| c.is_ascii_lowercase()))
        {
            let f = f.split(['=', '[', '<']).next().unwrap().to_string();
            assert!(
                names.contains(&f) || files.contains(&f.as_str()),
                "relievo {sub}: {f} is neither a shared setting nor a file"
            );
        }
    }
}
