//! The wire form of a board's maps: a small header, then a deflate stream of the stencil as
//! a bit mask and, for covered pixels only, 16-bit depth (quantised over the board's depth
//! range), RGBA8 colour and octahedral normals in two bytes. Planes are stored one after
//! another (all depths, then all colours, ...), which deflate compresses better than
//! interleaved pixels.

use std::io::Read;

use glam::{DVec3, Vec2, Vec3};

use crate::raster::{Basis, Maps};

const MAGIC: &[u8; 4] = b"RBB1";
/// magic, size, 13 f64 of basis, depth min and max.
const HEADER_BYTES: usize = 4 + 4 + 13 * 8 + 2 * 4;

thread_local! {
    /// One compressor per thread, reset between boards: making one allocates and clears
    /// its tables, which on a 64-pixel board costs as much as compressing it.
    static DEFLATE: std::cell::RefCell<flate2::Compress> =
        std::cell::RefCell::new(flate2::Compress::new(flate2::Compression::fast(), false));
}

/// Appends `payload` to `out` as a raw deflate stream (what `DeflateDecoder` reads).
fn deflate_into(payload: &[u8], out: &mut Vec<u8>) {
    DEFLATE.with(|compress| {
        let mut compress = compress.borrow_mut();
        compress.reset();
        let start_in = compress.total_in();
        loop {
            out.reserve(payload.len() / 2 + 1024);
            let read = (compress.total_in() - start_in) as usize;
            // Writing into a Vec with room cannot fail; a stream error would leave the
            // board short, which the decoder refuses.
            match compress.compress_vec(&payload[read..], out, flate2::FlushCompress::Finish) {
                Ok(flate2::Status::StreamEnd) | Err(_) => break,
                Ok(_) => {}
            }
        }
    });
}

/// A board's maps, encoded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EncodedBoard {
    /// The bytes.
    pub bytes: Vec<u8>,
}

/// Why bytes are not a board.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum DecodeError {
    /// Wrong magic or too short for the header.
    #[error("not an encoded board (bad header)")]
    BadHeader,
    /// A side of zero or above the maximum.
    #[error("board side {0} out of range")]
    BadSize(u32),
    /// The compressed payload is broken or of the wrong length.
    #[error("corrupt board payload: {0}")]
    Corrupt(String),
}

impl EncodedBoard {
    /// Encodes maps.
    pub fn encode(maps: &Maps) -> EncodedBoard {
        let covered: Vec<usize> = (0..maps.stencil.len())
            .filter(|&i| maps.stencil[i])
            .collect();
        let (mut low, mut high) = (f32::INFINITY, f32::NEG_INFINITY);
        for &i in &covered {
            low = low.min(maps.depth[i]);
            high = high.max(maps.depth[i]);
        }
        if covered.is_empty() {
            (low, high) = (0.0, 0.0);
        }
        let mut bytes = Vec::with_capacity(HEADER_BYTES + covered.len() * 8);
        bytes.extend_from_slice(MAGIC);
        bytes.extend_from_slice(&maps.size.to_le_bytes());
        let b = &maps.basis;
        let basis_values = [
            b.center.to_array(),
            [b.radius; 3],
            b.right.to_array(),
            b.up.to_array(),
            b.forward.to_array(),
        ];
        // Centre (3), radius (1), right, up, forward (3 each): 13 values.
        for value in basis_values
            .iter()
            .enumerate()
            .flat_map(|(k, v)| &v[..if k == 1 { 1 } else { 3 }])
        {
            bytes.extend_from_slice(&value.to_le_bytes());
        }
        bytes.extend_from_slice(&low.to_le_bytes());
        bytes.extend_from_slice(&high.to_le_bytes());

        let mut payload = Vec::with_capacity(maps.stencil.len() / 8 + covered.len() * 8);
        let mut mask = vec![0u8; maps.stencil.len().div_ceil(8)];
        for &i in &covered {
            mask[i / 8] |= 1 << (i % 8);
        }
        payload.extend_from_slice(&mask);
        let scale = if high > low {
            65535.0 / (high - low)
        } else {
            0.0
        };
        for &i in &covered {
            let q = quantise((maps.depth[i] - low) * scale, 65535.0) as u16;
            payload.extend_from_slice(&q.to_le_bytes());
        }
        for &i in &covered {
            payload.extend_from_slice(&maps.color[i]);
        }
        for &i in &covered {
            payload.extend_from_slice(&octahedral_encode(Vec3::from_array(maps.normal[i])));
        }
        deflate_into(&payload, &mut bytes);
        EncodedBoard { bytes }
    }

    /// Bytes of the same maps uncompressed at full precision: f32 depth, a stencil byte,
    /// RGBA8 colour and three f32 normal components per pixel.
    pub fn raw_bytes(size: u32) -> usize {
        (size as usize).pow(2) * (4 + 1 + 4 + 12)
    }

