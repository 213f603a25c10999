//! The simulated GRBL's `$` settings, kept, checked and printed as GRBL
//! 1.1h's settings.c and report.c keep, check and print them (single
//! precision, acceleration held in mm/min², travel held negative).

use crate::machine::Machine;
use glam::DVec3;

/// GRBL's printFloat: `decimals` places, rounded by adding a half in
/// single precision and truncating, as the firmware prints every number.
pub fn grbl_float(n: f32, decimals: u8) -> String {
    let mut s = String::new();
    let mut n = n;
    if n < 0.0 {
        s.push('-');
        n = -n;
    }
    let mut d = decimals;
    while d >= 2 {
        n *= 100.0;
        d -= 2;
    }
    if d > 0 {
        n *= 10.0;
    }
    let n = (n as f64 + 0.5) as f32;
    let mut a = (n as f64) as i64 as u32;
    let mut buf = Vec::new();
    while a > 0 {
        buf.push(b'0' + (a % 10) as u8);
        a /= 10;
    }
    while buf.len() < decimals as usize {
        buf.push(b'0');
    }
    if buf.len() == decimals as usize {
        buf.push(b'0');
    }
    for i in (1..=buf.len()).rev() {
        if i == decimals as usize {
            s.push('.');
        }
        s.push(buf[i - 1] as char);
    }
    s
}

/// A float to a small C integer as GRBL's host build converts it.
fn c_u8(x: f32) -> u8 {
    super::c_int(x as f64) as u8
}

/// GRBL's settings, by their numbers.
#[derive(Clone, Debug)]
pub struct Settings {
    /// $0-$6, $10, $13, $20-$23, $26, $32: GRBL's small integers and flags.
    ints: [u8; 33],
    /// $11, $12, $24, $25, $27, $30, $31, as stored.
    floats: [f32; 33],
    steps: [f32; 3],
    max_rate: [f32; 3],
    /// mm/min², as GRBL holds it.
    accel: [f32; 3],
    /// Negative, as GRBL holds it.
    travel: [f32; 3],
}

const INTS: [u8; 15] = [0, 1, 2, 3, 4, 5, 6, 10, 13, 20, 21, 22, 23, 26, 32];
const FLOATS: [u8; 7] = [11, 12, 24, 25, 27, 30, 31];

impl Settings {
    /// GRBL 1.1h's defaults (defaults.h, the generic build), with the
    /// machine file's rates, accelerations, travel, junction deviation and
    /// spindle range.
    pub fn of(m: &Machine) -> Settings {
        let mut s = Settings {
            ints: [0; 33],
            floats: [0.0; 33],
            steps: [0.0; 3],
            max_rate: [0.0; 3],
            accel: [0.0; 3],
            travel: [0.0; 3],
        };
        for (k, v) in [(0, 10), (1, 25), (10, 1), (26, 250)] {
            s.ints[k] = v;
        }
        for (k, v) in [(11, m.junction_deviation as f32), (12, 0.002)] {
            s.floats[k] = v;
        }
        for (k, v) in [(24, 25.0), (25, 500.0), (27, 1.0)] {
            s.floats[k] = v;
        }
        s.floats[30] = m.spindle.max as f32;
        s.floats[31] = m.spindle.min as f32;
        for k in 0..3 {
            s.steps[k] = m.steps_per_mm.get(k) as f32;
            s.max_rate[k] = m.max_rate.get(k) as f32;
            s.accel[k] = m.acceleration.get(k) as f32 * 60.0 * 60.0;
            s.travel[k] = -(m.travel.get(k) as f32);
        }
        s
    }

    /// Steps per mm per axis ($100-$102).
    pub fn steps_mm(&self) -> DVec3 {
        DVec3::from(self.steps.map(f64::from))
    }

    /// Top rate per axis, mm/min ($110-$112).
    pub fn rates(&self) -> DVec3 {
        DVec3::from(self.max_rate.map(f64::from))
    }

    /// Acceleration per axis, mm/s² ($120-$122).
    pub fn accels(&self) -> DVec3 {
        DVec3::new(
            self.acceleration(0),
            self.acceleration(1),
            self.acceleration(2),
        )
    }

    pub fn junction(&self) -> f64 {
        self.floats[11] as f64
    }

    pub fn arc_tolerance(&self) -> f64 {
        self.floats[12] as f64
    }

    /// mm/s² per axis.
    fn acceleration(&self, axis: usize) -> f64 {
        (self.accel[axis] / (60.0 * 60.0)) as f64
    }

    pub fn soft_limits(&self) -> bool {
        self.ints[20] != 0
    }

    pub fn homing(&self) -> bool {
        self.ints[22] != 0
    }

    pub fn report_inches(&self) -> bool {
        self.ints[13] != 0
    }

