//! Binary ray and hit files (little-endian, headerless, fixed-size records; see README).

use std::path::Path;

use crate::error::{Error, Result};
use crate::geom::{Hit, Ray};

/// Reads a ray file: 32-byte records `ox oy oz tmin dx dy dz tmax` (f32 LE).
pub fn read_rays(path: &Path) -> Result<Vec<Ray>> {
    let bytes = std::fs::read(path).map_err(|source| Error::Io { path: path.into(), source })?;
    rays_from_bytes(&bytes).map_err(|message| Error::InvalidInput(format!("{}: {message}", path.display())))
}

/// Parses ray records; the length must be a multiple of 32 bytes.
pub fn rays_from_bytes(bytes: &[u8]) -> std::result::Result<Vec<Ray>, String> {
    if bytes.len() % 32 != 0 {
        return Err(format!(
            "size {} is not a multiple of the 32-byte ray record ({} trailing bytes)",
            bytes.len(),
            bytes.len() % 32
        ));
    }
    Ok(bytes
        .chunks_exact(32)
        .map(|r| {
            let f = |i: usize| f32::from_le_bytes([r[4 * i], r[4 * i + 1], r[4 * i + 2], r[4 * i + 3]]);
            Ray { origin: [f(0), f(1), f(2)], tmin: f(3), dir: [f(4), f(5), f(6)], tmax: f(7) }
        })
        .collect())
}

/// Writes rays as 32-byte records.
pub fn write_rays(path: &Path, rays: &[Ray]) -> Result<()> {
    let bytes: Vec<u8> = rays
        .iter()
        .flat_map(|r| [r.origin[0], r.origin[1], r.origin[2], r.tmin, r.dir[0], r.dir[1], r.dir[2], r.tmax])
        .flat_map(f32::to_le_bytes)
        .collect();
    std::fs::write(path, bytes).map_err(|source| Error::Io { path: path.into(), source })
}

/// Writes hits as 16-byte records `t prim_id u v`.
pub fn write_hits(path: &Path, hits: &[Hit]) -> Result<()> {
    let mut bytes = Vec::with_capacity(hits.len() * 16);
    for h in hits {
        bytes.extend_from_slice(&h.t.to_le_bytes());
        bytes.extend_from_slice(&h.prim_id.to_le_bytes());
        bytes.extend_from_slice(&h.u.to_le_bytes());
        bytes.extend_from_slice(&h.v.to_le_bytes());
    }
    std::fs::write(path, bytes).map_err(|source| Error::Io { path: path.into(), source })
}

/// Reads a hit file.
pub fn read_hits(path: &Path) -> Result<Vec<Hit>> {
    let bytes = std::fs::read(path).map_err(|source| Error::Io { path: path.into(), source })?;
    if bytes.len() % 16 != 0 {
        return Err(Error::InvalidInput(format!(
            "{}: size {} is not a multiple of the 16-byte hit record",
            path.display(),
            bytes.len()
        )));
    }
    Ok(bytes
        .chunks_exact(16)
        .map(|r| {
            let w = |i: usize| [r[4 * i], r[4 * i + 1], r[4 * i + 2], r[4 * i + 3]];
            Hit {
                t: f32::from_le_bytes(w(0)),
                prim_id: u32::from_le_bytes(w(1)),
                u: f32::from_le_bytes(w(2)),
                v: f32::from_le_bytes(w(3)),
            }
        })
        .collect())
}
