//! What GRBL says, line by line: the welcome, status reports, a command's
//! replies.

use super::port::Port;
use super::state::State;
use super::STATUS;
use crate::bail;
use crate::error::Result;
use std::collections::VecDeque;

/// Reply lines from the port; bytes GRBL never sends (non-ASCII and
/// control bytes other than the line end) are line noise and dropped.
pub struct Replies<'a> {
    pub port: &'a mut dyn Port,
    partial: Vec<u8>,
    ready: VecDeque<String>,
}

impl<'a> Replies<'a> {
    pub fn new(port: &'a mut dyn Port) -> Replies<'a> {
        Replies {
            port,
            partial: Vec::new(),
            ready: VecDeque::new(),
        }
    }

    /// The next reply line, waiting up to `timeout` seconds.
    pub fn next(&mut self, timeout: f64) -> Result<Option<String>> {
        let until = self.port.now() + timeout;
        loop {
            if let Some(l) = self.ready.pop_front() {
                return Ok(Some(l));
            }
            let left = until - self.port.now();
            if left <= 0.0 {
                return Ok(None);
            }
            for b in self.port.read(left)? {
                match b {
                    b'\n' => {
                        let l = String::from_utf8_lossy(&self.partial).trim().to_string();
                        self.partial.clear();
                        if !l.is_empty() {
                            self.ready.push_back(l);
                        }
                    }
                    0x20..=0x7e => self.partial.push(b),
                    _ => {} // \r and noise
                }
            }
        }
    }

    /// Wait for the welcome (a board that resets when the port opens
    /// prints it once booted); without one, a status report says a GRBL is
    /// there, taken as it stands. Never a soft reset: 0x18 stops a running
    /// or held machine and is the user's to send (`relievo machine reset`).
    pub fn handshake(&mut self, timeout: f64) -> Result<()> {
        let until = self.port.now() + timeout;
        while self.port.now() < until {
            if let Some(l) = self.next(until - self.port.now())? {
                if l.starts_with("Grbl ") {
                    // and whatever follows it at once ([MSG:..]), for half
                    // a second at most: a chatty device never ends
                    let t = self.port.now() + 0.5;
                    while self.port.now() < t && self.next(0.05)?.is_some() {}
                    return Ok(());
                }
            }
        }
        if self.status()?.is_some() {
            return Ok(());
        }
        bail!(
            "no GRBL welcome within {timeout} s, nor a status report: is a GRBL controller on \
             this port, at this baud? (relievo never resets it on its own; `relievo machine \
             reset` does)"
        )
    }

    /// A status report (None if none comes within a second).
    pub fn status(&mut self) -> Result<Option<Status>> {
        self.port.write_all(&[STATUS])?;
        let until = self.port.now() + 1.0;
        while self.port.now() < until {
            if let Some(l) = self.next(until - self.port.now())? {
                if let Some(st) = parse_status(&l) {
                    return Ok(Some(st));
                }
            }
        }
        Ok(None)
    }

    /// Send one command and collect its reply lines up to `ok`/`error`.
    pub fn command(&mut self, cmd: &str, timeout: f64) -> Result<Vec<String>> {
        self.port.write_all(format!("{cmd}\n").as_bytes())?;
        let mut got = Vec::new();
        let until = self.port.now() + timeout;
        while self.port.now() < until {
            let Some(l) = self.next(until - self.port.now())? else {
                continue;
            };
            let done = l == "ok" || l.starts_with("error:");
            got.push(l);
            if done {
                return Ok(got);
            }
        }
        bail!("no reply to '{cmd}' within {timeout} s")
    }
}

/// A status report: `<State|MPos:x,y,z|Bf:blocks,bytes|...>`, each field
/// GRBL 1.1 may send (which ones, `$10` and the report's turn decide).
#[derive(Clone, Debug, PartialEq)]
pub struct Status {
    pub state: State,
    /// MPos, or WPos when the report gives that instead (`$10`).
    pub pos: [f64; 3],
    /// `pos` is WPos.
    pub work: bool,
    /// Free planner blocks and free receive-buffer bytes.
    pub free: Option<(usize, usize)>,
    /// The work coordinate offset, in the reports that carry it.
    pub wco: Option<[f64; 3]>,
    /// Actual feed, and spindle speed (`FS:`; `F:` has no spindle).
    pub feed: Option<(f64, Option<f64>)>,
    /// Feed, rapid and spindle overrides, percent (every few reports).
    pub overrides: Option<[u32; 3]>,
    /// Input pins that read active (`Pn:`).
    pub pins: String,
    /// Spindle and coolant (`A:`).
    pub accessories: String,
}

impl Status {
    /// Machine and work position, given the work offset (a report that
    /// carries none stands on the last one seen).
    pub fn positions(&self, wco: [f64; 3]) -> ([f64; 3], [f64; 3]) {
        let other = [0, 1, 2].map(|k| self.pos[k] + if self.work { wco[k] } else { -wco[k] });
        if self.work {
            (other, self.pos)
        } else {
            (self.pos, other)
        }
    }
}

/// The latest of `reports` made whole: GRBL gives the work offset and the
/// overrides (with `A:`) only every few reports, so those fields come
/// from the latest report that had them.
pub fn whole_report<'a>(reports: impl IntoIterator<Item = &'a str>) -> Option<String> {
    let (mut last, mut wco, mut ov) = (None, None, None);
    for r in reports.into_iter().filter(|r| r.starts_with('<')) {
        let body = r.trim_start_matches('<').trim_end_matches('>');
        let fields: Vec<&str> = body.split('|').collect();
        if let Some(w) = fields.iter().find(|f| f.starts_with("WCO:")) {
            wco = Some(w.to_string());
        }
        if let Some(k) = fields.iter().position(|f| f.starts_with("Ov:")) {
            ov = Some(
                fields[k..]
                    .iter()
                    .filter(|f| f.starts_with("Ov:") || f.starts_with("A:"))
                    .copied()
                    .collect::<Vec<_>>()
                    .join("|"),
            );
        }
        last = Some(
            fields
                .iter()
                .filter(|f| !f.starts_with("WCO:") && !f.starts_with("Ov:") && !f.starts_with("A:"))
                .copied()
                .collect::<Vec<_>>()
                .join("|"),
        );
    }
    let mut out = last?;
    for f in [wco, ov].into_iter().flatten() {
        out = out + "|" + &f;
    }
    Some(format!("<{out}>"))
}

