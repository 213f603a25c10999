//! Setting Z from a touch: a touch plate on the work (outside a job or
//! at its pause), or a fixed tool-length setter (a tool's length measured
//! before and after a change, the difference applied to the work zero).

use super::replies::Replies;
use crate::bail;
use crate::error::Result;
use crate::gcode::modal::Modal;
pub use crate::machine::Setter;
use glam::DVec3;
use std::sync::{Arc, Mutex};

/// A Z touch-off on a touch plate: G38.2 down fast, back off, again
/// slowly, then the work Z set from the trigger point so that the plate's
/// top is Z = thickness.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TouchOff {
    pub thickness: f64,
    /// Where the plate lies (work X, Y); None = under the tool.
    pub at: Option<(f64, f64)>,
    /// Fast probing feed, mm/min.
    pub feed: f64,
    /// How far the fast probe may go down, mm.
    pub travel: f64,
}

/// Slow probing feed, mm/min: the machine stops within a micrometre of
/// the trigger (the trigger point itself is what sets Z).
const SLOW_PROBE: f64 = 10.0;
/// Rise over the plate before moving to it, mm.
const PLATE_CLEARANCE: f64 = 10.0;

impl TouchOff {
    /// `THICKNESS[@X,Y]`, mm.
    pub fn parse(s: &str) -> std::result::Result<TouchOff, String> {
        let bad = || format!("'{s}': expected THICKNESS[@X,Y] in mm");
        let num = |v: &str| v.trim().parse::<f64>().ok().filter(|v| v.is_finite());
        let (t, at) = match s.split_once('@') {
            Some((t, at)) => {
                let (x, y) = at.split_once(',').ok_or_else(bad)?;
                (t, Some((num(x).ok_or_else(bad)?, num(y).ok_or_else(bad)?)))
            }
            None => (s, None),
        };
        let thickness = num(t).filter(|t| *t >= 0.0).ok_or_else(bad)?;
        Ok(TouchOff {
            thickness,
            at,
            feed: 100.0,
            travel: 50.0,
        })
    }
}

/// One line at a time, outside the job: its reply lines up to `ok`; an
/// error or alarm is the touch-off's failure.
fn exchange(r: &mut Replies, line: &str, timeout: f64) -> Result<Vec<String>> {
    r.port.write_all(format!("{line}\n").as_bytes())?;
    let until = r.port.now() + timeout;
    let mut got = Vec::new();
    while r.port.now() < until {
        let Some(l) = r.next(until - r.port.now())? else {
            continue;
        };
        if l == "ok" {
            return Ok(got);
        }
        if l.starts_with("error:") || l.starts_with("ALARM:") {
            bail!(
                "touch-off: '{line}' got {l}{}; the machine stands where the probe stopped",
                if l == "ALARM:5" {
                    " (the probe met nothing: is the plate under the tool and its clip on?)"
                } else {
                    ""
                }
            );
        }
        if !l.starts_with('<') {
            got.push(l);
        }
    }
    bail!("touch-off: no reply to '{line}' within {timeout} s")
}

/// x, y, z in a `[NAME:x,y,z...]` report line.
fn report_triple(lines: &[String], name: &str) -> Option<DVec3> {
    let body = lines
        .iter()
        .find_map(|l| l.strip_prefix(&format!("[{name}:")))?;
    let v: Vec<f64> = body
        .trim_end_matches(']')
        .split([',', ':'])
        .take(3)
        .map(|x| x.parse().ok())
        .collect::<Option<_>>()?;
    (v.len() == 3).then(|| DVec3::new(v[0], v[1], v[2]))
}

/// Probe down `travel` mm at `feed`, back off, probe again slowly: the
/// slow probe's trigger point, machine coordinates.
fn touch(r: &mut Replies, travel: f64, feed: f64) -> Result<DVec3> {
    let n = crate::gcode::emit::num;
    let probe_time = 60.0 * travel / feed + 30.0;
    exchange(
        r,
        &format!("G91G38.2Z-{}F{}", n(travel), n(feed)),
        probe_time,
    )?;
    exchange(r, "G91G0Z1", 30.0)?;
    let got = exchange(r, &format!("G91G38.2Z-2F{}", n(SLOW_PROBE)), 60.0)?;
    report_triple(&got, "PRB")
        .ok_or_else(|| crate::Error("touch-off: no [PRB:] report after G38.2".into()))
}

/// Wait until the moves sent have run: G4 P0 is answered once GRBL's
/// planner is empty.
fn settle(r: &mut Replies) -> Result<()> {
    exchange(r, "G4P0", 300.0).map(|_| ())
}

/// What lies between machine Z and work Z besides the active system's
/// offset: the G92 offset and the tool length offset (from `$#`); and the
/// active system's own Z offset (from `$G` and `$#`).
fn offsets(r: &mut Replies) -> Result<(f64, f64)> {
    // GRBL answers `$#` only standing (error:8 in motion)
    settle(r)?;
    let params = exchange(r, "$#", 5.0)?;
    let g92 = report_triple(&params, "G92").unwrap_or(DVec3::ZERO);
    let tlo = params
        .iter()
        .find_map(|l| l.strip_prefix("[TLO:"))
        .and_then(|v| v.trim_end_matches(']').parse::<f64>().ok())
        .unwrap_or(0.0);
    let modes = exchange(r, "$G", 5.0)?;
    let wcs = modes
        .iter()
        .find_map(|l| l.strip_prefix("[GC:"))
        .and_then(|m| m.split(' ').find(|w| w.starts_with("G5") && w.len() == 3))
        .unwrap_or("G54");
    let active = report_triple(&params, wcs).unwrap_or(DVec3::ZERO);
    Ok((g92.z + tlo, active.z))
}

