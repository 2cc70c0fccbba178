//! VTK XML PolyData (`.vtp`): the points, the polygons (fanned into triangles), the point-data
//! arrays and the field-data strings (3D Slicer records a model's frame in a `SPACE` string).
//!
//! Every data encoding VTK's `vtkXMLPolyDataWriter` produces is read (VTK file-format
//! documentation, "XML File Formats"):
//! - `format="ascii"`: numbers in the element's text;
//! - `format="binary"`: base64 in the element's text: the header and the data encoded together
//!   when uncompressed, each encoded on its own when compressed;
//! - `format="appended"` with `offset`: the same header and data in the file's `<AppendedData>`
//!   section after its `_` mark, raw bytes (`encoding="raw"`, VTK's default) or base64;
//! - the header: `header_type` UInt32 (the default) or UInt64 words, in the file's `byte_order`.
//!   Uncompressed it is one word, the data's byte count; with `compressor="vtkZLibDataCompressor"`
//!   it is [blocks, block size, last block size (0: a full block), compressed size of each
//!   block], followed by the blocks, each a zlib stream. LZ4 and LZMA compressors are refused by
//!   name (no decoder here).
//!
//! The XML tags are found by plain text search, not an XML parser: a VTK file is written by a
//! machine, with one tag per element and its attributes in double quotes.

use super::surface::Mesh;
use super::vtk::PointArray;
use crate::error::{Error, Result};
use crate::output::write_bytes_atomic;
use base64::Engine;
use std::io::Read;
use std::path::Path;

/// What a `.vtp` holds that facesim uses.
#[derive(Clone, Debug, PartialEq)]
pub struct Vtp {
    pub mesh: Mesh,
    pub point_data: Vec<PointArray>,
    /// Field-data string arrays: (name, the strings).
    pub field_strings: Vec<(String, Vec<String>)>,
}

impl Vtp {
    /// The frame Slicer recorded (`SPACE` field data: "RAS" or "LPS"), if any.
    pub fn space(&self) -> Option<&str> {
        self.field_strings
            .iter()
            .find(|(n, _)| n == "SPACE")
            .and_then(|(_, s)| s.first())
            .map(|s| s.as_str())
    }
}

/// VTK XML PolyData (`.vtp`, ASCII) with point data and a `SPACE` = "LPS" field-data string
/// (how 3D Slicer records the frame of a .vtp).
pub fn write_vtp(mesh: &Mesh, arrays: &[PointArray], path: &Path) -> Result<()> {
    write_bytes_atomic(path, |w| {
        let (nv, nt) = (mesh.vertices.len(), mesh.triangles.len());
        writeln!(w, r#"<?xml version="1.0"?>"#)?;
        writeln!(
            w,
            r#"<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian" header_type="UInt64">"#
        )?;
        writeln!(w, "<PolyData>")?;
        // "LPS" as VTK writes an ASCII string array: character codes, each string ended by 0.
        writeln!(
            w,
            r#"<FieldData><Array type="String" Name="SPACE" NumberOfTuples="1" format="ascii">76 80 83 0</Array></FieldData>"#
        )?;
        writeln!(
            w,
            r#"<Piece NumberOfPoints="{nv}" NumberOfVerts="0" NumberOfLines="0" NumberOfStrips="0" NumberOfPolys="{nt}">"#
        )?;
        writeln!(w, "<PointData>")?;
        for a in arrays {
            writeln!(
                w,
                r#"<DataArray type="Float64" Name="{}" NumberOfComponents="{}" format="ascii">"#,
                a.name, a.components
            )?;
            for row in a.values.chunks(a.components.max(1)) {
                let s: Vec<String> = row.iter().map(|x| x.to_string()).collect();
                writeln!(w, "{}", s.join(" "))?;
            }
            writeln!(w, "</DataArray>")?;
        }
        writeln!(w, "</PointData>")?;
        writeln!(
            w,
            r#"<Points><DataArray type="Float64" Name="Points" NumberOfComponents="3" format="ascii">"#
        )?;
        for v in &mesh.vertices {
            writeln!(w, "{} {} {}", v[0], v[1], v[2])?;
        }
        writeln!(w, "</DataArray></Points>")?;
        writeln!(
            w,
            r#"<Polys><DataArray type="Int64" Name="connectivity" format="ascii">"#
        )?;
        for t in &mesh.triangles {
            writeln!(w, "{} {} {}", t[0], t[1], t[2])?;
        }
        writeln!(w, "</DataArray>")?;
        writeln!(
            w,
            r#"<DataArray type="Int64" Name="offsets" format="ascii">"#
        )?;
        for k in 1..=nt {
            write!(w, "{} ", 3 * k)?;
        }
        writeln!(w, "\n</DataArray></Polys>")?;
        writeln!(w, "</Piece>\n</PolyData>\n</VTKFile>")?;
        Ok(())
    })
}

/// Read a `.vtp`: its mesh and named point-data arrays.
pub fn read_vtp(path: &Path) -> Result<(Mesh, Vec<PointArray>)> {
    read(path).map(|v| (v.mesh, v.point_data))
}

/// Read a `.vtp` in any of VTK's encodings (module doc).
pub fn read(path: &Path) -> Result<Vtp> {
    let bytes = std::fs::read(path).map_err(|e| Error::input(path, e))?;
    parse(&bytes).map_err(|m| Error::input(path, m))
}

type Parsed<T> = std::result::Result<T, String>;

/// The value of attribute `name` in a VTK XML opening tag (`<DataArray type="Float64" …`).
pub(crate) fn attr<'a>(tag: &'a str, name: &str) -> Option<&'a str> {
    let key = format!(" {name}=\"");
    let s = tag.find(&key)? + key.len();
    let e = tag[s..].find('"')? + s;
    Some(&tag[s..e])
}

