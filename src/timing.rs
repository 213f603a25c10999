//! Stage timings for `--timings` / `--verbose`.

use std::time::{Duration, Instant};

#[derive(Default, Debug)]
pub struct Timings {
    pub stages: Vec<(String, Duration)>,
}

impl Timings {
    /// Run `f` and record its wall time under `name`.
    pub fn time<T>(&mut self, name: &str, f: impl FnOnce() -> T) -> T {
        let t = Instant::now();
        let r = f();
        self.stages.push((name.to_string(), t.elapsed()));
        r
    }

    pub fn total(&self) -> Duration {
        self.stages.iter().map(|s| s.1).sum()
    }

    pub fn report(&self) -> String {
        let mut s = String::new();
        for (n, d) in &self.stages {
            s += &format!("  {:<22} {:>9.1} ms\n", n, d.as_secs_f64() * 1e3);
        }
        s += &format!(
            "  {:<22} {:>9.1} ms",
            "total",
            self.total().as_secs_f64() * 1e3
        );
        s
    }
}
