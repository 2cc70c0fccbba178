//! Legacy VTK polygon meshes (`.vtk`: ASCII or BINARY, the 4.2 cell lists 3D Slicer writes and
//! 5.1's OFFSETS/CONNECTIVITY) with per-point data arrays; VTK XML PolyData is `vtp`. 3D Slicer
//! marks the frame in the legacy header line ("SPACE=LPS"); the writer here marks LPS.

use super::surface::Mesh;
use crate::error::{Error, Result};
use crate::output::write_bytes_atomic;
use std::path::Path;

/// A per-point array (`components` values per point, row-major).
#[derive(Clone, Debug, PartialEq)]
pub struct PointArray {
    pub name: String,
    pub components: usize,
    pub values: Vec<f64>,
}

/// Read a legacy `.vtk` POLYDATA file: the mesh (polygons fanned, strips split) and its header
/// line (where Slicer writes SPACE=).
pub fn read_legacy(path: &Path) -> Result<(Mesh, String)> {
    let bytes = std::fs::read(path).map_err(|e| Error::input(path, e))?;
    parse_legacy(&bytes).map_err(|m| Error::input(path, m))
}

struct Cursor<'a> {
    b: &'a [u8],
    i: usize,
}

impl<'a> Cursor<'a> {
    fn line(&mut self) -> std::result::Result<&'a str, String> {
        let start = self.i;
        while self.i < self.b.len() && self.b[self.i] != b'\n' {
            self.i += 1;
        }
        let l = &self.b[start..self.i];
        self.i = (self.i + 1).min(self.b.len());
        std::str::from_utf8(l)
            .map(|s| s.trim_end_matches('\r'))
            .map_err(|_| "header is not text".to_string())
    }
    fn skip_line(&mut self) {
        while self.i < self.b.len() && self.b[self.i] != b'\n' {
            self.i += 1;
        }
        self.i = (self.i + 1).min(self.b.len());
    }
    fn word(&mut self) -> Option<&'a str> {
        while self.i < self.b.len() && self.b[self.i].is_ascii_whitespace() {
            self.i += 1;
        }
        let start = self.i;
        while self.i < self.b.len() && !self.b[self.i].is_ascii_whitespace() {
            self.i += 1;
        }
        (self.i > start)
            .then(|| std::str::from_utf8(&self.b[start..self.i]).ok())
            .flatten()
    }
    fn usize(&mut self, what: &str) -> std::result::Result<usize, String> {
        self.word()
            .and_then(|w| w.parse().ok())
            .ok_or_else(|| format!("{what}: expected a count"))
    }
    /// `n` numbers of VTK type `ty`, ASCII or big-endian binary.
    fn numbers(
        &mut self,
        n: usize,
        ty: &str,
        binary: bool,
    ) -> std::result::Result<Vec<f64>, String> {
        if !binary {
            return (0..n)
                .map(|_| {
                    self.word()
                        .and_then(|w| w.parse::<f64>().ok())
                        .ok_or_else(|| format!("expected {n} numbers of type {ty}"))
                })
                .collect();
        }
        // Binary data starts after the keyword line's newline.
        while self.i < self.b.len() && self.b[self.i] != b'\n' {
            self.i += 1;
        }
        self.i += 1;
        let size = match ty {
            "float" | "int" | "unsigned_int" => 4,
            "double" | "long" | "vtktypeint64" | "vtkIdType" | "unsigned_long" => 8,
            _ => return Err(format!("data type '{ty}' not supported")),
        };
        let end = self.i + n * size;
        let d = self
            .b
            .get(self.i..end)
            .ok_or("binary data shorter than its count")?;
        self.i = end;
        Ok(d.chunks_exact(size)
            .map(|c| match (ty, size) {
                ("float", _) => f32::from_be_bytes([c[0], c[1], c[2], c[3]]) as f64,
                ("int", _) => i32::from_be_bytes([c[0], c[1], c[2], c[3]]) as f64,
                ("unsigned_int", _) => u32::from_be_bytes([c[0], c[1], c[2], c[3]]) as f64,
                ("double", _) => f64::from_be_bytes(c.try_into().unwrap_or([0; 8])),
                _ => i64::from_be_bytes(c.try_into().unwrap_or([0; 8])) as f64,
            })
            .collect())
    }
}

