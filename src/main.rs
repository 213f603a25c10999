//! The `relievo` binary: parses flags into the library's option structs,
//! calls one library function per subcommand, prints errors once.

use clap::{Args, Parser, Subcommand};
use relievo::job::ReliefJob;
use relievo::relief::Method;
use relievo::scene::{Camera, View};
use std::io::IsTerminal;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "relievo",
    version,
    about = "3D scenes to bas-reliefs, bas-reliefs to GRBL CNC jobs"
)]
struct Cli {
    /// Print nothing but errors.
    #[arg(long, short, global = true)]
    quiet: bool,
    /// Print stage timings and details.
    #[arg(long, short, global = true, alias = "timings")]
    verbose: bool,
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Make a bas-relief from a 3D model (OBJ, STL), a depth PNG or a
    /// normal-map PNG; without MODEL, from the built-in demo scene.
    Relief(ReliefArgs),
    /// Simulate a G-code job cutting the stock and judge it against a relief.
    Simulate(SimulateArgs),
    /// Turn a relief into a GRBL job (roughing, raster/waterline finishing).
    Toolpath(ToolpathArgs),
    /// Relief and toolpath in one call; without MODEL, the demo scene.
    Carve(Box<CarveArgs>),
    /// Stream a job to a GRBL controller over a serial port.
    Send(SendArgs),
    /// List serial ports.
    Ports,
    /// Ask a GRBL controller for its status, unlock it or home it.
    Machine(MachineArgs),
    /// Serve a simulated GRBL 1.1 machine on a pseudo-terminal (prints its path).
    GrblSim(GrblSimArgs),
}

#[derive(Args)]
struct SendArgs {
    /// G-code job.
    job: PathBuf,
    /// Serial device, e.g. /dev/ttyUSB0.
    #[arg(long)]
    port: String,
    #[arg(long, default_value_t = 115200)]
    baud: u32,
    /// Run the whole job in GRBL's check mode first; stop if any line fails.
    #[arg(long)]
    check: bool,
    /// Send one line and wait for its reply (slower; for troublesome links).
    #[arg(long)]
    send_response: bool,
    /// Start at this job line, re-entering safely.
    #[arg(long, conflicts_with = "resume")]
    resume_from: Option<usize>,
    /// Resume after the last line this journal says GRBL acknowledged.
    #[arg(long)]
    resume: Option<PathBuf>,
    /// Journal of acknowledged lines [default: JOB.journal].
    #[arg(long)]
    journal: Option<PathBuf>,
}

