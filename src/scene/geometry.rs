//! Geometry as engines hold it: positions in a (possibly interleaved) vertex
//! buffer or a `&[Vec3]`, optional `u16`/`u32` indices, several geometries per
//! scene with the caller's ids, each placed by an optional 3×4 transform.
//!
//! [`Scene::from_geometries`] numbers the triangles in scene order: geometry by
//! geometry in the order given, each in its own triangle order (three indices,
//! or three vertices, per triangle). That number is the `prim_id` of hits, and
//! [`Scene::locate`] turns it back into (instance, geometry, triangle within the
//! geometry).
//!
//! Today the tracer holds one kd-tree over all triangles: a transformed
//! geometry is transformed on the CPU (f32, `Affine3A::transform_point3`) and
//! a geometry used twice is stored twice. Two-level traversal with shared
//! trees is not built yet (issue 29, items 2-5).

use glam::{Affine3A, Vec3};

use super::{Material, Scene};
use crate::error::{Error, Result};

/// Where a geometry's vertex positions are.
#[derive(Clone, Copy, Debug)]
pub enum Positions<'a> {
    /// One `Vec3` per vertex.
    Vec3(&'a [Vec3]),
    /// `count` vertices in a byte buffer: vertex `i`'s position is three
    /// little-endian `f32` at `offset + i * stride` (an interleaved vertex
    /// buffer: position, normal, uv… in one record). No alignment is needed.
    Strided {
        /// The vertex buffer's bytes.
        bytes: &'a [u8],
        /// Byte offset of the first vertex's position.
        offset: usize,
        /// Bytes from one vertex to the next (at least 12).
        stride: usize,
        /// Number of vertices.
        count: usize,
    },
}

/// A geometry's index buffer: three indices per triangle.
#[derive(Clone, Copy, Debug, Default)]
pub enum Indices<'a> {
    /// No index buffer: vertices 3i, 3i+1, 3i+2 form triangle i.
    #[default]
    None,
    /// 16-bit indices.
    U16(&'a [u16]),
    /// 32-bit indices.
    U32(&'a [u32]),
}

/// One geometry (a mesh, or one instance of it) of a scene.
#[derive(Clone, Copy, Debug)]
pub struct Geometry<'a> {
    /// The caller's id of the geometry, reported by [`Scene::locate`].
    pub id: u32,
    /// The caller's id of this placement (instance), reported by [`Scene::locate`].
    pub instance_id: u32,
    /// The vertex positions.
    pub positions: Positions<'a>,
    /// The indices (three per triangle), or none.
    pub indices: Indices<'a>,
    /// Object to world (`None`: the identity).
    pub transform: Option<Affine3A>,
    /// Index into the materials given to [`Scene::from_geometries`].
    pub material: u32,
}

impl<'a> Geometry<'a> {
    /// A geometry of `&[Vec3]` positions, without indices, transform or material
    /// (material 0), with `instance_id` equal to `id`.
    pub fn new(id: u32, positions: &'a [Vec3]) -> Self {
        Geometry {
            id,
            instance_id: id,
            positions: Positions::Vec3(positions),
            indices: Indices::None,
            transform: None,
            material: 0,
        }
    }

    /// A geometry of `count` positions in an interleaved vertex buffer (see
    /// [`Positions::Strided`]). Fails with `Error::InvalidInput` when the stride
    /// is below 12 bytes or the last position would end past the buffer.
    pub fn strided(id: u32, bytes: &'a [u8], offset: usize, stride: usize, count: usize) -> Result<Self> {
        if stride < 12 {
            return Err(Error::InvalidInput(format!("geometry {id}: vertex stride {stride} is below 12 bytes")));
        }
        let end = count
            .checked_sub(1)
            .map(|last| last.checked_mul(stride).and_then(|b| b.checked_add(offset)).and_then(|b| b.checked_add(12)));
        match end {
            Some(Some(end)) if end <= bytes.len() => {}
            None => {}
            _ => {
                return Err(Error::InvalidInput(format!(
                    "geometry {id}: {count} vertices of stride {stride} at offset {offset} do not fit a buffer \
                     of {} bytes",
                    bytes.len()
                )))
            }
        }
        Ok(Geometry { positions: Positions::Strided { bytes, offset, stride, count }, ..Geometry::new(id, &[]) })
    }

    /// The same geometry with an index buffer.
    pub fn with_indices(self, indices: Indices<'a>) -> Self {
        Geometry { indices, ..self }
    }

