//! The `send` command as one library call: a job file and a port in, the
//! job streamed (optionally checked first, optionally resumed), or one
//! clear error saying where it stopped and how to resume.

use super::port::Port;
use super::sender::{self, JobLine, Options, Outcome, Replies};
use crate::bail;
use crate::error::Result;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

#[derive(Clone, Debug, Default)]
pub struct SendJob {
    pub job: PathBuf,
    /// Validate the whole job in GRBL's check mode first.
    pub check: bool,
    /// Send one line and wait for its reply (instead of character counting).
    pub send_response: bool,
    /// Start at this job file line (with a safe re-entry).
    pub resume_from: Option<usize>,
    /// Resume after the last line this journal records.
    pub resume: Option<PathBuf>,
    /// Journal of acknowledged lines; `None` = JOB.journal.
    pub journal: Option<PathBuf>,
    pub progress: bool,
    pub rx_buffer: usize,
}

impl SendJob {
    pub fn journal_path(&self) -> PathBuf {
        self.journal.clone().unwrap_or_else(|| {
            let mut p = self.job.clone().into_os_string();
            p.push(".journal");
            p.into()
        })
    }

    pub fn run(&self, port: &mut dyn Port, cancel: &AtomicBool) -> Result<(Outcome, usize)> {
        let lines = sender::load_job(&self.job)?;
        let start = self.start(&lines)?;
        let journal = self.journal_path();
        let opts = Options {
            char_counting: !self.send_response,
            rx_buffer: self.rx_buffer.max(16),
            journal: Some(journal.clone()),
            progress: self.progress,
            ..Options::default()
        };
        let mut r = Replies::new(port);
        r.handshake(opts.welcome_timeout)?;
        if r.state()?.is_some_and(|s| s.starts_with("Alarm")) {
            bail!(
                "GRBL is in alarm (position may be lost after a reset in motion): check the \
                 machine, then `relievo machine home` or `unlock` on this port, and send again"
            );
        }
        if self.check {
            let errors = sender::check(&mut r, &lines, &opts)?;
            if !errors.is_empty() {
                let list: Vec<String> = errors.iter().map(|e| e.describe()).collect();
                bail!(
                    "{}: check mode found {} bad line(s), nothing was moved: {}",
                    self.job.display(),
                    errors.len(),
                    list.join("; ")
                );
            }
        }
        if start == 0 {
            // a fresh run starts a fresh journal
            std::fs::write(&journal, b"")
                .map_err(|e| crate::Error(format!("{}: {e}", journal.display())))?;
        }
        let preamble = if start > 0 {
            sender::reentry(&lines, start)
        } else {
            Vec::new()
        };
        let resume_hint = |acked_to: Option<usize>| {
            format!(
                "; the journal {} holds the last acknowledged line{}; resume with --resume {}",
                journal.display(),
                acked_to.map_or(String::new(), |l| format!(" ({l})")),
                journal.display()
            )
        };
        let out = match sender::stream(&mut r, &lines[start..], &preamble, &opts, false, cancel) {
            Ok(o) => o,
            Err(e) => {
                let last = sender::journal_last(&journal).ok();
                bail!("{}: {e}{}", self.job.display(), resume_hint(last));
            }
        };
        if let Some(stop) = &out.stop {
            let last = sender::journal_last(&journal).ok();
            bail!(
                "{}: {}{}",
                self.job.display(),
                stop.describe(),
                resume_hint(last)
            );
        }
        Ok((out, lines.len() - start))
    }

    /// Index of the first job line to send.
    fn start(&self, lines: &[JobLine]) -> Result<usize> {
        let after = match (&self.resume, self.resume_from) {
            (Some(_), Some(_)) => bail!("--resume and --resume-from: give one"),
            (Some(j), None) => sender::journal_last(j)? + 1,
            (None, Some(n)) => n,
            (None, None) => return Ok(0),
        };
        match lines.iter().position(|l| l.number >= after) {
            Some(k) => Ok(k),
            None => bail!(
                "{}: nothing left to send from line {after} (the job has {} lines)",
                self.job.display(),
                lines.last().map_or(0, |l| l.number)
            ),
        }
    }
}