#[derive(Args)]
struct MachineArgs {
    #[arg(value_enum)]
    action: MachineAction,
    #[arg(long)]
    port: String,
    #[arg(long, default_value_t = 115200)]
    baud: u32,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum MachineAction {
    Status,
    Unlock,
    Home,
}

#[derive(Args)]
struct GrblSimArgs {
    /// Machine profile for travel, rates and buffer size.
    #[arg(long, default_value = "grbl-generic")]
    machine: String,
    /// Simulated motion runs this many times faster than real time.
    #[arg(long, default_value_t = 1.0)]
    speed: f64,
    /// Append every executed line to this file.
    #[arg(long)]
    log: Option<PathBuf>,
    /// Fault: reply error:CODE (default 20) to the Nth G-code line.
    #[arg(long, value_name = "N[:CODE]")]
    error_at: Option<String>,
    /// Fault: raise ALARM:CODE (default 1) at the Nth G-code line.
    #[arg(long, value_name = "N[:CODE]")]
    alarm_at: Option<String>,
    /// Fault: drop the link after this many bytes.
    #[arg(long)]
    disconnect_after: Option<usize>,
    /// Fault: probability of noise bytes in a reply line.
    #[arg(long, default_value_t = 0.0)]
    garble: f64,
}

fn parse_fault(
    s: &Option<String>,
    default: u32,
    what: &str,
) -> relievo::Result<Option<(usize, u32)>> {
    let Some(s) = s else { return Ok(None) };
    let (n, c) = s.split_once(':').unwrap_or((s, ""));
    let n = n
        .parse()
        .map_err(|_| relievo::Error(format!("{what} {s}: expected N[:CODE]")))?;
    let c = if c.is_empty() {
        default
    } else {
        c.parse()
            .map_err(|_| relievo::Error(format!("{what} {s}: expected N[:CODE]")))?
    };
    Ok(Some((n, c)))
}

/// Ctrl-C: set by the signal handler, read by the sender.
static CANCEL: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

extern "C" fn on_sigint(_: libc::c_int) {
    CANCEL.store(true, std::sync::atomic::Ordering::Relaxed);
}

fn send(args: SendArgs, quiet: bool) -> relievo::Result<()> {
    use relievo::grbl::{job::SendJob, port::SerialLink};
    let job = SendJob {
        job: args.job,
        check: args.check,
        send_response: args.send_response,
        resume_from: args.resume_from,
        resume: args.resume,
        journal: args.journal,
        progress: !quiet,
        rx_buffer: 128,
    };
    // read the job before touching the machine
    relievo::grbl::sender::load_job(&job.job)?;
    let mut port = SerialLink::open(&args.port, args.baud)?;
    // SAFETY: the handler only stores to an atomic
    unsafe {
        libc::signal(
            libc::SIGINT,
            on_sigint as extern "C" fn(libc::c_int) as libc::sighandler_t,
        );
    }
    let (o, n) = job.run(&mut port, &CANCEL)?;
    if !quiet {
        eprintln!(
            "{}: {n} lines sent and acknowledged in {:.1} s ({} bytes, {:.0} bytes/s)",
            job.job.display(),
            o.seconds,
            o.bytes,
            o.bytes as f64 / o.seconds.max(1e-9)
        );
    }
    Ok(())
}

fn machine_cmd(args: MachineArgs) -> relievo::Result<()> {
    use relievo::grbl::{port::SerialLink, sender::Replies};
    let mut port = SerialLink::open(&args.port, args.baud)?;
    let mut r = Replies::new(&mut port);
    r.handshake(2.5)?;
    let lines = match args.action {
        MachineAction::Status => {
            r.port.write_all(b"?")?;
            let mut got = Vec::new();
            while let Some(l) = r.next(1.0)? {
                let status = l.starts_with('<');
                got.push(l);
                if status {
                    break;
                }
            }
            got
        }
        MachineAction::Unlock => r.command("$X", 5.0)?,
        MachineAction::Home => r.command("$H", 120.0)?,
    };
    for l in &lines {
        println!("{l}");
    }
    if let Some(e) = lines.iter().find(|l| l.starts_with("error:")) {
        let code: u32 = e[6..].parse().unwrap_or(0);
        relievo::bail!(
            "{}: {e} ({})",
            args.port,
            relievo::grbl::error_meaning(code)
        );
    }
    Ok(())
}

fn grbl_sim(args: GrblSimArgs) -> relievo::Result<()> {
    use relievo::grbl::sim::{Faults, SimGrbl};
    use std::io::{Read, Write};
    let m = relievo::machine::Machine::load(&args.machine)?;
    if !(args.speed.is_finite() && args.speed > 0.0) {
        relievo::bail!("--speed {}: must be positive", args.speed);
    }
    let mut sim = SimGrbl::new(&m);
    sim.faults = Faults {
        error_at: parse_fault(&args.error_at, 20, "--error-at")?,
        alarm_at: parse_fault(&args.alarm_at, 1, "--alarm-at")?,
        disconnect_after: args.disconnect_after,
        garble: args.garble,
    };
    let (mut master, slave) = serialport::TTYPort::pair()
        .map_err(|e| relievo::Error(format!("grbl-sim: no pseudo-terminal: {e}")))?;
    let name = serialport::SerialPort::name(&slave).unwrap_or_default();
    println!("{name}");
    std::io::stdout().flush().ok();
    let mut log = match &args.log {
        Some(p) => Some(
            std::fs::File::create(p)
                .map_err(|e| relievo::Error(format!("{}: {e}", p.display())))?,
        ),
        None => None,
    };
    let mut logged = 0;
    serialport::SerialPort::set_timeout(&mut master, std::time::Duration::from_millis(2))
        .map_err(|e| relievo::Error(format!("grbl-sim: {e}")))?;
    let start = std::time::Instant::now();
    let mut buf = [0u8; 1024];
    loop {
        let n = match master.read(&mut buf) {
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => 0,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => 0,
            Err(e) => relievo::bail!("grbl-sim: {e}"),
        };
        let t = start.elapsed().as_secs_f64() * args.speed;
        sim.advance(t);
        for &b in &buf[..n] {
            sim.receive(b);
        }
        let out = sim.take_output();
        if !out.is_empty() && !sim.disconnected {
            master
                .write_all(&out)
                .map_err(|e| relievo::Error(format!("grbl-sim: {e}")))?;
        }
        if let Some(f) = log.as_mut() {
            for l in &sim.log[logged..] {
                writeln!(f, "{l}").map_err(|e| relievo::Error(format!("grbl-sim log: {e}")))?;
            }
            logged = sim.log.len();
        }
        if sim.overflow > 0 {
            relievo::bail!(
                "grbl-sim: receive buffer overflow ({} bytes lost)",
                sim.overflow
            );
        }
    }
}

#[derive(Args)]
struct ToolpathArgs {
    /// Relief PNG (its JSON sidecar gives the size).
    relief: PathBuf,
    /// Output G-code job.
    #[arg(short, long, default_value = "job.nc")]
    output: PathBuf,
    /// Relief width in mm, for a heightmap without sidecar.
    #[arg(long, allow_negative_numbers = true)]
    width: Option<f64>,
    /// Relief depth in mm, for a heightmap without sidecar.
    #[arg(long, allow_negative_numbers = true)]
    depth: Option<f64>,
    /// Material preset for feeds, speeds, stepovers and step-downs.
    #[arg(long)]
    material: Option<String>,
    #[command(flatten)]
    cut: CutOpts,
}

#[derive(Args)]
struct CarveArgs {
    /// Model as for `relief`; without it, the demo scene.
    model: Option<PathBuf>,
    /// Output G-code job; the relief is written beside it as NAME-relief.png.
    #[arg(short, long, default_value = "job.nc")]
    output: PathBuf,
    #[command(flatten)]
    relief: ReliefOpts,
    #[command(flatten)]
    cut: CutOpts,
}

#[derive(Args)]
struct CutOpts {
    /// Finishing tool: ball:D, flat:D, vbit:ANGLE[:D],
    /// taperball:TIP_RADIUS:HALF_ANGLE[:D], or a name from the machine's
    /// tool table (T1, T2, ...).
    #[arg(long, default_value = "ball:3.175")]
    tool: String,
    /// Finishing strategy.
    #[arg(long, value_enum, default_value_t = relievo::cam::Finish::Raster)]
    finish: relievo::cam::Finish,
    /// Distance between rows (and waterline levels): MM or PERCENT% of the
    /// tool diameter [default: the material's, else 10%].
    #[arg(long, value_parser = relievo::cam::Stepover::parse)]
    stepover: Option<relievo::cam::Stepover>,
    /// Scallop height in mm; sets the stepover for a ball.
    #[arg(long)]
    scallop: Option<f64>,
    /// Raster angle in degrees.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    angle: f64,
    /// Climb milling: one-way rows, waterlines with the material on the
    /// right [default: zigzag rows, climb waterlines].
    #[arg(long, conflicts_with = "conventional")]
    climb: bool,
    /// Conventional milling: one-way rows, waterlines the other way round.
    #[arg(long)]
    conventional: bool,
    /// Rough first with this tool (flat:D or ball:D, or a tool-table name).
    #[arg(long)]
    rough: Option<String>,
    /// Roughing layer depth, mm [default: the material's, else the tool radius].
    #[arg(long, requires = "rough")]
    step_down: Option<f64>,
    /// Roughing stepover, MM or PERCENT% [default: the material's, else 40%].
    #[arg(long, requires = "rough", value_parser = relievo::cam::Stepover::parse)]
    rough_stepover: Option<relievo::cam::Stepover>,
    /// Material roughing leaves on the relief for the finish, mm.
    #[arg(
        long,
        default_value_t = 0.3,
        requires = "rough",
        allow_negative_numbers = true
    )]
    stock_to_leave: f64,
    /// Write the roughing to NAME-rough.nc instead of one job with an M0
    /// tool change.
    #[arg(long, requires = "rough")]
    split: bool,
    /// Merge collinear points within this distance, mm.
    #[arg(long, default_value_t = 0.005)]
    tolerance: f64,
    /// Cutting feed, mm/min [default: the material's, else 1000; within the machine's limit].
    #[arg(long)]
    feed: Option<f64>,
    /// Plunge feed, mm/min [default: the material's, else 300].
    #[arg(long)]
    plunge_feed: Option<f64>,
    /// Spindle speed [default: the material's, else 18000; within the machine's range].
    #[arg(long)]
    rpm: Option<f64>,
    /// Travel height above the stock top, mm.
    #[arg(long, default_value_t = 5.0)]
    safe_z: f64,
    /// Machine profile: grbl-generic, 3018, shapeoko, or a TOML file.
    #[arg(long, default_value = "grbl-generic")]
    machine: String,
    /// Job origin on the panel.
    #[arg(long, value_enum, default_value_t = relievo::cam::Origin::LowerLeft)]
    origin: relievo::cam::Origin,
    /// Also write a top view of the toolpath (SVG: cuts blue, rapids red).
    #[arg(long)]
    svg: Option<PathBuf>,
    /// Also write the simulated cut, shaded (PNG).
    #[arg(long)]
    preview: Option<PathBuf>,
    /// Light of the preview: azimuth (clockwise from the panel's top
    /// edge) and elevation, degrees [default: 315,35].
    #[arg(long, value_parser = parse_pair, allow_negative_numbers = true)]
    light: Option<(f64, f64)>,
    /// Write cuts deeper than the material allows the tool (the header and
    /// the summary say where).
    #[arg(long)]
    allow_deep_cuts: bool,
    /// Where Z0 is set: the stock top (roughing leaves a touch-off pad
    /// for the next tool) or the stock's bottom, the spoilboard (needs
    /// --stock).
    #[arg(long, value_enum, default_value_t = relievo::cam::ZZero::Top)]
    z_zero: relievo::cam::ZZero,
    /// Units of the G-code (flags stay in mm).
    #[arg(long, value_enum, default_value_t = relievo::cam::Units::Mm)]
    units: relievo::cam::Units,
    /// Stock width x height x thickness, mm [default: the panel plus
    /// margins, the relief's depth + 3 mm thick]; the panel is centred on
    /// it unless --margin places it.
    #[arg(long, value_parser = parse_stock)]
    stock: Option<(f64, f64, f64)>,
    /// Stock around the panel, mm (the panel sits this far from the
    /// stock's lower-left corner).
    #[arg(long)]
    margin: Option<f64>,
    /// Turn the panel a quarter (90 degrees counter-clockwise) on the machine.
    #[arg(long, value_parser = parse_rotation)]
    rotate: Option<bool>,
}

