//! Fuzzing harness (issue 14): every reader of outside input is fed
//! mutated copies of real inputs and must return Ok or an error, never
//! panic, hang or abort. Mutations are structure-aware: byte flips,
//! inserts, deletes, copies, G-code/TOML/JSON tokens and hostile numbers
//! (NaN, inf, 1e308, 5e-324, -0, huge integers); PNG chunks get their CRC
//! repaired half of the time so that the decoder looks past the checksum.
//!
//! A short run (`RELIEVO_FUZZ_CASES`, default 2000 per target) is part of
//! the test suite; the long run is
//! `RELIEVO_FUZZ_CASES=100000 cargo test --release --test fuzz`.
//! proptest shrinks any failure and records its seed in
//! `tests/fuzz.proptest-regressions`, which is replayed first on every
//! run; inputs found by hand are kept as cases in `regressions()` below.

use proptest::prelude::*;
use proptest::sample::Index;
use proptest::test_runner::{Config, FileFailurePersistence, TestRunner};
use relievo::gcode;
use relievo::grbl::sim::SimGrbl;
use relievo::machine::Machine;
use relievo::relief::file;
use relievo::relief::image_input;
use relievo::scene::{self, mesh, Camera};
use relievo::sim::{self, Stock};
use relievo::Grid;
use std::time::{Duration, Instant};

/// A case slower than this counts as a hang.
const HANG: Duration = Duration::from_secs(10);

#[derive(Clone, Debug)]
enum Op {
    Flip(Index, u8),
    Set(Index, u8),
    Insert(Index, Vec<u8>),
    Delete(Index, u8),
    Copy(Index, Index, u8),
    Token(Index, Index),
    Truncate(Index),
}

const TOKENS: &[&str] = &[
    "nan",
    "NaN",
    "inf",
    "-inf",
    "1e308",
    "-1e308",
    "5e-324",
    "-0",
    "0",
    "1e-320",
    "18446744073709551616",
    "4294967295",
    "65535",
    "-1",
    "1e9",
    ".",
    "-",
    "e",
    "G2",
    "G3",
    "G91",
    "G20",
    "G0",
    "G1",
    "M6",
    "M0",
    "M30",
    "T99",
    "R-1000000",
    "I1e9",
    "J-1e9",
    "F0",
    "F1e-300",
    "S-5",
    "P1e9",
    "Z-1e300",
    "X",
    "Y",
    "(tool: ball:3)",
    "(tool: ",
    "(frame: ",
    "(",
    ")",
    ";",
    "\n",
    "\r",
    "\0",
    "$",
    "?",
    "!",
    "~",
    "\u{18}",
    "\u{85}",
    "\u{ff}",
    "[",
    "]",
    "{",
    "}",
    "=",
    "\"",
    ",",
    ":",
    "solid",
    "facet normal",
    "vertex",
    "endloop",
    "v ",
    "f ",
    "o ",
    "g ",
    "vn ",
    "vt ",
    "/",
    "//",
    "IHDR",
    "IDAT",
    "IEND",
    "tRNS",
    "é",
];

fn op() -> impl Strategy<Value = Op> {
    prop_oneof![
        (any::<Index>(), any::<u8>()).prop_map(|(i, b)| Op::Flip(i, b)),
        (any::<Index>(), any::<u8>()).prop_map(|(i, b)| Op::Set(i, b)),
        (any::<Index>(), prop::collection::vec(any::<u8>(), 1..6))
            .prop_map(|(i, v)| Op::Insert(i, v)),
        (any::<Index>(), 1u8..64).prop_map(|(i, n)| Op::Delete(i, n)),
        (any::<Index>(), any::<Index>(), 1u8..255).prop_map(|(a, b, n)| Op::Copy(a, b, n)),
        (any::<Index>(), any::<Index>()).prop_map(|(i, t)| Op::Token(i, t)),
        any::<Index>().prop_map(Op::Truncate),
    ]
}

