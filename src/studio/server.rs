//! The studio's HTTP side: the page and its assets from the binary, a
//! small JSON/binary API over `Studio`, bounded bodies, and an error for
//! every bad request (a panic in one request is that request's 500, the
//! server keeps serving). Only this machine's own pages are answered: a
//! request naming another host (DNS rebinding) or sent from another site's
//! page (its Origin) is refused, as the studio is a step from a spindle.

use super::packet::{extreme, mean, shrink, Packet};
use super::settings::{CutSettings, ReliefSettings};
use super::work::{Fail, Studio};
use super::{machine, page, MAX_UPLOAD};
use serde_json::{json, Value};
use std::io::Read;
use std::net::{IpAddr, SocketAddr};
use std::sync::atomic::{AtomicUsize, Ordering::SeqCst};
use std::sync::Arc;
use tiny_http::{Header, Method, Request, Response};

/// Largest settings body (bytes).
const MAX_JSON: usize = 64 << 10;
/// Requests handled at once; more get a 503.
const MAX_ACTIVE: usize = 32;
/// Long side of the grids the views get (samples).
const VIEW_MAX: usize = 1024;
/// Most moves drawn in the job view.
const MAX_DRAWN_MOVES: usize = 400_000;

/// An answer: status, content type, body, extra headers.
pub struct Reply {
    status: u16,
    kind: &'static str,
    body: Vec<u8>,
    attachment: Option<String>,
}

impl Reply {
    pub(super) fn json(status: u16, v: Value) -> Reply {
        Reply {
            status,
            kind: "application/json",
            body: serde_json::to_vec(&v).expect("json serializes"),
            attachment: None,
        }
    }
    pub(super) fn error(status: u16, msg: impl Into<String>) -> Reply {
        Reply::json(status, json!({ "error": msg.into() }))
    }
    fn binary(body: Vec<u8>) -> Reply {
        Reply {
            status: 200,
            kind: "application/octet-stream",
            body,
            attachment: None,
        }
    }
    /// One of the page's own files, shown in place.
    fn file_inline(kind: &'static str, text: &str) -> Reply {
        Reply {
            status: 200,
            kind,
            body: text.as_bytes().to_vec(),
            attachment: None,
        }
    }
    fn file(kind: &'static str, name: &str, body: Vec<u8>) -> Reply {
        Reply {
            status: 200,
            kind,
            body,
            attachment: Some(name.to_string()),
        }
    }
}

/// Serve `studio` on `server` until the process ends.
pub fn run(server: tiny_http::Server, studio: Arc<Studio>) {
    let active = Arc::new(AtomicUsize::new(0));
    let at = server.server_addr().to_ip();
    for rq in server.incoming_requests() {
        if let Err(r) = at.map_or(Ok(()), |at| trusted(&rq, at)) {
            send(rq, r);
            continue;
        }
        if active.load(SeqCst) >= MAX_ACTIVE {
            send(rq, Reply::error(503, "busy: too many requests at once"));
            continue;
        }
        active.fetch_add(1, SeqCst);
        let (studio, active) = (studio.clone(), active.clone());
        std::thread::spawn(move || {
            handle(rq, &studio);
            active.fetch_sub(1, SeqCst);
        });
    }
}

fn send(rq: Request, r: Reply) {
    let mut resp = Response::from_data(r.body)
        .with_status_code(r.status)
        .with_header(header("Content-Type", r.kind))
        .with_header(header("Cache-Control", "no-store"));
    if let Some(name) = r.attachment {
        resp = resp.with_header(header(
            "Content-Disposition",
            &format!("attachment; filename=\"{name}\""),
        ));
    }
    // the client may have gone; nothing to do then
    let _ = rq.respond(resp);
}

/// A request's header `name`, if it has one.
fn header_of<'a>(rq: &'a Request, name: &str) -> Option<&'a str> {
    rq.headers()
        .iter()
        .find(|h| h.field.as_str().as_str().eq_ignore_ascii_case(name))
        .map(|h| h.value.as_str())
}