fn parse_rotation(s: &str) -> Result<bool, String> {
    match s.trim() {
        "90" => Ok(true),
        "0" => Ok(false),
        _ => Err(format!("'{s}': 0 or 90 (degrees)")),
    }
}

impl CutOpts {
    fn job(
        self,
        output: PathBuf,
        relief_name: String,
        material: Option<String>,
    ) -> relievo::cam::ToolpathJob {
        use relievo::cam::{Direction, Roughing, Stepover};
        let direction = match (self.climb, self.conventional) {
            (true, _) => Some(Direction::Climb),
            (_, true) => Some(Direction::Conventional),
            _ => None,
        };
        relievo::cam::ToolpathJob {
            tool: self.tool,
            finish: self.finish,
            direction,
            stepover: self.scallop.map(Stepover::Scallop).or(self.stepover),
            angle: self.angle,
            tolerance: self.tolerance,
            feed: self.feed,
            plunge_feed: self.plunge_feed,
            rpm: self.rpm,
            safe_z: self.safe_z,
            machine: self.machine,
            material,
            origin: self.origin,
            rough: self.rough.map(|tool| Roughing {
                tool,
                step_down: self.step_down,
                stepover: self.rough_stepover,
                stock_to_leave: self.stock_to_leave,
            }),
            split: self.split,
            output,
            allow_deep_cuts: self.allow_deep_cuts,
            z_zero: self.z_zero,
            units: self.units,
            layout: relievo::cam::layout::Layout {
                stock: self.stock,
                margin: self.margin,
                rotate: self.rotate.unwrap_or(false),
            },
            svg: self.svg,
            preview: self.preview,
            light: self.light,
            relief_name,
        }
    }
}

