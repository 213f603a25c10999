//! A job's planned ops delivered: emitted as G-code (one file with M0
//! tool changes, a split job, or one file per tile), judged by the
//! simulator (depth of cut, plunges, residual, travel), headed with the
//! notes and estimated times that judging settles, and written.

use super::finishing::LAYERS;
use super::setup::Work;
use super::{
    judge, layout, sim, stock, tile, view, CamSummary, Finish, JobFile, Op, Origin, ToolpathJob,
    Units, ZZero,
};
use crate::bail;
use crate::error::Result;
use crate::gcode::emit::Emitter;
use crate::machine::Machine;
use crate::output::Outputs;
use crate::relief::Relief;
use crate::tool::Tool;
use crate::toolpath::Pass;
use glam::DVec3;

/// The emitted files of a job: each file's path and text, its program
/// placed in the one job's frame, and the line each of its ops starts
/// after.
struct Emitted {
    texts: Vec<(std::path::PathBuf, String)>,
    progs: Vec<crate::gcode::Program>,
    op_starts: Vec<Vec<usize>>,
}

/// Each file's time and its share by op: what a carver plans the tool
/// changes and the day by.
struct Times {
    parts: Vec<Vec<(String, f64)>>,
    times: Vec<f64>,
}

impl ToolpathJob {
    /// Emit, judge, head and write the ops (see the module doc).
    pub(super) fn deliver(&self, mut ops: Vec<Op>, w: Work) -> Result<CamSummary> {
        let Work {
            relief,
            plan,
            machine,
            tool,
            cell,
            pad,
            limits,
            raw_points,
            step,
            rough_out,
            mut notes,
            mut t,
            ..
        } = w;
        let (relief, plan, m, limits) = (&relief, &plan, &machine, &limits);
        let z_shift = self.zero_ops(&mut ops, plan, pad);
        let n_rough = ops.iter().take_while(|o| o.title == "roughing").count();
        let rough_tool = (n_rough > 0).then(|| ops[0].tool);
        let header_notes = self.header_notes(&notes, plan, pad);
        let files = || {
            let finish_cell = (&tool, cell);
            self.job_files(
                ops,
                n_rough,
                relief,
                plan,
                finish_cell,
                &header_notes,
                z_shift,
                rough_out,
            )
        };
        let files = match self.layout.tile {
            Some(_) => t.time("tiles", files)?,
            None => files()?,
        };
        let emitted = self.emit_files(&files, relief, plan, m, z_shift, &mut t)?;
        // judged on the cells `simulate` takes by default (a cut hides at
        // most 1 um between their centres), so that carve reports what
        // simulate finds: on the planning cells the top of a wall the
        // roughing left fell between centres, and the 512 px demo's ball
        // read 0.996 mm deep where it cuts 1.095
        let judge_cell = {
            let pitch = relief.pitch_mm();
            let tools: Vec<Tool> = files
                .iter()
                .flat_map(|f| f.1.iter().map(|o| o.tool))
                .collect();
            let samples = relief.heights.w * relief.heights.h;
            let k = crate::sim::cells::oversample_for(&tools, pitch, samples);
            cell.min(pitch / k as f64)
        };
        let mut judged = t.time("judge", || {
            judge::run(&emitted.progs, relief, plan, z_shift, judge_cell)
        })?;
        refuse_too_deep(&judged, &emitted, &files, limits, rough_tool)?;
        if self.finish == Finish::Waterline {
            notes.push(format!(
                "waterline alone leaves up to {:.3} mm (mean {:.3} mm) on gentle slopes, \
                 where its loops lie far apart; raster+waterline finishes them",
                judged.residual.0, judged.residual.1
            ));
        }
        // what goes into each file's header now that it is judged: the
        // notes not yet there and its time; the lines reported move on by
        // as many lines as that takes
        let mut extra: Vec<String> = notes
            .iter()
            .filter(|n| !header_notes.contains(n))
            .cloned()
            .collect();
        let times = file_times(&emitted, &files, m);
        if let Some(n) = layers_advice(&times.parts, &times.times, &tool, m) {
            notes.push(n.clone());
            extra.push(n);
        }
        let estimate = |k: usize| times.estimate(k, m);
        let added =
            |extra: &[String], k: usize| comment_lines(extra) + comment_lines(&[estimate(k)]);
        if self.allow_deep_cuts {
            if let Some(n) = deep_cuts_note(&judged, &emitted.progs, limits, &extra, &added) {
                notes.push(n.clone());
                extra.push(n);
            }
        }
        judged.engagement.shift_lines(added(&extra, 0));
        let (rapid_mm, cut_mm) = judge::travel(&emitted.progs);
        let (lines, written) = self.write(
            emitted,
            &judged,
            relief,
            plan,
            z_shift,
            (&extra, &estimate),
            &mut t,
        )?;
        Ok(CamSummary {
            lines,
            raw_points,
            time_s: times.times.iter().sum(),
            time_by_op: total_shares(times.parts.into_iter().flatten()),
            stepover_mm: step,
            written,
            notes,
            engagement: judged.engagement,
            residual: judged.residual,
            gouge: judged.gouge,
            rapid_mm,
            cut_mm,
            timings: t,
        })
    }

