//! Triangle meshes from OBJ (tobj) and STL (stl_io), checked before use:
//! a mesh that reaches the rasterizer has finite vertices, in-range indices
//! and at least one triangle.

use crate::bail;
use crate::error::{Context, Result};
use glam::{Mat4, Vec3};
use std::io::{BufRead, Read};
use std::path::Path;

/// A triangle soup with object names kept (for selective scaling).
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    pub positions: Vec<Vec3>,
    pub triangles: Vec<[u32; 3]>,
    /// Index into `objects` for each triangle.
    pub tri_object: Vec<u16>,
    pub objects: Vec<String>,
    /// Normals from the file (OBJ `vn`) and, per triangle, the normal of
    /// each corner; empty when the file has none for some triangle.
    pub normals: Vec<Vec3>,
    pub normal_tris: Vec<[u32; 3]>,
}

impl Mesh {
    /// Append another mesh transformed by `m`, keeping its object names.
    pub fn append(&mut self, other: &Mesh, m: Mat4) {
        let base = self.positions.len() as u32;
        let obase = self.objects.len() as u16;
        self.positions
            .extend(other.positions.iter().map(|p| m.transform_point3(*p)));
        self.triangles
            .extend(other.triangles.iter().map(|t| t.map(|i| i + base)));
        self.tri_object
            .extend(other.tri_object.iter().map(|o| o + obase));
        self.objects.extend(other.objects.iter().cloned());
        // file normals would not cover both parts: computed ones serve
        self.normals.clear();
        self.normal_tris.clear();
    }

    /// Add one named object from raw parts.
    pub fn push_object(&mut self, name: &str, positions: &[Vec3], triangles: &[[u32; 3]]) {
        let base = self.positions.len() as u32;
        let id = self.objects.len() as u16;
        self.objects.push(name.to_string());
        self.positions.extend_from_slice(positions);
        self.triangles
            .extend(triangles.iter().map(|t| t.map(|i| i + base)));
        self.tri_object
            .extend(std::iter::repeat_n(id, triangles.len()));
    }