    /// The same geometry placed by `transform` (object to world).
    pub fn with_transform(self, transform: Affine3A) -> Self {
        Geometry { transform: Some(transform), ..self }
    }

    /// The same geometry as instance `instance_id`.
    pub fn with_instance_id(self, instance_id: u32) -> Self {
        Geometry { instance_id, ..self }
    }

    /// The same geometry with material `material` (an index into the scene's materials).
    pub fn with_material(self, material: u32) -> Self {
        Geometry { material, ..self }
    }

    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        match self.positions {
            Positions::Vec3(p) => p.len(),
            Positions::Strided { count, .. } => count,
        }
    }

    /// Number of triangles (indices or vertices / 3; a remainder is an error in
    /// [`Scene::from_geometries`]).
    pub fn triangle_count(&self) -> usize {
        self.index_count() / 3
    }

    fn index_count(&self) -> usize {
        match self.indices {
            Indices::None => self.vertex_count(),
            Indices::U16(i) => i.len(),
            Indices::U32(i) => i.len(),
        }
    }

    /// Vertex `i`'s position in object space (`i` < `vertex_count()`).
    fn position(&self, i: usize) -> Vec3 {
        match self.positions {
            Positions::Vec3(p) => p[i],
            Positions::Strided { bytes, offset, stride, .. } => {
                let at = offset + i * stride;
                let f = |k: usize| {
                    let b = &bytes[at + 4 * k..at + 4 * k + 4];
                    f32::from_le_bytes([b[0], b[1], b[2], b[3]])
                };
                Vec3::new(f(0), f(1), f(2))
            }
        }
    }

    fn index(&self, k: usize) -> usize {
        match self.indices {
            Indices::None => k,
            Indices::U16(i) => usize::from(i[k]),
            Indices::U32(i) => i[k] as usize,
        }
    }

    /// The triangles before the transform, checked as [`Geometry::world_triangles`].
    pub(crate) fn object_triangles(&self, out: &mut Vec<[Vec3; 3]>) -> Result<()> {
        Geometry { transform: None, ..*self }.world_triangles(out)
    }

    /// The world-space triangles, checked: every index in range, every used
    /// position finite before and after the transform.
    pub(crate) fn world_triangles(&self, out: &mut Vec<[Vec3; 3]>) -> Result<()> {
        let (id, count) = (self.id, self.index_count());
        if count % 3 != 0 {
            let what = if matches!(self.indices, Indices::None) { "vertices (no indices)" } else { "indices" };
            return Err(Error::InvalidInput(format!("geometry {id}: {count} {what} is not a multiple of 3")));
        }
        if let Some(t) = self.transform {
            let m = [t.matrix3.x_axis, t.matrix3.y_axis, t.matrix3.z_axis, t.translation];
            if !m.iter().all(|c| c.is_finite()) {
                return Err(Error::InvalidInput(format!("geometry {id}: the transform is not finite: {t:?}")));
            }
        }
        let vertices = self.vertex_count();
        out.reserve(count / 3);
        for tri in 0..count / 3 {
            let mut corners = [Vec3::ZERO; 3];
            for (c, corner) in corners.iter_mut().enumerate() {
                let v = self.index(3 * tri + c);
                if v >= vertices {
                    return Err(Error::InvalidInput(format!(
                        "geometry {id}: triangle {tri} uses vertex {v}, past its {vertices} vertices"
                    )));
                }
                let p = self.position(v);
                if !p.is_finite() {
                    return Err(Error::InvalidInput(format!(
                        "geometry {id}: vertex {v} (of triangle {tri}) is not finite: {p}"
                    )));
                }
                *corner = self.transform.map_or(p, |t| t.transform_point3(p));
                if !corner.is_finite() {
                    return Err(Error::InvalidInput(format!(
                        "geometry {id}: vertex {v} (of triangle {tri}) overflows under the transform: {p} -> {corner}"
                    )));
                }
            }
            out.push(corners);
        }
        Ok(())
    }
}

/// Where a geometry's triangles sit in a scene's numbering.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GeometryRange {
    /// The caller's geometry id.
    pub geometry_id: u32,
    /// The caller's instance id.
    pub instance_id: u32,
    /// The scene's number (`prim_id`) of the geometry's first triangle.
    pub first_prim: u32,
    /// The geometry's triangle count.
    pub count: u32,
}

/// A hit's `prim_id` in the caller's terms.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PrimLocation {
    /// The instance's id.
    pub instance_id: u32,
    /// The geometry's id.
    pub geometry_id: u32,
    /// The triangle's number within its geometry.
    pub prim_index: u32,
}

