//! All-or-nothing output: every file of a command is first written to a
//! temporary file beside its target, and only when all are written are
//! they renamed into place. A failure leaves no output file behind.

use crate::bail;
use crate::error::Result;
use std::path::{Path, PathBuf};

/// Writes a file's content into its temporary file: a large output (the
/// STL of a 67 million pixel relief is 6.7 GB) goes to disk as it is made
/// instead of being held.
pub type Writer<'a> = Box<dyn FnOnce(&mut dyn std::io::Write) -> std::io::Result<()> + 'a>;

enum Content<'a> {
    Bytes(Vec<u8>),
    Stream(Writer<'a>),
}

#[derive(Default)]
pub struct Outputs<'a> {
    files: Vec<(PathBuf, Content<'a>)>,
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

impl<'a> Outputs<'a> {
    pub fn add(&mut self, path: &Path, bytes: Vec<u8>) {
        self.files.push((path.to_path_buf(), Content::Bytes(bytes)));
    }

    /// A file whose content `write` streams out when the outputs commit.
    pub fn add_stream(&mut self, path: &Path, write: Writer<'a>) {
        self.files
            .push((path.to_path_buf(), Content::Stream(write)));
    }

    /// Write everything or nothing.
    pub fn commit(self) -> Result<()> {
        let mut written: Vec<PathBuf> = Vec::new();
        let cleanup = |w: &[PathBuf]| w.iter().for_each(|t| drop(std::fs::remove_file(t)));
        let paths: Vec<PathBuf> = self.files.iter().map(|f| f.0.clone()).collect();
        for (path, content) in self.files {
            let tmp = temp_path(&path);
            let result = match content {
                Content::Bytes(bytes) => std::fs::write(&tmp, bytes),
                Content::Stream(write) => std::fs::File::create(&tmp).and_then(|f| {
                    let mut w = std::io::BufWriter::with_capacity(1 << 20, f);
                    write(&mut w)?;
                    std::io::Write::flush(&mut w)
                }),
            };
            if let Err(e) = result {
                cleanup(&written);
                drop(std::fs::remove_file(&tmp));
                bail!("{}: cannot write: {e}", path.display());
            }
            written.push(tmp);
        }
        for (k, path) in paths.iter().enumerate() {
            if let Err(e) = std::fs::rename(&written[k], path) {
                cleanup(&written[k..]);
                for p in &paths[..k] {
                    drop(std::fs::remove_file(p));
                }
                bail!("{}: cannot write: {e}", path.display());
            }
        }
        Ok(())
    }
}