    /// A normal per triangle corner for smooth shading: the file's own
    /// normals where it has them, else the area-weighted mean of the faces
    /// around the vertex (vertices welded by position) that lie within
    /// `crease_deg` of the corner's face, so real creases stay sharp.
    pub fn corner_normals(&self, crease_deg: f64) -> Vec<[Vec3; 3]> {
        if !self.normal_tris.is_empty() && self.normal_tris.len() == self.triangles.len() {
            return self
                .normal_tris
                .iter()
                .map(|t| t.map(|i| self.normals[i as usize]))
                .collect();
        }
        use rayon::prelude::*;
        // weld by exact position (seams of patches, and an STL's triangle
        // soup, share no indices): each vertex maps to the first one at
        // its place, found by sorting (position, index)
        let key = |i: usize| self.positions[i].to_array().map(f32::to_bits);
        let mut order: Vec<u32> = (0..self.positions.len() as u32).collect();
        order.par_sort_unstable_by_key(|&i| (key(i as usize), i));
        let mut weld = vec![0u32; self.positions.len()];
        let mut first = 0;
        for (k, &i) in order.iter().enumerate() {
            if k == 0 || key(i as usize) != key(order[k - 1] as usize) {
                first = i;
            }
            weld[i as usize] = first;
        }
        let face: Vec<Vec3> = self
            .triangles
            .par_iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.positions[i as usize]);
                (b - a).cross(c - a)
            })
            .collect();
        let unit: Vec<Vec3> = face.par_iter().map(|f| f.normalize_or_zero()).collect();
        // the faces around each welded vertex, in face order (compressed
        // rows: `start[v]..start[v + 1]` of `around`)
        let mut start = vec![0u32; self.positions.len() + 1];
        for t in &self.triangles {
            for &i in t {
                start[weld[i as usize] as usize + 1] += 1;
            }
        }
        for v in 1..start.len() {
            start[v] += start[v - 1];
        }
        let mut fill = start.clone();
        let mut around = vec![0u32; 3 * self.triangles.len()];
        for (f, t) in self.triangles.iter().enumerate() {
            for &i in t {
                let v = weld[i as usize] as usize;
                around[fill[v] as usize] = f as u32;
                fill[v] += 1;
            }
        }
        let cos = crease_deg.to_radians().cos() as f32;
        self.triangles
            .par_iter()
            .enumerate()
            .map(|(f, t)| {
                let own = unit[f];
                t.map(|i| {
                    let v = weld[i as usize] as usize;
                    let n: Vec3 = around[start[v] as usize..start[v + 1] as usize]
                        .iter()
                        .filter(|&&g| unit[g as usize].dot(own) >= cos)
                        .map(|&g| face[g as usize])
                        .sum();
                    n.normalize_or(own)
                })
            })
            .collect()
    }

    /// Axis-aligned bounds of the vertices that triangles use.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        for t in &self.triangles {
            for &i in t {
                let p = self.positions[i as usize];
                lo = lo.min(p);
                hi = hi.max(p);
            }
        }
        (lo, hi)
    }

    /// Reject what would break later stages, naming `what`.
    pub fn validate(&self, what: &str) -> Result<()> {
        if self.triangles.is_empty() {
            bail!("{what}: the model has no triangles (empty scene)");
        }
        let n = self.positions.len() as u32;
        for (k, t) in self.triangles.iter().enumerate() {
            if let Some(&i) = t.iter().find(|&&i| i >= n) {
                bail!(
                    "{what}: triangle {} refers to vertex {} but there are only {n}",
                    k + 1,
                    i + 1
                );
            }
        }
        if let Some(k) = self.positions.iter().position(|p| !p.is_finite()) {
            bail!(
                "{what}: vertex {} has a coordinate that is not a finite number",
                k + 1
            );
        }
        let (lo, hi) = self.bounds();
        if (hi - lo).max_element() <= 0.0 {
            bail!("{what}: all triangles collapse to one point");
        }
        if (hi - lo).max_element() > 1e15 {
            bail!(
                "{what}: the model is absurdly large ({})",
                (hi - lo).max_element()
            );
        }
        if self.objects.len() > u16::MAX as usize - 1 {
            bail!("{what}: more than {} objects", u16::MAX - 1);
        }
        Ok(())
    }
}

/// Most triangles a model may have: about 4 GB of memory at 250 bytes
/// each, loaded in about 13 s (6 million: 1.1 GB, 4.1 s for a 512 px relief).
pub const MAX_TRIANGLES: usize = 16_000_000;

fn check_triangles(n: usize, what: &str) -> Result<()> {
    if n > MAX_TRIANGLES {
        bail!(
            "{what}: {:.1} million triangles, more than the {:.0} million taken; \
             decimate the model (a relief at 16384 px needs no more than 2 per pixel)",
            n as f64 / 1e6,
            MAX_TRIANGLES as f64 / 1e6
        );
    }
    Ok(())
}

/// Load an OBJ or STL file, chosen by extension.
pub fn load(path: &Path) -> Result<Mesh> {
    let what = path.display().to_string();
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let mesh = match ext.as_str() {
        "obj" => {
            let bytes = crate::input::read(path, crate::input::MAX_FILE)?;
            read_obj(&mut std::io::Cursor::new(bytes), &what)?
        }
        "stl" => read_stl(&crate::input::read(path, crate::input::MAX_FILE)?, &what)?,
        _ => bail!("{what}: unknown model format '.{ext}' (expected .obj, .stl or .png)"),
    };
    mesh.validate(&what)?;
    Ok(mesh)
}