fn report_cam(s: &relievo::cam::CamSummary, quiet: bool, verbose: bool) {
    if !quiet {
        for n in &s.notes {
            println!("{n}");
        }
        println!("{}", s.engagement.summary());
        println!(
            "rapids {:.1} m, cutting {:.1} m; simulated gouge {:.4} mm, residual max {:.3} / mean {:.4} mm",
            s.rapid_mm / 1000.0,
            s.cut_mm / 1000.0,
            s.gouge,
            s.residual.0,
            s.residual.1
        );
        eprintln!(
            "{}: {} lines ({} CL points merged), stepover {:.3} mm, estimated {}",
            s.written
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", "),
            s.lines,
            s.raw_points,
            s.stepover_mm,
            relievo::sim::hms(s.time_s)
        );
    }
    if verbose {
        eprintln!(
            "stage timings ({} threads):\n{}",
            rayon::current_num_threads(),
            s.timings.report()
        );
    }
}

#[derive(Args)]
struct SimulateArgs {
    /// G-code job (GRBL 1.1 dialect).
    job: PathBuf,
    /// Target relief PNG (its JSON sidecar gives the size).
    #[arg(long)]
    relief: PathBuf,
    /// Relief width in mm, for a heightmap without sidecar.
    #[arg(long, allow_negative_numbers = true)]
    width: Option<f64>,
    /// Relief depth in mm, for a heightmap without sidecar.
    #[arg(long, allow_negative_numbers = true)]
    depth: Option<f64>,
    /// ball:D, flat:D, taperball:TIP_RADIUS:HALF_ANGLE[:D], vbit:ANGLE[:D] [default: the job's (tool: ..) comment].
    #[arg(long)]
    tool: Option<String>,
    /// Stock WIDTHxHEIGHTxTHICKNESS in mm, from the origin [default: the relief's panel, depth + 3 mm thick].
    #[arg(long, value_parser = parse_stock)]
    stock: Option<(f64, f64, f64)>,
    /// Stock cells per relief pixel along each axis.
    #[arg(long, default_value_t = 1)]
    oversample: usize,
    /// Machine profile: grbl-generic, 3018, shapeoko, or a TOML file.
    #[arg(long, default_value = "grbl-generic")]
    machine: String,
    /// Job coordinates X,Y of the travel box's lower-left corner.
    #[arg(long, value_parser = parse_pair, default_value = "0,0", allow_negative_numbers = true)]
    travel_origin: (f64, f64),
    /// Cut surface as a relief PNG (+ JSON sidecar).
    #[arg(short, long, default_value = "cut.png")]
    output: PathBuf,
    /// Report as JSON.
    #[arg(long)]
    report: Option<PathBuf>,
    /// Deviation map PNG: red = gouge, blue = residual.
    #[arg(long)]
    deviation: Option<PathBuf>,
}

