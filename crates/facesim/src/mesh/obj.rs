//! Wavefront OBJ: `v x y z [r g b]` and `f a b c …` (with `a/t/n` forms, negative indices and
//! polygons fanned into triangles). Other statements are ignored.
//!
//! Read by hand rather than with tobj: tobj renumbers vertices in the order faces first use
//! them, drops unreferenced ones and stores f32, but docs/reference/case.md requires `face_pre` to keep the
//! file's vertices in the file's order, and predicted displacements are compared at the
//! micrometre level. The writer prints shortest-round-trip f64, so OBJ round trips exactly.

use super::surface::Mesh;
use crate::error::{Error, Result};
use crate::output::write_bytes_atomic;
use std::path::Path;

pub fn read(path: &Path) -> Result<Mesh> {
    let bytes = std::fs::read(path).map_err(|e| Error::input(path, e))?;
    let text = String::from_utf8(bytes)
        .map_err(|_| Error::input(path, "not a text OBJ file (invalid UTF-8)"))?;
    let mut mesh = Mesh::default();
    let mut colors: Vec<[u8; 3]> = Vec::new();
    let mut faces: Vec<(usize, Vec<i64>)> = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let lineno = n + 1;
        let mut w = line.split_whitespace();
        match w.next() {
            Some("v") => {
                let vals: Vec<f64> = w
                    .map(|x| x.parse::<f64>())
                    .collect::<std::result::Result<_, _>>()
                    .map_err(|_| {
                        Error::input(path, format!("line {lineno}: bad vertex '{line}'"))
                    })?;
                if vals.len() < 3 {
                    return Err(Error::input(
                        path,
                        format!("line {lineno}: a vertex needs x y z"),
                    ));
                }
                mesh.vertices.push([vals[0], vals[1], vals[2]]);
                if vals.len() >= 6 {
                    colors.push(
                        [vals[3], vals[4], vals[5]]
                            .map(|c| (c.clamp(0.0, 1.0) * 255.0).round() as u8),
                    );
                }
            }
            Some("f") => {
                let idx: Vec<i64> = w
                    .map(|x| x.split('/').next().unwrap_or("").parse::<i64>())
                    .collect::<std::result::Result<_, _>>()
                    .map_err(|_| Error::input(path, format!("line {lineno}: bad face '{line}'")))?;
                if idx.len() < 3 {
                    return Err(Error::input(
                        path,
                        format!("line {lineno}: a face needs 3 vertices"),
                    ));
                }
                faces.push((lineno, idx));
            }
            _ => {}
        }
    }
    let nv = mesh.vertices.len() as i64;
    for (lineno, idx) in faces {
        // OBJ indices are 1-based; negative ones count back from the end.
        let resolved: Vec<u32> = idx
            .iter()
            .map(|&i| {
                let r = if i > 0 { i - 1 } else { nv + i };
                if i == 0 || r < 0 || r >= nv {
                    Err(Error::input(
                        path,
                        format!(
                            "line {lineno}: face uses vertex index {i}, but there are {nv} vertices"
                        ),
                    ))
                } else {
                    Ok(r as u32)
                }
            })
            .collect::<Result<_>>()?;
        for k in 1..resolved.len() - 1 {
            mesh.triangles
                .push([resolved[0], resolved[k], resolved[k + 1]]);
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
            // `{}` on f64 prints the shortest string that parses back to the same number.
            match &mesh.colors {
                Some(c) => writeln!(
                    w,
                    "v {} {} {} {:.6} {:.6} {:.6}",
                    v[0],
                    v[1],
                    v[2],
                    c[i][0] as f64 / 255.0,
                    c[i][1] as f64 / 255.0,
                    c[i][2] as f64 / 255.0
                )?,
                None => writeln!(w, "v {} {} {}", v[0], v[1], v[2])?,
            }
        }
        for t in &mesh.triangles {
            writeln!(w, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1)?;
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_file_order_precision_and_colours() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("m.obj");
        std::fs::write(&p, "# x\nv 0.1 0.2 0.3 1 0 0\nv 1e-7 2 3 0 1 0\nv 5 6 7.000000000001 0 0 1\nv 9 9 9 0 0 0\nf 3/1/1 -4 2\n").unwrap();
        let m = read(&p).unwrap();
        assert_eq!(m.vertices[0], [0.1, 0.2, 0.3]);
        assert_eq!(m.vertices[2][2], 7.000000000001);
        assert_eq!(m.triangles, vec![[2, 0, 1]]);
        assert_eq!(m.colors.as_ref().unwrap()[1], [0, 255, 0]);
        let q = d.path().join("back.obj");
        write(&m, &q).unwrap();
        assert_eq!(read(&q).unwrap(), m);
    }
}