    /// Each op's Z zero for the operator, and the Z shift of the job's
    /// coordinates (the stock's thickness with Z0 on the spoilboard).
    fn zero_ops(&self, ops: &mut [Op], plan: &layout::Plan, pad: Option<(f64, f64, f64)>) -> f64 {
        let shift = plan.shift;
        let zero = match (self.z_zero, pad) {
            (ZZero::Bottom, _) => "set Z0 on the spoilboard (the stock's bottom)".to_string(),
            (ZZero::Top, Some(p)) => format!(
                "set Z0 on the pad's top at X{:.1} Y{:.1} (the stock top)",
                p.0 + shift.x,
                p.1 + shift.y
            ),
            (ZZero::Top, None) => "set Z0 on the stock top again".to_string(),
        };
        for op in ops {
            op.zero = match (self.z_zero, op.title) {
                (ZZero::Top, "cutout") => "set Z0 on the stock top beside the panel".into(),
                _ => zero.clone(),
            };
        }
        match self.z_zero {
            ZZero::Top => 0.0,
            ZZero::Bottom => plan.stock.2,
        }
    }

    /// The notes every file's header carries: the job's, and the pad.
    fn header_notes(
        &self,
        notes: &[String],
        plan: &layout::Plan,
        pad: Option<(f64, f64, f64)>,
    ) -> Vec<String> {
        let mut header_notes = notes.to_vec();
        if let Some(p) = pad {
            header_notes.push(format!(
                "touch-off pad: {:.0} mm square at X{:.1} Y{:.1}, left at the stock top by roughing, cut last",
                p.2,
                p.0 + plan.shift.x,
                p.1 + plan.shift.y
            ));
        }
        header_notes
    }

    /// The files: one job, a split job (roughing in its own file), or one
    /// job per tile; each with its own frame and header notes.
    #[allow(clippy::too_many_arguments)]
    fn job_files(
        &self,
        mut ops: Vec<Op>,
        n_rough: usize,
        relief: &Relief,
        plan: &layout::Plan,
        finish_cell: (&Tool, f64),
        header_notes: &[String],
        z_shift: f64,
        rough_out: std::path::PathBuf,
    ) -> Result<Vec<JobFile>> {
        let one = |ops| {
            (
                self.output.clone(),
                ops,
                plan.clone(),
                header_notes.to_vec(),
            )
        };
        Ok(match self.layout.tile {
            Some(size) => {
                self.tiled(ops, relief, plan, size, finish_cell, header_notes, z_shift)?
            }
            None if self.split && n_rough > 0 => {
                let rest = ops.split_off(n_rough);
                vec![
                    (rough_out, ops, plan.clone(), header_notes.to_vec()),
                    one(rest),
                ]
            }
            None => vec![one(ops)],
        })
    }

