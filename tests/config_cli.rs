//! A user's settings, completions, manual pages and the help's examples,
//! through the real binary.

mod common;

use common::*;
use std::path::Path;
use std::process::Output;

/// relievo with its settings file at `cfg`.
fn with(cfg: &Path, args: &[&str]) -> Output {
    bin()
        .args(args)
        .env("RELIEVO_CONFIG", cfg)
        .output()
        .unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).to_string()
}

/// `config set machine shapeoko`, then `carve` makes a Shapeoko job (its
/// header says so) and `-v` says the machine came from the file; a flag
/// still wins; `unset` brings back the built-in default.
#[test]
fn a_setting_is_the_default_and_a_flag_still_wins() {
    let d = scratch("config");
    let cfg = d.join("nested/relievo.toml");
    let job = d.join("job.nc");
    let job_s = job.to_str().unwrap();
    let carve = |extra: &[&str]| {
        let mut a = vec!["carve", "--resolution", "48", "-o", job_s];
        a.extend_from_slice(extra);
        let out = with(&cfg, &a);
        ok(&out);
        let text = std::fs::read_to_string(&job).unwrap();
        let machine = text
            .lines()
            .find(|l| l.starts_with("(machine: "))
            .unwrap()
            .to_string();
        (machine, stderr(&out))
    };
    ok(&with(&cfg, &["config", "set", "machine", "shapeoko"]));
    ok(&with(&cfg, &["config", "set", "tool", "T2"]));
    let path = with(&cfg, &["config", "path"]);
    assert_eq!(
        String::from_utf8_lossy(&path.stdout).trim(),
        cfg.to_str().unwrap()
    );
    let (machine, said) = carve(&["-v"]);
    assert!(machine.starts_with("(machine: Shapeoko"), "{machine}");
    let from_file = format!("machine = shapeoko (settings file {})", cfg.display());
    assert!(said.contains(&from_file), "{said}");
    assert!(said.contains("tool = T2 (settings file"), "{said}");
    assert!(said.contains("units = mm (built-in default)"), "{said}");
    let (machine, said) = carve(&["-v", "--machine", "3018"]);
    assert!(machine.starts_with("(machine: 3018"), "{machine}");
    assert!(said.contains("machine = 3018 (command line)"), "{said}");
    let show = with(&cfg, &["config", "show"]);
    let shown = String::from_utf8_lossy(&show.stdout);
    assert!(
        shown.contains("machine = shapeoko") && shown.contains("port unset"),
        "{shown}"
    );
    ok(&with(&cfg, &["config", "unset", "machine"]));
    let (machine, _) = carve(&[]);
    assert!(machine.starts_with("(machine: GRBL generic"), "{machine}");
    std::fs::remove_dir_all(d).unwrap();
}

/// A bad setting is refused with the key; a bad file stops every command
/// with one error naming the file, the line and the key, writing nothing;
/// `config path` still answers, so the file can be found and mended.
#[test]
fn bad_settings_are_refused_by_file_line_and_key() {
    let d = scratch("config-bad");
    let cfg = d.join("relievo.toml");
    for (args, says) in [
        (
            vec!["config", "set", "speed", "3"],
            "unknown setting 'speed'",
        ),
        (
            vec!["config", "set", "machine", "nosuch"],
            "machine = nosuch:",
        ),
        (
            vec!["config", "set", "studio-port", "70000"],
            "studio-port = 70000:",
        ),
        (
            vec!["config", "set", "units", "cubit"],
            "units = cubit: 'cubit': expected mm or in",
        ),
    ] {
        let out = with(&cfg, &args);
        assert_eq!(out.status.code(), Some(1), "{args:?}");
        assert!(stderr(&out).contains(says), "{args:?}: {}", stderr(&out));
        assert!(!cfg.exists(), "{args:?} wrote the file");
    }
    std::fs::write(&cfg, "machine = \"3018\"\n# a comment\ncolour = \"red\"\n").unwrap();
    let job = d.join("job.nc");
    let out = with(
        &cfg,
        &["carve", "--resolution", "48", "-o", job.to_str().unwrap()],
    );
    assert_eq!(out.status.code(), Some(1));
    let said = stderr(&out);
    assert_eq!(said.lines().count(), 1, "{said}");
    assert!(
        said.contains(&format!(
            "{}: line 3: unknown setting 'colour'",
            cfg.display()
        )),
        "{said}"
    );
    assert!(!job.exists());
    ok(&with(&cfg, &["config", "path"]));
    std::fs::write(&cfg, "\nmachine = true\n").unwrap();
    let said = stderr(&with(
        &cfg,
        &["relief", "-o", d.join("r.png").to_str().unwrap()],
    ));
    assert!(
        said.contains("line 2: machine: expected a string"),
        "{said}"
    );
    std::fs::remove_dir_all(d).unwrap();
}

/// Completions for every shell, manual pages for every command, and help
/// that ends with examples.
#[test]
fn completions_man_pages_and_examples() {
    for shell in ["bash", "zsh", "fish", "powershell"] {
        let out = run(&["completions", shell]);
        ok(&out);
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(
            text.contains("relievo") && text.contains("carve"),
            "{shell}"
        );
    }
    let d = scratch("man");
    ok(&run(&["man", d.to_str().unwrap()]));
    let subs = [
        "relief",
        "simulate",
        "toolpath",
        "carve",
        "send",
        "ports",
        "machine",
        "grbl-sim",
        "studio",
        "config",
        "completions",
        "man",
    ];
    for sub in subs {
        let page = std::fs::read_to_string(d.join(format!("relievo-{sub}.1"))).unwrap();
        assert!(page.contains(".TH"), "{sub}");
        let help = run(&[sub, "--help"]);
        let text = String::from_utf8_lossy(&help.stdout);
        let tail = &text[text
            .rfind("Examples:")
            .unwrap_or_else(|| panic!("{sub}: no examples"))..];
        let examples = tail
            .lines()
            .filter(|l| l.trim_start().starts_with("relievo "))
            .count();
        assert!((2..=3).contains(&examples), "{sub}: {examples} examples");
    }
    assert!(d.join("relievo.1").exists());
    std::fs::remove_dir_all(d).unwrap();
}