/// The file-wide settings of the binary encodings.
struct Layout<'a> {
    big_endian: bool,
    /// Header word size: 4 (UInt32) or 8 (UInt64).
    word: usize,
    zlib: bool,
    /// The bytes after the `_` of `<AppendedData>`, and whether they are base64 text.
    appended: Option<(&'a [u8], bool)>,
}

impl Layout<'_> {
    fn word_at(&self, b: &[u8]) -> usize {
        let mut v = 0u64;
        for k in 0..self.word {
            let byte = if self.big_endian {
                b[k]
            } else {
                b[self.word - 1 - k]
            };
            v = (v << 8) | byte as u64;
        }
        v as usize
    }

    /// The header words at the start of `b` (already decoded bytes): one, or 3 + blocks with zlib.
    fn header_len(&self, b: &[u8]) -> Parsed<usize> {
        let words = if self.zlib {
            if b.len() < self.word {
                return Err("data array header cut short".into());
            }
            self.word_at(b).checked_add(3).ok_or("absurd block count")?
        } else {
            1
        };
        words
            .checked_mul(self.word)
            .ok_or_else(|| "absurd block count".into())
    }

    /// The data of a binary array, from its header onwards in `b` (raw bytes).
    fn data(&self, b: &[u8]) -> Parsed<Vec<u8>> {
        let hl = self.header_len(b)?;
        let header = b.get(..hl).ok_or("data array header cut short")?;
        let words: Vec<usize> = header
            .chunks_exact(self.word)
            .map(|w| self.word_at(w))
            .collect();
        self.body(&words, &b[hl..])
    }

    /// The data given its header `words` and what follows the header (raw bytes).
    fn body(&self, words: &[usize], rest: &[u8]) -> Parsed<Vec<u8>> {
        if !self.zlib {
            return rest
                .get(..words[0])
                .map(|d| d.to_vec())
                .ok_or_else(|| "data array shorter than its byte count".into());
        }
        let (blocks, size, last) = (words[0], words[1], words[2]);
        // No allocation from the header's sizes: a damaged header must not ask for terabytes.
        let mut out = Vec::new();
        let mut at = 0usize;
        for (k, &c) in words[3..].iter().enumerate() {
            let block = at
                .checked_add(c)
                .and_then(|end| rest.get(at..end))
                .ok_or("compressed data shorter than its block sizes")?;
            let want = if k + 1 == blocks && last != 0 {
                last
            } else {
                size
            };
            let before = out.len();
            flate2::read::ZlibDecoder::new(block)
                .take(want as u64)
                .read_to_end(&mut out)
                .map_err(|e| format!("corrupt zlib block ({e})"))?;
            if out.len() - before != want {
                return Err("a zlib block is shorter than the header says".into());
            }
            at += c;
        }
        Ok(out)
    }

    /// A base64 text holding the header and the data, each encoded on its own.
    fn base64_data(&self, text: &[u8]) -> Parsed<Vec<u8>> {
        let text: Vec<u8> = text
            .iter()
            .copied()
            .filter(|c| !c.is_ascii_whitespace())
            .collect();
        let b64 = |s: &[u8]| {
            base64::engine::general_purpose::STANDARD
                .decode(s)
                .map_err(|e| format!("bad base64 data ({e})"))
        };
        // Characters of a separately encoded chunk of n bytes.
        let chars = |n: usize| n.div_ceil(3).saturating_mul(4);
        // The first word: the byte count, or with zlib the block count. (Decoding a prefix of
        // whole 4-character groups gives the first bytes of a longer chunk.)
        let first = b64(text.get(..chars(self.word)).ok_or("data array cut short")?)?;
        if !self.zlib {
            // Uncompressed, VTK encodes the byte count and the data as one chunk.
            let n = self.word_at(&first);
            let all = b64(text
                .get(..chars(self.word.saturating_add(n)))
                .ok_or("data array shorter than its byte count")?)?;
            return Ok(all[self.word..self.word + n].to_vec());
        }
        // Compressed, the header is a chunk of its own, then the blocks are one more.
        let hl = self.header_len(&first)?;
        let hc = chars(hl);
        let header = b64(text.get(..hc).ok_or("data array header cut short")?)?;
        let words: Vec<usize> = header[..hl]
            .chunks_exact(self.word)
            .map(|w| self.word_at(w))
            .collect();
        // The data chunk: as many characters as its encoded length (appended data runs on).
        let n = words[3..].iter().fold(0usize, |a, w| a.saturating_add(*w));
        let body = b64(text
            .get(hc..hc.saturating_add(chars(n)))
            .ok_or("data array shorter than its byte count")?)?;
        self.body(&words, &body)
    }
}

