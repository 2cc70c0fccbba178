//! tets.vtu (docs/reference/case.md outputs): the volumetric model as a VTK XML UnstructuredGrid, ASCII, in LPS
//! mm. Cells are linear tetrahedra (VTK type 10) or quadratic tetrahedra (VTK type 24, nodes: the
//! four corners, then the mid-edge nodes of edges 0-1, 1-2, 2-0, 0-3, 1-3, 2-3). Point data
//! `displacement` (mm) and `constraint` (0 free, 1 fixed, 2 moved with a bone segment, 3
//! sliding); cell data `youngs_modulus` (kPa), `poisson_ratio` and `tissue`. Every number is
//! written in Rust's shortest round-trip form, so [`read`] returns exactly the values written and
//! a re-solve from the file starts from the model's own numbers.
//!
//! The reader reads what [`write()`] writes (ASCII DataArrays inside one Piece), which is also what
//! ParaView writes when told to save ASCII; it is not a general VTK reader.

use crate::error::{Error, Result};
use crate::mesh::vtp::attr;
use crate::output::write_bytes_atomic;
use std::io::Write;
use std::path::Path;

/// VTK cell types.
const VTK_TETRA: u8 = 10;
const VTK_QUADRATIC_TETRA: u8 = 24;

/// Tetrahedra by node index: linear (4 corners, positive volume) or quadratic (4 corners then
/// the mid-edge nodes of 0-1, 1-2, 2-0, 0-3, 1-3, 2-3: VTK's and CalculiX C3D10's order).
#[derive(Clone, Copy, Debug)]
pub enum Cells<'a> {
    Linear(&'a [[u32; 4]]),
    Quadratic(&'a [[u32; 10]]),
}

impl Cells<'_> {
    pub fn len(&self) -> usize {
        match self {
            Cells::Linear(c) => c.len(),
            Cells::Quadratic(c) => c.len(),
        }
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Nodes per cell (4 or 10).
    pub(crate) fn nodes_per_cell(&self) -> usize {
        match self {
            Cells::Linear(_) => 4,
            Cells::Quadratic(_) => 10,
        }
    }
    /// The node indices of cell `c`.
    pub fn cell(&self, c: usize) -> &[u32] {
        match self {
            Cells::Linear(v) => &v[c],
            Cells::Quadratic(v) => &v[c],
        }
    }
    fn vtk_type(&self) -> u8 {
        match self {
            Cells::Linear(_) => VTK_TETRA,
            Cells::Quadratic(_) => VTK_QUADRATIC_TETRA,
        }
    }
}

/// The owned counterpart of [`Cells`], as read from a file.
#[derive(Clone, Debug, PartialEq)]
pub enum CellsOwned {
    Linear(Vec<[u32; 4]>),
    Quadratic(Vec<[u32; 10]>),
}

impl CellsOwned {
    pub fn view(&self) -> Cells<'_> {
        match self {
            CellsOwned::Linear(c) => Cells::Linear(c),
            CellsOwned::Quadratic(c) => Cells::Quadratic(c),
        }
    }
}

/// Constraint codes of the `constraint` point data.
pub const FREE: u8 = 0;
pub const FIXED: u8 = 1;
pub const MOVED: u8 = 2;
pub(crate) const SLIDING: u8 = 3;

/// What tets.vtu holds, borrowed from the model: one entry per node for `nodes`, `displacement`
/// and `constraint`, one per cell for `youngs_kpa`, `poisson` and `tissue`.
#[derive(Clone, Copy, Debug)]
pub struct TetsVtu<'a> {
    pub nodes: &'a [[f64; 3]],
    pub cells: Cells<'a>,
    pub displacement: &'a [[f64; 3]],
    pub constraint: &'a [u8],
    pub youngs_kpa: &'a [f64],
    pub poisson: &'a [f64],
    pub tissue: &'a [u8],
}

/// A tets.vtu read back.
#[derive(Clone, Debug, PartialEq)]
pub struct TetsVtuOwned {
    pub nodes: Vec<[f64; 3]>,
    pub cells: CellsOwned,
    pub displacement: Vec<[f64; 3]>,
    pub constraint: Vec<u8>,
    pub youngs_kpa: Vec<f64>,
    pub poisson: Vec<f64>,
    pub tissue: Vec<u8>,
}

