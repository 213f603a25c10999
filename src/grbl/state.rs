//! GRBL 1.1's machine states, by name: what a status report's first field
//! says (`<Hold:0|...`), parsed once, so the sender, the simulated machine
//! and the job's checks ask the state and not its spelling.

use std::fmt;

/// The state a GRBL 1.1 controller reports, with its sub-state where it
/// has one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum State {
    Idle,
    Run,
    /// Feed hold: 0 complete (the machine stands), 1 still decelerating.
    Hold(u8),
    Jog,
    /// Locked out until unlocked or homed.
    Alarm,
    /// Safety door: 0 closed and ready, 1 machine stopped, 2 opened and
    /// retracting, 3 closed and restoring.
    Door(u8),
    /// Check mode (`$C`): lines parsed, nothing moves.
    Check,
    Home,
    Sleep,
}

impl State {
    /// The state a status report's first field names, e.g. `Hold:0`.
    pub fn parse(s: &str) -> Option<State> {
        let (name, sub) = match s.split_once(':') {
            Some((n, k)) => (n, Some(k.parse::<u8>().ok()?)),
            None => (s, None),
        };
        Some(match (name, sub) {
            ("Idle", None) => State::Idle,
            ("Run", None) => State::Run,
            ("Hold", k) => State::Hold(k.unwrap_or(0)),
            ("Jog", None) => State::Jog,
            ("Alarm", None) => State::Alarm,
            ("Door", k) => State::Door(k.unwrap_or(0)),
            ("Check", None) => State::Check,
            ("Home", None) => State::Home,
            ("Sleep", None) => State::Sleep,
            _ => return None,
        })
    }

    /// Held by a feed hold or an open door: stopped mid-job until cycle
    /// start.
    pub fn is_held(self) -> bool {
        matches!(self, State::Hold(_) | State::Door(_))
    }
}

impl fmt::Display for State {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            State::Idle => write!(f, "Idle"),
            State::Run => write!(f, "Run"),
            State::Hold(k) => write!(f, "Hold:{k}"),
            State::Jog => write!(f, "Jog"),
            State::Alarm => write!(f, "Alarm"),
            State::Door(k) => write!(f, "Door:{k}"),
            State::Check => write!(f, "Check"),
            State::Home => write!(f, "Home"),
            State::Sleep => write!(f, "Sleep"),
        }
    }
}

/// Whether GRBL stands, from its status reports: two saying Idle in a
/// row with every line sent answered. GRBL can say Idle once with moves
/// still queued (a report and the cycle start due in the same pass of its
/// realtime loop print the report first), never twice.
#[derive(Clone, Copy, Debug, Default)]
pub struct Standing(u32);

impl Standing {
    /// Known to stand (as after two Idle reports).
    pub fn sure() -> Standing {
        Standing(2)
    }

    /// A status report's state; `owed`: a line sent is not yet answered.
    pub fn report(&mut self, state: State, owed: bool) {
        self.0 = if state == State::Idle && !owed {
            self.0.saturating_add(1)
        } else {
            0
        };
    }

    /// A line went out: the reports before it say nothing of it.
    pub fn sent(&mut self) {
        self.0 = 0;
    }

    pub fn is_sure(self) -> bool {
        self.0 >= 2
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_state_reads_back_as_written() {
        for s in [
            State::Idle,
            State::Run,
            State::Hold(0),
            State::Hold(1),
            State::Jog,
            State::Alarm,
            State::Door(3),
            State::Check,
            State::Home,
            State::Sleep,
        ] {
            assert_eq!(State::parse(&s.to_string()), Some(s));
        }
        assert_eq!(State::parse("Hold"), Some(State::Hold(0)));
        for bad in ["", "idle", "Run:1", "Hold:x", "Door:", "Busy"] {
            assert_eq!(State::parse(bad), None, "{bad}");
        }
        assert!(State::Door(1).is_held() && !State::Run.is_held());
    }

    #[test]
    fn standing_takes_two_idle_reports_with_nothing_owed() {
        let mut s = Standing::default();
        s.report(State::Idle, false);
        assert!(!s.is_sure(), "one Idle report");
        s.report(State::Idle, false);
        assert!(s.is_sure());
        s.sent();
        s.report(State::Idle, true);
        s.report(State::Idle, false);
        assert!(!s.is_sure(), "Idle while a line was owed");
        s.report(State::Run, false);
        s.report(State::Idle, false);
        assert!(!s.is_sure(), "Run between");
        assert!(Standing::sure().is_sure());
    }
}