/// One `<DataArray>` or `<Array>` element: its opening tag and its text.
struct Element<'a> {
    tag: &'a str,
    text: &'a str,
}

/// Every element named `name` in `sec`.
fn elements<'a>(sec: &'a str, name: &str) -> Parsed<Vec<Element<'a>>> {
    let (open, close) = (format!("<{name}"), format!("</{name}>"));
    let mut out = Vec::new();
    let mut rest = sec;
    while let Some(s) = rest.find(&open) {
        let tag_end = rest[s..].find('>').ok_or("unterminated data array")? + s;
        let tag = &rest[s..tag_end];
        if tag.ends_with('/') {
            out.push(Element { tag, text: "" });
            rest = &rest[tag_end..];
            continue;
        }
        let end = rest[tag_end..]
            .find(&close)
            .ok_or("unterminated data array")?
            + tag_end;
        // VTK writes child elements (InformationKey, with numbers of their own) after ASCII
        // data and before binary data: the data is the text on either side of the children.
        let inner = &rest[tag_end + 1..end];
        let text = match (inner.find('<'), inner.rfind('>')) {
            (Some(a), Some(_)) if !inner[..a].trim().is_empty() => &inner[..a],
            (Some(_), Some(b)) => &inner[b + 1..],
            _ => inner,
        };
        out.push(Element { tag, text });
        rest = &rest[end..];
    }
    Ok(out)
}

/// The values of a numeric array as f64.
fn numbers(e: &Element, layout: &Layout) -> Parsed<Vec<f64>> {
    let ty = attr(e.tag, "type").ok_or("data array without a type")?;
    let name = attr(e.tag, "Name").unwrap_or("?");
    if attr(e.tag, "format") == Some("ascii") {
        return e
            .text
            .split_whitespace()
            .map(|w| {
                w.parse::<f64>()
                    .map_err(|_| format!("'{w}' is not a number in {name}"))
            })
            .collect();
    }
    let bytes = raw(e, layout)?;
    let size = match ty {
        "Int8" | "UInt8" => 1,
        "Int16" | "UInt16" => 2,
        "Int32" | "UInt32" | "Float32" => 4,
        "Int64" | "UInt64" | "Float64" => 8,
        _ => return Err(format!("data array {name} has unsupported type {ty}")),
    };
    if bytes.len() % size != 0 {
        return Err(format!(
            "data array {name}: {} bytes is not a whole number of {ty}",
            bytes.len()
        ));
    }
    Ok(bytes
        .chunks_exact(size)
        .map(|c| {
            let mut b = [0u8; 8];
            if layout.big_endian {
                b[8 - size..].copy_from_slice(c);
                b[8 - size..].reverse();
            } else {
                b[..size].copy_from_slice(c);
            }
            let u = u64::from_le_bytes(b);
            match ty {
                "Int8" => u as u8 as i8 as f64,
                "UInt8" => u as u8 as f64,
                "Int16" => u as u16 as i16 as f64,
                "UInt16" => u as u16 as f64,
                "Int32" => u as u32 as i32 as f64,
                "UInt32" => u as u32 as f64,
                "Float32" => f32::from_bits(u as u32) as f64,
                "Int64" => u as i64 as f64,
                "UInt64" => u as f64,
                _ => f64::from_bits(u),
            }
        })
        .collect())
}