impl Scene {
    /// A scene of several geometries (see the module docs for the numbering).
    /// `materials` are the materials the geometries' `material` indices name (an
    /// empty list: one default material, which every geometry must then name as 0).
    ///
    /// Errors (`Error::InvalidInput`, naming the geometry by its id and the
    /// triangle and vertex): no triangles at all; an index or vertex count that
    /// is not a multiple of 3; an index past the geometry's vertices; a position
    /// a triangle uses that is not finite, or a transform that is not finite or
    /// makes one overflow; a material index past `materials`; more triangles
    /// than hits can number. Zero-area triangles are kept (the numbering holds)
    /// and counted in `degenerate_count`; the tracer never reports them.
    pub fn from_geometries(geometries: &[Geometry], materials: Vec<Material>) -> Result<Scene> {
        let materials = if materials.is_empty() { vec![Material::default()] } else { materials };
        let mut triangles = Vec::new();
        let mut material_ids = Vec::new();
        let mut ranges = Vec::with_capacity(geometries.len());
        for g in geometries {
            if g.material as usize >= materials.len() {
                return Err(Error::InvalidInput(format!(
                    "geometry {}: material {} is past the {} materials given",
                    g.id,
                    g.material,
                    materials.len()
                )));
            }
            let first = triangles.len();
            g.world_triangles(&mut triangles)?;
            if triangles.len() >= crate::consts::PRIM_INCOMPLETE as usize {
                return Err(Error::InvalidInput(format!("too many triangles (more than {})", triangles.len())));
            }
            material_ids.resize(triangles.len(), g.material);
            ranges.push(GeometryRange {
                geometry_id: g.id,
                instance_id: g.instance_id,
                first_prim: first as u32,
                count: (triangles.len() - first) as u32,
            });
        }
        if triangles.is_empty() {
            return Err(Error::InvalidInput("scene has no triangles".into()));
        }
        let mut scene = Scene::assemble(None, triangles, material_ids, materials);
        scene.geometries = ranges;
        Ok(scene)
    }

