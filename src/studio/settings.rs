//! What the page sends, read with the command line's own definition of
//! each setting (`ops::settings`), and the `relievo` command line that
//! makes the same files: the flags the page's settings became.

use crate::ops::settings::Given;

/// The relief settings as the page gave them.
pub type ReliefSettings = Given<crate::ops::settings::ReliefSettings>;
/// The cutting settings as the page gave them.
pub type CutSettings = Given<crate::ops::settings::CutSettings>;

/// A word for a shell: quoted when it holds anything but plain characters.
pub fn shell_word(s: &str) -> String {
    let plain = !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_./:=,%+@".contains(c));
    if plain {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', r"'\''"))
    }
}

/// `relievo relief MODEL FLAGS -o relief.png`, ready for a shell.
pub fn relief_command(model: Option<&str>, r: &ReliefSettings) -> String {
    command("relief", model, r.flags.clone(), "relief.png")
}

/// `relievo carve MODEL RELIEF-FLAGS CUT-FLAGS -o job.nc`.
pub fn carve_command(model: Option<&str>, r: &ReliefSettings, c: &CutSettings) -> String {
    let mut args = r.flags.clone();
    args.extend(c.flags.iter().cloned());
    command("carve", model, args, "job.nc")
}

fn command(sub: &str, model: Option<&str>, args: Vec<String>, out: &str) -> String {
    let mut words = vec!["relievo".to_string(), sub.to_string()];
    words.extend(model.map(shell_word));
    words.extend(args.iter().map(|a| shell_word(a)));
    words.push("-o".into());
    words.push(out.into());
    words.join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn defaults_say_nothing_and_changes_are_flags() {
        assert_eq!(
            relief_command(None, &ReliefSettings::defaults()),
            "relievo relief -o relief.png"
        );
        let r = ReliefSettings::from_json(&json!({
            "depth": 2.5,
            "yaw": -12.25,
            "fov": 20,
            "emphasize": [["tea pot", 2.0]],
            "free_background": true,
        }))
        .unwrap();
        assert_eq!(
            relief_command(Some("my model.obj"), &r),
            "relievo relief 'my model.obj' --yaw -12.25 --depth 2.5 --free-background \
             --emphasize 'tea pot=2' -o relief.png"
        );
        assert_eq!(r.emphasize, vec![("tea pot".to_string(), 2.0)]);
        let c = CutSettings::from_json(&json!({"stepover": "8%", "arcs": false})).unwrap();
        assert_eq!(
            carve_command(None, &ReliefSettings::defaults(), &c),
            "relievo carve --stepover 8% --arcs off -o job.nc"
        );
    }

    #[test]
    fn bad_values_and_names_are_refused_with_their_flag() {
        let e = ReliefSettings::from_json(&json!({"view": "sideways"}))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("'sideways'") && e.contains("--view") && e.contains("front"),
            "{e}"
        );
        let e = CutSettings::from_json(&json!({"finish": "spiral"}))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("--finish") && e.contains("raster+waterline"),
            "{e}"
        );
        let e = ReliefSettings::from_json(&json!({"colour": 3}))
            .unwrap_err()
            .to_string();
        assert_eq!(e, "unknown setting 'colour'");
        // a file the command line names is not a setting a page may give
        for path in ["stl", "stencil", "depth_out", "svg", "preview", "output"] {
            assert!(ReliefSettings::from_json(&json!({ path: "x" })).is_err());
            assert!(CutSettings::from_json(&json!({ path: "x" })).is_err());
        }
    }
}