impl TetsVtuOwned {
    pub fn view(&self) -> TetsVtu<'_> {
        TetsVtu {
            nodes: &self.nodes,
            cells: self.cells.view(),
            displacement: &self.displacement,
            constraint: &self.constraint,
            youngs_kpa: &self.youngs_kpa,
            poisson: &self.poisson,
            tissue: &self.tissue,
        }
    }
}

/// Lengths agree, indices are in range, constraint codes known, numbers finite: what both the
/// writer (a model bug must not become an unreadable file) and the reader check.
fn check(v: &TetsVtu) -> std::result::Result<(), String> {
    let (n, c) = (v.nodes.len(), v.cells.len());
    for (name, len, want) in [
        ("displacement", v.displacement.len(), n),
        ("constraint", v.constraint.len(), n),
        ("youngs_modulus", v.youngs_kpa.len(), c),
        ("poisson_ratio", v.poisson.len(), c),
        ("tissue", v.tissue.len(), c),
    ] {
        if len != want {
            return Err(format!("{name} has {len} values, expected {want}"));
        }
    }
    for i in 0..c {
        if let Some(bad) = v.cells.cell(i).iter().find(|&&k| k as usize >= n) {
            return Err(format!("cell {i} names node {bad} of {n}"));
        }
    }
    if let Some(i) = v.constraint.iter().position(|&k| k > SLIDING) {
        return Err(format!(
            "node {i} has constraint {}, expected 0 to 3",
            v.constraint[i]
        ));
    }
    let flat = |a: &[[f64; 3]]| a.iter().position(|p| p.iter().any(|x| !x.is_finite()));
    if let Some(i) = flat(v.nodes) {
        return Err(format!("node {i} has a non-finite coordinate"));
    }
    if let Some(i) = flat(v.displacement) {
        return Err(format!("node {i} has a non-finite displacement"));
    }
    if let Some(i) = v
        .youngs_kpa
        .iter()
        .zip(v.poisson)
        .position(|(e, p)| !(e.is_finite() && p.is_finite()))
    {
        return Err(format!("cell {i} has a non-finite material"));
    }
    Ok(())
}

/// Write tets.vtu atomically (a failed write leaves any previous file as it was).
pub fn write(path: &Path, v: &TetsVtu) -> Result<()> {
    check(v).map_err(|m| Error::output(path, m))?;
    write_bytes_atomic(path, |w| write_to(w, v))
}