    /// Every file emitted as G-code, read back as a program, checked
    /// against the machine's travel and placed in the one job's frame.
    fn emit_files(
        &self,
        files: &[JobFile],
        relief: &Relief,
        plan: &layout::Plan,
        m: &Machine,
        z_shift: f64,
        t: &mut crate::timing::Timings,
    ) -> Result<Emitted> {
        let mut texts = Vec::new();
        let mut op_starts = Vec::new();
        for (file, group, fplan, fnotes) in files {
            let (text, starts) = t.time("g-code", || {
                self.emit(group, relief, fplan, m, z_shift, fnotes)
            });
            texts.push((file.clone(), text));
            op_starts.push(starts);
        }
        let progs: Vec<crate::gcode::Program> = texts
            .iter()
            .map(|(_, text)| super::layout::Frame::program(text))
            .collect::<Result<_>>()?;
        for ((file, _), prog) in texts.iter().zip(&progs) {
            judge::fits_travel(prog, m, file)?;
        }
        let progs = progs
            .iter()
            .zip(files)
            .map(|(p, f)| p.moved(plan.shift - f.2.shift))
            .collect();
        Ok(Emitted {
            texts,
            progs,
            op_starts,
        })
    }

    /// The files written, headed with the judged notes and each file's
    /// estimate, with the SVG and preview asked for; all or nothing.
    /// Returns the lines written and the files, the job first.
    #[allow(clippy::too_many_arguments)]
    fn write(
        &self,
        emitted: Emitted,
        judged: &judge::Judged,
        relief: &Relief,
        plan: &layout::Plan,
        z_shift: f64,
        (extra, estimate): (&[String], &dyn Fn(usize) -> String),
        t: &mut crate::timing::Timings,
    ) -> Result<(usize, Vec<std::path::PathBuf>)> {
        let mut out = Outputs::default();
        let mut lines = 0;
        let mut written = Vec::new();
        for (k, (file, text)) in emitted.texts.into_iter().enumerate() {
            let mut text = with_comments(text, extra);
            text = with_comments(text, &[estimate(k)]);
            // counted as written: a wrapped comment takes several lines
            lines += text.lines().count();
            out.add(&file, text.into_bytes());
            written.push(file);
        }
        // a split job's finishing file (the one named -o, written last)
        // comes first in the list; tiles stay in their order
        if self.layout.tile.is_none() {
            written.rotate_right(1);
        }
        if let Some(svg) = &self.svg {
            let doc = t.time("svg", || {
                view::top_view(&emitted.progs, relief, plan, z_shift)
            });
            out.add(svg, doc.into_bytes());
            written.push(svg.clone());
        }
        if let Some(pv) = &self.preview {
            let png = t.time("preview", || {
                view::simulated_preview(judged, relief, self.light)
            });
            out.add(pv, png?);
            written.push(pv.clone());
        }
        t.time("write", || out.commit())?;
        Ok((lines, written))
    }

