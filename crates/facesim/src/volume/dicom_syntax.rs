//! Which DICOM transfer syntaxes facesim decodes, and their names for messages.
//!
//! The decoders are dicom-pixeldata's codec features (Cargo.toml): `jpeg` (jpeg-decoder: JPEG
//! baseline and lossless process 14 / SV1), `rle` (RLE Lossless), `openjpeg-sys` (OpenJPEG,
//! built from C: JPEG 2000 and HTJ2K), `deflate`, and, with facesim's feature `jpeg-ls`, CharLS
//! (JPEG-LS). A syntax the registry only knows by name (a stub) is refused before any pixel is
//! read. The table of syntaxes, decoders, licences and tests is docs/guide/dicom.md.

use dicom_encoding::TransferSyntaxIndex;
use dicom_transfer_syntax_registry::TransferSyntaxRegistry;

/// `uid` with its standard name, e.g. `1.2.840.10008.1.2.4.70 (JPEG Lossless, Non-Hierarchical,
/// First-Order Prediction)`; unknown UIDs are said to be unknown.
pub(crate) fn describe(uid: &str) -> String {
    match TransferSyntaxRegistry.get(uid) {
        Some(ts) => format!("{uid} ({})", ts.name()),
        None => format!("{uid} (not a transfer syntax this DICOM library knows)"),
    }
}

/// Whether the pixel data of transfer syntax `uid` can be decoded; `Err` says why not in words
/// that fit after the file's name.
pub(crate) fn check_decodable(uid: &str) -> std::result::Result<(), String> {
    match TransferSyntaxRegistry.get(uid) {
        Some(ts) if ts.can_decode_all() => Ok(()),
        _ => Err(format!(
            "transfer syntax {} is not decoded by facesim (docs/guide/dicom.md lists those that are); \
             convert the series first, e.g. `gdcmconv --raw IN OUT`",
            describe(uid)
        )),
    }
}
