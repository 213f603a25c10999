//! Tool engagement, measured on the simulated cut: for every move, the
//! thickest layer of material it took off any one stock cell (its axial
//! depth of cut) and how wide across the move it cut (its radial
//! engagement). A carver's limits are on these two figures: a tool may cut
//! its step-down deep at partial width, and less when it slots.

use super::Sweep;
use crate::gcode::{Kind, Program};
use crate::tool::Tool;

/// A cell counts toward the width of a cut when the move took more than
/// this off it (mm): thinner slivers are the scallops of the rows beside.
pub const SKIN: f32 = 0.01;
/// A move cuts "under its axis" (a plunge, when it goes steeply down) when
/// it takes more than this off a cell within a quarter radius of its end:
/// more than the scallop a neighbouring row leaves there.
pub const PLUNGE_SKIN: f32 = 0.1;
/// Figures compared with limits allow this much (mm): the simulator's f32
/// heights and the G-code grid.
pub const SLACK: f64 = 0.005;
/// Cells further across a move than this share of the tool's radius are
/// shaved by its side: a wall the last rows left a few hundredths of a mm
/// proud, cut at full height but at a width of under 5% of the tool's
/// diameter, the light side cut that finishes walls. Their thickness is
/// not the move's axial depth of cut (it still counts toward its width).
pub const SIDE_SHAVE: f32 = 0.9;

/// Whether a cell `across` from a move of a tool of radius `r` is shaved
/// by its side (`SIDE_SHAVE`).
#[inline(always)]
pub fn shaved(across: f32, r: f32) -> bool {
    across.abs() > SIDE_SHAVE * r
}

/// A move slots when it cuts at least this share of the tool's full width
/// at its depth of cut.
pub const SLOT_SHARE: f64 = 0.9;

/// What one move removed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MoveCut {
    /// Thickest layer taken off one cell, mm.
    pub axial: f32,
    /// Extent across the move (signed offsets from its line, mm) of the
    /// cells it took more than SKIN off.
    pub lo: f32,
    pub hi: f32,
    /// Thickest layer taken off a cell near the axis at the move's end.
    pub core: f32,
}

impl MoveCut {
    pub const NONE: MoveCut = MoveCut {
        axial: 0.0,
        lo: f32::INFINITY,
        hi: f32::NEG_INFINITY,
        core: 0.0,
    };

    /// Account one cell: `removed` mm taken off at offset `across`;
    /// `shaved` when the cell lies in the outer SIDE_SHAVE of the width.
    #[inline(always)]
    pub fn add(&mut self, removed: f32, across: f32, near_axis: bool, shaved: bool) {
        self.axial = if removed > self.axial && !shaved {
            removed
        } else {
            self.axial
        };
        let on = removed > SKIN;
        self.lo = if on && across < self.lo {
            across
        } else {
            self.lo
        };
        self.hi = if on && across > self.hi {
            across
        } else {
            self.hi
        };
        self.core = if near_axis && removed > self.core {
            removed
        } else {
            self.core
        };
    }

    pub fn merge(&mut self, o: &MoveCut) {
        self.axial = self.axial.max(o.axial);
        self.lo = self.lo.min(o.lo);
        self.hi = self.hi.max(o.hi);
        self.core = self.core.max(o.core);
    }

    /// Width cut across the move (mm), cells counted whole.
    pub fn width(&self, pitch: f64) -> f64 {
        if self.hi >= self.lo {
            (self.hi - self.lo) as f64 + pitch
        } else {
            0.0
        }
    }
}

/// Unit vector across the move in XY (X for a vertical move).
#[inline]
pub fn across(sw: &Sweep) -> (f64, f64) {
    let l = sw.axy.sqrt();
    if l > 1e-12 {
        (-sw.d.y / l, sw.d.x / l)
    } else {
        (1.0, 0.0)
    }
}

/// Squared radius around the axis that counts as "under the tool".
#[inline]
pub fn core_radius2(r: f64) -> f64 {
    (r / 4.0).powi(2)
}

/// The engagement of one tool over its stretches of a job.
#[derive(Clone, Debug, serde::Serialize, PartialEq)]
pub struct ToolEngagement {
    pub tool: String,
    /// Largest axial depth of cut and the job line where it occurs.
    pub max_axial_mm: f64,
    pub axial_line: usize,
    /// Largest radial engagement (width cut across the move).
    pub max_radial_mm: f64,
    pub radial_line: usize,
    /// Deepest cut at (nearly) the tool's full width.
    pub max_slot_mm: f64,
    pub slot_line: usize,
}

/// What a job asks of its tools.
#[derive(Clone, Debug, Default, serde::Serialize, PartialEq)]
pub struct Engagement {
    pub tools: Vec<ToolEngagement>,
    /// Lines of feed moves that go steeply down into material under the
    /// tool's axis instead of ramping.
    pub plunges: Vec<usize>,
}

/// One move over a limit.
#[derive(Clone, Debug, PartialEq)]
pub struct Over {
    pub line: usize,
    pub tool: Tool,
    pub depth: f64,
    pub limit: f64,
    pub slotting: bool,
}

