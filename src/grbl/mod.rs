//! GRBL 1.1 on the wire (DESIGN.md section 8): what its codes mean, the
//! simulated machine the sender is tested against, the port it talks
//! through and the sender itself.

mod lines;
pub mod port;
mod replies;
pub mod resume;
pub mod sender;
pub mod sim;
pub mod state;
mod stream;
mod touchoff;

/// GRBL 1.1's meaning of `error:N`.
pub fn error_meaning(n: u32) -> &'static str {
    match n {
        1 => "G-code words consist of a letter and a value; letter was not found",
        2 => "missing the expected G-code word value or numeric value format is not valid",
        3 => "'$' system command was not recognized or supported",
        4 => "negative value received for an expected positive value",
        5 => "homing cycle failure: homing is not enabled via settings",
        8 => "'$' command cannot be used unless GRBL is idle",
        9 => "G-code commands are locked out during alarm or jog state",
        10 => "soft limits cannot be enabled without homing also enabled",
        11 => "max characters per line exceeded; the line was not processed",
        15 => "jog target exceeds machine travel",
        20 => "unsupported or invalid G-code command found in block",
        21 => "more than one G-code command from the same modal group found in block",
        22 => "feed rate has not yet been set or is undefined",
        23 => "G-code command in block requires an integer value",
        24 => "more than one G-code command that requires axis words found in block",
        25 => "repeated G-code word found in block",
        26 => "no axis words found in block for G-code command that requires them",
        27 => "line number value is invalid",
        28 => "G-code command is missing a required value word",
        31 => "axis words found in block when no command or current modal state uses them",
        33 => "motion command has an invalid target",
        34 => "arc radius definition is invalid",
        36 => "unused value words found in block",
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
