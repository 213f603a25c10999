//! All-or-nothing output: every file of a command is first written to a
//! temporary file beside its target, and only when all are written are
//! they renamed into place. A failure leaves no output file behind.

use crate::bail;
use crate::error::Result;
use std::path::{Path, PathBuf};

#[derive(Default)]
pub struct Outputs {
    files: Vec<(PathBuf, Vec<u8>)>,
}

fn temp_path(p: &Path) -> PathBuf {
    let name = p
        .file_name()
        .map(|n| n.to_string_lossy().to_string())
        .unwrap_or_default();
    p.with_file_name(format!(".{name}.relievo-{}.tmp", std::process::id()))
}

/// Fail early, before long work, when `path` cannot be written: its
/// directory must exist and it must not be a directory itself.
pub fn check_writable(path: &Path) -> Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if !dir.is_dir() {
        bail!(
            "{}: cannot write: directory {} does not exist",
            path.display(),
            dir.display()
        );
    }
    if path.is_dir() {
        bail!("{}: cannot write: it is a directory", path.display());
    }
    Ok(())
}

impl Outputs {
    pub fn add(&mut self, path: &Path, bytes: Vec<u8>) {
        self.files.push((path.to_path_buf(), bytes));
    }

    /// Write everything or nothing.
    pub fn commit(self) -> Result<()> {
        let mut written: Vec<PathBuf> = Vec::new();
        let cleanup = |w: &[PathBuf]| w.iter().for_each(|t| drop(std::fs::remove_file(t)));
        for (path, bytes) in &self.files {
            let tmp = temp_path(path);
            if let Err(e) = std::fs::write(&tmp, bytes) {
                cleanup(&written);
                drop(std::fs::remove_file(&tmp));
                bail!("{}: cannot write: {e}", path.display());
            }
            written.push(tmp);
        }
        for (k, (path, _)) in self.files.iter().enumerate() {
            if let Err(e) = std::fs::rename(&written[k], path) {
                cleanup(&written[k..]);
                for (p, _) in &self.files[..k] {
                    drop(std::fs::remove_file(p));
                }
                bail!("{}: cannot write: {e}", path.display());
            }
        }
        Ok(())
    }
}
