//! The sender's view of a serial link: write bytes, read what arrived
//! within a timeout, and tell the time. Two implementations: a real
//! serial port (the serialport crate), and an in-memory link to the
//! simulated machine that runs in simulated time at a given baud rate, so
//! a 100,000-line job streams in a moment and link utilisation is exact.

use super::sim::SimGrbl;
use crate::bail;
use crate::error::Result;
use std::collections::VecDeque;
use std::time::{Duration, Instant};

pub trait Port {
    fn write_all(&mut self, bytes: &[u8]) -> Result<()>;
    /// What arrived within `timeout` seconds (empty when nothing did).
    fn read(&mut self, timeout: f64) -> Result<Vec<u8>>;
    /// Seconds since the link opened.
    fn now(&self) -> f64;
}

/// A real serial port.
pub struct SerialLink {
    port: Box<dyn serialport::SerialPort>,
    name: String,
    start: Instant,
}

impl SerialLink {
    /// Open `path` without raising DTR where the platform allows: a board
    /// that resets on DTR (an Arduino Uno's bootloader) is then left running
    /// (on Linux the kernel still raises DTR for a moment as the port
    /// opens, so an Uno resets anyway; see the README's troubleshooting).
    pub fn open(path: &str, baud: u32) -> Result<SerialLink> {
        let port = serialport::new(path, baud)
            .timeout(Duration::from_millis(50))
            .dtr_on_open(false)
            .open()
            .map_err(|e| crate::Error(format!("--port {path}: {e}")))?;
        Ok(SerialLink {
            port,
            name: path.to_string(),
            start: Instant::now(),
        })
    }
}

impl Port for SerialLink {
    fn write_all(&mut self, bytes: &[u8]) -> Result<()> {
        use std::io::Write;
        self.port
            .write_all(bytes)
            .and_then(|_| self.port.flush())
            .map_err(|e| crate::Error(format!("{}: write failed: {e}", self.name)))
    }

    fn read(&mut self, timeout: f64) -> Result<Vec<u8>> {
        let t = Duration::from_secs_f64(timeout.clamp(0.001, 10.0));
        self.port
            .set_timeout(t)
            .map_err(|e| crate::Error(format!("{}: {e}", self.name)))?;
        let mut buf = [0u8; 4096];
        match self.port.read(&mut buf) {
            Ok(0) => bail!("{}: the port closed (disconnected)", self.name),
            Ok(n) => Ok(buf[..n].to_vec()),
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => Ok(Vec::new()),
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => Ok(Vec::new()),
            Err(e) => bail!("{}: read failed (disconnected?): {e}", self.name),
        }
    }

    fn now(&self) -> f64 {
        self.start.elapsed().as_secs_f64()
    }
}

/// The simulated machine behind a simulated serial line: each byte takes
/// 10 bit times (8N1) on its wire, each direction has its own wire, and
/// the machine's planner runs on the same clock.
pub struct MemPort {
    pub sim: SimGrbl,
    byte_time: f64,
    t: f64,
    up: VecDeque<(f64, u8)>,
    up_free: f64,
    down: VecDeque<(f64, u8)>,
    down_free: f64,
    /// Bytes the host has written.
    pub written: usize,
}

impl MemPort {
    pub fn new(sim: SimGrbl, baud: u32) -> MemPort {
        let mut p = MemPort {
            sim,
            byte_time: 10.0 / baud as f64,
            t: 0.0,
            up: VecDeque::new(),
            up_free: 0.0,
            down: VecDeque::new(),
            down_free: 0.0,
            written: 0,
        };
        p.collect();
        p
    }

    /// Seconds a byte takes on the wire.
    pub fn byte_time(&self) -> f64 {
        self.byte_time
    }

    /// The board's output, onto the wire toward the host.
    fn collect(&mut self) {
        for b in self.sim.take_output() {
            self.down_free = self.down_free.max(self.t) + self.byte_time;
            self.down.push_back((self.down_free, b));
        }
    }

    /// Reconnect after a disconnect: fresh wires, the board reset.
    pub fn reconnect(&mut self) {
        self.up.clear();
        self.down.clear();
        self.sim.reconnect();
        self.collect();
    }
}

impl Port for MemPort {
    fn write_all(&mut self, bytes: &[u8]) -> Result<()> {
        if self.sim.disconnected {
            bail!("simulated port: disconnected");
        }
        for &b in bytes {
            self.up_free = self.up_free.max(self.t) + self.byte_time;
            self.up.push_back((self.up_free, b));
        }
        self.written += bytes.len();
        Ok(())
    }

    fn read(&mut self, timeout: f64) -> Result<Vec<u8>> {
        let deadline = self.t + timeout.max(0.0);
        loop {
            let arrived = self.down.iter().take_while(|d| d.0 <= self.t).count();
            if arrived > 0 {
                return Ok(self.down.drain(..arrived).map(|d| d.1).collect());
            }
            if self.sim.disconnected && self.down.is_empty() {
                bail!("simulated port: disconnected");
            }
            let next = [
                self.up.front().map(|u| u.0),
                self.down.front().map(|d| d.0),
                self.sim.next_event(),
            ]
            .into_iter()
            .flatten()
            .fold(f64::INFINITY, f64::min);
            if next > deadline {
                self.t = deadline;
                self.sim.advance(self.t);
                self.collect();
                return Ok(Vec::new());
            }
            self.t = self.t.max(next);
            while let Some(&(at, b)) = self.up.front() {
                if at > self.t {
                    break;
                }
                self.up.pop_front();
                self.sim.advance(at);
                self.sim.receive(b);
            }
            self.sim.advance(self.t);
            self.collect();
        }
    }

    fn now(&self) -> f64 {
        self.t
    }
}