/// Whether `host[:port]` names this server: an address it listens on (any
/// IP literal when it listens on all of them) or `localhost`, at its port.
/// A DNS name is refused: pointed at 127.0.0.1 by another site (DNS
/// rebinding), it would hand that site the studio.
fn names_us(authority: &str, at: SocketAddr) -> bool {
    let (host, port) = match authority.rsplit_once(':') {
        Some((h, p)) if !p.contains(']') => (h, p.parse::<u16>().ok()),
        _ => (authority, Some(80)),
    };
    if port != Some(at.port()) {
        return false;
    }
    if host.eq_ignore_ascii_case("localhost") {
        return at.ip().is_loopback() || at.ip().is_unspecified();
    }
    match host
        .trim_start_matches('[')
        .trim_end_matches(']')
        .parse::<IpAddr>()
    {
        Ok(ip) => {
            ip == at.ip() || at.ip().is_unspecified() || (ip.is_loopback() && at.ip().is_loopback())
        }
        Err(_) => false,
    }
}

/// Refuse a request for another host, or from another site's page.
/// The header a request that changes anything carries the secret in.
pub const SECRET_HEADER: &str = "X-Relievo-Secret";

fn trusted(rq: &Request, at: SocketAddr) -> Result<(), Reply> {
    let host = header_of(rq, "Host").unwrap_or("");
    if !names_us(host, at) {
        return Err(Reply::error(
            403,
            format!("refused: the request names host '{host}', not this studio ({at})"),
        ));
    }
    if let Some(origin) = header_of(rq, "Origin") {
        let ok = origin
            .strip_prefix("http://")
            .is_some_and(|o| names_us(o, at));
        if !ok {
            return Err(Reply::error(
                403,
                format!("refused: a page from '{origin}' may not use this studio"),
            ));
        }
    }
    Ok(())
}

fn header(k: &str, v: &str) -> Header {
    Header::from_bytes(k.as_bytes(), v.as_bytes()).expect("ASCII header")
}

fn handle(mut rq: Request, studio: &Studio) {
    if rq.url().split('?').next() == Some("/api/machine/live") {
        return live(rq, studio);
    }
    let reply = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| route(&mut rq, studio)))
        .unwrap_or_else(|_| Reply::error(500, "internal error (the studio goes on serving)"));
    send(rq, reply);
}

/// The body, refused when longer than `max` (from its declared length
/// first, so a huge upload is not read at all).
fn body(rq: &mut Request, max: usize) -> Result<Vec<u8>, Reply> {
    let too_big = || {
        Reply::error(
            413,
            format!("request too large: at most {} MB", max as f64 / 1048576.0),
        )
    };
    if rq.body_length().is_some_and(|n| n > max) {
        return Err(too_big());
    }
    let mut b = Vec::new();
    rq.as_reader()
        .take(max as u64 + 1)
        .read_to_end(&mut b)
        .map_err(|e| Reply::error(400, format!("reading the request: {e}")))?;
    if b.len() > max {
        return Err(too_big());
    }
    Ok(b)
}

/// The query parameter `key` of a URL, percent-decoded.
fn query(url: &str, key: &str) -> Option<String> {
    let q = url.split_once('?')?.1;
    q.split('&').find_map(|kv| {
        let (k, v) = kv.split_once('=')?;
        (k == key).then(|| percent_decode(v))
    })
}

