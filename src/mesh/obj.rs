//! Wavefront OBJ through tobj (positions, faces, optional `v x y z r g b` colours).

use super::Mesh;
use crate::error::{Error, Result};
use crate::output::write_bytes_atomic;
use std::path::Path;

pub fn read(path: &Path) -> Result<Mesh> {
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        ignore_points: true,
        ignore_lines: true,
    };
    let (models, _) = tobj::load_obj(path, &opts)
        .map_err(|e| Error::input(path, format!("unreadable OBJ ({e})")))?;
    let mut mesh = Mesh::default();
    let mut colors = Vec::new();
    for m in &models {
        let base = mesh.vertices.len();
        let p = &m.mesh.positions;
        let nv = p.len() / 3;
        mesh.vertices
            .extend((0..nv).map(|i| [p[3 * i] as f64, p[3 * i + 1] as f64, p[3 * i + 2] as f64]));
        let c = &m.mesh.vertex_color;
        if c.len() == p.len() {
            colors.extend(
                (0..nv).map(|i| {
                    [0, 1, 2].map(|k| (c[3 * i + k].clamp(0.0, 1.0) * 255.0).round() as u8)
                }),
            );
        }
        for t in m.mesh.indices.chunks_exact(3) {
            if let Some(&bad) = t.iter().find(|&&i| i as usize >= nv) {
                return Err(Error::input(
                    path,
                    format!(
                        "face uses vertex index {}, but there are {nv} vertices",
                        bad + 1
                    ),
                ));
            }
            mesh.triangles
                .push([t[0], t[1], t[2]].map(|i| (i as usize + base) as u32));
        }
    }
    if !colors.is_empty() && colors.len() == mesh.vertices.len() {
        mesh.colors = Some(colors);
    }
    Ok(mesh)
}

pub fn write(mesh: &Mesh, path: &Path) -> Result<()> {
    write_bytes_atomic(path, |w| {
        writeln!(w, "# facesim: LPS frame, millimetres")?;
        for (i, v) in mesh.vertices.iter().enumerate() {
            // 17 significant digits: OBJ round trips bit-exactly.
            match &mesh.colors {
                Some(c) => writeln!(
                    w,
                    "v {:e} {:e} {:e} {:.6} {:.6} {:.6}",
                    v[0],
                    v[1],
                    v[2],
                    c[i][0] as f64 / 255.0,
                    c[i][1] as f64 / 255.0,
                    c[i][2] as f64 / 255.0
                )?,
                None => writeln!(w, "v {:e} {:e} {:e}", v[0], v[1], v[2])?,
            }
        }
        for t in &mesh.triangles {
            writeln!(w, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1)?;
        }
        Ok(())
    })
}