    /// The job's ops cut into tiles of at most `size` (row by row from the
    /// lower-left), one file each: every pass clipped to its tile (the
    /// clearing ops to the tile grown by the finishing tool's radius and
    /// a little, so that finishing along a border meets cleared stock),
    /// ramped in again where it now starts in material, travelling at
    /// safe Z; X0 Y0 at the tile's lower-left corner.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn tiled(
        &self,
        ops: Vec<Op>,
        relief: &Relief,
        plan: &layout::Plan,
        (tw, th): (f64, f64),
        (finish, cell): (&Tool, f64),
        notes: &[String],
        z_shift: f64,
    ) -> Result<Vec<JobFile>> {
        if !(tw.is_finite() && th.is_finite() && tw > 0.0 && th > 0.0) {
            bail!("--tile {tw}x{th}: sizes must be positive");
        }
        if self.cutout.is_some() {
            bail!("--tile with --cutout: cut the tiles out one by one is not supported; leave out --cutout");
        }
        if self.split {
            bail!(
                "--tile with --split: every tile is a file of its own already; leave out --split"
            );
        }
        if self.z_zero == ZZero::Top && ops.iter().any(|o| o.tool != ops[0].tool) {
            bail!(
                "--tile: the job changes tools, and the stock top does not survive roughing in \
                 every tile; zero Z on the spoilboard: --z-zero bottom --stock WxHxT"
            );
        }
        let (pw, ph) = (relief.width_mm, relief.height_mm);
        let tiles = tile::grid(pw, ph, tw, th);
        let grow = finish.radius() + 0.5;
        let mut planned = stock::Planned::new(plan.stock_in_panel(cell, ph));
        let stem = self
            .output
            .file_stem()
            .map_or("job".into(), |s| s.to_string_lossy().to_string());
        let (nx, ny) = tiles.last().map_or((1, 1), |t| t.1);
        let mut out = Vec::new();
        let mut prev: Option<[f64; 4]> = None;
        for (rect, (c, r)) in &tiles {
            let mut tile_ops = Vec::new();
            for op in &ops {
                let g = if op.title == "finishing" { 0.0 } else { grow };
                let around = [rect[0] - g, rect[1] - g, rect[2] + g, rect[3] + g];
                let safe = op.settings.safe_z;
                let pieces: Vec<Pass> = op
                    .passes
                    .iter()
                    .flat_map(|p| tile::clip(&p.pts, around))
                    .map(|pts| Pass { pts, clear_z: safe })
                    .collect();
                let passes = planned.ramp_and_cut(pieces, op.tool, true);
                if !passes.is_empty() {
                    tile_ops.push(Op {
                        passes,
                        ..op.clone()
                    });
                }
            }
            if tile_ops.is_empty() {
                continue;
            }
            let tplan = layout::Plan {
                shift: DVec3::new(-rect[0], -rect[1], 0.0),
                ..plan.clone()
            };
            let (sx, sy) = (rect[0] + plan.panel_at.0, rect[1] + plan.panel_at.1);
            let mut n = notes.to_vec();
            n.push(format!(
                "tile {c},{r} of {nx} x {ny}: panel X{:.2}..{:.2} Y{:.2}..{:.2}; X0 Y0 at its \
                 lower-left corner, X{sx:.2} Y{sy:.2} from the stock's lower-left corner{}",
                rect[0],
                rect[2],
                rect[1],
                rect[3],
                match prev {
                    Some(p) => format!(
                        "; from the last tile, move the stock by X{:.2} Y{:.2} (or zero X and Y there)",
                        -(rect[0] - p[0]),
                        -(rect[1] - p[1])
                    ),
                    None => String::new(),
                }
            ));
            if z_shift > 0.0 {
                n.push("Z0 stays on the spoilboard from tile to tile".into());
            }
            prev = Some(*rect);
            let file = self.output.with_file_name(format!("{stem}-tile{c}-{r}.nc"));
            out.push((file, tile_ops, tplan, n));
        }
        Ok(out)
    }

    /// One G-code file for `ops`, tool changes between them.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn emit(
        &self,
        ops: &[Op],
        relief: &Relief,
        plan: &layout::Plan,
        m: &Machine,
        z_shift: f64,
        notes: &[String],
    ) -> (String, Vec<usize>) {
        let header = |op: &Op| {
            vec![
                format!(
                    "tool: {} (radius {} mm) for {}",
                    op.tool.spec(),
                    op.tool.radius(),
                    op.title
                ),
                format!("strategy: {}", op.strategy),
                format!(
                    "feed {} plunge {} mm/min, {} rpm, safe Z {}",
                    op.settings.feed, op.settings.plunge_feed, op.settings.rpm, op.settings.safe_z
                ),
            ]
        };
        let (sw, sh, st) = plan.stock;
        let mut top = vec![
            "relievo GRBL 1.1 job".to_string(),
            format!("relief: {}", self.relief_name),
            format!(
                "material: {}",
                self.material.as_deref().unwrap_or("not given")
            ),
            format!(
                "panel: {:.2} x {:.2} mm, relief depth {:.3} mm{}",
                relief.width_mm,
                relief.height_mm,
                relief.depth_mm,
                if self.layout.rotate {
                    ", turned 90 deg"
                } else {
                    ""
                }
            ),
            format!(
                "stock: {sw:.2} x {sh:.2} x {st:.2} mm, origin at its {}",
                if self.origin == Origin::Center {
                    "centre"
                } else {
                    "lower-left corner"
                }
            ),
            match self.z_zero {
                ZZero::Top => "Z0 = stock top".to_string(),
                ZZero::Bottom => format!("Z0 = stock bottom (spoilboard), stock top at Z{st}"),
            },
            // machine-readable: the simulator places the relief by it
            plan.frame(z_shift).comment(),
            format!(
                "machine: {}, units: {}",
                m.name,
                if self.units == Units::In {
                    "inch (G20)"
                } else {
                    "mm"
                }
            ),
        ];
        top.extend(notes.iter().cloned());
        top.extend(header(&ops[0]));
        let inch = self.units == Units::In;
        let mut e = Emitter::new(&top, &ops[0].settings, inch, z_shift);
        e.arcs = self.arcs;
        e.steps = Some(DVec3::new(
            m.steps_per_mm.x,
            m.steps_per_mm.y,
            m.steps_per_mm.z,
        ));
        let shift = plan.shift;
        // op 0 starts with the job (its header is the job's); every other
        // at its own header, after the tool before it is put away (its
        // retract and spindle stop count with that tool, as `simulate`
        // counts them by the (tool: ..) comments)
        let mut starts = vec![0];
        for (k, op) in ops.iter().enumerate() {
            let change = k > 0 && op.tool != ops[k - 1].tool;
            if change {
                e.put_away(&op.settings);
            }
            if k > 0 {
                starts.push(e.out.lines().count());
            }
            if change {
                e.fit(&header(op), &op.settings, &op.zero);
            } else if k > 0 {
                for h in header(op).iter().skip(1) {
                    crate::gcode::emit::comment(&mut e.out, h);
                }
            }
            for pass in &op.passes {
                let pts: Vec<DVec3> = pass
                    .pts
                    .iter()
                    .map(|p| DVec3::new(p.x + shift.x, p.y + shift.y, p.z))
                    .collect();
                e.pass(&pts, &op.settings, pass.clear_z);
            }
        }
        (e.finish(&ops[ops.len() - 1].settings), starts)
    }
}