    /// `$10` bit 0: reports give the machine position (else the work's).
    pub fn report_mpos(&self) -> bool {
        self.ints[10] & 1 != 0
    }

    /// `$10` bit 1: reports give the buffers' room (`Bf:`).
    pub fn report_buffers(&self) -> bool {
        self.ints[10] & 2 != 0
    }

    /// The spindle speed GRBL sets for `rpm` ($30 max, $31 min): at or
    /// above the maximum the maximum, below the minimum the minimum, 0
    /// off.
    pub fn spindle_rpm(&self, rpm: f64) -> f64 {
        let (max, min) = (self.floats[30] as f64, self.floats[31] as f64);
        if min >= max || rpm >= max {
            max
        } else if rpm <= min {
            if rpm == 0.0 {
                0.0
            } else {
                min
            }
        } else {
            rpm
        }
    }

    /// Whether machine position `p` lies outside the travel soft limits
    /// guard: GRBL's machine space runs from 0 down to -travel on each
    /// axis (without HOMING_FORCE_SET_ORIGIN, as in its default build).
    pub fn beyond_travel(&self, p: [f64; 3]) -> bool {
        (0..3).any(|k| {
            let v = p[k] as f32;
            v > 0.0 || v < self.travel[k]
        })
    }

    /// `$n=value`: GRBL's settings_store_global_setting.
    pub fn store(&mut self, n: u8, value: f32) -> Result<(), u32> {
        if value < 0.0 {
            return Err(4);
        }
        if n >= 100 {
            let (group, axis) = ((n - 100) / 10, ((n - 100) % 10) as usize);
            if axis >= 3 || group >= 4 {
                return Err(3);
            }
            match group {
                0 => self.steps[axis] = value,
                1 => self.max_rate[axis] = value,
                2 => self.accel[axis] = value * 60.0 * 60.0,
                _ => self.travel[axis] = -value,
            }
            return Ok(());
        }
        let int = c_u8(value);
        match n {
            0 if int < 3 => return Err(6),
            20 if int != 0 && !self.homing() => return Err(10),
            22 if int == 0 => {
                self.ints[22] = 0;
                self.ints[20] = 0;
            }
            4 | 5 | 6 | 13 | 20 | 21 | 22 | 32 => self.ints[n as usize] = u8::from(int != 0),
            n if INTS.contains(&n) => self.ints[n as usize] = int,
            n if FLOATS.contains(&n) => self.floats[n as usize] = value,
            _ => return Err(3),
        }
        Ok(())
    }

    /// `$$` as GRBL prints it, a line per setting.
    pub fn report(&self) -> Vec<String> {
        let mut out = Vec::new();
        for n in [
            0u8, 1, 2, 3, 4, 5, 6, 10, 11, 12, 13, 20, 21, 22, 23, 24, 25, 26, 27, 30, 31, 32,
        ] {
            let v = match n {
                30 | 31 => grbl_float(self.floats[n as usize], 0),
                n if FLOATS.contains(&n) => grbl_float(self.floats[n as usize], 3),
                n => self.ints[n as usize].to_string(),
            };
            out.push(format!("${n}={v}"));
        }
        for (g, vals) in [
            self.steps,
            self.max_rate,
            self.accel.map(|a| a / (60.0 * 60.0)),
            self.travel.map(|t| -t),
        ]
        .iter()
        .enumerate()
        {
            for (k, v) in vals.iter().enumerate() {
                out.push(format!("${}={}", 100 + 10 * g + k, grbl_float(*v, 3)));
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_print_as_grbl_prints_them() {
        assert_eq!(grbl_float(0.0, 3), "0.000");
        assert_eq!(grbl_float(-0.0001, 3), "-0.000");
        assert_eq!(grbl_float(1000.0, 0), "1000");
        assert_eq!(grbl_float(0.5, 0), "1");
        assert_eq!(grbl_float(12.3456, 3), "12.346");
        assert_eq!(grbl_float(0.002, 3), "0.002");
    }

    #[test]
    fn settings_are_checked_as_grbl_checks_them() {
        let mut s = Settings::of(&Machine::load("grbl-generic").unwrap());
        assert_eq!(s.store(0, 2.0), Err(6));
        assert_eq!(s.store(20, 1.0), Err(10));
        assert_eq!(s.store(22, 1.0), Ok(()));
        assert_eq!(s.store(20, 1.0), Ok(()));
        assert!(s.soft_limits());
        assert_eq!(s.store(22, 0.0), Ok(()));
        assert!(!s.soft_limits());
        assert_eq!(s.store(103, 1.0), Err(3));
        assert_eq!(s.store(140, 1.0), Err(3));
        assert_eq!(s.store(120, -1.0), Err(4));
        assert_eq!(s.store(10, 258.0), Ok(()));
        assert!(s.report().contains(&"$10=2".to_string()));
        assert_eq!(s.report().len(), 34);
    }
}
