//! PLY (ascii, binary little- and big-endian) through ply-rs-bw, with vertex colours, extra
//! per-vertex scalar properties and an optional `edge` element with its own properties.

use super::surface::{Column, Edges, Mesh};
use crate::error::{Error, Result};
use crate::output::write_bytes_atomic;
use ply_rs_bw::parser::Parser;
use ply_rs_bw::ply::{
    Addable, DefaultElement, ElementDef, Ply, Property, PropertyDef, PropertyType, ScalarType,
};
use ply_rs_bw::writer::Writer;
use std::path::Path;

pub use ply_rs_bw::ply::Encoding;

fn scalar(p: &Property) -> Option<f64> {
    Some(match *p {
        Property::Char(v) => v as f64,
        Property::UChar(v) => v as f64,
        Property::Short(v) => v as f64,
        Property::UShort(v) => v as f64,
        Property::Int(v) => v as f64,
        Property::UInt(v) => v as f64,
        Property::Float(v) => v as f64,
        Property::Double(v) => v,
        _ => return None,
    })
}

fn index_list(p: &Property) -> Option<Vec<i64>> {
    Some(match p {
        Property::ListChar(v) => v.iter().map(|&x| x as i64).collect(),
        Property::ListUChar(v) => v.iter().map(|&x| x as i64).collect(),
        Property::ListShort(v) => v.iter().map(|&x| x as i64).collect(),
        Property::ListUShort(v) => v.iter().map(|&x| x as i64).collect(),
        Property::ListInt(v) => v.iter().map(|&x| x as i64).collect(),
        Property::ListUInt(v) => v.iter().map(|&x| x as i64).collect(),
        _ => return None,
    })
}

/// Refuse headers that promise more elements than the file has bytes (each element needs at
/// least one byte), before the parser allocates for them.
fn check_counts(path: &Path, bytes: &[u8]) -> Result<()> {
    let end = bytes
        .windows(10)
        .position(|w| w == b"end_header")
        .ok_or_else(|| Error::input(path, "not a PLY file (no end_header)"))?;
    if !bytes.starts_with(b"ply") {
        return Err(Error::input(path, "not a PLY file (missing 'ply' magic)"));
    }
    let header = String::from_utf8_lossy(&bytes[..end]);
    let mut total: u128 = 0;
    for line in header.lines() {
        let w: Vec<&str> = line.split_whitespace().collect();
        if w.len() == 3 && w[0] == "element" {
            let n: u128 = w[2]
                .parse()
                .map_err(|_| Error::input(path, format!("bad element count in '{line}'")))?;
            total += n;
        }
    }
    if total > bytes.len() as u128 {
        return Err(Error::input(
            path,
            format!(
                "header declares {total} elements but the file has only {} bytes (truncated?)",
                bytes.len()
            ),
        ));
    }
    Ok(())
}

pub fn read(path: &Path) -> Result<Mesh> {
    let bytes = std::fs::read(path).map_err(|e| Error::input(path, e))?;
    check_counts(path, &bytes)?;
    let parser = Parser::<DefaultElement>::new();
    let ply = parser
        .read_ply(&mut bytes.as_slice())
        .map_err(|e| Error::input(path, format!("unreadable PLY ({e})")))?;
    let verts = ply
        .payload
        .get("vertex")
        .ok_or_else(|| Error::input(path, "no vertex element"))?;
    let mut mesh = Mesh::default();
    read_vertices(path, verts, &mut mesh)?;
    if let Some(faces) = ply.payload.get("face") {
        mesh.triangles = read_faces(path, faces, mesh.vertices.len())?;
    }
    if let Some(edges) = ply.payload.get("edge") {
        mesh.edges = Some(read_edges(path, edges, mesh.vertices.len())?);
    }
    Ok(mesh)
}

