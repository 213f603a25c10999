//! A user's own defaults: the machine, material, units, tool and port they
//! use every day, kept in a TOML file in the platform's config directory
//! (`RELIEVO_CONFIG` names another). A flag on the command line beats the
//! file, and the file beats the built-in default.

use crate::error::{Error, Result};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// One setting a user may keep.
pub struct Key {
    pub name: &'static str,
    pub what: &'static str,
    /// The commands and their flag (clap's argument id) it stands in for.
    pub flags: &'static [(&'static str, &'static str)],
    check: fn(&str) -> Result<()>,
}

/// Every setting the file may hold; any other key is refused.
pub const KEYS: &[Key] = &[
    Key {
        name: "machine",
        what: "machine profile: grbl-generic, 3018, shapeoko, or a TOML file",
        flags: &[
            ("carve", "machine"),
            ("toolpath", "machine"),
            ("simulate", "machine"),
            ("grbl-sim", "machine"),
        ],
        check: |v| crate::machine::Machine::load(v).map(drop),
    },
    Key {
        name: "material",
        what: "material preset (machines/materials.toml)",
        flags: &[
            ("relief", "material"),
            ("carve", "material"),
            ("toolpath", "material"),
        ],
        check: |v| crate::materials::find(v).map(drop),
    },
    Key {
        name: "units",
        what: "units of the G-code: mm or in",
        flags: &[("carve", "units"), ("toolpath", "units")],
        check: |v| match v {
            "mm" | "in" => Ok(()),
            _ => Err(Error(format!("'{v}': expected mm or in"))),
        },
    },
    Key {
        name: "tool",
        what:
            "finishing tool: ball:D, flat:D, vbit:ANGLE[:D], taperball:R:ANGLE[:D] or T1, T2, ...",
        flags: &[("carve", "tool"), ("toolpath", "tool")],
        check: |v| {
            let table =
                v.len() > 1 && v.starts_with('T') && v[1..].bytes().all(|b| b.is_ascii_digit());
            if table {
                Ok(())
            } else {
                crate::tool::Tool::parse(v).map(drop)
            }
        },
    },
    Key {
        name: "port",
        what: "serial port of the controller, e.g. /dev/ttyUSB0 or COM3",
        flags: &[("send", "port"), ("machine", "port")],
        check: |v| {
            if v.trim().is_empty() {
                Err(Error("expected a serial port's name".into()))
            } else {
                Ok(())
            }
        },
    },
    Key {
        name: "studio-port",
        what: "TCP port the studio listens on",
        flags: &[("studio", "port")],
        check: |v| {
            v.parse::<u16>()
                .map(drop)
                .map_err(|_| Error(format!("'{v}': expected a port number 0..65535")))
        },
    },
];

/// The settings in force from the file (empty where it has none).
#[derive(Clone, Debug, Default)]
pub struct Settings {
    pub path: PathBuf,
    values: BTreeMap<String, String>,
}

/// Where the settings file is: `RELIEVO_CONFIG`, else `config.toml` in the
/// platform's config directory for relievo.
pub fn path() -> Result<PathBuf> {
    if let Some(p) = std::env::var_os("RELIEVO_CONFIG") {
        return Ok(PathBuf::from(p));
    }
    directories::ProjectDirs::from("", "", "relievo")
        .map(|d| d.config_dir().join("config.toml"))
        .ok_or_else(|| {
            Error("no home directory to keep settings in; set RELIEVO_CONFIG to a file".into())
        })
}

fn key(name: &str) -> Result<&'static Key> {
    KEYS.iter().find(|k| k.name == name).ok_or_else(|| {
        let names: Vec<&str> = KEYS.iter().map(|k| k.name).collect();
        Error(format!(
            "unknown setting '{name}' (settings: {})",
            names.join(", ")
        ))
    })
}

impl Settings {
    /// The settings file, or none if it does not exist yet.
    pub fn load() -> Result<Settings> {
        let path = path()?;
        match std::fs::read_to_string(&path) {
            Ok(text) => Settings::parse(&text, &path),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(Settings {
                path,
                values: BTreeMap::new(),
            }),
            Err(e) => Err(Error(format!("{}: {e}", path.display()))),
        }
    }

