//! Raw voxel samples to values: the one decoder of the readers that take raw voxels.

/// Voxel values from raw samples `width` bytes wide, of `kind` 'i' (signed integer), 'u'
/// (unsigned) or 'f' (float; 8 bytes: double), little-endian unless `big`: the one decoder of
/// the readers that take raw voxels (NRRD, InVesalius, vtk.js), each mapping its own type names
/// to (kind, width).
pub(crate) fn decode_samples(raw: &[u8], kind: char, width: usize, big: bool) -> Vec<f32> {
    let value = |c: &[u8]| -> f32 {
        let mut b = [0u8; 8];
        b[..width].copy_from_slice(c);
        if big {
            b[..width].reverse();
        }
        match (kind, width) {
            ('i', 1) => b[0] as i8 as f32,
            ('u', 1) => b[0] as f32,
            ('i', 2) => i16::from_le_bytes([b[0], b[1]]) as f32,
            ('u', 2) => u16::from_le_bytes([b[0], b[1]]) as f32,
            ('i', 4) => i32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f32,
            ('u', 4) => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f32,
            ('f', 4) => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            _ => f64::from_le_bytes(b) as f32,
        }
    };
    raw.chunks_exact(width).map(value).collect()
}