/// Refuse the job at its first cut deeper than its tool may take, with
/// what to do about it.
fn refuse_too_deep(
    judged: &judge::Judged,
    emitted: &Emitted,
    files: &[JobFile],
    limits: &super::setup::Limits,
    rough_tool: Option<Tool>,
) -> Result<()> {
    let Some((k, o)) = judge::first_over(judged, &emitted.progs, &|tl| limits.of(tl)) else {
        return Ok(());
    };
    let what = format!(
        "{}line {}: {} cuts {:.3} mm deep{} (allowed {:.3} mm in {})",
        if files.len() > 1 {
            format!("{}, ", files[k].0.display())
        } else {
            String::new()
        },
        o.line,
        o.tool.spec(),
        o.depth,
        if o.slotting { " at full width" } else { "" },
        o.limit,
        limits.name
    );
    // the op the line belongs to: the last that starts before it
    let op = emitted.op_starts[k]
        .iter()
        .rposition(|&s| s < o.line)
        .unwrap_or(0);
    let roughing = files[k].1[op].title == "roughing";
    let advice = match rough_tool {
        // roughing is there: the spot is one it cannot reach (a channel or
        // corner narrower than its tool) and the finishing tool's own
        // layers cannot be entered
        Some(rt) if !roughing => format!(
            "{} cannot reach there, nor can the finishing tool's layers be entered: \
             rough with a smaller tool (--rough flat:D), or pass --allow-deep-cuts",
            rt.spec()
        ),
        Some(_) => "lower --step-down, or pass --allow-deep-cuts".into(),
        None => "rough first (--rough), lower --step-down, or pass --allow-deep-cuts".into(),
    };
    bail!("{what}: {advice}");
}

/// With --allow-deep-cuts, the note naming the first cut deeper than the
/// material allows, its line number counted after the header grows by
/// `extra` and the note itself.
fn deep_cuts_note(
    judged: &judge::Judged,
    progs: &[crate::gcode::Program],
    limits: &super::setup::Limits,
    extra: &[String],
    added: &dyn Fn(&[String], usize) -> usize,
) -> Option<String> {
    let (k, o) = judge::first_over(judged, progs, &|tl| limits.material_of(tl))?;
    let note = |by: usize| {
        format!(
            "--allow-deep-cuts: line {} cuts {:.3} mm deep with {} (limit {:.3} mm)",
            o.line + by,
            o.depth,
            o.tool.spec(),
            o.limit
        )
    };
    // the note's own lines count: settle the number twice
    let mut by = added(extra, k);
    for _ in 0..2 {
        let with: Vec<String> = extra.iter().cloned().chain([note(by)]).collect();
        by = added(&with, k);
    }
    Some(note(by))
}