fn parse_legacy(b: &[u8]) -> std::result::Result<(Mesh, String), String> {
    let mut c = Cursor { b, i: 0 };
    if !c.line()?.starts_with("# vtk DataFile") {
        return Err("not a legacy VTK file (no '# vtk DataFile' line)".into());
    }
    let header = c.line()?.to_string();
    let binary = match c.line()?.trim() {
        "ASCII" => false,
        "BINARY" => true,
        other => return Err(format!("'{other}': expected ASCII or BINARY")),
    };
    let mut mesh = Mesh::default();
    let mut seen_dataset = false;
    while let Some(kw) = c.word() {
        match kw {
            "DATASET" => {
                let t = c.word().unwrap_or_default();
                if t != "POLYDATA" {
                    return Err(format!("DATASET {t}: a surface model must be POLYDATA"));
                }
                seen_dataset = true;
            }
            "POINTS" => {
                let n = c.usize("POINTS")?;
                let ty = c.word().unwrap_or_default();
                let v = c.numbers(3 * n, ty, binary)?;
                mesh.vertices = v.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
            }
            "POLYGONS" | "TRIANGLE_STRIPS" | "VERTICES" | "LINES" => {
                let a = c.usize(kw)?;
                let size = c.usize(kw)?;
                // 5.1 files: OFFSETS then CONNECTIVITY; 4.2: one list "n i0 i1 …".
                let save = c.i;
                let cells: Vec<Vec<usize>> = if c.word() == Some("OFFSETS") {
                    let ty = c.word().unwrap_or_default().to_string();
                    let off = c.numbers(a, &ty, binary)?;
                    if c.word() != Some("CONNECTIVITY") {
                        return Err(format!("{kw}: OFFSETS without CONNECTIVITY"));
                    }
                    let ty = c.word().unwrap_or_default().to_string();
                    let con = c.numbers(size, &ty, binary)?;
                    off.windows(2)
                        .map(|w| {
                            con.get(w[0] as usize..w[1] as usize)
                                .map(|s| s.iter().map(|x| *x as usize).collect())
                                .ok_or_else(|| format!("{kw}: offsets out of range"))
                        })
                        .collect::<std::result::Result<_, _>>()?
                } else {
                    c.i = save;
                    let list = c.numbers(size, "int", binary)?;
                    let mut cells = Vec::with_capacity(a);
                    let mut k = 0;
                    for _ in 0..a {
                        let n = *list.get(k).ok_or(format!("{kw}: list too short"))? as usize;
                        let ids = list
                            .get(k + 1..k + 1 + n)
                            .ok_or(format!("{kw}: list too short"))?;
                        cells.push(ids.iter().map(|x| *x as usize).collect());
                        k += 1 + n;
                    }
                    cells
                };
                for ids in cells {
                    let ok = ids.iter().all(|i| *i < u32::MAX as usize);
                    if !ok {
                        return Err(format!("{kw}: index out of range"));
                    }
                    let ids: Vec<u32> = ids.iter().map(|i| *i as u32).collect();
                    match kw {
                        "POLYGONS" => {
                            for k in 1..ids.len().saturating_sub(1) {
                                mesh.triangles.push([ids[0], ids[k], ids[k + 1]]);
                            }
                        }
                        "TRIANGLE_STRIPS" => {
                            for k in 0..ids.len().saturating_sub(2) {
                                let t = if k % 2 == 0 {
                                    [ids[k], ids[k + 1], ids[k + 2]]
                                } else {
                                    [ids[k + 1], ids[k], ids[k + 2]]
                                };
                                mesh.triangles.push(t);
                            }
                        }
                        _ => {}
                    }
                }
            }
            // The data set's field data (VTK 9 writes it before POINTS): skipped.
            "FIELD" => skip_field(&mut c, binary)?,
            // Array metadata (VTK 9 writes it after an array): up to the next empty line.
            "METADATA" => {
                c.line()?;
                while !c.line()?.trim().is_empty() {}
            }
            // Point and cell data are not needed to build a surface: stop here.
            "POINT_DATA" | "CELL_DATA" => break,
            other => return Err(format!("unexpected keyword '{other}'")),
        }
    }
    if !seen_dataset {
        return Err("no DATASET POLYDATA".into());
    }
    let n = mesh.vertices.len();
    if mesh.triangles.iter().flatten().any(|i| *i as usize >= n) {
        return Err("a cell refers to a point beyond POINTS".into());
    }
    Ok((mesh, header))
}

/// A 3-component point array for [`crate::mesh::two_triangles`]: the file-format tests' data.
#[cfg(test)]
pub(crate) fn test_displacement() -> PointArray {
    PointArray {
        name: "displacement_mm".into(),
        components: 3,
        values: (0..12).map(|i| i as f64 * 0.1).collect(),
    }
}