    /// Decodes, checking every length before allocating.
    pub fn decode(&self) -> Result<Maps, DecodeError> {
        let bytes = &self.bytes;
        if bytes.len() < HEADER_BYTES || &bytes[..4] != MAGIC {
            return Err(DecodeError::BadHeader);
        }
        let size = u32::from_le_bytes([bytes[4], bytes[5], bytes[6], bytes[7]]);
        if size == 0 || size > crate::MAX_MAP_SIZE {
            return Err(DecodeError::BadSize(size));
        }
        let f64_at = |k: usize| {
            let at = 8 + k * 8;
            f64::from_le_bytes(bytes[at..at + 8].try_into().unwrap_or([0; 8]))
        };
        let vector = |k: usize| DVec3::new(f64_at(k), f64_at(k + 1), f64_at(k + 2));
        let basis = Basis {
            center: vector(0),
            radius: f64_at(3),
            right: vector(4),
            up: vector(7),
            forward: vector(10),
        };
        basis
            .check()
            .map_err(|why| DecodeError::Corrupt(format!("bad basis: {why}")))?;
        let f32_at = |at: usize| f32::from_le_bytes(bytes[at..at + 4].try_into().unwrap_or([0; 4]));
        let (low, high) = (f32_at(8 + 13 * 8), f32_at(12 + 13 * 8));
        // Depth is z in the unit sphere's frame: [-1, 1], with room for rounding.
        if !(low >= -1.01 && high <= 1.01 && high >= low) {
            return Err(DecodeError::Corrupt(format!(
                "bad depth range {low}..{high}"
            )));
        }
        let pixels = (size as usize).pow(2);
        let mask_len = pixels.div_ceil(8);
        // Read at most the largest payload a board of this size can have, plus one byte to
        // notice a longer one.
        let limit = (mask_len + pixels * 8 + 1) as u64;
        let mut payload = Vec::new();
        flate2::read::DeflateDecoder::new(&bytes[HEADER_BYTES..])
            .take(limit)
            .read_to_end(&mut payload)
            .map_err(|e| DecodeError::Corrupt(e.to_string()))?;
        if payload.len() < mask_len {
            return Err(DecodeError::Corrupt("stencil cut short".into()));
        }
        let stencil: Vec<bool> = (0..pixels)
            .map(|i| payload[i / 8] & (1 << (i % 8)) != 0)
            .collect();
        let covered: Vec<usize> = (0..pixels).filter(|&i| stencil[i]).collect();
        if payload.len() != mask_len + covered.len() * 8 {
            return Err(DecodeError::Corrupt(format!(
                "payload of {} bytes for {} covered pixels",
                payload.len(),
                covered.len()
            )));
        }
        let (depths, rest) = payload[mask_len..].split_at(covered.len() * 2);
        let (colors, normals) = rest.split_at(covered.len() * 4);
        let mut maps = Maps {
            size,
            basis,
            depth: vec![f32::NAN; pixels],
            stencil,
            color: vec![[0; 4]; pixels],
            normal: vec![[0.0; 3]; pixels],
        };
        for (k, &i) in covered.iter().enumerate() {
            let q = u16::from_le_bytes([depths[2 * k], depths[2 * k + 1]]);
            maps.depth[i] = low + q as f32 / 65535.0 * (high - low);
            maps.color[i] = [
                colors[4 * k],
                colors[4 * k + 1],
                colors[4 * k + 2],
                colors[4 * k + 3],
            ];
            maps.normal[i] = octahedral_decode([normals[2 * k], normals[2 * k + 1]]).to_array();
        }
        Ok(maps)
    }
}

/// A unit vector in two bytes (Cigolle et al. 2014): project onto the octahedron, fold the
/// lower half over, quantise.
fn octahedral_encode(n: Vec3) -> [u8; 2] {
    let n = n / (n.x.abs() + n.y.abs() + n.z.abs()).max(1e-12);
    let mut p = Vec2::new(n.x, n.y);
    if n.z < 0.0 {
        p = (Vec2::ONE - Vec2::new(p.y.abs(), p.x.abs())) * Vec2::new(sign(p.x), sign(p.y));
    }
    p.to_array()
        .map(|c| quantise((c * 0.5 + 0.5) * 255.0, 255.0) as u8)
}

/// `x` rounded to the nearest integer in `[0, max]` (halves up). Not `f32::round`: a libm
/// call on x86-64's baseline, 1% of a tree's 256-pixel board.
fn quantise(x: f32, max: f32) -> u32 {
    (x.clamp(0.0, max) + 0.5) as u32
}

fn octahedral_decode(bytes: [u8; 2]) -> Vec3 {
    let p = Vec2::new(bytes[0] as f32, bytes[1] as f32) / 255.0 * 2.0 - Vec2::ONE;
    let mut n = Vec3::new(p.x, p.y, 1.0 - p.x.abs() - p.y.abs());
    if n.z < 0.0 {
        let folded =
            (Vec2::ONE - Vec2::new(n.y.abs(), n.x.abs())) * Vec2::new(sign(n.x), sign(n.y));
        n.x = folded.x;
        n.y = folded.y;
    }
    n.normalize_or_zero()
}

fn sign(v: f32) -> f32 {
    if v >= 0.0 { 1.0 } else { -1.0 }
}

#[cfg(test)]
mod tests {
    use super::quantise;

    #[test]
    fn quantise_rounds_halves_up_and_clamps_into_its_range() {
        let cases = [
            (0.49, 0),
            (0.5, 1),
            (1.5, 2),
            (2.5, 3),
            (254.4, 254),
            (254.6, 255),
            (300.0, 255),
            (-3.0, 0),
            (f32::NAN, 0),
        ];
        for (x, expected) in cases {
            assert_eq!(quantise(x, 255.0), expected, "{x}");
        }
        assert_eq!(quantise(65534.5, 65535.0), 65535);
    }
}
