//! A job's lines as the sender sends them: comments and spaces stripped,
//! each line's motion, dwell, pause and sync read by the one modal
//! interpreter, the comments before an M0 kept as what it asks of the
//! operator.

use crate::bail;
use crate::error::Result;
use crate::gcode::modal::Modal;
use crate::gcode::parse::{parse_line, strip};
use glam::DVec3;
use std::path::Path;

/// One line to send: where it is in the file, and what GRBL will get.
#[derive(Clone, Debug, PartialEq)]
pub struct JobLine {
    /// 1-based line in the job file.
    pub number: usize,
    /// Comments and spaces stripped (every byte counts against the buffer).
    pub text: String,
    /// The file's line as written, for messages.
    pub original: String,
    /// relievo reads the line (else GRBL may still take it; the sender
    /// then cannot vouch for running it twice).
    pub known: bool,
    /// Its move along the axis it moves most, mm (infinite for an arc,
    /// 0 without motion): a move of a motor step or more is sure to take
    /// a planner block.
    pub travel: f64,
    /// GRBL empties its planner before it answers the line.
    pub sync: bool,
    /// It moves in G91: running it twice moves twice.
    pub relative: bool,
    /// Seconds of dwell.
    pub dwell: f64,
    /// M0: the machine holds here (a tool change) until cycle start.
    pub pause: bool,
    /// The comments on the lines without G-code just before it (what an
    /// M0 asks of the operator).
    pub note: String,
    /// At an M0, the job's modal state there (units, distance mode, and
    /// where the tool stands in work coordinates), for a touch-off.
    pub state: Option<Box<Modal>>,
}

/// The lines of a job that carry anything for GRBL.
pub fn load_job(path: &Path) -> Result<Vec<JobLine>> {
    let text = crate::input::read_text(path, crate::input::MAX_FILE)?;
    job_lines(&text, &path.display().to_string())
}

/// The lines of job `text` (named `what` in errors) that carry anything
/// for GRBL.
pub fn job_lines(text: &str, what: &str) -> Result<Vec<JobLine>> {
    let mut out = Vec::new();
    let mut modal = Modal::new(DVec3::ZERO);
    let mut note = String::new();
    for (k, l) in text.lines().enumerate() {
        let s = strip(l);
        // '%' marks a program's start and end in a file; GRBL takes it
        // for a bad word, so it is not sent
        if s.is_empty() || s == "%" {
            for c in parse_line(l, k + 1).comments {
                if !note.is_empty() {
                    note.push_str("; ");
                }
                note.push_str(&c);
            }
            continue;
        }
        // GRBL acts on these bytes wherever they come, even inside a line:
        // a '!' in a job would hold the machine and the job end "done"
        if let Some(b) = s
            .bytes()
            .find(|&b| matches!(b, b'?' | b'!' | b'~') || !(0x20..0x7f).contains(&b))
        {
            bail!(
                "{what}: line {}: the byte 0x{b:02x} is a GRBL realtime command or not G-code; \
                 a job line cannot carry it",
                k + 1
            );
        }
        if s.len() > 79 {
            bail!(
                "{what}: line {}: {} characters after stripping; GRBL takes 79",
                k + 1,
                s.len()
            );
        }
        let step = modal.apply(&parse_line(&s, k + 1)).ok();
        let travel = step.as_ref().map_or(0.0, |st| match st.to {
            Some(_) if st.motion >= 2 => f64::INFINITY,
            Some(to) => (to - st.from).abs().max_element(),
            None => 0.0,
        });
        out.push(JobLine {
            number: k + 1,
            text: s,
            original: l.trim().to_string(),
            known: step.is_some(),
            travel,
            sync: step.as_ref().is_some_and(|st| st.sync),
            relative: step.as_ref().is_some_and(|st| st.relative),
            pause: step.as_ref().is_some_and(|st| st.pause),
            state: step
                .as_ref()
                .is_some_and(|st| st.pause)
                .then(|| Box::new(modal.clone())),
            dwell: step.and_then(|st| st.dwell).unwrap_or(0.0),
            note: std::mem::take(&mut note),
        });
    }
    if out.is_empty() {
        bail!("{what}: no G-code in the job");
    }
    Ok(out)
}
