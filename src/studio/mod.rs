//! `relievo studio`: a page on 127.0.0.1 to design a relief, check its
//! job and download the files. The page only shows and sends settings;
//! every computation is the library's (`work`), reached over a small API
//! (`server`).

pub mod machine;
pub mod packet;
pub mod server;
pub mod settings;
pub mod work;

use crate::error::{Error, Result};
use serde_json::{json, Value};
use std::net::SocketAddr;
use std::path::Path;
use std::sync::Arc;

/// Largest model upload (bytes): a binary STL of 2.6 million triangles.
pub const MAX_UPLOAD: usize = 128 << 20;

/// The page, from the binary: no file to find, no network needed.
pub mod page {
    pub const INDEX: &str = include_str!("page/index.html");
    pub const SCRIPT: &str = include_str!("page/studio.js");
    pub const MACHINE: &str = include_str!("page/machine.js");
    pub const STYLE: &str = include_str!("page/studio.css");
}

/// The machines (with their tool tables) and materials the page offers.
pub fn options() -> Value {
    let machines: Vec<Value> = crate::machine::builtin_names()
        .into_iter()
        .filter_map(|n| {
            let m = crate::machine::Machine::load(n).ok()?;
            let tools: Vec<Value> = m
                .tools
                .iter()
                .map(|(id, t)| json!({"id": id, "tool": t.tool, "name": t.name}))
                .collect();
            let setter = m.setter.map(|s| [s.x, s.y, s.z]);
            Some(
                json!({"id": n, "name": m.name, "tools": tools, "setter": setter,
                        "travel": [m.travel.x, m.travel.y, m.travel.z]}),
            )
        })
        .collect();
    let materials: Vec<Value> = crate::materials::builtin()
        .into_iter()
        .map(|(k, m)| json!({"id": k, "description": m.description}))
        .collect();
    use crate::ops::settings::{CutSettings, Given, ReliefSettings};
    let settings = json!({
        "relief": Given::<ReliefSettings>::describe(),
        "cut": Given::<CutSettings>::describe(),
    });
    json!({"machines": machines, "materials": materials, "settings": settings,
           "max_upload": MAX_UPLOAD, "max_resolution": work::MAX_RESOLUTION})
}

/// Bind `addr` (port 0 = any free one) and serve the studio on `model`
/// until the process ends; `ready` gets the address bound.
pub fn serve(model: Option<&Path>, addr: SocketAddr, ready: impl FnOnce(SocketAddr)) -> Result<()> {
    let studio = Arc::new(work::Studio::new(model, &std::env::temp_dir())?);
    let server = tiny_http::Server::http(addr)
        .map_err(|e| Error(format!("studio: cannot listen on {addr}: {e}")))?;
    let bound = server
        .server_addr()
        .to_ip()
        .ok_or_else(|| Error("studio: not an IP address".into()))?;
    ready(bound);
    server::run(server, studio);
    Ok(())
}