fn parse_stock(s: &str) -> Result<(f64, f64, f64), String> {
    let v: Vec<f64> = s
        .split(['x', 'X'])
        .map(|p| p.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("'{s}': expected WxHxT in mm"))?;
    match v[..] {
        [a, b, c] => Ok((a, b, c)),
        _ => Err(format!("'{s}': expected WxHxT in mm")),
    }
}

fn parse_pair(s: &str) -> Result<(f64, f64), String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("'{s}': expected X,Y"))?;
    match v[..] {
        [a, b] => Ok((a, b)),
        _ => Err(format!("'{s}': expected X,Y")),
    }
}

#[derive(Args)]
struct ReliefArgs {
    /// OBJ, STL (ASCII or binary), grayscale depth PNG (white = near) or RGB normal-map PNG.
    model: Option<PathBuf>,
    /// Output relief: 16-bit PNG; a JSON sidecar is written beside it.
    #[arg(short, long, default_value = "relief.png")]
    output: PathBuf,
    /// Also write a shaded preview PNG.
    #[arg(long)]
    preview: Option<PathBuf>,
    #[command(flatten)]
    opts: ReliefOpts,
}

#[derive(Args)]
struct ReliefOpts {
    /// View preset (where the eye is, seen from the model).
    #[arg(long, value_enum, default_value_t = View::Front)]
    view: View,
    /// Extra turn about the vertical axis, degrees.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    yaw: f64,
    /// Extra elevation of the eye, degrees.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pitch: f64,
    /// Field of view in degrees; 0 = orthographic.
    #[arg(long, default_value_t = 20.0, allow_negative_numbers = true)]
    fov: f64,
    /// Long side of the relief in pixels (meshes render at twice this).
    #[arg(long, default_value_t = 512, allow_negative_numbers = true)]
    resolution: usize,
    /// Panel width in mm (the height follows the aspect).
    #[arg(long, default_value_t = 100.0, allow_negative_numbers = true)]
    width: f64,
    /// Relief depth in mm [default: from --material, else 5].
    #[arg(long, allow_negative_numbers = true)]
    depth: Option<f64>,
    /// Compression strength: C(x) = ln(1 + alpha x) / alpha [default: from --material, else 4].
    #[arg(long, allow_negative_numbers = true)]
    alpha: Option<f64>,
    /// Silhouette threshold: a slope (scene depth per image width) above which an edge is an outline.
    #[arg(long, default_value_t = 8.0, allow_negative_numbers = true)]
    silhouette: f64,
    /// Trace every outline with a constant step of this height (mm).
    #[arg(long, allow_negative_numbers = true)]
    steps: Option<f64>,
    /// Hold the background flat at height 0 (Dirichlet) instead of free.
    #[arg(long)]
    flat_background: bool,
    /// Feature-band gains, finest first, e.g. 2,1.5,1 [default: from --material].
    #[arg(long, value_delimiter = ',')]
    bands: Option<Vec<f64>>,
    /// Scale one OBJ object's slopes: NAME=GAIN (repeatable).
    #[arg(long, value_parser = parse_emphasis)]
    emphasize: Vec<(String, f64)>,
    /// Grayscale mask PNG for selective scaling (white = full gain).
    #[arg(long)]
    stencil: Option<PathBuf>,
    /// Gain inside --stencil.
    #[arg(long, default_value_t = 2.0, allow_negative_numbers = true)]
    stencil_gain: f64,
    /// Material preset: depth ratio, bands and compression (see machines/materials.toml).
    #[arg(long)]
    material: Option<String>,
    /// Mirror left to right (for stamping dies).
    #[arg(long)]
    mirror: bool,
    /// Hollow relief (for moulds).
    #[arg(long)]
    invert: bool,
    /// gradient (Weyrich 2007) or linear (Cignoni 1997 baseline).
    #[arg(long, value_enum, default_value_t = Method::Gradient)]
    method: Method,
    /// Also write the relief as a watertight binary STL solid.
    #[arg(long)]
    stl: Option<PathBuf>,
    /// Base thickness under the relief in the STL, mm.
    #[arg(long, default_value_t = 2.0, allow_negative_numbers = true)]
    base: f64,
    /// Also write the depth buffer (at relief resolution) as a 16-bit PNG.
    #[arg(long)]
    depth_out: Option<PathBuf>,
}