fn write_to(w: &mut dyn Write, v: &TetsVtu) -> std::io::Result<()> {
    let npc = v.cells.nodes_per_cell();
    writeln!(w, r#"<?xml version="1.0"?>"#)?;
    writeln!(
        w,
        r#"<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian" header_type="UInt64">"#
    )?;
    writeln!(w, "<UnstructuredGrid>")?;
    writeln!(
        w,
        r#"<Piece NumberOfPoints="{}" NumberOfCells="{}">"#,
        v.nodes.len(),
        v.cells.len()
    )?;
    writeln!(w, "<PointData Vectors=\"displacement\">")?;
    vectors(w, "displacement", v.displacement)?;
    ints(
        w,
        "constraint",
        "Int32",
        v.constraint.iter().map(|&k| k as u64),
    )?;
    writeln!(w, "</PointData>")?;
    writeln!(w, "<CellData>")?;
    floats(w, "youngs_modulus", v.youngs_kpa)?;
    floats(w, "poisson_ratio", v.poisson)?;
    ints(w, "tissue", "UInt8", v.tissue.iter().map(|&k| k as u64))?;
    writeln!(w, "</CellData>")?;
    writeln!(w, "<Points>")?;
    vectors(w, "Points", v.nodes)?;
    writeln!(w, "</Points>")?;
    writeln!(w, "<Cells>")?;
    let conn = (0..v.cells.len()).flat_map(|c| v.cells.cell(c).iter().map(|&k| k as u64));
    ints(w, "connectivity", "Int64", conn)?;
    let offsets = (1..=v.cells.len()).map(|c| (c * npc) as u64);
    ints(w, "offsets", "Int64", offsets)?;
    let t = v.cells.vtk_type() as u64;
    ints(w, "types", "UInt8", (0..v.cells.len()).map(|_| t))?;
    writeln!(w, "</Cells>")?;
    writeln!(w, "</Piece>")?;
    writeln!(w, "</UnstructuredGrid>")?;
    writeln!(w, "</VTKFile>")
}

/// `{:e}` is Rust's shortest decimal that parses back to the same f64.
fn vectors(w: &mut dyn Write, name: &str, a: &[[f64; 3]]) -> std::io::Result<()> {
    writeln!(
        w,
        r#"<DataArray type="Float64" Name="{name}" NumberOfComponents="3" format="ascii">"#
    )?;
    for p in a {
        writeln!(w, "{:e} {:e} {:e}", p[0], p[1], p[2])?;
    }
    writeln!(w, "</DataArray>")
}

fn floats(w: &mut dyn Write, name: &str, a: &[f64]) -> std::io::Result<()> {
    writeln!(
        w,
        r#"<DataArray type="Float64" Name="{name}" format="ascii">"#
    )?;
    for x in a {
        writeln!(w, "{x:e}")?;
    }
    writeln!(w, "</DataArray>")
}

fn ints(
    w: &mut dyn Write,
    name: &str,
    ty: &str,
    a: impl Iterator<Item = u64>,
) -> std::io::Result<()> {
    writeln!(w, r#"<DataArray type="{ty}" Name="{name}" format="ascii">"#)?;
    // Twelve to a line keeps the file readable and its lines short.
    for (i, x) in a.enumerate() {
        write!(w, "{x}{}", if i % 12 == 11 { "\n" } else { " " })?;
    }
    writeln!(w, "\n</DataArray>")
}

/// Read a tets.vtu written by [`write()`] (or an ASCII equivalent); every problem is a one-line
/// error naming the file.
pub fn read(path: &Path) -> Result<TetsVtuOwned> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::input(path, e))?;
    parse(&text).map_err(|m| Error::input(path, format!("not a readable tets.vtu: {m}")))
}

/// A DataArray: its section (Points, Cells, PointData, CellData), name, components, values.
struct Array<'t> {
    section: &'static str,
    name: String,
    components: usize,
    text: &'t str,
}

