//! Resuming a job after a fault (DESIGN.md section 8). An `ok` from GRBL
//! means a line is in its planner, not that it ran, and a cut link loses
//! the `ok`s of lines that did run. So the journal records three things:
//! what was sent, what was acknowledged, and what is known to have run
//! (GRBL answered a line that waits for the planner to empty, or a status
//! report showed how many moves were still queued). The lines between
//! the last known-run line and the last sent one are in doubt: a resume
//! runs them again, which is safe only for lines that land in the same
//! place however often they run.

use super::sender::JobLine;
use crate::bail;
use crate::error::{Context, Result};
use crate::gcode::modal::Modal;
use crate::gcode::parse::parse_line;
use glam::DVec3;
use std::collections::VecDeque;
use std::io::Write;
use std::path::{Path, PathBuf};

/// The journal being written while streaming: `>N` before line N goes on
/// the wire, `N` when GRBL acknowledges it, `=N` when every line up to N
/// is known to have run. Records are flushed before the bytes they
/// announce are written, so a crash never hides a sent line.
pub struct Journal {
    file: std::io::BufWriter<std::fs::File>,
    path: PathBuf,
    executed: Option<usize>,
}

impl Journal {
    /// Open `path` for appending (`fresh`: emptied first).
    pub fn open(path: &Path, fresh: bool) -> Result<Journal> {
        let file = std::fs::OpenOptions::new()
            .create(true)
            .append(!fresh)
            .write(true)
            .truncate(fresh)
            .open(path)
            .ctx(path.display().to_string())?;
        Ok(Journal {
            file: std::io::BufWriter::new(file),
            path: path.to_path_buf(),
            executed: None,
        })
    }

    fn record(&mut self, r: std::fmt::Arguments) -> Result<()> {
        writeln!(self.file, "{r}").ctx(self.path.display().to_string())
    }

    pub fn sent(&mut self, number: usize) -> Result<()> {
        self.record(format_args!(">{number}"))
    }

    pub fn acked(&mut self, number: usize) -> Result<()> {
        self.record(format_args!("{number}"))
    }

    /// Every line up to `number` has run.
    pub fn executed(&mut self, number: usize) -> Result<()> {
        if self.executed.is_some_and(|e| e >= number) {
            return Ok(());
        }
        self.executed = Some(number);
        self.record(format_args!("={number}"))
    }

    pub fn flush(&mut self) -> Result<()> {
        self.file.flush().ctx(self.path.display().to_string())
    }
}

/// What a journal says, over every run it records.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Record {
    /// The furthest line sent.
    pub sent: Option<usize>,
    /// The furthest line acknowledged.
    pub acked: Option<usize>,
    /// Every line up to this one has run.
    pub executed: Option<usize>,
}

impl Record {
    pub fn read(path: &Path) -> Result<Record> {
        let what = path.display().to_string();
        let text = crate::input::read_text(path, crate::input::MAX_FILE)?;
        let mut r = Record::default();
        for (k, l) in text.lines().enumerate() {
            let l = l.trim();
            if l.is_empty() {
                continue;
            }
            let (slot, num) = match l.as_bytes()[0] {
                b'>' => (&mut r.sent, &l[1..]),
                b'=' => (&mut r.executed, &l[1..]),
                _ => (&mut r.acked, l),
            };
            let n: usize = num.parse().map_err(|_| {
                crate::Error(format!("{what}: line {}: not a journal record", k + 1))
            })?;
            *slot = Some(slot.map_or(n, |s| s.max(n)));
        }
        Ok(r)
    }

    /// The furthest line that may have reached the machine.
    pub fn reached(&self) -> Option<usize> {
        self.sent.max(self.acked)
    }
}

/// The lines in doubt: from the first line not known to have run to the
/// last line that may have reached the machine, as indices into `lines`
/// (empty when `end < start`).
pub fn doubt(lines: &[JobLine], r: &Record) -> (usize, usize) {
    let start = lines
        .iter()
        .position(|l| r.executed.is_none_or(|e| l.number > e))
        .unwrap_or(lines.len());
    let end = match r.reached() {
        Some(s) => lines
            .iter()
            .rposition(|l| l.number <= s)
            .map_or(0, |k| k + 1),
        None => 0,
    };
    (start, end)
}

/// Why running `lines[from..to]` a second time could change the cut, if
/// it could: the first line that moves relatively, or that relievo cannot
/// read (and so cannot vouch for).
pub fn unsafe_rerun(lines: &[JobLine], from: usize, to: usize) -> Option<String> {
    lines.get(from..to)?.iter().find_map(|l| {
        let why = if !l.known {
            "relievo cannot read it, so cannot tell that running it twice is harmless"
        } else if l.relative {
            "it moves relative to where the machine is (G91), so running it twice moves twice"
        } else {
            return None;
        };
        Some(format!("job line {} '{}': {why}", l.number, l.original))
    })
}