fn parse_emphasis(s: &str) -> Result<(String, f64), String> {
    let (name, gain) = s
        .split_once('=')
        .ok_or_else(|| format!("'{s}': expected NAME=GAIN"))?;
    let gain: f64 = gain
        .parse()
        .map_err(|_| format!("'{s}': GAIN must be a number"))?;
    Ok((name.to_string(), gain))
}

impl ReliefOpts {
    fn job(self, model: Option<PathBuf>, output: PathBuf) -> ReliefJob {
        ReliefJob {
            model,
            camera: Camera {
                view: self.view,
                yaw: self.yaw,
                pitch: self.pitch,
                fov: self.fov,
            },
            resolution: self.resolution,
            width_mm: self.width,
            depth_mm: self.depth,
            alpha: self.alpha,
            silhouette: self.silhouette,
            steps_mm: self.steps,
            flat_background: self.flat_background,
            bands: self.bands,
            emphasize: self.emphasize,
            stencil: self.stencil,
            stencil_gain: self.stencil_gain,
            material: self.material,
            mirror: self.mirror,
            invert: self.invert,
            method: self.method,
            output,
            stl: self.stl,
            base_mm: self.base,
            preview: None,
            depth_out: self.depth_out,
        }
    }
}

/// A spinner on a terminal, nothing in pipes or with --quiet.
fn spinner(quiet: bool) -> Option<indicatif::ProgressBar> {
    if quiet || !std::io::stderr().is_terminal() {
        return None;
    }
    let pb = indicatif::ProgressBar::new_spinner();
    pb.enable_steady_tick(std::time::Duration::from_millis(100));
    Some(pb)
}