    /// Settings from a file's text; an error names the file, the line and
    /// the key.
    pub fn parse(text: &str, path: &Path) -> Result<Settings> {
        let at =
            |line: usize, msg: String| Error(format!("{}: line {line}: {msg}", path.display()));
        let table: toml::Table = text.parse().map_err(|e: toml::de::Error| {
            let line = e.span().map_or(1, |s| {
                text[..s.start.min(text.len())].matches('\n').count() + 1
            });
            at(line, e.message().trim().to_string())
        })?;
        let line_of = |name: &str| {
            text.lines()
                .position(|l| {
                    let l = l.trim_start();
                    l.strip_prefix(name)
                        .or_else(|| l.strip_prefix(&format!("\"{name}\"")))
                        .is_some_and(|rest| rest.trim_start().starts_with('='))
                })
                .map_or(1, |i| i + 1)
        };
        let mut values = BTreeMap::new();
        for (name, v) in &table {
            let line = line_of(name);
            let k = key(name).map_err(|e| at(line, e.0))?;
            let v = match v {
                toml::Value::String(s) => s.clone(),
                toml::Value::Integer(i) => i.to_string(),
                other => {
                    return Err(at(
                        line,
                        format!("{name}: expected a string, not {}", other.type_str()),
                    ))
                }
            };
            (k.check)(&v).map_err(|e| at(line, format!("{name} = {v}: {}", e.0)))?;
            values.insert(name.clone(), v);
        }
        Ok(Settings {
            path: path.to_path_buf(),
            values,
        })
    }

    pub fn get(&self, name: &str) -> Option<&str> {
        self.values.get(name).map(String::as_str)
    }

    /// Every setting held, in key order.
    pub fn iter(&self) -> impl Iterator<Item = (&str, &str)> {
        self.values.iter().map(|(k, v)| (k.as_str(), v.as_str()))
    }

    /// Keep `value` for `name`, after checking both.
    pub fn set(&mut self, name: &str, value: &str) -> Result<()> {
        let k = key(name)?;
        (k.check)(value).map_err(|e| Error(format!("{name} = {value}: {}", e.0)))?;
        self.values.insert(name.to_string(), value.to_string());
        Ok(())
    }

    /// Forget `name`; whether it was held.
    pub fn unset(&mut self, name: &str) -> Result<bool> {
        key(name)?;
        Ok(self.values.remove(name).is_some())
    }

    /// The file's text: one `key = value` line per setting.
    pub fn to_text(&self) -> String {
        let mut t = toml::Table::new();
        for (k, v) in &self.values {
            let v = match (k.as_str(), v.parse::<i64>()) {
                ("studio-port", Ok(i)) => toml::Value::Integer(i),
                _ => toml::Value::String(v.clone()),
            };
            t.insert(k.clone(), v);
        }
        format!("# relievo settings (relievo config set KEY VALUE)\n{t}")
    }

    /// Write the file (whole or not at all), making its directory.
    pub fn save(&self) -> Result<()> {
        let what = |e: std::io::Error| Error(format!("{}: {e}", self.path.display()));
        if let Some(dir) = self.path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(what)?;
        }
        let mut out = crate::output::Outputs::default();
        out.add(&self.path, self.to_text().into_bytes());
        out.commit()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_round_trips_and_bad_ones_name_file_line_and_key() {
        let p = Path::new("cfg.toml");
        let s = Settings::parse(
            "# mine\nmachine = \"shapeoko\"\nstudio-port = 8080\ntool = \"T2\"\n",
            p,
        )
        .unwrap();
        assert_eq!(s.get("machine"), Some("shapeoko"));
        assert_eq!(s.get("studio-port"), Some("8080"));
        let again = Settings::parse(&s.to_text(), p).unwrap();
        assert_eq!(
            again.iter().collect::<Vec<_>>(),
            s.iter().collect::<Vec<_>>()
        );
        let err = |text: &str| Settings::parse(text, p).unwrap_err().0;
        assert_eq!(
            err("machine = \"3018\"\n\nspeed = 3\n"),
            "cfg.toml: line 3: unknown setting 'speed' (settings: machine, material, units, tool, port, studio-port)"
        );
        assert!(err("units = \"furlong\"").starts_with("cfg.toml: line 1: units = furlong: "));
        assert!(err("tool = \"ball:0\"").starts_with("cfg.toml: line 1: tool = ball:0: "));
        assert!(
            err("\n\nmachine = [1]").starts_with("cfg.toml: line 3: machine: expected a string")
        );
        assert!(err("machine = \n").starts_with("cfg.toml: line 1: "));
        let mut s = s;
        assert!(s.set("colour", "red").is_err());
        assert!(s.set("studio-port", "99999").is_err());
        s.set("units", "in").unwrap();
        assert!(s.unset("units").unwrap());
        assert!(!s.unset("units").unwrap());
    }
}