    /// The instance, geometry and triangle within it of hit number `prim_id`
    /// (`None` past the scene's triangles). A scene not made from geometries is
    /// one geometry of id 0, instance 0.
    pub fn locate(&self, prim_id: u32) -> Option<PrimLocation> {
        if prim_id as usize >= self.triangles.len() {
            return None;
        }
        if self.geometries.is_empty() {
            return Some(PrimLocation { instance_id: 0, geometry_id: 0, prim_index: prim_id });
        }
        // Ranges are contiguous and in order: the last non-empty one starting at
        // or before prim_id holds it.
        let after = self.geometries.partition_point(|r| r.first_prim <= prim_id);
        let r = self.geometries[..after].iter().rev().find(|r| r.count > 0)?;
        Some(PrimLocation {
            instance_id: r.instance_id,
            geometry_id: r.geometry_id,
            prim_index: prim_id - r.first_prim,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Mat3, Quat};

    fn quad() -> Vec<Vec3> {
        vec![Vec3::new(0., 0., 0.), Vec3::new(1., 0., 0.), Vec3::new(1., 1., 0.), Vec3::new(0., 1., 0.)]
    }

    #[test]
    fn indexed_strided_and_plain_geometries_give_the_same_triangles() {
        let p = quad();
        let idx32 = [0u32, 1, 2, 0, 2, 3];
        let idx16 = [0u16, 1, 2, 0, 2, 3];
        // Interleaved: 4 bytes of padding, the position, 8 bytes of "uv".
        let mut bytes = Vec::new();
        for v in &p {
            bytes.extend_from_slice(&[0xAB; 4]);
            for c in v.to_array() {
                bytes.extend_from_slice(&c.to_le_bytes());
            }
            bytes.extend_from_slice(&[0xCD; 8]);
        }
        let a = Geometry::new(7, &p).with_indices(Indices::U32(&idx32));
        let b = Geometry::strided(8, &bytes, 4, 24, 4).unwrap().with_indices(Indices::U16(&idx16));
        let soup: Vec<Vec3> = idx32.iter().map(|&i| p[i as usize]).collect();
        let c = Geometry::new(9, &soup).with_instance_id(42);
        let s = Scene::from_geometries(&[a, b, c], vec![]).unwrap();
        assert_eq!(s.triangles.len(), 6);
        for k in 0..2 {
            assert_eq!(s.triangles[k], s.triangles[k + 2]);
            assert_eq!(s.triangles[k], s.triangles[k + 4]);
        }
        assert_eq!(s.triangles[1], [p[0], p[2], p[3]]);
        let at = |i| s.locate(i).unwrap();
        assert_eq!(at(0), PrimLocation { instance_id: 7, geometry_id: 7, prim_index: 0 });
        assert_eq!(at(3), PrimLocation { instance_id: 8, geometry_id: 8, prim_index: 1 });
        assert_eq!(at(4), PrimLocation { instance_id: 42, geometry_id: 9, prim_index: 0 });
        assert_eq!(s.locate(6), None);
    }

    #[test]
    fn transforms_place_instances_and_empty_geometries_keep_numbering() {
        let p = quad();
        let idx = [0u32, 1, 2, 0, 2, 3];
        let t = Affine3A::from_scale_rotation_translation(
            Vec3::new(2., -1., 3.),
            Quat::from_rotation_z(0.5),
            Vec3::new(10., 0., 0.),
        );
        let g = Geometry::new(1, &p).with_indices(Indices::U32(&idx));
        let empty = Geometry::new(5, &[]);
        let s = Scene::from_geometries(&[g, empty, g.with_transform(t).with_instance_id(2)], vec![]).unwrap();
        assert_eq!(s.triangles.len(), 4);
        assert_eq!(s.triangles[3][2], t.transform_point3(p[3]));
        assert_eq!(s.locate(2).unwrap(), PrimLocation { instance_id: 2, geometry_id: 1, prim_index: 0 });
        assert_eq!(s.locate(1).unwrap(), PrimLocation { instance_id: 1, geometry_id: 1, prim_index: 1 });
        assert_eq!(s.geometries[1], GeometryRange { geometry_id: 5, instance_id: 5, first_prim: 2, count: 0 });
        // A mirroring transform (negative determinant) is accepted as is.
        let m = Affine3A::from_mat3(Mat3::from_diagonal(Vec3::new(-1., 1., 1.)));
        assert!(Scene::from_geometries(&[g.with_transform(m)], vec![]).is_ok());
    }

    #[test]
    fn bad_geometry_is_a_clear_error() {
        let p = quad();
        let msg = |g: Geometry| Scene::from_geometries(&[g], vec![]).unwrap_err().to_string();
        let e = msg(Geometry::new(3, &p).with_indices(Indices::U32(&[0, 1, 4])));
        assert!(e.contains("geometry 3") && e.contains("vertex 4") && e.contains("4 vertices"), "{e}");
        let e = msg(Geometry::new(3, &p).with_indices(Indices::U16(&[0, 1])));
        assert!(e.contains("not a multiple of 3"), "{e}");
        let e = msg(Geometry::new(3, &p));
        assert!(e.contains("4 vertices (no indices)"), "{e}");
        let mut nan = p.clone();
        nan[2].y = f32::NAN;
        let e = msg(Geometry::new(3, &nan).with_indices(Indices::U32(&[0, 1, 2])));
        assert!(e.contains("vertex 2") && e.contains("not finite"), "{e}");
        // An unused NaN vertex is fine.
        assert!(
            Scene::from_geometries(&[Geometry::new(3, &nan).with_indices(Indices::U32(&[0, 1, 3]))], vec![]).is_ok()
        );
        let huge = Affine3A::from_scale_rotation_translation(Vec3::splat(1e38), Quat::IDENTITY, Vec3::splat(3e38));
        let e = msg(Geometry::new(3, &p[..3]).with_transform(huge));
        assert!(e.contains("overflows"), "{e}");
        let e = msg(Geometry::new(3, &p[..3]).with_material(1));
        assert!(e.contains("material 1"), "{e}");
        let e = Scene::from_geometries(&[Geometry::new(3, &[])], vec![]).unwrap_err().to_string();
        assert!(e.contains("no triangles"), "{e}");
        let bytes = [0u8; 40];
        let e = Geometry::strided(4, &bytes, 4, 12, 4).unwrap_err().to_string();
        assert!(e.contains("do not fit a buffer of 40 bytes"), "{e}");
        assert!(Geometry::strided(4, &bytes, 4, 12, 3).is_ok());
        let e = Geometry::strided(4, &bytes, 0, 8, 2).unwrap_err().to_string();
        assert!(e.contains("stride 8"), "{e}");
        assert!(Geometry::strided(4, &bytes, usize::MAX, usize::MAX, 3).is_err());
    }
}