fn apply(seed: &[u8], ops: &[Op]) -> Vec<u8> {
    let mut v = seed.to_vec();
    for o in ops {
        let at = |i: &Index, v: &Vec<u8>| i.index(v.len() + 1);
        match o {
            Op::Flip(i, b) if !v.is_empty() => {
                let k = i.index(v.len());
                v[k] ^= 1 << (b % 8);
            }
            Op::Set(i, b) if !v.is_empty() => {
                let k = i.index(v.len());
                v[k] = *b;
            }
            Op::Insert(i, bytes) => {
                let k = at(i, &v);
                v.splice(k..k, bytes.iter().copied());
            }
            Op::Delete(i, n) => {
                let k = at(i, &v);
                let e = (k + *n as usize).min(v.len());
                v.drain(k..e);
            }
            Op::Copy(a, b, n) if !v.is_empty() => {
                let from = a.index(v.len());
                let piece: Vec<u8> = v[from..(from + *n as usize).min(v.len())].to_vec();
                let k = at(b, &v);
                v.splice(k..k, piece);
            }
            Op::Token(i, t) => {
                let k = at(i, &v);
                let tok = TOKENS[t.index(TOKENS.len())].as_bytes();
                v.splice(k..k, tok.iter().copied());
            }
            Op::Truncate(i) => {
                let k = at(i, &v);
                v.truncate(k);
            }
            _ => {}
        }
    }
    v
}

/// Mutated seeds: (which seed, mutations, a flag each target may use).
fn input(seeds: usize) -> impl Strategy<Value = (usize, Vec<Op>, bool)> {
    (0..seeds, prop::collection::vec(op(), 0..10), any::<bool>())
}

fn cases() -> u32 {
    std::env::var("RELIEVO_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(2000)
}

/// Run `target` on mutated `seeds`; fail on a panic or a case over HANG.
fn fuzz(name: &str, seeds: &[Vec<u8>], target: impl Fn(&[u8], bool)) {
    let mut runner = TestRunner::new(Config {
        cases: cases(),
        failure_persistence: Some(Box::new(FileFailurePersistence::WithSource(
            "proptest-regressions",
        ))),
        source_file: Some(file!()),
        max_shrink_iters: 2000,
        ..Config::default()
    });
    let slowest = std::cell::Cell::new(Duration::ZERO);
    let result = runner.run(&input(seeds.len()), |(k, ops, flag)| {
        let bytes = apply(&seeds[k], &ops);
        let t = Instant::now();
        target(&bytes, flag);
        let took = t.elapsed();
        slowest.set(slowest.get().max(took));
        prop_assert!(took < HANG, "{name}: one input took {took:?}");
        Ok(())
    });
    eprintln!(
        "fuzz {name}: {} cases, slowest {:?}",
        cases(),
        slowest.get()
    );
    if let Err(e) = result {
        panic!("fuzz {name}: {e}");
    }
}

fn fixture(name: &str) -> Vec<u8> {
    std::fs::read(std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(name)).unwrap()
}

/// A small mesh through every stage that reads its numbers: checks, camera,
/// smooth normals, rasterizer.
fn mesh_target(bytes: &[u8], stl: bool) {
    let m = if stl {
        mesh::read_stl(bytes, "fuzz.stl")
    } else {
        mesh::read_obj(&mut std::io::Cursor::new(bytes), "fuzz.obj")
    };
    if let Ok(m) = m {
        if m.validate("fuzz").is_ok() && m.triangles.len() < 5000 {
            // faceted, and smooth (the default: welding, vertex normals)
            for smooth in [None, Some(45.0)] {
                let _ = scene::render(
                    &m,
                    &Camera::default(),
                    16,
                    2,
                    (1 << 26, "allowed"),
                    smooth,
                    &|_| {},
                );
            }
        }
    }
}

#[test]
fn fuzz_meshes() {
    let obj = b"# two objects, groups, normals and texture indices\n\
        o base\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n\
        f 1/1/1 2/1/1 3/1/1\nf 1//1 3//1 4//1\n\
        g top\nv 0.2 0.2 0.5\nv 0.8 0.2 0.5\nv 0.5 0.8 0.7\nf 5 6 7\nf -1 -2 -3\n"
        .to_vec();
    let ascii = b"solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n\
        vertex 0 1 0.5\nendloop\nendfacet\nfacet normal 0 0 1\nouter loop\nvertex 1 0 0\n\
        vertex 1 1 0.2\nvertex 0 1 0.5\nendloop\nendfacet\nendsolid t\n"
        .to_vec();
    let mut binary = vec![0u8; 80];
    binary.extend(2u32.to_le_bytes());
    for t in [
        [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.3]],
        [[1.0, 0.0, 0.0], [1.0, 1.0, 0.6], [0.0, 1.0, 0.3]],
    ] {
        binary.extend([0u8; 12]);
        for p in t {
            for c in p {
                binary.extend(c.to_le_bytes());
            }
        }
        binary.extend([0u8; 2]);
    }
    fuzz("obj", &[obj], |b, _| mesh_target(b, false));
    fuzz("stl", &[ascii, binary], |b, _| mesh_target(b, true));
}