/// Positions, colours (when the first vertex has red, green and blue) and every other scalar
/// property of the first vertex as a column.
fn read_vertices(path: &Path, verts: &[DefaultElement], mesh: &mut Mesh) -> Result<()> {
    let coord = |v: &DefaultElement, k: &str, i: usize| -> Result<f64> {
        v.get(k)
            .and_then(scalar)
            .ok_or_else(|| Error::input(path, format!("vertex {i} lacks a numeric '{k}'")))
    };
    for (i, v) in verts.iter().enumerate() {
        mesh.vertices
            .push([coord(v, "x", i)?, coord(v, "y", i)?, coord(v, "z", i)?]);
    }
    if let Some(first) = verts.first() {
        if ["red", "green", "blue"]
            .iter()
            .all(|k| first.contains_key(*k))
        {
            let c = |v: &DefaultElement, k: &str| {
                v.get(k).and_then(scalar).unwrap_or(0.0).clamp(0.0, 255.0) as u8
            };
            mesh.colors = Some(
                verts
                    .iter()
                    .map(|v| [c(v, "red"), c(v, "green"), c(v, "blue")])
                    .collect(),
            );
        }
        for (name, p) in first.iter() {
            if ["x", "y", "z", "red", "green", "blue", "alpha"].contains(&name.as_str())
                || scalar(p).is_none()
            {
                continue;
            }
            let values = verts
                .iter()
                .map(|v| v.get(name).and_then(scalar).unwrap_or(f64::NAN))
                .collect();
            mesh.vertex_columns.push(Column {
                name: name.clone(),
                values,
            });
        }
    }
    Ok(())
}

/// Faces as triangles (polygons as fans), every index checked against `nv` vertices.
fn read_faces(path: &Path, faces: &[DefaultElement], nv: usize) -> Result<Vec<[u32; 3]>> {
    let mut triangles = Vec::new();
    for (f, face) in faces.iter().enumerate() {
        let idx = face
            .get("vertex_indices")
            .or_else(|| face.get("vertex_index"))
            .and_then(index_list)
            .ok_or_else(|| Error::input(path, format!("face {f} has no vertex_indices list")))?;
        if idx.len() < 3 {
            return Err(Error::input(
                path,
                format!("face {f} has {} vertices", idx.len()),
            ));
        }
        if let Some(bad) = idx.iter().find(|&&i| i < 0 || i as usize >= nv) {
            return Err(Error::input(
                path,
                format!("face {f} uses vertex index {bad}, but there are {nv} vertices"),
            ));
        }
        // Polygons become triangle fans.
        for k in 1..idx.len() - 1 {
            triangles.push([idx[0] as u32, idx[k] as u32, idx[k + 1] as u32]);
        }
    }
    Ok(triangles)
}

/// Edges (vertex1, vertex2) checked against `nv` vertices, with their other scalar properties
/// as columns.
fn read_edges(path: &Path, edges: &[DefaultElement], nv: usize) -> Result<Edges> {
    let mut e = Edges::default();
    for (n, ed) in edges.iter().enumerate() {
        let a = ed.get("vertex1").and_then(scalar);
        let b = ed.get("vertex2").and_then(scalar);
        match (a, b) {
            (Some(a), Some(b))
                if a >= 0.0 && b >= 0.0 && (a as usize) < nv && (b as usize) < nv =>
            {
                e.pairs.push([a as u32, b as u32])
            }
            _ => {
                return Err(Error::input(
                    path,
                    format!("edge {n} has missing or out-of-range vertex1/vertex2"),
                ));
            }
        }
    }
    if let Some(first) = edges.first() {
        for (name, p) in first.iter() {
            if name == "vertex1" || name == "vertex2" || scalar(p).is_none() {
                continue;
            }
            let values = edges
                .iter()
                .map(|v| v.get(name).and_then(scalar).unwrap_or(f64::NAN))
                .collect();
            e.columns.push(Column {
                name: name.clone(),
                values,
            });
        }
    }
    Ok(e)
}

fn def(name: &str, t: ScalarType) -> PropertyDef {
    PropertyDef::new(name.to_string(), PropertyType::Scalar(t))
}

/// Columns named `kind`/`label` are written as uchar (docs/reference/case.md springs.ply), others as float.
fn column_type(name: &str) -> ScalarType {
    if name == "kind" || name == "label" {
        ScalarType::UChar
    } else {
        ScalarType::Float
    }
}

fn column_value(name: &str, v: f64) -> Property {
    match column_type(name) {
        ScalarType::UChar => Property::UChar(v.clamp(0.0, 255.0) as u8),
        _ => Property::Float(v as f32),
    }
}

