//! Machine time of a job on relievo's simulated GRBL, in its own
//! simulated clock (the host's speed does not count), to set beside the
//! firmware's (bench/firmware_time.sh reads GRBL 1.1h's step log) and
//! `simulate`'s estimate:
//!   cargo bench --bench grbl_time -- JOB.nc [MACHINE]
//! Lines go one at a time, each once the last is answered (GRBL answers a
//! move when it is planned, so the planner stays full); a program pause
//! (M0) is released at once. Dwells before the first move are not
//! counted, as the firmware's step log does not count them.

use relievo::grbl::sim::SimGrbl;
use relievo::machine::Machine;

fn main() {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| a != "--bench")
        .collect();
    let Some(job) = args.first() else {
        eprintln!("usage: cargo bench --bench grbl_time -- JOB.nc [MACHINE]");
        std::process::exit(2);
    };
    let machine = Machine::load(args.get(1).map_or("grbl-generic", |s| s.as_str())).unwrap();
    let text = std::fs::read_to_string(job).unwrap();
    let mut s = SimGrbl::new(&machine);
    s.take_output();
    let mut t = 0.0f64;
    let mut first_move: Option<f64> = None;
    for line in text.lines() {
        for b in line.bytes().chain([b'\n']) {
            s.receive(b);
        }
        loop {
            let out = String::from_utf8_lossy(&s.take_output()).to_string();
            if out.contains("ok") || out.contains("error") {
                break;
            }
            match s.next_event() {
                Some(at) => {
                    t = t.max(at);
                    s.advance(t);
                }
                // held at M0: the operator goes on at once
                None => s.receive(b'~'),
            }
        }
        if first_move.is_none() && s.moving() {
            first_move = Some(t);
        }
    }
    while let Some(at) = s.next_event() {
        t = t.max(at);
        s.advance(t);
    }
    let start = first_move.unwrap_or(0.0);
    println!("{job}: relievo grbl-sim machine time {:.3} s", t - start);
}
