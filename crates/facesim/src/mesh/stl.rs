//! STL, ASCII and binary. Corners are stored per triangle; they are merged into shared vertices
//! when exactly equal (as every STL writer repeats them). The header (binary) or `solid` line
//! (ASCII) is returned: 3D Slicer writes its frame there ("SPACE=RAS" or "SPACE=LPS").

use super::surface::Mesh;
use crate::error::{Error, Result};
use crate::output::write_bytes_atomic;
use std::collections::HashMap;
use std::path::Path;

/// The mesh and the header text.
pub fn read(path: &Path) -> Result<(Mesh, String)> {
    let bytes = std::fs::read(path).map_err(|e| Error::input(path, e))?;
    // Binary: 80-byte header, u32 count, 50 bytes per triangle. ASCII files also start with
    // "solid", so the size decides.
    if bytes.len() >= 84 {
        let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
        if bytes.len() == 84 + 50 * n {
            return Ok(read_binary(&bytes, n));
        }
    }
    let text = std::str::from_utf8(&bytes).map_err(|_| {
        Error::input(
            path,
            "not an STL file (neither binary of the right size nor ASCII)",
        )
    })?;
    read_ascii(text).map_err(|m| Error::input(path, m))
}

fn read_binary(bytes: &[u8], n: usize) -> (Mesh, String) {
    let header = String::from_utf8_lossy(&bytes[..80])
        .trim_end_matches('\0')
        .to_string();
    let mut w = Welder::default();
    for t in 0..n {
        let rec = &bytes[84 + 50 * t..84 + 50 * (t + 1)];
        let f = |k: usize| {
            f32::from_le_bytes([rec[4 * k], rec[4 * k + 1], rec[4 * k + 2], rec[4 * k + 3]]) as f64
        };
        // 12 bytes of normal, then 3 corners.
        let tri = [0, 1, 2].map(|c| w.index([f(3 + 3 * c), f(4 + 3 * c), f(5 + 3 * c)]));
        w.mesh.triangles.push(tri);
    }
    (w.mesh, header)
}

fn read_ascii(text: &str) -> std::result::Result<(Mesh, String), String> {
    let header = text.lines().next().unwrap_or_default().trim().to_string();
    if !header.starts_with("solid") {
        return Err("not an STL file (no 'solid' line)".into());
    }
    let mut w = Welder::default();
    let mut corners: Vec<u32> = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("vertex") => {
                let v: Vec<f64> = it.filter_map(|x| x.parse().ok()).collect();
                if v.len() != 3 || v.iter().any(|x| !x.is_finite()) {
                    return Err(format!("line {}: bad vertex '{}'", n + 1, line.trim()));
                }
                corners.push(w.index([v[0], v[1], v[2]]));
            }
            Some("endloop") => {
                // Polygons (rare in STL) are fanned.
                for k in 1..corners.len().saturating_sub(1) {
                    w.mesh
                        .triangles
                        .push([corners[0], corners[k], corners[k + 1]]);
                }
                corners.clear();
            }
            _ => {}
        }
    }
    Ok((w.mesh, header))
}

#[derive(Default)]
struct Welder {
    mesh: Mesh,
    index: HashMap<[u64; 3], u32>,
}

impl Welder {
    fn index(&mut self, p: [f64; 3]) -> u32 {
        let mesh = &mut self.mesh;
        *self
            .index
            .entry(p.map(|c| (c + 0.0).to_bits()))
            .or_insert_with(|| {
                mesh.vertices.push(p);
                (mesh.vertices.len() - 1) as u32
            })
    }
}

/// Binary STL (f32, as the format has it) with `header` (at most 80 bytes kept).
pub fn write(mesh: &Mesh, path: &Path, header: &str) -> Result<()> {
    write_bytes_atomic(path, |w| {
        let mut h = [0u8; 80];
        let hb = header.as_bytes();
        h[..hb.len().min(80)].copy_from_slice(&hb[..hb.len().min(80)]);
        w.write_all(&h)?;
        w.write_all(&(mesh.triangles.len() as u32).to_le_bytes())?;
        for t in &mesh.triangles {
            let p = t.map(|v| mesh.vertices[v as usize]);
            let n = crate::vec3::cross(crate::vec3::sub(p[1], p[0]), crate::vec3::sub(p[2], p[0]));
            let l = crate::vec3::norm(n);
            let n = if l > 0.0 { n.map(|c| c / l) } else { n };
            for c in n.iter().chain(p.iter().flatten()) {
                w.write_all(&(*c as f32).to_le_bytes())?;
            }
            w.write_all(&[0, 0])?;
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn binary_and_ascii_read_the_same_tetrahedron() {
        let dir = tempfile::tempdir().unwrap();
        let m = Mesh::new(
            vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
            ],
            vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]],
        );
        let bin = dir.path().join("t.stl");
        write(&m, &bin, "test SPACE=RAS").unwrap();
        let (b, h) = read(&bin).unwrap();
        assert_eq!(h, "test SPACE=RAS");
        assert_eq!(b.vertices.len(), 4);
        // Corners are merged in order of first use: compare triangles by their coordinates.
        let corners = |x: &Mesh| -> Vec<[[f64; 3]; 3]> {
            x.triangles
                .iter()
                .map(|t| t.map(|v| x.vertices[v as usize]))
                .collect()
        };
        assert_eq!(corners(&b), corners(&m));
        let mut text = String::from("solid x SPACE=LPS\n");
        for t in &m.triangles {
            text.push_str("facet normal 0 0 0\nouter loop\n");
            for v in t {
                let p = m.vertices[*v as usize];
                text.push_str(&format!("vertex {} {} {}\n", p[0], p[1], p[2]));
            }
            text.push_str("endloop\nendfacet\n");
        }
        text.push_str("endsolid x\n");
        let asc = dir.path().join("a.stl");
        std::fs::write(&asc, text).unwrap();
        let (a, h) = read(&asc).unwrap();
        assert!(h.contains("SPACE=LPS"));
        assert_eq!(a.vertices, b.vertices);
        assert_eq!(a.triangles, b.triangles);
    }
}
