//! Reading outside files with a stated size bound: a 1 GiB model, a
//! device like /dev/zero or a FIFO that never ends gets one clear error
//! instead of eating the machine's memory.

use crate::bail;
use crate::error::{Context, Result};
use std::io::Read;
use std::path::Path;

/// Largest model (OBJ, STL) or G-code file read, bytes.
pub const MAX_FILE: u64 = 1 << 30;
/// Largest small text file (sidecar JSON, machine TOML), bytes.
pub const MAX_TEXT: u64 = 1 << 20;

/// The bytes of `path`, refused past `max` bytes (read no further than
/// that, whatever the file claims to be).
pub fn read(path: &Path, max: u64) -> Result<Vec<u8>> {
    let what = path.display();
    let f = std::fs::File::open(path).ctx(&what)?;
    let mut bytes = Vec::new();
    f.take(max + 1).read_to_end(&mut bytes).ctx(&what)?;
    if bytes.len() as u64 > max {
        bail!(
            "{what}: larger than the {} MiB read (a file this size is not a job or model \
             relievo takes; decimate or split it)",
            max >> 20
        );
    }
    Ok(bytes)
}

/// `read` as UTF-8 text.
pub fn read_text(path: &Path, max: u64) -> Result<String> {
    String::from_utf8(read(path, max)?)
        .map_err(|_| crate::Error(format!("{}: not a UTF-8 text file", path.display())))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn endless_devices_are_refused_at_the_bound() {
        let e = read(Path::new("/dev/zero"), 1 << 16).unwrap_err();
        assert!(e.0.contains("/dev/zero: larger than"), "{e}");
        assert_eq!(read(Path::new("/dev/null"), 10).unwrap(), Vec::<u8>::new());
    }
}
