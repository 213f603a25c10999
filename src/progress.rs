//! What a long stage tells the person waiting: a spinner naming the stage,
//! and a bar where the stage knows its share done. Silent off a terminal
//! and with --quiet, so logs and pipes stay clean.

use std::io::IsTerminal;
use std::time::Duration;

/// A progress line on stderr, or nothing.
#[derive(Clone, Default)]
pub struct Progress(Option<indicatif::ProgressBar>);

const SPIN: &str = "{spinner} {msg} ({elapsed})";
const BAR: &str = "{msg} [{bar:30}] {percent}% ({elapsed})";

impl Progress {
    /// Nothing shown.
    pub fn none() -> Self {
        Progress(None)
    }

    /// A spinner on stderr when it is a terminal and not `quiet`.
    pub fn on_terminal(quiet: bool) -> Self {
        if quiet || !std::io::stderr().is_terminal() {
            return Progress(None);
        }
        let pb = indicatif::ProgressBar::new_spinner();
        if let Ok(style) = indicatif::ProgressStyle::with_template(SPIN) {
            pb.set_style(style);
        }
        pb.enable_steady_tick(Duration::from_millis(100));
        Progress(Some(pb))
    }

    /// A new stage, named: a spinner until it tells its share.
    pub fn stage(&self, what: &str) {
        if let Some(pb) = &self.0 {
            if let Ok(style) = indicatif::ProgressStyle::with_template(SPIN) {
                pb.set_style(style);
            }
            // (after the style: a bar without a length would show 0%)
            pb.unset_length();
            pb.set_message(what.to_string());
        }
    }

    /// The share of the stage done, 0 to 1: the spinner becomes a bar.
    pub fn share(&self, done: f64) {
        if let Some(pb) = &self.0 {
            if pb.length() != Some(1000) {
                pb.set_length(1000);
                if let Ok(style) = indicatif::ProgressStyle::with_template(BAR) {
                    pb.set_style(style.progress_chars("=> "));
                }
            }
            pb.set_position((done.clamp(0.0, 1.0) * 1000.0) as u64);
        }
    }

    /// Clear the line.
    pub fn finish(&self) {
        if let Some(pb) = &self.0 {
            pb.finish_and_clear();
        }
    }
}