/// Follows which acknowledged lines are known to have run while
/// streaming: a line is known to have run once GRBL answers a line that
/// waits for the planner to empty, once more moves than the planner holds
/// have been acknowledged after it, or once a status report's free
/// planner blocks (`Bf:`) say that its move has left the planner.
pub struct Tracker {
    planner: usize,
    min_move: f64,
    /// Acknowledged moving lines (indices) not yet known to have run.
    queued: VecDeque<usize>,
    last_acked: Option<usize>,
}

impl Tracker {
    pub fn new(planner: usize, min_move: f64) -> Tracker {
        Tracker {
            planner: planner.max(1),
            min_move,
            queued: VecDeque::new(),
            last_acked: None,
        }
    }

    /// Line `k` was acknowledged; returns the last line now known to have
    /// run, if that moved on.
    pub fn acked(&mut self, lines: &[JobLine], k: usize) -> Option<usize> {
        self.last_acked = Some(k);
        if lines[k].sync {
            self.queued.clear();
            return Some(k);
        }
        // a shorter move may take no block: counting it could wrongly
        // push an earlier line out of the planner; not counting it only
        // keeps more lines in doubt
        if lines[k].travel >= self.min_move {
            self.queued.push_back(k);
        }
        self.in_planner(self.planner)
    }

    /// The first line that may not have run yet: the oldest in the
    /// planner, else the one after the last acknowledged.
    pub fn first_unrun(&self) -> usize {
        self.queued
            .front()
            .copied()
            .unwrap_or_else(|| self.last_acked.map_or(0, |k| k + 1))
    }

    /// A status report said `free` planner blocks were free.
    pub fn status(&mut self, free: usize) -> Option<usize> {
        self.in_planner(self.planner.saturating_sub(free))
    }

    /// At most `q` moves are in the planner: they are the last `q` moving
    /// lines acknowledged, and everything acknowledged before them ran.
    fn in_planner(&mut self, q: usize) -> Option<usize> {
        if q == 0 {
            self.queued.clear();
            return self.last_acked;
        }
        if self.queued.len() <= q {
            return None;
        }
        self.queued.drain(..self.queued.len() - q);
        self.queued.front().and_then(|&k| k.checked_sub(1))
    }
}

/// Lines that put the machine back where the job was before `lines[from]`:
/// units, distance mode, spindle, up to the job's safe height, over the
/// point, down at the plunge feed, then the job's feed. A G92 offset the
/// job had set (GRBL forgets it at a reset) is cleared, the point reached
/// in the coordinates without it, and set again there with G92: the
/// machine then reads the job's own coordinates at the very same place.
pub fn reentry(lines: &[JobLine], from: usize) -> Vec<String> {
    let mut m = Modal::new(DVec3::ZERO);
    for p in lines[..from].iter().map(|l| parse_line(&l.text, l.number)) {
        // a line GRBL would refuse changes nothing there either
        let _ = m.apply(&p);
    }
    reentry_at(&m, highest_z(lines))
}

/// The highest Z a job's lines name (its safe height, or above it).
pub fn highest_z(lines: &[JobLine]) -> f64 {
    lines
        .iter()
        .map(|l| parse_line(&l.text, l.number))
        .flat_map(|p| p.words.into_iter().filter(|w| w.0 == 'Z'))
        .fold(0.0f64, |t, w| t.max(w.1))
}

/// Lines that put the machine back in the job's modal state `m`, at its
/// position, by way of `top` (or 5 mm, or where it stands, the highest).
pub fn reentry_at(m: &Modal, top: f64) -> Vec<String> {
    // in the job's work coordinates, its coordinate system and tool
    // length offset restored first (a reset keeps the former, not the
    // latter)
    let pos = m.pos - m.wco();
    let safe = top.max(pos.z).max(5.0);
    let n = |v: f64| crate::gcode::emit::num(v);
    let mut out = vec!["G21G90".to_string()];
    if m.coord != 0 {
        out.push(format!("G{}", 54 + m.coord));
    }
    if m.tlo_on {
        out.push(format!("G43.1Z{}", n(m.tlo)));
    }
    // without the job's G92 offset until the point is reached
    let g = m.g92;
    if g != DVec3::ZERO {
        out.push("G92.1".into());
    }
    if let Some(dir) = m.spindle {
        out.push(format!("M{dir}S{}", n(m.speed)));
        out.push("G4P2".into());
    }
    out.push(format!("G0Z{}", n(safe + g.z)));
    out.push(format!("G0X{}Y{}", n(pos.x + g.x), n(pos.y + g.y)));
    let f = m.feed.unwrap_or(300.0);
    out.push(format!("G1Z{}F{}", n(pos.z + g.z), n(f.min(300.0))));
    if g != DVec3::ZERO {
        out.push(format!("G92X{}Y{}Z{}", n(pos.x), n(pos.y), n(pos.z)));
    }
    out.push(format!("F{}", n(f)));
    if m.inches {
        out.push("G20".into());
    }
    if m.plane != crate::dialect::arc::Plane::Xy {
        out.push(format!("G{}", m.plane.code()));
    }
    if !m.absolute {
        out.push("G91".into());
    }
    out
}