/// Repair every PNG chunk's CRC so that mutations reach the decoder.
fn fix_crcs(png: &mut [u8]) {
    let mut at = 8;
    while at + 12 <= png.len() {
        let len = u32::from_be_bytes(png[at..at + 4].try_into().unwrap()) as usize;
        let end = at + 8 + len;
        if end + 4 > png.len() {
            break;
        }
        let crc = crc32(&png[at + 4..end]);
        png[end..end + 4].copy_from_slice(&crc.to_be_bytes());
        at = end + 4;
    }
}

fn crc32(data: &[u8]) -> u32 {
    let mut c = !0u32;
    for &b in data {
        c ^= b as u32;
        for _ in 0..8 {
            c = if c & 1 != 0 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
    }
    !c
}

fn png_seeds() -> Vec<Vec<u8>> {
    let g16 = Grid::from_vec(6, 4, (0..24u16).map(|v| v * 2700).collect());
    let g8 = Grid::from_vec(5, 3, (0..15u8).map(|v| v * 17).collect());
    let rgb: Vec<u8> = (0..4 * 4)
        .flat_map(|k| [128u8, (k * 9) as u8, 255])
        .collect();
    vec![
        file::png16(&g16),
        file::png8(&g8),
        file::png_rgb(4, 4, &rgb),
    ]
}

#[test]
fn fuzz_png_and_sidecar() {
    let seeds = png_seeds();
    fuzz("png", &seeds, |b, fix| {
        let mut b = b.to_vec();
        if fix {
            fix_crcs(&mut b);
        }
        if let Ok(img) = file::decode_bytes(&b, "fuzz.png") {
            let _ = image_input::image_model(img.clone(), "fuzz".into());
            let _ = file::relief_from(
                file::gray(img),
                None,
                "fuzz.json",
                Some(50.0),
                Some(2.0),
                "fuzz.png",
            );
        }
    });
    let side = br#"{"width_mm": 100.0, "height_mm": 62.5, "depth_mm": 3.2, "pixels": [4, 2], "params": {"alpha": 4}}"#.to_vec();
    let heights = Grid::from_vec(4, 2, vec![0.0, 0.2, 0.4, 1.0, 0.5, 0.1, 0.0, 0.3]);
    fuzz("sidecar", &[side], |b, flag| {
        let text = String::from_utf8_lossy(b);
        let over = flag.then_some(10.0);
        let Ok(side) = file::parse_sidecar(&text, "fuzz.json") else {
            return;
        };
        if let Ok(r) = file::relief_from(
            heights.clone(),
            Some(&side),
            "fuzz.json",
            over,
            None,
            "fuzz.png",
        ) {
            assert!(r.width_mm.is_finite() && r.depth_mm.is_finite() && r.pitch_mm() > 0.0);
        }
    });
}

fn machine_text(name: &str) -> Vec<u8> {
    fixture(&format!("machines/{name}.toml"))
}

const JOB: &str = "(relievo GRBL 1.1 job)\n\
(frame: stock X0 Y0 W40 H30 T8, panel X0 Y0, Z0 top)\n\
(tool: flat:3.175 [radius 1.5875 mm] for roughing)\n\
G21 G90 G17 G94\nM3 S1000\nG4 P2\nG0 Z5\nX0 Y0\nZ1\nG1 Z-1.2 F300\nX10 Y5 F500\n\
G2 X20 Y5 I5 J0\nG3 X10 Y15 R8\nG91 G1 X-2 Y-2\nG90\n\
G20 G1 X0.5 Y0.5\nG21\nG0 Z5\nM5\n(tool: ball:3.175 [radius 1.5875 mm] for finishing)\n\
(change the tool, set Z0, then resume)\nM0\nM3 S1000\nG4 P2\nX0 Y0\nG1 Z-3.0634 F300\n\
X2.0833 Z-3.0953 F500\nX6.25 Z-3.1593\nX11.4583 Z-3.2392 ; comment\nG0 Z5\nM5\nM30\n";

#[test]
fn fuzz_gcode() {
    let m = Machine::load("3018").unwrap();
    let stock = Stock {
        x0: -5.0,
        y0: -5.0,
        width: 50.0,
        height: 40.0,
        thickness: 8.0,
        pitch: 0.5,
    };
    fuzz("gcode", &[JOB.as_bytes().to_vec()], |b, with_tool| {
        let text = String::from_utf8_lossy(b);
        let _ = relievo::cam::layout::Frame::find(&text);
        if let Ok(prog) = gcode::program(&text) {
            let _ = sim::estimate_time(&prog, &m);
            let _ = sim::out_of_travel(&prog, &m, (0.0, 0.0));
            let tool = with_tool.then(|| relievo::tool::Tool::parse("vbit:60:3").unwrap());
            let (w, h) = stock.cells();
            let mut cut = Grid::new(w, h, 0.0f32);
            let _ = sim::cut_program_measured(&stock, &mut cut, &prog, tool);
        }
    });
    // the simulated machine reads the same bytes off its serial line
    fuzz("grbl-sim", &[JOB.as_bytes().to_vec()], |b, status| {
        let mut g = SimGrbl::new(&m);
        let mut t = 0.0;
        for &c in b {
            g.receive(c);
            if status && c == b'\n' {
                g.receive(b'?');
            }
            t += 1e-3;
            g.advance(t);
            let _ = g.take_output();
        }
        // let what was planned finish (a bounded number of blocks)
        for _ in 0..10_000 {
            match g.next_event() {
                Some(e) => g.advance(e),
                None => break,
            }
        }
    });
}

#[test]
fn fuzz_profiles() {
    let seeds: Vec<Vec<u8>> = ["3018", "shapeoko", "grbl-generic"]
        .iter()
        .map(|n| machine_text(n))
        .collect();
    let prog = gcode::program(JOB).unwrap();
    fuzz("machine", &seeds, |b, _| {
        let text = String::from_utf8_lossy(b);
        if let Ok(m) = Machine::parse(&text, "fuzz.toml") {
            let _ = sim::estimate_time(&prog, &m);
            let _ = sim::out_of_travel(&prog, &m, (0.0, 0.0));
            let _ = SimGrbl::new(&m);
            let names: Vec<String> = m.tools.keys().cloned().collect();
            for n in names {
                if let Ok(t) = m.tool(&n) {
                    let _ = m.roughing_tool(&t);
                }
            }
        }
    });
    let materials = fixture("machines/materials.toml");
    fuzz("materials", &[materials], |b, _| {
        let text = String::from_utf8_lossy(b);
        if let Ok(all) = relievo::materials::parse(&text, "fuzz.toml") {
            for m in all.values() {
                for d in [0.5, 3.175, 12.0] {
                    if let Some(c) = m.cutting_for(d) {
                        assert!(c.step_down.is_finite() && c.feed.is_finite());
                    }
                }
            }
        }
    });
}

/// Inputs found by hand or by the fuzzer that once panicked or hung.
#[test]
fn regressions() {
    // (the CLI cases of issue 14 are in tests/bad_inputs.rs)
    // arcs of a kilometre's radius hung the simulator
    assert!(gcode::program("G17 G1 Z-1 F100\nG2 X10 Y0 R-1000000\n").is_err());
    // a sidecar's width of 5e-324 panicked
    let g = Grid::from_vec(2, 2, vec![0.0, 1.0, 0.5, 0.2]);
    let side = r#"{"format": "relievo-relief/1", "width_mm": 5e-324, "height_mm": 1,
        "depth_mm": 3, "pixels": [2, 2]}"#;
    let side = file::parse_sidecar(side, "tiny.json").unwrap();
    let e = file::relief_from(g, Some(&side), "tiny.json", None, None, "tiny.png").unwrap_err();
    assert!(e.0.contains("tiny.png: width 5e-324"), "{e}");
    // a frame word starting with a multibyte character panicked (fuzzer)
    let frame = "(frame: stock \u{e9}Y0 Y0 W1 H1 T1, panel X0 Y0, Z0 top)\n";
    assert!(relievo::cam::layout::Frame::find(frame).is_err());
    // a frame's stock of 1e300 mm overflowed the simulator's cell count
    let frame = "(frame: stock X0 Y0 W1e300 H1 T1, panel X0 Y0, Z0 top)\n";
    assert!(relievo::cam::layout::Frame::find(frame).is_err());
}