fn percent_decode(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let hex = |c: u8| (c as char).to_digit(16);
        match b[i] {
            b'%' if i + 2 < b.len() => match (hex(b[i + 1]), hex(b[i + 2])) {
                (Some(h), Some(l)) => {
                    out.push((h * 16 + l) as u8);
                    i += 3;
                    continue;
                }
                _ => out.push(b'%'),
            },
            b'+' => out.push(b' '),
            c => out.push(c),
        }
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// What the page sends to make a relief or a job: each kind of settings
/// as a JSON object, read by the command line's definition.
#[derive(serde::Deserialize, Default)]
#[serde(default, deny_unknown_fields)]
struct Sent {
    relief: serde_json::Map<String, serde_json::Value>,
    cut: serde_json::Map<String, serde_json::Value>,
}

struct Ask {
    relief: ReliefSettings,
    cut: CutSettings,
}

fn ask(rq: &mut Request) -> Result<Ask, Reply> {
    let b = body(rq, MAX_JSON)?;
    let sent: Sent =
        serde_json::from_slice(&b).map_err(|e| Reply::error(400, format!("bad settings: {e}")))?;
    let bad = |e: crate::Error| Reply::error(400, e.0);
    Ok(Ask {
        relief: ReliefSettings::from_json(&sent.relief.into()).map_err(bad)?,
        cut: CutSettings::from_json(&sent.cut.into()).map_err(bad)?,
    })
}

fn failed(f: Fail) -> Reply {
    match f {
        Fail::Superseded => Reply::json(409, json!({"superseded": true})),
        Fail::Bad(e) => Reply::error(400, e.0),
    }
}

fn route(rq: &mut Request, studio: &Studio) -> Reply {
    let url = rq.url().to_string();
    let path = url.split('?').next().unwrap_or("");
    // a change needs the secret in its header; a look at the machine
    // needs it too (in the header, or the query a WebSocket can carry)
    let post = *rq.method() == Method::Post;
    let keyed = if post {
        header_of(rq, SECRET_HEADER) == Some(studio.secret.as_str())
    } else {
        has_secret(rq, &url, studio)
    };
    if (post || path.starts_with("/api/machine/")) && !keyed {
        return Reply::error(
            403,
            "refused: the request lacks this studio's secret (its own page sends it)",
        );
    }
    match (rq.method(), path) {
        (Method::Get, "/") | (Method::Get, "/index.html") => {
            let meta = format!(
                "<head>\n<meta name=\"relievo-secret\" content=\"{}\">",
                studio.secret
            );
            Reply::file_inline(
                "text/html; charset=utf-8",
                &page::INDEX.replacen("<head>", &meta, 1),
            )
        }
        (Method::Get, "/studio.js") => Reply::file_inline("text/javascript", page::SCRIPT),
        (Method::Get, "/studio.css") => Reply::file_inline("text/css", page::STYLE),
        (Method::Get, "/machine.js") => Reply::file_inline("text/javascript", page::MACHINE),
        (Method::Get, "/api/machine/ports") => machine::ports(),
        (Method::Get, "/api/machine/state") => machine::state(studio),
        (Method::Post, "/api/machine/upload") => {
            let name = query(&url, "name").unwrap_or_else(|| "job.nc".into());
            match body(rq, machine::MAX_NC) {
                Ok(b) => machine::upload(studio, &name, &b),
                Err(r) => r,
            }
        }
        (Method::Post, p) if p.starts_with("/api/machine/") => {
            let call = body(rq, MAX_JSON).and_then(|b| {
                serde_json::from_slice::<machine::Call>(&b)
                    .map_err(|e| Reply::error(400, format!("bad machine call: {e}")))
            });
            match call {
                Ok(c) => machine::post(studio, &p["/api/machine/".len()..], c),
                Err(r) => r,
            }
        }
        (Method::Get, "/api/options") => Reply::json(200, super::options()),
        (Method::Get, "/api/model") => Reply::json(200, model_info(studio)),
        (Method::Get, "/api/mesh") => mesh(studio),
        (Method::Post, "/api/model") => {
            let Some(name) = query(&url, "name") else {
                return Reply::error(400, "upload: the file's name is missing (?name=)");
            };
            let b = match body(rq, MAX_UPLOAD) {
                Ok(b) => b,
                Err(r) => return r,
            };
            match studio.upload(&name, &b) {
                Ok(_) => Reply::json(200, model_info(studio)),
                Err(e) => Reply::error(400, e.0),
            }
        }
        (Method::Post, "/api/demo") => match studio.open(None) {
            Ok(_) => Reply::json(200, model_info(studio)),
            Err(e) => Reply::error(400, e.0),
        },
        (Method::Post, "/api/relief") => match ask(rq) {
            Ok(a) => match studio.relief(&a.relief) {
                Ok(m) => relief_packet(&m),
                Err(f) => failed(f),
            },
            Err(r) => r,
        },
        (Method::Post, "/api/job") => match ask(rq) {
            Ok(a) => match studio.job(&a.relief, &a.cut) {
                Ok(j) => job_packet(&j),
                Err(f) => failed(f),
            },
            Err(r) => r,
        },
        (Method::Get, p) if p.starts_with("/api/download/") => {
            download(studio, &p["/api/download/".len()..])
        }
        (Method::Get, _) | (Method::Post, _) => Reply::error(404, format!("no such page: {path}")),
        (m, _) => Reply::error(405, format!("{m} is not served")),
    }
}

/// The secret in the request's header, or (for a WebSocket, which a page
/// cannot give headers) its `secret` query parameter.
fn has_secret(rq: &Request, url: &str, studio: &Studio) -> bool {
    header_of(rq, SECRET_HEADER) == Some(studio.secret.as_str())
        || query(url, "secret").as_deref() == Some(studio.secret.as_str())
}

/// The Machine panel's live readout: a WebSocket (RFC 6455 handshake
/// here, frames by tungstenite) for this studio's own page only.
fn live(rq: Request, studio: &Studio) {
    let url = rq.url().to_string();
    if !has_secret(&rq, &url, studio) {
        return send(
            rq,
            Reply::error(403, "refused: the request lacks this studio's secret"),
        );
    }
    let Some(key) = header_of(&rq, "Sec-WebSocket-Key").map(str::to_string) else {
        return send(rq, Reply::error(400, "a WebSocket, please"));
    };
    let accept = tungstenite::handshake::derive_accept_key(key.as_bytes());
    let resp = Response::empty(101).with_header(header("Sec-WebSocket-Accept", &accept));
    let ws = rq.upgrade("websocket", resp);
    machine::live(ws, studio);
}

fn model_info(studio: &Studio) -> Value {
    let m = studio.model();
    json!({
        "name": m.name.clone().unwrap_or_else(|| "demo scene".into()),
        "demo": m.name.is_none(),
        "version": m.version,
        "objects": m.mesh.as_ref().map(|x| x.objects.clone()).unwrap_or_default(),
        "triangles": m.mesh.as_ref().map_or(0, |x| x.triangles.len()),
        "picture": m.mesh.is_none(),
    })
}

/// The model's triangles for the page's 3D view.
fn mesh(studio: &Studio) -> Reply {
    let m = studio.model();
    let Some(mesh) = &m.mesh else {
        return Reply::error(404, "a picture has no 3D view");
    };
    let pos: Vec<f32> = mesh.positions.iter().flat_map(|p| p.to_array()).collect();
    let idx: Vec<u32> = mesh.triangles.iter().flatten().copied().collect();
    Reply::binary(
        Packet::new(json!({"version": m.version}))
            .f32("positions", &pos)
            .u32("triangles", &idx)
            .bytes(),
    )
}

fn relief_packet(m: &super::work::Made) -> Reply {
    let r = &m.relief;
    let view = shrink(&r.heights, VIEW_MAX, mean);
    Reply::binary(
        Packet::new(json!({
            "w": view.w,
            "h": view.h,
            "pixels": [r.heights.w, r.heights.h],
            "width_mm": r.width_mm,
            "height_mm": r.height_mm,
            "depth_mm": r.depth_mm,
            "warnings": m.warnings,
            "command": m.command,
            "timings": m.timings.report(),
        }))
        .f32("heights", &view.data)
        .bytes(),
    )
}

fn job_packet(j: &super::work::JobMade) -> Reply {
    let s = &j.summary;
    let rep = &j.sim.report;
    let st = j.sim.stock;
    let cut = shrink(&j.sim.cut, VIEW_MAX, mean);
    // residual as its mean over a stepover: no beat of scallops and cells
    let dev = shrink(
        &crate::sim::map::smoothed(&j.sim.deviation, s.stepover_mm / st.pitch),
        VIEW_MAX,
        extreme,
    );
    // moves as pairs of points (x, y, z, 0 = rapid / 1 = feed)
    let segs = &j.program.segments;
    let stride = segs.len().div_ceil(MAX_DRAWN_MOVES).max(1);
    let mut moves = Vec::with_capacity(segs.len() / stride * 8);
    for g in segs.iter().step_by(stride) {
        let k = matches!(g.kind, crate::gcode::Kind::Feed) as u8 as f32;
        for p in [g.a, g.b] {
            moves.extend([p.x as f32, p.y as f32, p.z as f32, k]);
        }
    }
    let relief = &j.relief.relief;
    Reply::binary(
        Packet::new(json!({
            "lines": s.lines,
            "time": s.time_text(),
            "time_s": s.time_s,
            "gouge_mm": rep.max_gouge_mm,
            "residual_mm": [rep.max_residual_mm, rep.mean_residual_mm],
            "between_cells_mm": rep.between_cells_mm,
            "gouge_exact_per_move": rep.gouge_exact_per_move,
            "rapids_in_stock": rep.rapids_in_stock.len(),
            "out_of_travel": rep.out_of_travel.len(),
            "engagement": s.engagement.summary(),
            "notes": s.notes,
            "rapid_m": s.rapid_mm / 1000.0,
            "cut_m": s.cut_mm / 1000.0,
            "stepover_mm": s.stepover_mm,
            "stock": {"x0": st.x0, "y0": st.y0, "width": st.width, "height": st.height,
                      "thickness": st.thickness},
            "panel": {"x0": j.sim.panel_at.0, "y0": j.sim.panel_at.1,
                      "width": relief.width_mm, "height": relief.height_mm, "depth": relief.depth_mm},
            "cells": [cut.w, cut.h],
            "stock_cells": [j.sim.cut.w, j.sim.cut.h],
            "cell_mm": rep.cell_mm,
            "moves_drawn": moves.len() / 8,
            "moves": segs.len(),
            "command": j.command,
        }))
        .f32("cut", &cut.data)
        .f32("deviation", &dev.data)
        .f32("moves", &moves)
        .bytes(),
    )
}

fn download(studio: &Studio, what: &str) -> Reply {
    let none = |w: &str| Reply::error(404, format!("no {w} made yet"));
    match what {
        "relief.png" | "relief.json" | "relief.stl" => {
            let Some(m) = studio.last_relief() else {
                return none("relief");
            };
            match what {
                "relief.png" => Reply::file("image/png", what, m.files().0),
                "relief.json" => Reply::file("application/json", what, m.files().1),
                _ => {
                    let mut b = Vec::new();
                    match crate::export::write_stl(&m.relief, m.job.base_mm, &mut b) {
                        Ok(()) => Reply::file("model/stl", what, b),
                        Err(e) => Reply::error(500, format!("STL: {e}")),
                    }
                }
            }
        }
        "job.nc" | "job.svg" => {
            let Some(j) = studio.last_job() else {
                return none("job");
            };
            let kind = if what == "job.nc" {
                "text/plain"
            } else {
                "image/svg+xml"
            };
            match std::fs::read(j.dir.join(what)) {
                Ok(b) => Reply::file(kind, what, b),
                Err(e) => Reply::error(500, format!("{what}: {e}")),
            }
        }
        _ => Reply::error(404, format!("no such download: {what}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn queries_decode() {
        assert_eq!(
            query("/api/model?x=1&name=my%20tea+pot.obj", "name").as_deref(),
            Some("my tea pot.obj")
        );
        assert_eq!(query("/api/model?name=a%2", "name").as_deref(), Some("a%2"));
        assert_eq!(query("/api/model", "name"), None);
    }

    #[test]
    fn only_this_machine_s_names_are_answered() {
        let at: SocketAddr = "127.0.0.1:7171".parse().unwrap();
        for ok in [
            "127.0.0.1:7171",
            "localhost:7171",
            "LOCALHOST:7171",
            "[::1]:7171",
            "127.0.0.2:7171",
        ] {
            assert!(names_us(ok, at), "{ok}");
        }
        for bad in [
            "evil.example:7171",
            "127.0.0.1.nip.io:7171",
            "127.0.0.1:80",
            "127.0.0.1",
            "192.168.1.5:7171",
            "",
            "[::1]",
        ] {
            assert!(!names_us(bad, at), "{bad}");
        }
        // listening on every address: any IP literal, never a DNS name
        let all: SocketAddr = "0.0.0.0:8080".parse().unwrap();
        assert!(names_us("192.168.1.5:8080", all) && names_us("localhost:8080", all));
        assert!(!names_us("studio.example:8080", all));
        let lan: SocketAddr = "192.168.1.5:8080".parse().unwrap();
        assert!(names_us("192.168.1.5:8080", lan) && !names_us("10.0.0.1:8080", lan));
    }
}