/// Coordinates are written as double: the predicted face must keep sub-micron precision.
pub(crate) fn to_ply(mesh: &Mesh, encoding: Encoding) -> Ply<DefaultElement> {
    let mut ply = Ply::<DefaultElement>::new();
    ply.header.encoding = encoding;
    ply.header
        .comments
        .push("facesim: LPS frame, millimetres".to_string());
    let mut vdef = ElementDef::new("vertex".to_string());
    for k in ["x", "y", "z"] {
        vdef.properties.add(def(k, ScalarType::Double));
    }
    if mesh.colors.is_some() {
        for k in ["red", "green", "blue"] {
            vdef.properties.add(def(k, ScalarType::UChar));
        }
    }
    for c in &mesh.vertex_columns {
        vdef.properties.add(def(&c.name, column_type(&c.name)));
    }
    ply.header.elements.add(vdef);
    let mut verts = Vec::with_capacity(mesh.vertices.len());
    for (i, v) in mesh.vertices.iter().enumerate() {
        let mut e = DefaultElement::new();
        e.insert("x".into(), Property::Double(v[0]));
        e.insert("y".into(), Property::Double(v[1]));
        e.insert("z".into(), Property::Double(v[2]));
        if let Some(c) = &mesh.colors {
            e.insert("red".into(), Property::UChar(c[i][0]));
            e.insert("green".into(), Property::UChar(c[i][1]));
            e.insert("blue".into(), Property::UChar(c[i][2]));
        }
        for c in &mesh.vertex_columns {
            e.insert(c.name.clone(), column_value(&c.name, c.values[i]));
        }
        verts.push(e);
    }
    ply.payload.insert("vertex".into(), verts);
    if !mesh.triangles.is_empty() || mesh.edges.is_none() {
        let mut fdef = ElementDef::new("face".to_string());
        fdef.properties.add(PropertyDef::new(
            "vertex_indices".to_string(),
            PropertyType::List(ScalarType::UChar, ScalarType::Int),
        ));
        ply.header.elements.add(fdef);
        let faces = mesh
            .triangles
            .iter()
            .map(|t| {
                let mut e = DefaultElement::new();
                e.insert(
                    "vertex_indices".into(),
                    Property::ListInt(t.iter().map(|&i| i as i32).collect()),
                );
                e
            })
            .collect();
        ply.payload.insert("face".into(), faces);
    }
    if let Some(edges) = &mesh.edges {
        let mut edef = ElementDef::new("edge".to_string());
        edef.properties.add(def("vertex1", ScalarType::Int));
        edef.properties.add(def("vertex2", ScalarType::Int));
        for c in &edges.columns {
            edef.properties.add(def(&c.name, column_type(&c.name)));
        }
        ply.header.elements.add(edef);
        let list = edges
            .pairs
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let mut e = DefaultElement::new();
                e.insert("vertex1".into(), Property::Int(p[0] as i32));
                e.insert("vertex2".into(), Property::Int(p[1] as i32));
                for c in &edges.columns {
                    e.insert(c.name.clone(), column_value(&c.name, c.values[i]));
                }
                e
            })
            .collect();
        ply.payload.insert("edge".into(), list);
    }
    ply
}

pub fn write(mesh: &Mesh, path: &Path, encoding: Encoding) -> Result<()> {
    if encoding == Encoding::BinaryLittleEndian {
        let bytes = binary_le(mesh);
        return write_bytes_atomic(path, |w| w.write_all(&bytes));
    }
    let mut ply = to_ply(mesh, encoding);
    write_bytes_atomic(path, |w| {
        Writer::new()
            .write_ply(&mut &mut *w, &mut ply)
            .map(|_| ())
            .map_err(|e| std::io::Error::other(e.to_string()))
    })
}

