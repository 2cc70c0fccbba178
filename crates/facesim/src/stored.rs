//! The framing of facesim's binary files (plan_basis.bin, reduced_model.bin; docs/design/plan-basis.md
//! "File format", docs/design/reduced.md "The stored model"), little-endian:
//!
//! ```text
//! magic        8 bytes
//! format       u32
//! version len  u32, then the facesim version (UTF-8) that wrote it
//! header len   u32, then a JSON header (UTF-8)
//! zero padding to a multiple of 8 bytes, then the file's arrays
//! ```
//!
//! Reading checks the magic, the format version and the facesim version; every short read is
//! one line naming the file.

use crate::error::{Error, Result};
use std::path::Path;

/// Zero bytes that bring `len` to a multiple of 8.
pub(crate) fn pad8(len: usize) -> usize {
    (8 - len % 8) % 8
}

/// The file's head: magic, format, the facesim version that wrote it, the JSON header and the
/// padding.
pub(crate) fn head(magic: &[u8; 8], format: u32, version: &str, json: &[u8]) -> Vec<u8> {
    let version = version.as_bytes();
    let mut head = Vec::with_capacity(24 + version.len() + json.len());
    head.extend_from_slice(magic);
    head.extend_from_slice(&format.to_le_bytes());
    head.extend_from_slice(&(version.len() as u32).to_le_bytes());
    head.extend_from_slice(version);
    head.extend_from_slice(&(json.len() as u32).to_le_bytes());
    head.extend_from_slice(json);
    head.resize(head.len() + pad8(head.len()), 0);
    head
}

/// Points as little-endian f64 triples.
pub(crate) fn point_bytes(v: &[[f64; 3]]) -> Vec<u8> {
    let mut buf = Vec::with_capacity(24 * v.len());
    for c in v.iter().flatten() {
        buf.extend_from_slice(&c.to_le_bytes());
    }
    buf
}

/// A cursor over a file's bytes whose every short read is an error naming the file.
pub(crate) struct Reader<'a> {
    pub path: &'a Path,
    /// What the file is, in messages ("plan basis").
    pub kind: &'a str,
    pub bytes: &'a [u8],
    pub at: usize,
}

impl<'a> Reader<'a> {
    /// Check the head (magic, format, version) and return the reader after the padding, with
    /// the facesim version and the JSON header.
    pub fn open(
        path: &'a Path,
        kind: &'a str,
        bytes: &'a [u8],
        magic: &[u8; 8],
        format: u32,
    ) -> Result<(Reader<'a>, String, &'a [u8])> {
        let mut r = Reader {
            path,
            kind,
            bytes,
            at: 0,
        };
        if r.take(8, "the magic bytes")? != magic {
            return Err(Error::input(
                path,
                format!("not a facesim {kind} (wrong magic bytes)"),
            ));
        }
        let found = r.u32("the format version")?;
        if found != format {
            return Err(Error::input(
                path,
                format!("{kind} format version {found}, this facesim reads version {format}"),
            ));
        }
        let vlen = r.u32("the facesim version")? as usize;
        let version = String::from_utf8_lossy(r.take(vlen, "the facesim version")?).to_string();
        let ours = env!("CARGO_PKG_VERSION");
        if version != ours {
            return Err(Error::input(
                path,
                format!(
                    "{kind} written by facesim {version}, this is facesim {ours}: run the case again"
                ),
            ));
        }
        let hlen = r.u32("the header")? as usize;
        let header = r.take(hlen, "the header")?;
        let pad = pad8(r.at);
        r.take(pad, "the padding")?;
        Ok((r, version, header))
    }

    pub fn take(&mut self, len: usize, what: &str) -> Result<&'a [u8]> {
        let end = self.at.checked_add(len).filter(|e| *e <= self.bytes.len());
        let Some(end) = end else {
            return Err(Error::input(
                self.path,
                format!(
                    "truncated {}: {what} is cut off at byte {}",
                    self.kind,
                    self.bytes.len()
                ),
            ));
        };
        let b = &self.bytes[self.at..end];
        self.at = end;
        Ok(b)
    }

    pub fn u32(&mut self, what: &str) -> Result<u32> {
        let b = self.take(4, what)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    pub fn points(&mut self, n: usize, what: &str) -> Result<Vec<[f64; 3]>> {
        let len = n
            .checked_mul(24)
            .ok_or_else(|| Error::input(self.path, format!("{}: {what} too large", self.kind)))?;
        let b = self.take(len, what)?;
        let f = |i: usize| {
            let mut a = [0u8; 8];
            a.copy_from_slice(&b[8 * i..8 * i + 8]);
            f64::from_le_bytes(a)
        };
        Ok((0..n)
            .map(|v| [f(3 * v), f(3 * v + 1), f(3 * v + 2)])
            .collect())
    }

    /// Error unless every byte was read.
    pub fn finish(&self, after: &str) -> Result<()> {
        if self.at != self.bytes.len() {
            return Err(Error::input(
                self.path,
                format!(
                    "{}: {} bytes after {after} (corrupt or wrong sizes)",
                    self.kind,
                    self.bytes.len() - self.at
                ),
            ));
        }
        Ok(())
    }
}

/// The file's bytes; a missing file says `missing`.
pub(crate) fn read_bytes(path: &Path, missing: &str) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|e| {
        Error::input(
            path,
            if e.kind() == std::io::ErrorKind::NotFound {
                missing.to_string()
            } else {
                e.to_string()
            },
        )
    })
}