/// The first `N` comma-separated numbers of a field (GRBL built with
/// more axes sends more).
fn numbers<T: std::str::FromStr + Copy + Default, const N: usize>(v: &str) -> Option<[T; N]> {
    let mut out = [T::default(); N];
    let mut it = v.split(',');
    for x in out.iter_mut() {
        *x = it.next()?.parse().ok()?;
    }
    Some(out)
}

/// Parse a status report line (None for anything else, or a garbled one).
pub fn parse_status(l: &str) -> Option<Status> {
    let body = l.strip_prefix('<')?.strip_suffix('>')?;
    let mut parts = body.split('|');
    let mut st = Status {
        state: State::parse(parts.next()?)?,
        pos: [0.0; 3],
        work: false,
        free: None,
        wco: None,
        feed: None,
        overrides: None,
        pins: String::new(),
        accessories: String::new(),
    };
    for p in parts {
        let Some((key, v)) = p.split_once(':') else {
            continue;
        };
        match key {
            "MPos" | "WPos" => (st.pos, st.work) = (numbers(v)?, key == "WPos"),
            "Bf" => st.free = Some(numbers::<usize, 2>(v).map(|[a, b]| (a, b))?),
            "WCO" => st.wco = Some(numbers(v)?),
            "FS" => st.feed = Some(numbers::<f64, 2>(v).map(|[f, s]| (f, Some(s)))?),
            "F" => st.feed = Some((numbers::<f64, 1>(v)?[0], None)),
            "Ov" => st.overrides = Some(numbers(v)?),
            "Pn" => st.pins = v.to_string(),
            "A" => st.accessories = v.to_string(),
            _ => {}
        }
    }
    Some(st)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reports_are_made_whole() {
        let r = whole_report([
            "<Idle|MPos:1.000,0.000,0.000|FS:0,0|WCO:1.000,2.000,3.000>",
            "<Idle|MPos:1.000,0.000,0.000|FS:0,1000|Ov:100,50,120|A:SF>",
            "<Run|MPos:2.000,0.000,0.000|FS:300,1000>",
        ]);
        assert_eq!(
            r.as_deref(),
            Some(
                "<Run|MPos:2.000,0.000,0.000|FS:300,1000|WCO:1.000,2.000,3.000|Ov:100,50,120|A:SF>"
            )
        );
        assert_eq!(whole_report(["ok"]), None);
    }
}