fn parse(text: &str) -> std::result::Result<TetsVtuOwned, String> {
    let vtk_file = text
        .find("<VTKFile")
        .and_then(|at| Some(&text[at..at + text[at..].find('>')?]));
    if vtk_file.and_then(|t| attr(t, "type")) != Some("UnstructuredGrid") {
        return Err("no VTKFile of type UnstructuredGrid".into());
    }
    if text.matches("<Piece").count() != 1 {
        return Err("expected exactly one Piece".into());
    }
    let piece_at = text.find("<Piece").ok_or("no Piece")?;
    let piece = &text[piece_at..piece_at + text[piece_at..].find('>').ok_or("unclosed Piece")?];
    let count = |key: &str| -> std::result::Result<usize, String> {
        attr(piece, key)
            .ok_or_else(|| format!("Piece has no {key}"))?
            .parse()
            .map_err(|_| format!("Piece's {key} is not a count"))
    };
    let (np, nc) = (count("NumberOfPoints")?, count("NumberOfCells")?);

    // Each DataArray belongs to the last section opened before it.
    let sections = ["Points", "Cells", "PointData", "CellData"];
    let mut arrays = Vec::new();
    let mut rest = text;
    let mut offset = 0;
    while let Some(at) = rest.find("<DataArray") {
        let open_end = at + rest[at..].find('>').ok_or("unclosed DataArray tag")?;
        let tag = &rest[at..open_end];
        let close = open_end
            + rest[open_end..]
                .find("</DataArray>")
                .ok_or("DataArray without its end tag")?;
        if rest[open_end + 1..close].contains('<') {
            return Err("DataArray without its end tag".into());
        }
        let before = &text[..offset + at];
        let section = sections
            .iter()
            .filter_map(|s| before.rfind(&format!("<{s}")).map(|p| (p, *s)))
            .max()
            .map(|(_, s)| s)
            .ok_or("a DataArray outside Points, Cells, PointData and CellData")?;
        let format = attr(tag, "format").unwrap_or_default();
        if format != "ascii" {
            return Err(format!(
                "DataArray format \"{format}\": only ascii is read (save as ASCII)"
            ));
        }
        arrays.push(Array {
            section,
            name: attr(tag, "Name").unwrap_or_default().to_string(),
            components: attr(tag, "NumberOfComponents")
                .map(|c| c.parse().map_err(|_| "bad NumberOfComponents".to_string()))
                .transpose()?
                .unwrap_or(1),
            text: &rest[open_end + 1..close],
        });
        let next = close + "</DataArray>".len();
        offset += next;
        rest = &rest[next..];
    }
    let find = |section: &str, name: Option<&str>| -> std::result::Result<&Array, String> {
        arrays
            .iter()
            .find(|a| a.section == section && name.is_none_or(|n| a.name == n))
            .ok_or_else(|| format!("no {} array in {section}", name.unwrap_or("data")))
    };
    let nodes = vec3(find("Points", None)?, np)?;
    let displacement = vec3(find("PointData", Some("displacement"))?, np)?;
    let constraint = small_ints(find("PointData", Some("constraint"))?, np)?;
    let youngs_kpa = numbers::<f64>(find("CellData", Some("youngs_modulus"))?, nc)?;
    let poisson = numbers::<f64>(find("CellData", Some("poisson_ratio"))?, nc)?;
    let tissue = small_ints(find("CellData", Some("tissue"))?, nc)?;
    let types = small_ints(find("Cells", Some("types"))?, nc)?;
    let offsets = numbers::<usize>(find("Cells", Some("offsets"))?, nc)?;
    let conn_array = find("Cells", Some("connectivity"))?;
    let conn = numbers::<u32>(conn_array, conn_array.text.split_whitespace().count())?;

    let npc = match types.first() {
        None | Some(&VTK_TETRA) => 4,
        Some(&VTK_QUADRATIC_TETRA) => 10,
        Some(t) => {
            return Err(format!(
                "cell type {t}: expected tetra (10) or quadratic tetra (24)"
            ));
        }
    };
    if let Some(i) = types.iter().position(|&t| t != types[0]) {
        return Err(format!(
            "cell {i} has type {}, cell 0 type {}: mixed cells",
            types[i], types[0]
        ));
    }
    if let Some(i) = (0..nc).find(|&c| offsets[c] != (c + 1) * npc) {
        return Err(format!(
            "cell {i}'s offset {} is not {}",
            offsets[i],
            (i + 1) * npc
        ));
    }
    if conn.len() != nc * npc {
        return Err(format!(
            "connectivity has {} entries, expected {}",
            conn.len(),
            nc * npc
        ));
    }
    let cells = if npc == 4 {
        CellsOwned::Linear(conn.chunks(4).map(|c| [c[0], c[1], c[2], c[3]]).collect())
    } else {
        CellsOwned::Quadratic(
            conn.chunks(10)
                .map(|c| std::array::from_fn(|k| c[k]))
                .collect(),
        )
    };
    let v = TetsVtuOwned {
        nodes,
        cells,
        displacement,
        constraint,
        youngs_kpa,
        poisson,
        tissue,
    };
    check(&v.view())?;
    Ok(v)
}

fn numbers<T: std::str::FromStr>(a: &Array, want: usize) -> std::result::Result<Vec<T>, String> {
    let v = a
        .text
        .split_whitespace()
        .map(|s| {
            s.parse::<T>()
                .map_err(|_| format!("\"{s}\" in {} is not a number of its type", a.name))
        })
        .collect::<std::result::Result<Vec<T>, String>>()?;
    if v.len() != want * a.components {
        return Err(format!(
            "{} has {} values, expected {}",
            if a.name.is_empty() { "Points" } else { &a.name },
            v.len(),
            want * a.components
        ));
    }
    Ok(v)
}