/// Where a resume starts, from a journal: the first line in doubt, with
/// every line that may run a second time safe to run again.
pub fn resume_point(lines: &[JobLine], journal: &Path) -> Result<usize> {
    let r = Record::read(journal)?;
    let (start, end) = doubt(lines, &r);
    if start >= lines.len() {
        bail!(
            "{}: every line of the job has run; nothing to resume",
            journal.display()
        );
    }
    if let Some(why) = unsafe_rerun(lines, start, end) {
        bail!(
            "{}: cannot resume safely: job lines {} to {} were sent but may or may not have \
             run, and {why}; check where the machine is and choose the line yourself with \
             --resume-from",
            journal.display(),
            lines[start].number,
            lines[end - 1].number
        );
    }
    Ok(start)
}

/// One sentence on where a stopped job stands, for its error message.
pub fn standing(lines: &[JobLine], journal: &Path) -> String {
    let Ok(r) = Record::read(journal) else {
        return String::new();
    };
    if r.reached().is_none() {
        return "; nothing was sent, so the job can simply be sent again".into();
    }
    let (start, end) = doubt(lines, &r);
    let ran = r
        .executed
        .map_or("no line is known to have run".into(), |e| {
            format!("every line up to {e} has run")
        });
    let doubt = if end > start {
        format!(
            "; lines {} to {} were sent and may or may not have run",
            lines[start].number,
            lines[end - 1].number
        )
    } else {
        String::new()
    };
    let advice = match unsafe_rerun(lines, start, end) {
        Some(why) => format!(
            "; a resume would run them again, which is unsafe: {why}; check the machine and \
             choose the line with --resume-from"
        ),
        None => format!(
            "; resume with --resume {} (it re-enters at line {})",
            journal.display(),
            lines.get(start).map_or(0, |l| l.number)
        ),
    };
    format!("; the journal says {ran}{doubt}{advice}")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gcode::modal::Modal;

    /// The machine state after `lines`, and after a reset then the
    /// re-entry preamble for the line after them: the same machine
    /// position, work offset (G55, TLO and G92 included) and modes.
    #[test]
    fn reentry_restores_offsets_and_the_point() {
        let text = "G21G90\nG10L2P2X5Y6Z-7\nG55\nG43.1Z1.5\nG0Z3\nG0X10Y10\n\
                    G92X0Y0Z2\nM3S1000\nG1Z-1F400\nG1X4Y3\nG1X8Y1\nM5\nM30\n";
        let lines = crate::grbl::sender::job_lines(text, "job.nc").unwrap();
        let from = lines.iter().position(|l| l.text == "G1X8Y1").unwrap();
        let fold = |m: &mut Modal, ls: &[String]| {
            for (k, l) in ls.iter().enumerate() {
                m.apply(&parse_line(l, k + 1)).unwrap();
            }
        };
        let mut before = Modal::new(DVec3::new(-50.0, -40.0, -1.0));
        let texts: Vec<String> = lines[..from].iter().map(|l| l.text.clone()).collect();
        fold(&mut before, &texts);
        assert_ne!(before.g92, DVec3::ZERO);
        // a reset: G54, no TLO, no G92, the stored offsets kept; the
        // machine wherever the stop left it
        let mut after = before.after_reset(DVec3::new(-20.0, -3.0, -0.5));
        let pre = reentry(&lines, from);
        fold(&mut after, &pre);
        assert!((after.pos - before.pos).length() < 1e-9, "{pre:?}");
        assert!((after.wco() - before.wco()).length() < 1e-9, "{pre:?}");
        assert!((after.g92 - before.g92).length() < 1e-9, "{pre:?}");
        assert_eq!((after.coord, after.tlo_on), (before.coord, before.tlo_on));
        assert_eq!(after.spindle, before.spindle);
        // the tool stays clear of the work until over the point: it
        // rises to the job's safe height (in its own coordinates) first
        let work_z = |l: &str| l.strip_prefix("G0Z").map(|z| z.parse::<f64>().unwrap());
        let rise = pre.iter().find_map(|l| work_z(l)).unwrap();
        assert!(rise - before.g92.z >= 3.0, "{pre:?}");
    }
}