/// Pass over a FIELD block (after its keyword): `name n`, then per array `name components
/// tuples type` and its values (strings one per line).
fn skip_field(c: &mut Cursor, binary: bool) -> std::result::Result<(), String> {
    c.word().ok_or("FIELD without a name")?;
    let arrays = c.usize("FIELD")?;
    for _ in 0..arrays {
        let name = c.word().ok_or("FIELD: array name missing")?.to_string();
        let n = c.usize(&name)? * c.usize(&name)?;
        let ty = c.word().ok_or("FIELD: array type missing")?;
        if ty == "string" {
            // One per line; in a BINARY file each begins with a length byte (not text).
            for _ in 0..=n {
                c.skip_line();
            }
        } else {
            c.numbers(n, ty, binary)?;
        }
        // VTK 9 follows an array with its METADATA block.
        let save = c.i;
        if c.word() == Some("METADATA") {
            c.line()?;
            while !c.line()?.trim().is_empty() {}
        } else {
            c.i = save;
        }
    }
    Ok(())
}

/// Legacy ASCII `.vtk` POLYDATA with point data, header line marking LPS.
pub fn write_legacy(mesh: &Mesh, arrays: &[PointArray], path: &Path) -> Result<()> {
    write_bytes_atomic(path, |w| {
        writeln!(w, "# vtk DataFile Version 4.2")?;
        writeln!(w, "facesim output. SPACE=LPS")?;
        writeln!(w, "ASCII\nDATASET POLYDATA")?;
        writeln!(w, "POINTS {} double", mesh.vertices.len())?;
        for v in &mesh.vertices {
            writeln!(w, "{} {} {}", v[0], v[1], v[2])?;
        }
        let n = mesh.triangles.len();
        writeln!(w, "POLYGONS {n} {}", 4 * n)?;
        for t in &mesh.triangles {
            writeln!(w, "3 {} {} {}", t[0], t[1], t[2])?;
        }
        if !arrays.is_empty() {
            writeln!(w, "POINT_DATA {}", mesh.vertices.len())?;
            for a in arrays {
                writeln!(w, "SCALARS {} double {}", a.name, a.components)?;
                writeln!(w, "LOOKUP_TABLE default")?;
                for row in a.values.chunks(a.components.max(1)) {
                    let s: Vec<String> = row.iter().map(|x| x.to_string()).collect();
                    writeln!(w, "{}", s.join(" "))?;
                }
            }
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::two_triangles;

    #[test]
    fn legacy_round_trip_with_point_data() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("m.vtk");
        write_legacy(&two_triangles(), &[test_displacement()], &p).unwrap();
        let (m, h) = read_legacy(&p).unwrap();
        assert!(h.contains("SPACE=LPS"));
        assert_eq!(m.vertices, two_triangles().vertices);
        assert_eq!(m.triangles, two_triangles().triangles);
    }

    #[test]
    fn legacy_binary_and_5_1_cells() {
        // BINARY 4.2: big-endian floats and ints, a quad fanned into two triangles.
        let mut b = b"# vtk DataFile Version 4.2\n3D Slicer output. SPACE=RAS\nBINARY\nDATASET POLYDATA\nPOINTS 4 float\n".to_vec();
        for v in [0.0f32, 0., 0., 1., 0., 0., 1., 1., 0., 0., 1., 0.] {
            b.extend(v.to_be_bytes());
        }
        b.extend(b"\nPOLYGONS 1 5\n");
        for v in [4i32, 0, 1, 2, 3] {
            b.extend(v.to_be_bytes());
        }
        b.extend(b"\n");
        let (m, h) = parse_legacy(&b).unwrap();
        assert!(h.contains("SPACE=RAS"));
        assert_eq!(m.vertices[2], [1.0, 1.0, 0.0]);
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        let t = "# vtk DataFile Version 5.1\nx\nASCII\nDATASET POLYDATA\nPOINTS 3 double\n0 0 0 1 0 0 0 1 0\nPOLYGONS 2 3\nOFFSETS vtktypeint64\n0 3\nCONNECTIVITY vtktypeint64\n0 1 2\n";
        let (m, _) = parse_legacy(t.as_bytes()).unwrap();
        assert_eq!(m.triangles, vec![[0, 1, 2]]);
        let bad = "# vtk DataFile Version 4.2\nx\nASCII\nDATASET POLYDATA\nPOINTS 1 double\n0 0 0\nPOLYGONS 1 4\n3 0 1 2\n";
        assert!(parse_legacy(bad.as_bytes()).unwrap_err().contains("beyond"));
    }
}
