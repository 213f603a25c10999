//! The README is the user's guide: every command block in it runs, in
//! order, in one scratch folder, as a user would type it, with `relievo`
//! the binary under test. Only two lines are not run, each named here:
//! `cargo install` (the binary is the one cargo built) and `cargo test`
//! (this test is part of it).

mod common;

use std::path::Path;
use std::process::Command;

/// The `sh` blocks of a Markdown text, each as its lines.
fn sh_blocks(text: &str) -> Vec<Vec<String>> {
    let mut blocks = Vec::new();
    let mut cur: Option<Vec<String>> = None;
    for line in text.lines() {
        match (&mut cur, line.trim_start().starts_with("```")) {
            (None, true) if line.trim() == "```sh" => cur = Some(Vec::new()),
            (Some(_), true) => blocks.push(cur.take().unwrap()),
            (Some(b), false) => b.push(line.to_string()),
            _ => {}
        }
    }
    assert!(cur.is_none(), "README.md: an sh block is not closed");
    blocks
}

/// A README line as the test runs it: `cargo run --release -- ARGS` is
/// `relievo ARGS`; the two cargo lines that cannot run here are None.
fn as_run(line: &str) -> Option<String> {
    let cmd = line.split('#').next().unwrap_or("").trim();
    if let Some(args) = cmd.strip_prefix("cargo run --release -- ") {
        return Some(format!("relievo {args}"));
    }
    match cmd {
        "cargo install --path ." | "cargo test --release" => None,
        c if c.starts_with("cargo ") => {
            panic!("README.md: no rule to run '{c}' in tests/readme.rs")
        }
        _ => Some(line.to_string()),
    }
}

fn run_block(dir: &Path, k: usize, lines: &[String]) {
    let script: Vec<String> = lines.iter().filter_map(|l| as_run(l)).collect();
    let bin = Path::new(env!("CARGO_BIN_EXE_relievo"));
    let path = format!(
        "{}:{}",
        bin.parent().unwrap().display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let out = Command::new("timeout")
        .args(["300", "bash", "-e", "-o", "pipefail", "-c"])
        .arg(script.join("\n"))
        .current_dir(dir)
        .env("PATH", path)
        .env("RELIEVO_CONFIG", dir.join("settings.toml"))
        .output()
        .expect("bash runs");
    assert!(
        out.status.success(),
        "README.md block {k} failed ({}):\n{}\n--- stderr:\n{}",
        out.status,
        script.join("\n"),
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn every_command_in_the_readme_runs() {
    let text = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("README.md"))
        .expect("README.md");
    let lines = text.lines().count();
    assert!(lines <= 300, "README.md has {lines} lines, more than 300");
    let blocks = sh_blocks(&text);
    // it opens with the two commands a newcomer needs
    let first: Vec<&str> = blocks[0]
        .iter()
        .map(|l| l.split('#').next().unwrap().trim())
        .collect();
    assert_eq!(
        first,
        ["cargo run --release -- carve", "cargo test --release"]
    );
    assert!(
        text.trim_start().starts_with("# relievo\n\n```sh"),
        "the two commands come first"
    );

    let dir = common::scratch("readme");
    std::os::unix::fs::symlink(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures"),
        dir.join("fixtures"),
    )
    .unwrap();
    for (k, b) in blocks.iter().enumerate() {
        run_block(&dir, k, b);
        if k == 0 {
            // the demo writes only the files it says
            let mut made: Vec<String> = std::fs::read_dir(&dir)
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            made.sort();
            assert_eq!(
                made,
                ["fixtures", "job-relief.json", "job-relief.png", "job.nc"]
            );
        }
    }
    let has = |f: &str| {
        let p = dir.join(f);
        assert!(
            p.metadata().map(|m| m.len() > 0).unwrap_or(false),
            "README's commands did not make {f}"
        );
        std::fs::read_to_string(&p).unwrap_or_default()
    };
    for f in [
        "bunny.png",
        "bunny.json",
        "nefertiti-look.png",
        "teaset.png",
        "spot.svg",
        "bunny-cut.png",
        "coin.nc",
        "relievo.bash",
        "man-pages/relievo.1",
        "man-pages/relievo-carve.1",
    ] {
        has(f);
    }
    // the job made while the settings held the Shapeoko is for it
    assert!(has("demo.nc").contains("(machine: Shapeoko"));
    let report: serde_json::Value = serde_json::from_str(&has("bunny-cut.json")).unwrap();
    assert!(report["max_gouge_mm"].as_f64().unwrap() < 0.001, "{report}");
    // and the settings were all unset again
    let settings = std::fs::read_to_string(dir.join("settings.toml")).unwrap_or_default();
    assert!(
        !settings.contains("machine") && !settings.contains("material"),
        "{settings}"
    );
    std::fs::remove_dir_all(dir).unwrap();
}

/// Nothing in the README points outside the repository.
#[test]
fn the_readme_links_only_into_the_repository() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join("README.md")).unwrap();
    assert!(
        !text.contains("../"),
        "README.md points outside the repository"
    );
    let mut rest = text.as_str();
    while let Some(i) = rest.find("](") {
        let link = &rest[i + 2..rest[i..].find(')').map_or(rest.len(), |j| i + j)];
        if !link.starts_with("http") {
            assert!(
                root.join(link).exists(),
                "README.md links to {link}, which is not there"
            );
        }
        rest = &rest[i + 2..];
    }
}