/// A Z touch-off, the machine idle: over the plate (rising over it
/// first), probe down fast, back off, probe slowly, set the active
/// system's Z from the slow probe's trigger point (G10 L2, net of G92 and
/// the tool length offset, so the machine's overshoot does not count),
/// rise clear of the plate; at a job's pause (`job`), return to where it
/// paused, its units and distance mode restored.
pub fn touch_off(r: &mut Replies, t: &TouchOff, job: Option<&Modal>) -> Result<()> {
    let n = crate::gcode::emit::num;
    let work = job.map(|m| m.pos - m.wco());
    exchange(r, "G21", 5.0)?;
    if let Some((x, y)) = t.at {
        exchange(
            r,
            &format!("G91G0Z{}", n(t.thickness + PLATE_CLEARANCE)),
            60.0,
        )?;
        exchange(r, &format!("G90G0X{}Y{}", n(x), n(y)), 120.0)?;
    }
    let prb = touch(r, t.travel, t.feed)?;
    let (between, _) = offsets(r)?;
    // work Z at the trigger = the plate's thickness
    let wcs_z = prb.z - between - t.thickness;
    exchange(r, &format!("G10L2P0Z{}", n(wcs_z)), 5.0)?;
    let clear = work.map_or(0.0, |w| w.z).max(t.thickness + 5.0);
    exchange(r, &format!("G90G0Z{}", n(clear)), 60.0)?;
    if let (Some(_), Some(w)) = (t.at, work) {
        exchange(r, &format!("G90G0X{}Y{}", n(w.x), n(w.y)), 120.0)?;
        exchange(r, &format!("G90G0Z{}", n(w.z)), 60.0)?;
    }
    eprintln!(
        "touch-off: the plate's top at machine Z{:.3}; work Z0 set {:.3} mm below it",
        prb.z, t.thickness
    );
    if job.is_some_and(|m| m.inches) {
        exchange(r, "G20", 5.0)?;
    }
    if job.is_some_and(|m| !m.absolute) {
        exchange(r, "G91", 5.0)?;
    }
    // the machine standing when it returns
    settle(r)
}

/// Up to the setter's Z, over it, touch it; back up. Returns the
/// trigger point's work Z (the setter's top as this tool and the
/// present work zero see it) and the active system's Z offset, the
/// machine back at the setter's Z.
fn measure(r: &mut Replies, s: &Setter) -> Result<(f64, f64)> {
    let n = crate::gcode::emit::num;
    exchange(r, "G21", 5.0)?;
    exchange(r, &format!("G53G0Z{}", n(s.z)), 60.0)?;
    exchange(r, &format!("G53G0X{}Y{}", n(s.x), n(s.y)), 120.0)?;
    let prb = touch(r, s.travel, s.feed)?;
    exchange(r, &format!("G53G0Z{}", n(s.z)), 60.0)?;
    let (between, wcs_z) = offsets(r)?;
    Ok((prb.z - between - wcs_z, wcs_z))
}

/// Something done with the port between lines, on the machine's behalf:
/// outside a job, or at a job's tool change (the sender's re-entry then
/// puts the machine back where the job was).
#[derive(Clone, Debug)]
pub enum Routine {
    /// Touch off Z on the plate.
    Plate(TouchOff),
    /// Measure the tool in the spindle on the setter as the reference
    /// (the setter's top in work Z), kept in `top`.
    SetterReference(Setter, Arc<Mutex<Option<f64>>>),
    /// Measure the new tool on the setter and shift the work zero by the
    /// difference from the reference, so the new tool's tip reads the
    /// same work Z the old one did.
    SetterApply(Setter, Arc<Mutex<Option<f64>>>),
}

impl Routine {
    /// Run it; returns what to tell the carver.
    pub fn run(&self, r: &mut Replies) -> Result<String> {
        let n = crate::gcode::emit::num;
        match self {
            Routine::Plate(t) => {
                touch_off(r, t, None)?;
                Ok(format!(
                    "touch-off: work Z set so the plate's top reads {:.3}",
                    t.thickness
                ))
            }
            Routine::SetterReference(s, top) => {
                let (z, _) = measure(r, s)?;
                *top.lock().unwrap_or_else(|e| e.into_inner()) = Some(z);
                Ok(format!(
                    "tool setter: this tool reads the setter's top at work Z{z:.3} (the reference)"
                ))
            }
            Routine::SetterApply(s, top) => {
                let Some(reference) = *top.lock().unwrap_or_else(|e| e.into_inner()) else {
                    bail!(
                        "tool setter: no reference yet: measure the tool that set Z0 before \
                         changing it"
                    );
                };
                let (z, wcs_z) = measure(r, s)?;
                let shift = z - reference;
                exchange(r, &format!("G10L2P0Z{}", n(wcs_z + shift)), 5.0)?;
                Ok(format!(
                    "tool setter: the new tool is {:.3} mm {} than the one that set Z0; work Z0 \
                     moved with it",
                    shift.abs(),
                    if shift >= 0.0 { "longer" } else { "shorter" }
                ))
            }
        }
    }
}
