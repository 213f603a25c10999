//! GRBL 1.1 on the wire (DESIGN.md section 8): what its codes mean, the
//! simulated machine the sender is tested against, the port it talks
//! through and the sender itself.

mod lines;
pub mod port;
pub mod remote;
mod replies;
pub mod resume;
pub mod sender;
pub mod session;
pub mod sim;
pub mod state;
mod stream;
pub mod touchoff;

/// GRBL 1.1's meaning of `error:N`.
pub fn error_meaning(n: u32) -> &'static str {
    match n {
        1 => "G-code words consist of a letter and a value; letter was not found",
        2 => "missing the expected G-code word value or numeric value format is not valid",
        3 => "'$' system command was not recognized or supported",
        4 => "negative value received for an expected positive value",
        5 => "homing cycle failure: homing is not enabled via settings",
        6 => "step pulse time must be longer than 3 microseconds ($0)",
        7 => "EEPROM read failed; the settings it held were restored to their defaults",
        8 => "'$' command cannot be used unless GRBL is idle",
        9 => "G-code commands are locked out during alarm or jog state",
        10 => "soft limits cannot be enabled without homing also enabled",
        11 => "max characters per line exceeded; the line was not processed",
        12 => "a setting's value makes the step rate exceed the most GRBL supports (30 kHz)",
        13 => "safety door opened; the door state began",
        14 => "build info or startup line longer than GRBL stores; not stored",
        15 => "jog target exceeds machine travel",
        16 => "jog command without '=' or with G-code a jog does not take",
        17 => "laser mode needs the spindle's PWM output",
        20 => "unsupported or invalid G-code command found in block",
        21 => "more than one G-code command from the same modal group found in block",
        22 => "feed rate has not yet been set or is undefined",
        23 => "G-code command in block requires an integer value",
        24 => "more than one G-code command that requires axis words found in block",
        25 => "repeated G-code word found in block",
        26 => "no axis words found in block for G-code command that requires them",
        27 => "line number value is invalid",
        28 => "G-code command is missing a required value word",
        29 => "G59.x work coordinate systems are not supported",
        30 => "G53 is allowed only in G0 and G1 motion modes",
        31 => "axis words found in block when no command or current modal state uses them",
        32 => "G2/G3 arcs need at least one axis word in the arc's plane",
        33 => "motion command has an invalid target",
        34 => "arc radius definition is invalid",
        35 => "G2/G3 arcs need at least one offset word in the arc's plane",
        36 => "unused value words found in block",
        37 => "G43.1 dynamic tool length offset is not on the tool length axis (Z)",
        38 => "tool number greater than max supported value",
        _ => "unknown error code",
    }
}

/// GRBL 1.1's meaning of `ALARM:N`.
pub fn alarm_meaning(n: u32) -> &'static str {
    match n {
        1 => "hard limit triggered; position is likely lost, re-homing is recommended",
        2 => "soft limit: the motion target exceeds the machine travel",
        3 => "reset while in motion; position is likely lost, re-homing is recommended",
        4 => "probe fail: the probe is not in the expected initial state",
        5 => "probe fail: the probe did not contact the workpiece",
        6 => "homing fail: reset during the homing cycle",
        7 => "homing fail: safety door opened during the homing cycle",
        8 => "homing fail: pull-off failed to clear the limit switch",
        9 => "homing fail: could not find the limit switch",
        10 => "homing fail: the second switch of a dual axis did not trigger within the search distance after the first",
        _ => "unknown alarm code",
    }
}

/// The welcome GRBL prints after power-up and every reset.
pub const WELCOME: &str = "Grbl 1.1h ['$' for help]";

/// Realtime commands: single bytes GRBL acts on at once, outside the buffer.
pub const STATUS: u8 = b'?';
pub const FEED_HOLD: u8 = b'!';
pub const CYCLE_START: u8 = b'~';
pub const SOFT_RESET: u8 = 0x18;
/// Jog cancel: a jog stops, its queued blocks dropped.
pub const JOG_CANCEL: u8 = 0x85;
/// Toggles the spindle off while in feed hold.
pub const SPINDLE_STOP: u8 = 0x9e;
/// The safety door opened: a hold that turns the spindle and coolant off
/// and restores them (after 4 s of spindle) at cycle start.
pub const SAFETY_DOOR: u8 = 0x84;

#[cfg(test)]
mod tests {
    use super::*;

    /// The codes GRBL 1.1h documents (doc/csv: errors 1-17 and 20-38,
    /// alarms 1-10) each have a meaning; codes it does not use do not.
    #[test]
    fn every_code_grbl_documents_has_a_meaning() {
        for e in (1..=17).chain(20..=38) {
            assert!(!error_meaning(e).starts_with("unknown"), "error:{e}");
        }
        for a in 1..=10 {
            assert!(!alarm_meaning(a).starts_with("unknown"), "ALARM:{a}");
        }
        for unused in [0, 18, 19, 39] {
            assert!(
                error_meaning(unused).starts_with("unknown"),
                "error:{unused}"
            );
        }
        assert!(alarm_meaning(11).starts_with("unknown"));
    }
}