/// Parse OBJ text: every object and group becomes one named object.
pub fn read_obj(reader: &mut impl BufRead, what: &str) -> Result<Mesh> {
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        ..Default::default()
    };
    let (models, _materials) =
        tobj::load_obj_buf(reader, &opts, |_| Err(tobj::LoadError::OpenFileFailed)).ctx(what)?;
    check_triangles(models.iter().map(|m| m.mesh.indices.len() / 3).sum(), what)?;
    let mut mesh = Mesh::default();
    let mut all_normals = true;
    for m in &models {
        let p = &m.mesh.positions;
        let pos: Vec<Vec3> = p
            .chunks_exact(3)
            .map(|c| Vec3::new(c[0], c[1], c[2]))
            .collect();
        let tris: Vec<[u32; 3]> = m
            .mesh
            .indices
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect();
        if !tris.is_empty() {
            mesh.push_object(&m.name, &pos, &tris);
            all_normals &= m.mesh.normal_indices.len() == m.mesh.indices.len();
            let base = mesh.normals.len() as u32;
            mesh.normals.extend(
                m.mesh
                    .normals
                    .chunks_exact(3)
                    .map(|c| Vec3::new(c[0], c[1], c[2])),
            );
            mesh.normal_tris.extend(
                m.mesh
                    .normal_indices
                    .chunks_exact(3)
                    .map(|c| [c[0] + base, c[1] + base, c[2] + base]),
            );
        }
    }
    let n = mesh.normals.len() as u32;
    let usable = mesh.normal_tris.iter().flatten().all(|&i| i < n)
        && mesh.normals.iter().all(|v| v.is_finite());
    if !all_normals || !usable {
        mesh.normals.clear();
        mesh.normal_tris.clear();
    }
    Ok(mesh)
}

/// Parse ASCII or binary STL. The binary size is checked first so that a
/// garbage header cannot ask for billions of facets.
pub fn read_stl(bytes: &[u8], what: &str) -> Result<Mesh> {
    let ascii = bytes.trim_ascii_start().starts_with(b"solid")
        && bytes.iter().take(1024).all(|b| b.is_ascii());
    if !ascii {
        if bytes.len() < 84 {
            bail!("{what}: not an STL file (too short for a binary STL header)");
        }
        let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
        check_triangles(n, what)?;
        if 84 + 50 * n != bytes.len() {
            bail!(
                "{what}: not a valid binary STL ({} bytes, but the header announces {n} triangles = {} bytes)",
                bytes.len(),
                84 + 50 * n
            );
        }
    }
    let mut cur = std::io::Cursor::new(bytes);
    let m = stl_io::read_stl(&mut cur).ctx(what)?;
    let mut rest = Vec::new();
    cur.read_to_end(&mut rest).ok();
    check_triangles(m.faces.len(), what)?;
    let pos: Vec<Vec3> = m
        .vertices
        .iter()
        .map(|v| Vec3::new(v[0], v[1], v[2]))
        .collect();
    let tris: Vec<[u32; 3]> = m
        .faces
        .iter()
        .map(|f| f.vertices.map(|i| i as u32))
        .collect();
    let mut mesh = Mesh::default();
    let name = Path::new(what)
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("stl");
    mesh.push_object(name, &pos, &tris);
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn obj(text: &str) -> Result<Mesh> {
        let m = read_obj(&mut std::io::Cursor::new(text.as_bytes()), "t.obj")?;
        m.validate("t.obj")?;
        Ok(m)
    }

    #[test]
    fn obj_objects_and_groups_keep_names() {
        let m = obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\no a\nf 1 2 3\ng b\nf 2 4 3\n").unwrap();
        assert_eq!(m.objects, vec!["a", "b"]);
        assert_eq!(m.tri_object, vec![0, 1]);
    }

    #[test]
    fn obj_errors() {
        assert!(obj("").unwrap_err().0.contains("no triangles"));
        assert!(obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n").is_err());
        let e = obj("v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap_err();
        assert!(e.0.contains("finite"), "{e}");
    }

    #[test]
    fn stl_rejects_garbage_and_reads_binary() {
        assert!(read_stl(&[7u8; 300], "g.stl").is_err());
        let mut b = vec![0u8; 80];
        b.extend(1u32.to_le_bytes());
        for v in [
            0.0f32, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0,
        ] {
            b.extend(v.to_le_bytes());
        }
        b.extend([0u8, 0]);
        let m = read_stl(&b, "t.stl").unwrap();
        assert_eq!(m.triangles.len(), 1);
        m.validate("t.stl").unwrap();
    }
}