fn run(cli: Cli) -> relievo::Result<()> {
    match cli.cmd {
        Cmd::Send(args) => send(args, cli.quiet),
        Cmd::Machine(args) => machine_cmd(args),
        Cmd::GrblSim(args) => grbl_sim(args),
        Cmd::Ports => {
            let ports = serialport::available_ports()
                .map_err(|e| relievo::Error(format!("listing serial ports: {e}")))?;
            if ports.is_empty() {
                eprintln!("no serial ports found");
            }
            for p in ports {
                println!("{}", p.port_name);
            }
            Ok(())
        }
        Cmd::Simulate(args) => simulate(args, cli.quiet, cli.verbose),
        Cmd::Toolpath(args) => {
            let relief = relievo::relief::file::load(&args.relief, args.width, args.depth)?;
            let job = args.cut.job(
                args.output.clone(),
                args.relief.display().to_string(),
                args.material,
            );
            let s = job.run(&relief)?;
            report_cam(&s, cli.quiet, cli.verbose);
            Ok(())
        }
        Cmd::Carve(args) => {
            let stem = args
                .output
                .file_stem()
                .map(|s| s.to_string_lossy().to_string())
                .unwrap_or("job".into());
            let relief_path = args.output.with_file_name(format!("{stem}-relief.png"));
            let material = args.relief.material.clone();
            let rjob = args.relief.job(args.model, relief_path.clone());
            let cam = args.cut.job(
                args.output.clone(),
                relief_path.display().to_string(),
                material,
            );
            relievo::output::check_writable(&args.output)?;
            let r = rjob.run(&mut |_| {})?;
            let s = match cam.run(&r.relief) {
                Ok(s) => s,
                Err(e) => {
                    // all or nothing: no relief without its job
                    for p in &r.written {
                        let _ = std::fs::remove_file(p);
                    }
                    return Err(e);
                }
            };
            if !cli.quiet {
                eprintln!("relief -> {}", relief_path.display());
            }
            report_cam(&s, cli.quiet, cli.verbose);
            Ok(())
        }
        Cmd::Relief(args) => {
            let mut job = args.opts.job(args.model, args.output);
            job.preview = args.preview;
            let pb = spinner(cli.quiet);
            let mut stage = |s: &str| {
                if let Some(pb) = &pb {
                    pb.set_message(s.to_string());
                }
            };
            let res = job.run(&mut stage);
            if let Some(pb) = pb {
                pb.finish_and_clear();
            }
            let s = res?;
            if !cli.quiet {
                let r = &s.relief;
                eprintln!(
                    "relief {} x {} px, {:.1} x {:.1} mm, depth {:.2} mm, {} silhouette edges -> {}",
                    r.heights.w,
                    r.heights.h,
                    r.width_mm,
                    r.height_mm,
                    r.depth_mm,
                    s.silhouette_edges,
                    s.written.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ")
                );
            }
            if cli.verbose {
                eprintln!(
                    "stage timings ({} threads):\n{}",
                    rayon::current_num_threads(),
                    s.timings.report()
                );
            }
            Ok(())
        }
    }
}

fn simulate(args: SimulateArgs, quiet: bool, verbose: bool) -> relievo::Result<()> {
    let job = relievo::simulate::SimulateJob {
        job: args.job,
        relief: args.relief,
        relief_width: args.width,
        relief_depth: args.depth,
        tool: args.tool,
        stock: args.stock,
        oversample: args.oversample,
        machine: args.machine,
        travel_origin: args.travel_origin,
        output: args.output,
        report: args.report,
        deviation: args.deviation,
    };
    let pb = spinner(quiet);
    if let Some(pb) = &pb {
        pb.set_message("simulating");
    }
    let res = job.run();
    if let Some(pb) = pb {
        pb.finish_and_clear();
    }
    let s = res?;
    if !quiet {
        eprintln!(
            "simulated {} on {} x {} cells\n{}",
            s.tool.spec(),
            s.cells.0,
            s.cells.1,
            s.report.summary()
        );
    }
    if verbose {
        eprintln!(
            "stage timings ({} threads):\n{}",
            rayon::current_num_threads(),
            s.timings.report()
        );
    }
    Ok(())
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) if !e.use_stderr() => {
            // --help and --version
            let _ = e.print();
            return ExitCode::SUCCESS;
        }
        Err(e) => {
            // one line, like every other error
            let text = e.render().to_string();
            let mut first = text
                .lines()
                .next()
                .unwrap_or("invalid arguments")
                .trim_end()
                .to_string();
            // clap lists missing arguments on the lines after the first
            if first.ends_with(':') {
                let missing: Vec<&str> = text
                    .lines()
                    .skip(1)
                    .map(str::trim)
                    .take_while(|l| !l.is_empty())
                    .collect();
                first = format!("{first} {}", missing.join(", "));
            }
            eprintln!("{first} (see relievo --help)");
            return ExitCode::from(2);
        }
    };
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