/// Each file's estimate on the machine, by op.
fn file_times(emitted: &Emitted, files: &[JobFile], m: &Machine) -> Times {
    let parts: Vec<Vec<(String, f64)>> = emitted
        .progs
        .iter()
        .zip(&emitted.op_starts)
        .zip(files)
        .map(|((p, starts), f)| {
            let secs = sim::time_by_part(p, m, starts);
            op_shares(f.1.iter().map(|o| (o.title, &o.tool)), &secs)
        })
        .collect();
    let times = parts
        .iter()
        .map(|ps| ps.iter().map(|p| p.1).sum())
        .collect();
    Times { parts, times }
}

impl Times {
    /// File `k`'s estimate as its header says it.
    fn estimate(&self, k: usize, m: &Machine) -> String {
        let split = if self.parts[k].len() > 1 {
            format!(": {}", sim::shares_text(&self.parts[k]))
        } else {
            String::new()
        };
        format!(
            "estimated time: {} on {}{split}",
            sim::hms(self.times[k]),
            m.name
        )
    }
}

/// When a small finishing tool's own layers take over half the job: how
/// long, and the usual faster plan (the largest ball in the tool table up
/// to 1/4 in finishes, the small tool follows as a rest tool). On the
/// 512 px demo a 1 mm ball's layers take 7h 36m of 11h 40m; ball:3.175
/// with --rest ball:1 takes 2h 53m.
fn layers_advice(
    parts: &[Vec<(String, f64)>],
    times: &[f64],
    tool: &Tool,
    m: &Machine,
) -> Option<String> {
    let total: f64 = times.iter().sum();
    let layers: f64 = parts
        .iter()
        .flatten()
        .filter(|p| p.0.starts_with(LAYERS))
        .map(|p| p.1)
        .sum();
    if layers <= 0.5 * total {
        return None;
    }
    let bigger = m
        .finishing_ball(tool)
        .map_or("a larger ball".to_string(), |(k, spec)| {
            format!("{k} ({spec})")
        });
    Some(format!(
        "{} steps down in layers for {} of the {}: finishing with {bigger} and --rest {} \
         (only where the larger ball cannot reach) is usually much faster",
        tool.spec(),
        sim::hms(layers),
        sim::hms(total),
        tool.spec()
    ))
}

/// Seconds per op, ops of the same title and tool added together:
/// ("roughing flat:3.175", seconds), in job order.
fn op_shares<'a>(
    ops: impl Iterator<Item = (&'a str, &'a Tool)>,
    secs: &[f64],
) -> Vec<(String, f64)> {
    total_shares(
        ops.zip(secs)
            .map(|((title, tool), &s)| (format!("{title} {}", tool.spec()), s)),
    )
}

/// Shares of the same name added together wherever they stand, in the
/// order first met: a file's ops of one kind, a tiled job's roughing over
/// all its tiles.
fn total_shares(shares: impl Iterator<Item = (String, f64)>) -> Vec<(String, f64)> {
    let mut out: Vec<(String, f64)> = Vec::new();
    for (name, s) in shares {
        match out.iter_mut().find(|o| o.0 == name) {
            Some(o) => o.1 += s,
            None => out.push((name, s)),
        }
    }
    out
}

/// How many lines `with_comments` adds for `notes`.
fn comment_lines(notes: &[String]) -> usize {
    let mut s = String::new();
    for n in notes {
        crate::gcode::emit::comment(&mut s, n);
    }
    s.lines().count()
}

/// Insert comment lines after the header comments.
fn with_comments(mut text: String, lines: &[String]) -> String {
    let mut add = String::new();
    for l in lines {
        crate::gcode::emit::comment(&mut add, l);
    }
    let at = text
        .lines()
        .take_while(|l| l.starts_with('('))
        .map(|l| l.len() + 1)
        .sum();
    text.insert_str(at, &add);
    text
}