/// The binary little-endian file `to_ply` + ply-rs would write, packed directly: ply-rs builds a
/// hash map per element, which made writing the outputs a visible share of a run (the header
/// and record layout are the same; a test checks the bytes are identical).
fn binary_le(mesh: &Mesh) -> Vec<u8> {
    let ty = |name: &str| match column_type(name) {
        ScalarType::UChar => "uchar",
        _ => "float",
    };
    let mut h = String::from(
        "ply\nformat binary_little_endian 1.0\ncomment facesim: LPS frame, millimetres\n",
    );
    h += &format!("element vertex {}\n", mesh.vertices.len());
    for k in ["x", "y", "z"] {
        h += &format!("property double {k}\n");
    }
    if mesh.colors.is_some() {
        for k in ["red", "green", "blue"] {
            h += &format!("property uchar {k}\n");
        }
    }
    for c in &mesh.vertex_columns {
        h += &format!("property {} {}\n", ty(&c.name), c.name);
    }
    let faces = !mesh.triangles.is_empty() || mesh.edges.is_none();
    if faces {
        h += &format!(
            "element face {}\nproperty list uchar int vertex_indices\n",
            mesh.triangles.len()
        );
    }
    if let Some(edges) = &mesh.edges {
        h += &format!(
            "element edge {}\nproperty int vertex1\nproperty int vertex2\n",
            edges.pairs.len()
        );
        for c in &edges.columns {
            h += &format!("property {} {}\n", ty(&c.name), c.name);
        }
    }
    h += "end_header\n";
    let mut b = h.into_bytes();
    let column = |b: &mut Vec<u8>, name: &str, v: f64| match column_value(name, v) {
        Property::UChar(x) => b.push(x),
        Property::Float(x) => b.extend(x.to_le_bytes()),
        _ => {}
    };
    b.reserve(mesh.vertices.len() * 27 + mesh.triangles.len() * 13);
    for (i, v) in mesh.vertices.iter().enumerate() {
        for x in v {
            b.extend(x.to_le_bytes());
        }
        if let Some(c) = &mesh.colors {
            b.extend(c[i]);
        }
        for c in &mesh.vertex_columns {
            column(&mut b, &c.name, c.values[i]);
        }
    }
    if faces {
        for t in &mesh.triangles {
            b.push(3);
            for &i in t {
                b.extend((i as i32).to_le_bytes());
            }
        }
    }
    if let Some(edges) = &mesh.edges {
        for (i, p) in edges.pairs.iter().enumerate() {
            b.extend((p[0] as i32).to_le_bytes());
            b.extend((p[1] as i32).to_le_bytes());
            for c in &edges.columns {
                column(&mut b, &c.name, c.values[i]);
            }
        }
    }
    b
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_direct_binary_writer_gives_ply_rs_bytes() {
        let mut bare = sample();
        bare.colors = None;
        bare.edges = None;
        bare.vertex_columns.clear();
        let mut edges_only = sample();
        edges_only.triangles.clear();
        for m in [sample(), bare, edges_only] {
            let mut ply = to_ply(&m, Encoding::BinaryLittleEndian);
            let mut reference = Vec::new();
            Writer::new().write_ply(&mut reference, &mut ply).unwrap();
            assert_eq!(binary_le(&m), reference);
        }
    }

    fn sample() -> Mesh {
        let mut m = crate::mesh::two_triangles();
        m.colors = Some(vec![[255, 0, 0], [0, 255, 0], [0, 0, 255], [7, 8, 9]]);
        m.vertex_columns.push(Column {
            name: "dist".into(),
            values: vec![0.5, 1.0, 2.0, 4.0],
        });
        m.edges = Some(Edges {
            pairs: vec![[0, 3], [1, 2]],
            columns: vec![
                Column {
                    name: "stiffness".into(),
                    values: vec![0.25, 3.0],
                },
                Column {
                    name: "kind".into(),
                    values: vec![0.0, 1.0],
                },
            ],
        });
        m
    }

    #[test]
    fn round_trip_every_encoding() {
        let d = tempfile::tempdir().unwrap();
        for enc in [
            Encoding::Ascii,
            Encoding::BinaryLittleEndian,
            Encoding::BinaryBigEndian,
        ] {
            let p = d.path().join(format!("{enc:?}.ply"));
            write(&sample(), &p, enc).unwrap();
            let back = read(&p).unwrap();
            assert_eq!(back, sample(), "{enc:?}");
        }
    }

    #[test]
    fn refuses_count_bomb_and_bad_index() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("bomb.ply");
        std::fs::write(
            &p,
            "ply\nformat ascii 1.0\nelement vertex 99999999999\nproperty float x\nend_header\n",
        )
        .unwrap();
        assert!(read(&p).unwrap_err().to_string().contains("declares"));
        let p = d.path().join("idx.ply");
        std::fs::write(
            &p,
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
             element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n",
        )
        .unwrap();
        let e = read(&p).unwrap_err().to_string();
        assert!(e.contains("idx.ply") && e.contains("index 7"), "{e}");
    }
}