/// Whether move `k` slots: cuts (nearly) the tool's full width at its depth.
fn slots(tool: &Tool, mc: &MoveCut, pitch: f64) -> bool {
    mc.width(pitch) + pitch >= SLOT_SHARE * tool.width_at(mc.axial as f64)
}

impl Engagement {
    /// Sum up the measured moves of `prog` (`moves[k]` for segment k)
    /// by the tool stretches `runs`.
    pub fn measure(
        prog: &Program,
        moves: &[MoveCut],
        runs: &[(usize, usize, Tool)],
        pitch: f64,
    ) -> Engagement {
        let mut e = Engagement::default();
        for &(from, to, tool) in runs {
            let spec = tool.spec();
            let k = match e.tools.iter().position(|t| t.tool == spec) {
                Some(k) => k,
                None => {
                    e.tools.push(ToolEngagement {
                        tool: spec,
                        max_axial_mm: 0.0,
                        axial_line: 0,
                        max_radial_mm: 0.0,
                        radial_line: 0,
                        max_slot_mm: 0.0,
                        slot_line: 0,
                    });
                    e.tools.len() - 1
                }
            };
            let te = &mut e.tools[k];
            for (seg, mc) in prog.segments[from..to].iter().zip(&moves[from..to]) {
                if seg.kind == Kind::Rapid {
                    continue;
                }
                let (a, w) = (mc.axial as f64, mc.width(pitch));
                if a > te.max_axial_mm {
                    (te.max_axial_mm, te.axial_line) = (a, seg.line);
                }
                if w > te.max_radial_mm {
                    (te.max_radial_mm, te.radial_line) = (w, seg.line);
                }
                if a > te.max_slot_mm && slots(&tool, mc, pitch) {
                    (te.max_slot_mm, te.slot_line) = (a, seg.line);
                }
                let d = seg.b - seg.a;
                if d.z < 0.0 && d.truncate().length() < -d.z && mc.core > PLUNGE_SKIN {
                    e.plunges.push(seg.line);
                }
            }
        }
        e.plunges.dedup();
        e
    }

    /// The first move deeper than its tool's limits (`limits(tool)` =
    /// allowed depth of cut and allowed slotting depth), if any.
    pub fn first_over(
        prog: &Program,
        moves: &[MoveCut],
        runs: &[(usize, usize, Tool)],
        pitch: f64,
        limits: &dyn Fn(&Tool) -> (f64, f64),
    ) -> Option<Over> {
        for &(from, to, tool) in runs {
            let (depth, slot) = limits(&tool);
            for (seg, mc) in prog.segments[from..to].iter().zip(&moves[from..to]) {
                if seg.kind == Kind::Rapid {
                    continue;
                }
                let a = mc.axial as f64;
                let over = |limit: f64, slotting| Over {
                    line: seg.line,
                    tool,
                    depth: a,
                    limit,
                    slotting,
                };
                if a > depth + SLACK {
                    return Some(over(depth, false));
                }
                if a > slot + SLACK && slots(&tool, mc, pitch) {
                    return Some(over(slot, true));
                }
            }
        }
        None
    }

    /// The line numbers moved on by `by` (comments put into the job's
    /// header after it was judged).
    pub fn shift_lines(&mut self, by: usize) {
        for t in &mut self.tools {
            t.axial_line += by;
            t.radial_line += by;
            t.slot_line += by;
        }
        for p in &mut self.plunges {
            *p += by;
        }
    }

    /// Add another file's engagement: the larger figures per tool.
    pub fn absorb(&mut self, o: Engagement) {
        for t in o.tools {
            match self.tools.iter_mut().find(|m| m.tool == t.tool) {
                None => self.tools.push(t),
                Some(m) => {
                    if t.max_axial_mm > m.max_axial_mm {
                        (m.max_axial_mm, m.axial_line) = (t.max_axial_mm, t.axial_line);
                    }
                    if t.max_radial_mm > m.max_radial_mm {
                        (m.max_radial_mm, m.radial_line) = (t.max_radial_mm, t.radial_line);
                    }
                    if t.max_slot_mm > m.max_slot_mm {
                        (m.max_slot_mm, m.slot_line) = (t.max_slot_mm, t.slot_line);
                    }
                }
            }
        }
        self.plunges.extend(o.plunges);
    }

    /// Lines for the summary, one per tool.
    pub fn summary(&self) -> String {
        let mut s: Vec<String> = self
            .tools
            .iter()
            .map(|t| {
                format!(
                    "{}: depth of cut up to {:.3} mm (line {}), width up to {:.3} mm (line {}), slotting up to {:.3} mm deep",
                    t.tool, t.max_axial_mm, t.axial_line, t.max_radial_mm, t.radial_line, t.max_slot_mm
                )
            })
            .collect();
        s.push(if self.plunges.is_empty() {
            "plunges into material: none".to_string()
        } else {
            format!(
                "plunges into material: {} (first at line {})",
                self.plunges.len(),
                self.plunges[0]
            )
        });
        s.join("\n")
    }
}