/// The decoded bytes of a binary or appended array.
fn raw(e: &Element, layout: &Layout) -> Parsed<Vec<u8>> {
    let name = attr(e.tag, "Name").unwrap_or("?");
    match attr(e.tag, "format") {
        Some("binary") => layout.base64_data(e.text.as_bytes()),
        Some("appended") => {
            let (data, base64) = layout.appended.ok_or_else(|| {
                format!("data array {name} is appended but there is no <AppendedData>")
            })?;
            let offset: usize = attr(e.tag, "offset")
                .and_then(|o| o.trim().parse().ok())
                .ok_or_else(|| format!("appended data array {name} without an offset"))?;
            let at = data.get(offset..).ok_or_else(|| {
                format!("data array {name}: offset {offset} beyond the appended data")
            })?;
            if base64 {
                layout.base64_data(at)
            } else {
                layout.data(at)
            }
        }
        other => Err(format!(
            "data array {name} has format {other:?} (expected ascii, binary or appended)"
        )),
    }
}

/// The strings of a String array: each ended by a 0 byte (ASCII: as character codes).
fn strings(e: &Element, layout: &Layout) -> Parsed<Vec<String>> {
    let bytes: Vec<u8> = if attr(e.tag, "format") == Some("ascii") {
        e.text
            .split_whitespace()
            .map(|w| {
                w.parse::<u8>()
                    .map_err(|_| format!("'{w}' is not a character code"))
            })
            .collect::<Parsed<_>>()?
    } else {
        raw(e, layout)?
    };
    Ok(bytes
        .split(|b| *b == 0)
        .filter(|s| !s.is_empty())
        .map(|s| String::from_utf8_lossy(s).into_owned())
        .collect())
}