fn vec3(a: &Array, n: usize) -> std::result::Result<Vec<[f64; 3]>, String> {
    if a.components != 3 {
        return Err(format!(
            "{} has {} components, expected 3",
            a.name, a.components
        ));
    }
    Ok(numbers::<f64>(a, n)?
        .chunks(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect())
}

fn small_ints(a: &Array, n: usize) -> std::result::Result<Vec<u8>, String> {
    if a.components != 1 {
        return Err(format!(
            "{} has {} components, expected 1",
            a.name, a.components
        ));
    }
    numbers::<u8>(a, n)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> TetsVtuOwned {
        TetsVtuOwned {
            nodes: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
                [1.0, 1.0, 1.0],
            ],
            cells: CellsOwned::Linear(vec![[0, 1, 2, 3], [1, 2, 3, 4]]),
            // Values whose shortest decimal forms are long, tiny, huge and negative.
            displacement: vec![
                [0.1 + 0.2, -1.0 / 3.0, 1e-300],
                [f64::MAX, f64::MIN_POSITIVE, -0.0],
                [std::f64::consts::PI, 2.0_f64.sqrt(), 5e-324],
                [0.0; 3],
                [1.0, 2.0, 3.0],
            ],
            constraint: vec![FIXED, FREE, MOVED, SLIDING, FREE],
            youngs_kpa: vec![3.0, 15.000000000000002],
            poisson: vec![0.45, 0.49],
            tissue: vec![2, 255],
        }
    }

    #[test]
    fn a_written_file_reads_back_bit_for_bit() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("tets.vtu");
        let v = sample();
        write(&p, &v.view()).unwrap();
        let back = read(&p).unwrap();
        assert_eq!(back, v);
        for (a, b) in back.displacement.iter().zip(&v.displacement) {
            for c in 0..3 {
                assert_eq!(a[c].to_bits(), b[c].to_bits());
            }
        }
        // Quadratic cells keep their ten nodes in order.
        let mut q = sample();
        q.cells = CellsOwned::Quadratic(vec![[0, 1, 2, 3, 4, 4, 3, 2, 1, 0]]);
        q.youngs_kpa.truncate(1);
        q.poisson.truncate(1);
        q.tissue.truncate(1);
        write(&p, &q.view()).unwrap();
        let text = std::fs::read_to_string(&p).unwrap();
        assert!(text.contains("\n24 \n"), "VTK type 24");
        assert_eq!(read(&p).unwrap(), q);
    }

    #[test]
    fn inconsistent_data_is_refused_on_writing() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("tets.vtu");
        let mut v = sample();
        v.constraint.pop();
        let e = write(&p, &v.view()).unwrap_err().to_string();
        assert!(e.contains("tets.vtu") && e.contains("constraint"), "{e}");
        let mut v = sample();
        v.displacement[1][0] = f64::NAN;
        assert!(write(&p, &v.view()).is_err());
        assert!(!p.exists());
    }

    #[test]
    fn malformed_files_are_one_line_errors_naming_the_file() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("tets.vtu");
        write(&p, &sample().view()).unwrap();
        let good = std::fs::read_to_string(&p).unwrap();
        let cases = [
            ("", "UnstructuredGrid"),
            (
                &good.replace("NumberOfPoints=\"5\"", "NumberOfPoints=\"6\"") as &str,
                "values",
            ),
            (
                &good.replace("format=\"ascii\"", "format=\"binary\""),
                "ascii",
            ),
            (&good.replace("\n10 10 \n", "\n10 24 \n"), "mixed"),
            (
                &good.replace("0 1 2 3 1 2 3 4", "0 1 2 3 1 2 3 9"),
                "node 9",
            ),
            (
                &good.replace("Name=\"tissue\"", "Name=\"labels\""),
                "tissue",
            ),
            (
                &good.replace("</DataArray>\n</Points>", "</Points>"),
                "end tag",
            ),
            (&good.replace("1 0 2 3 0", "1 0 7 3 0"), "constraint"),
            (&good.replace("4.5e-1", "4.5e-1x"), "not a number"),
        ];
        for (text, what) in cases {
            std::fs::write(&p, text).unwrap();
            let e = read(&p).unwrap_err().to_string();
            assert!(
                e.contains("tets.vtu") && e.contains(what) && !e.contains('\n'),
                "{what}: {e}"
            );
        }
        let e = read(&d.path().join("missing.vtu")).unwrap_err().to_string();
        assert!(e.contains("missing.vtu"), "{e}");
    }
}
