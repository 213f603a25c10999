//! relievo: 3D scenes to bas-reliefs (Weyrich et al. 2007) and
//! bas-reliefs to CNC jobs. Data flows one way:
//! scene -> relief -> (toolpath -> gcode -> sim / grbl), in layers that
//! import only from below (docs/architecture.md): foundations, scene,
//! relief, dialect, cutter, gcode, toolpath, sim, grbl, cam, then `ops`,
//! the jobs each command runs as one call.

pub mod cam;
pub mod cutter;
pub mod dialect;
pub mod error;
pub mod export;
pub mod grid;
pub mod input;
pub mod materials;
pub mod ops;
pub mod output;
pub mod preview;
pub mod progress;
pub mod relief;
pub mod scene;
pub mod settings;
pub mod timing;

pub use error::{Error, Result};
pub use grid::Grid;
pub mod gcode;
pub mod grbl;
pub mod machine;
pub mod sim;
pub mod studio;

#[cfg(test)]
mod testing;
pub mod tool;
pub mod toolpath;
