//! The jobs each command runs as one library call, side by side: a typed
//! input, one `run`, a typed output. The command layer (`src/cmd`) parses
//! flags into these; the studio builds the same jobs from its page.
//!
//! - `relief`: a model (or the demo scene) -> a relief file (`ReliefJob`),
//!   from the relief settings the command line and the studio share
//!   (`ReliefSettings`);
//! - `toolpath`: a relief -> a GRBL job (`ToolpathJob`, whose stages live
//!   in `cam`);
//! - `simulate`: jobs and a relief -> the simulated cut and its report
//!   (`SimulateJob`);
//! - `send`: a job file -> streamed to a GRBL controller (`SendJob`).

pub mod relief;
pub mod send;
pub mod settings;
pub mod simulate;
pub mod toolpath;