fn parse(bytes: &[u8]) -> Parsed<Vtp> {
    // The XML ends where appended raw data begins; only that part must be text.
    let xml_end = find(bytes, b"<AppendedData").unwrap_or(bytes.len());
    let text = std::str::from_utf8(&bytes[..xml_end])
        .map_err(|_| "not a VTK XML file (not text before <AppendedData>)")?;
    let end = bytes.trim_ascii_end();
    if !end.ends_with(b"</VTKFile>") {
        return Err("file cut short (it does not end with </VTKFile>)".into());
    }
    let head_start = text.find("<VTKFile").ok_or("not a VTK XML PolyData file")?;
    let head = &text[head_start..head_start + text[head_start..].find('>').unwrap_or(0)];
    if attr(head, "type") != Some("PolyData") {
        return Err("not a VTK XML PolyData file".into());
    }
    let word = match attr(head, "header_type") {
        None | Some("UInt32") => 4,
        Some("UInt64") => 8,
        Some(t) => return Err(format!("unsupported header_type {t}")),
    };
    let zlib = match attr(head, "compressor") {
        None | Some("") => false,
        Some("vtkZLibDataCompressor") => true,
        Some(c) => {
            return Err(format!(
                "compressor {c} is not supported (only vtkZLibDataCompressor): save without compression or with zlib"
            ));
        }
    };
    let appended = match bytes[xml_end..].iter().position(|b| *b == b'>') {
        Some(gt) if xml_end < bytes.len() => {
            let tag = String::from_utf8_lossy(&bytes[xml_end..xml_end + gt]).into_owned();
            let rest = &bytes[xml_end + gt + 1..];
            let mark = rest
                .iter()
                .position(|b| *b == b'_')
                .ok_or("<AppendedData> without its '_' mark")?;
            Some((&rest[mark + 1..], attr(&tag, "encoding") == Some("base64")))
        }
        _ => None,
    };
    let layout = Layout {
        big_endian: attr(head, "byte_order") == Some("BigEndian"),
        word,
        zlib,
        appended,
    };

    // An element's opening tag may carry attributes (`<PointData Vectors="…">`).
    let section = |name: &str| -> Option<&str> {
        let open = format!("<{name}");
        let s = text.match_indices(&open).map(|(i, _)| i).find(|&i| {
            matches!(
                text.as_bytes().get(i + open.len()),
                Some(b'>' | b' ' | b'\n' | b'\r' | b'\t')
            )
        })?;
        let e = text[s..].find(&format!("</{name}>"))? + s;
        Some(&text[s..e])
    };
    let piece_start = text.find("<Piece").ok_or("no <Piece>")?;
    let piece = &text[piece_start..];
    let piece_tag = &piece[..piece.find('>').unwrap_or(0)];
    if attr(piece_tag, "NumberOfStrips").is_some_and(|n| n.trim() != "0") {
        return Err(
            "triangle strips are not supported: save the model without strips (or as .vtk)".into(),
        );
    }
    let points = elements(section("Points").ok_or("no <Points>")?, "DataArray")?;
    let p = numbers(points.first().ok_or("no point coordinates")?, &layout)?;
    let mut mesh = Mesh {
        vertices: p.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        ..Mesh::default()
    };
    if let Some(polys) = section("Polys") {
        let a = elements(polys, "DataArray")?;
        let find = |n: &str| -> Parsed<Vec<f64>> {
            let e = a
                .iter()
                .find(|e| attr(e.tag, "Name") == Some(n))
                .ok_or_else(|| format!("Polys without {n}"))?;
            numbers(e, &layout)
        };
        let con = find("connectivity")?;
        let mut start = 0usize;
        for o in find("offsets")? {
            let end = o as usize;
            let ids = con.get(start..end).ok_or("offsets out of range")?;
            for k in 1..ids.len().saturating_sub(1) {
                mesh.triangles
                    .push([ids[0] as u32, ids[k] as u32, ids[k + 1] as u32]);
            }
            start = end;
        }
    }
    let mut point_data = Vec::new();
    if let Some(pd) = section("PointData") {
        for e in elements(pd, "DataArray")? {
            point_data.push(PointArray {
                name: attr(e.tag, "Name").unwrap_or_default().to_string(),
                components: attr(e.tag, "NumberOfComponents")
                    .and_then(|c| c.parse().ok())
                    .unwrap_or(1),
                values: numbers(&e, &layout)?,
            });
        }
    }
    let mut field_strings = Vec::new();
    if let Some(fd) = section("FieldData") {
        for e in elements(fd, "Array")? {
            if attr(e.tag, "type") == Some("String") {
                let name = attr(e.tag, "Name").unwrap_or_default().to_string();
                field_strings.push((name, strings(&e, &layout)?));
            }
        }
    }
    let n = mesh.vertices.len();
    if mesh.triangles.iter().flatten().any(|i| *i as usize >= n) {
        return Err("a cell refers to a point beyond the points".into());
    }
    Ok(Vtp {
        mesh,
        point_data,
        field_strings,
    })
}

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ascii_round_trip_with_point_data_and_space() {
        let dir = tempfile::tempdir().unwrap();
        let mesh = crate::mesh::two_triangles();
        let a = crate::mesh::vtk::test_displacement();
        let p = dir.path().join("m.vtp");
        write_vtp(&mesh, std::slice::from_ref(&a), &p).unwrap();
        let v = read(&p).unwrap();
        assert_eq!(v.mesh.vertices, mesh.vertices);
        assert_eq!(v.mesh.triangles, mesh.triangles);
        assert_eq!(v.point_data, vec![a]);
        assert_eq!(v.space(), Some("LPS"));
    }

    #[test]
    fn zlib_header_words_and_blocks() {
        // Two blocks of 8 and 4 bytes (block size 8, last 4), UInt32 little-endian header.
        let data: Vec<u8> = (0u8..12).collect();
        let z = |b: &[u8]| {
            use std::io::Write;
            let mut e = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
            e.write_all(b).unwrap();
            e.finish().unwrap()
        };
        let (c1, c2) = (z(&data[..8]), z(&data[8..]));
        let mut b = Vec::new();
        for w in [2u32, 8, 4, c1.len() as u32, c2.len() as u32] {
            b.extend(w.to_le_bytes());
        }
        b.extend(&c1);
        b.extend(&c2);
        let layout = Layout {
            big_endian: false,
            word: 4,
            zlib: true,
            appended: None,
        };
        assert_eq!(layout.data(&b).unwrap(), data);
        // Cut inside the second block: one line, no panic.
        assert!(layout.data(&b[..b.len() - 3]).is_err());
        // Absurd counts and sizes (a damaged header) are refused without allocating them.
        let mut huge = b.clone();
        huge[..4].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(layout.data(&huge).is_err());
        let mut huge = b.clone();
        huge[12..16].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(layout.data(&huge).is_err());
        let wide = Layout { word: 8, ..layout };
        let mut b8 = Vec::new();
        for w in [u64::MAX, 8, 4, u64::MAX, 1] {
            b8.extend(w.to_le_bytes());
        }
        assert!(wide.data(&b8).is_err());
        b8[..8].copy_from_slice(&2u64.to_le_bytes());
        assert!(wide.data(&b8).is_err());
    }
}
