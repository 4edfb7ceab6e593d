//! Scenes: triangles, materials and cameras, loaded from OBJ + MTL files
//! (feature `obj`) or made from triangles.
//!
//! Triangles are numbered in the order their faces appear in the OBJ file, each
//! n-gon fanned as `(a0,a1,a2), (a0,a2,a3), …`: that number is the `prim_id`
//! of hits. Zero-area triangles are kept so that the numbering holds.

mod camera;
mod geometry;
#[cfg(feature = "gltf")]
mod gltf;
#[cfg(any(feature = "obj", test))]
mod obj;
mod text;

#[cfg(any(feature = "obj", test))]
use std::collections::HashMap;
#[cfg(any(feature = "obj", feature = "gltf", test))]
use std::path::Path;
use std::path::PathBuf;

use glam::Vec3;

pub use camera::Camera;
pub use geometry::{Geometry, GeometryRange, Indices, Positions, PrimLocation};

use crate::error::{Error, Result};
use crate::geom::Aabb;
use crate::kdtree::tree::is_zero_area;

/// A surface material, from an MTL `newmtl` block.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// The `newmtl` name (`"default"` for the default material).
    pub name: String,
    /// Diffuse reflectance (`Kd`).
    pub kd: Vec3,
    /// Specular reflectance (`Ks`).
    pub ks: Vec3,
    /// Specular exponent (`Ns`).
    pub ns: f32,
    /// Illumination model (`illum`); 3 is a ray-traced mirror.
    pub illum: u32,
    /// Emitted radiance (`Ke`); non-zero for lights.
    pub ke: Vec3,
}

impl Default for Material {
    /// 80 % grey diffuse, no specular part, no emission, `illum 0`.
    fn default() -> Self {
        Material { name: "default".into(), kd: Vec3::splat(0.8), ks: Vec3::ZERO, ns: 0.0, illum: 0, ke: Vec3::ZERO }
    }
}

impl Material {
    /// True when the material emits light (`Ke` is not zero).
    pub fn is_emissive(&self) -> bool {
        self.ke != Vec3::ZERO
    }

    /// Converts a tobj material; what the MTL leaves out comes from `Material::default()`.
    #[cfg(any(feature = "obj", test))]
    fn from_tobj(m: tobj::Material) -> Material {
        let d = Material::default();
        // tobj 4.0.5 parses `Ke` itself; older versions left it in `unknown_param`.
        let ke = m.emissive.map(Vec3::from).or_else(|| {
            let values: Vec<f32> =
                m.unknown_param.get("Ke")?.split_whitespace().map_while(|w| w.parse().ok()).collect();
            (values.len() == 3 && values.iter().all(|x| x.is_finite())).then(|| Vec3::from_slice(&values))
        });
        Material {
            name: m.name,
            kd: m.diffuse.map_or(d.kd, Vec3::from),
            ks: m.specular.map_or(d.ks, Vec3::from),
            ns: m.shininess.unwrap_or(d.ns),
            illum: m.illumination_model.map_or(d.illum, u32::from),
            ke: ke.unwrap_or(d.ke),
        }
    }
}

/// A triangle scene: flat arrays indexed by triangle number (`prim_id`).
#[derive(Clone, Debug)]
pub struct Scene {
    /// The OBJ file it came from (`None` for `from_triangles`).
    pub path: Option<PathBuf>,
    /// The triangles, numbered in face order (fan triangulation).
    pub triangles: Vec<[Vec3; 3]>,
    /// Per triangle, an index into `materials`.
    pub material_ids: Vec<u32>,
    /// The materials of the MTL files, in file order, plus a default material at
    /// the end when some faces have none (no `usemtl`, an unknown name, or no MTL).
    pub materials: Vec<Material>,
    /// The box around all triangles.
    pub bounds: Aabb,
    /// Number of zero-area triangles ([`crate::kdtree::tree::is_zero_area`], the
    /// builder's rule), kept so that numbering is preserved.
    pub degenerate_count: usize,
    /// The geometries' ranges of triangle numbers, in order (empty for a scene
    /// that is one geometry: an OBJ file, `from_triangles`); see [`Scene::locate`].
    pub geometries: Vec<GeometryRange>,
    /// The scene file's own camera (glTF: the first camera node), if any.
    pub camera: Option<Camera>,
}

impl Scene {
    /// Loads an OBJ file and the MTL files it names (relative to its folder).
    ///
    /// Errors: `Error::Io` when the file cannot be read; `Error::Scene` naming the
    /// file and, where there is one, the line, for malformed content (not UTF-8
    /// text, wrong number of coordinates, bad numbers, faces with fewer than 3
    /// vertices, indices that are 0 or out of range, non-finite coordinates of
    /// a vertex a face uses), a malformed MTL file, and a scene without triangles.
    /// An MTL file that cannot be read, or a `usemtl` of an unknown material, is
    /// a warning on stderr; those faces get the default material.
    ///
    /// A `.gltf` or `.glb` file is read as glTF 2.0 instead (feature `gltf`;
    /// see [`Geometry`] for the numbering and the module `gltf` for what is read).
    #[cfg(any(feature = "obj", feature = "gltf", test))]
    pub fn load(path: &Path) -> Result<Scene> {
        let ext = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
        if ext == "gltf" || ext == "glb" {
            #[cfg(feature = "gltf")]
            return gltf::load(path);
            #[cfg(not(feature = "gltf"))]
            return Err(text::scene_error(path, None, "reading glTF needs kdtrace's `gltf` feature"));
        }
        #[cfg(any(feature = "obj", test))]
        return Scene::load_obj(path);
        #[cfg(not(any(feature = "obj", test)))]
        return Err(text::scene_error(path, None, "reading OBJ needs kdtrace's `obj` feature"));
    }

    /// A scene file as a two-level scene ([`crate::twolevel`]): a glTF file's mesh
    /// primitives each once with their own kd-trees, placed by the nodes that use
    /// them (instance id: the node's index, mask 0xff); an OBJ file as one
    /// geometry (id 0) placed once without transform. Also returns each
    /// instance's range in the numbering [`Scene::load`] gives the same file, so
    /// that a hit's `prim_id` there is `ranges[instance_index].first_prim + prim_index`.
    ///
    /// Errors: those of [`Scene::load`].
    #[cfg(any(feature = "obj", feature = "gltf", test))]
    pub fn load_two_level(
        path: &Path,
        config: &crate::kdtree::BuildConfig,
    ) -> Result<(crate::twolevel::TwoLevelScene, Vec<GeometryRange>)> {
        let ext = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
        if ext == "gltf" || ext == "glb" {
            #[cfg(feature = "gltf")]
            return gltf::load_two_level(path, config);
        }
        let scene = Scene::load(path)?;
        let n = scene.triangles.len() as u32;
        let bottom = crate::twolevel::BottomLevel::new(0, scene.triangles, config);
        let identity =
            crate::twolevel::Instance { geometry: 0, transform: glam::Affine3A::IDENTITY, instance_id: 0, mask: 0xff };
        let two = crate::twolevel::TwoLevelScene::new(vec![bottom], &[identity])?;
        Ok((two, vec![GeometryRange { geometry_id: 0, instance_id: 0, first_prim: 0, count: n }]))
    }

    #[cfg(any(feature = "obj", test))]
    fn load_obj(path: &Path) -> Result<Scene> {
        let bytes = std::fs::read(path).map_err(|source| Error::Io { path: path.to_path_buf(), source })?;
        let obj = obj::parse_obj(path, &bytes)?;
        if obj.triangle_count() == 0 {
            return Err(text::scene_error(path, None, "scene has no triangles"));
        }

        let mut materials = Vec::new();
        let mut by_name = HashMap::new();
        let mut read_any_mtl = false;
        for (argument, line) in &obj.mtllibs {
            for mtl_path in obj::mtl_paths(path, argument) {
                match obj::load_mtl(&mtl_path)? {
                    Some(list) => {
                        read_any_mtl = true;
                        for m in list {
                            by_name.insert(m.name.clone(), materials.len() as u32);
                            materials.push(m);
                        }
                    }
                    None => eprintln!(
                        "warning: {}:{line}: cannot read material file {}; its faces get the default material",
                        path.display(),
                        mtl_path.display()
                    ),
                }
            }
        }

        // Resolve the usemtl names; faces without a known material get the default.
        let default_id = materials.len() as u32;
        let resolved: Vec<u32> = obj
            .usemtl_names
            .iter()
            .map(|name| {
                by_name.get(name).copied().unwrap_or_else(|| {
                    if read_any_mtl {
                        eprintln!("warning: {}: unknown material {name:?}; using the default", path.display());
                    }
                    default_id
                })
            })
            .collect();
        let material_ids: Vec<u32> =
            obj.usemtl.iter().map(|&u| if u == obj::NO_USEMTL { default_id } else { resolved[u as usize] }).collect();
        if material_ids.contains(&default_id) {
            materials.push(Material::default());
        }
        Scene::from_obj(path, &obj, material_ids, materials)
    }

    /// The parsed OBJ as one indexed geometry (id 0, instance 0) through
    /// [`Scene::from_geometries`], the API engines use; then the faces' own
    /// materials (`usemtl`), triangle by triangle.
    #[cfg(any(feature = "obj", test))]
    fn from_obj(path: &Path, obj: &obj::ObjFile, material_ids: Vec<u32>, materials: Vec<Material>) -> Result<Scene> {
        let geometry = Geometry::new(0, &obj.positions).with_indices(Indices::U32(&obj.indices));
        let mut scene = Scene::from_geometries(&[geometry], Vec::new())
            .map_err(|e| text::scene_error(path, None, e.to_string()))?;
        scene.path = Some(path.to_path_buf());
        scene.material_ids = material_ids;
        scene.materials = materials;
        Ok(scene)
    }

    /// A scene from OBJ text in memory, geometry only: `mtllib` is not followed
    /// and every face gets the default material. `name` names the source in
    /// errors. The same checks and errors as [`Scene::load`].
    #[cfg(any(feature = "obj", test))]
    pub fn from_obj_bytes(name: &Path, bytes: &[u8]) -> Result<Scene> {
        let obj = obj::parse_obj(name, bytes)?;
        if obj.triangle_count() == 0 {
            return Err(text::scene_error(name, None, "scene has no triangles"));
        }
        let ids = vec![0; obj.triangle_count()];
        Scene::from_obj(name, &obj, ids, vec![Material::default()])
    }

    /// A scene of the given triangles with one default material. Fails with
    /// `Error::InvalidInput` when there are no triangles or a coordinate is not finite.
    pub fn from_triangles(triangles: Vec<[Vec3; 3]>) -> Result<Scene> {
        if triangles.is_empty() {
            return Err(Error::InvalidInput("scene has no triangles".into()));
        }
        if triangles.len() >= crate::consts::PRIM_INCOMPLETE as usize {
            return Err(Error::InvalidInput(format!("too many triangles ({})", triangles.len())));
        }
        if let Some(i) = triangles.iter().position(|t| !t.iter().all(|v| v.is_finite())) {
            return Err(Error::InvalidInput(format!("triangle {i} has a non-finite coordinate: {:?}", triangles[i])));
        }
        let material_ids = vec![0; triangles.len()];
        Ok(Scene::assemble(None, triangles, material_ids, vec![Material::default()]))
    }

    /// The material of triangle `prim_id`. Panics when `prim_id` is not a triangle number.
    pub fn material(&self, prim_id: u32) -> &Material {
        &self.materials[self.material_ids[prim_id as usize] as usize]
    }

    fn assemble(
        path: Option<PathBuf>,
        triangles: Vec<[Vec3; 3]>,
        material_ids: Vec<u32>,
        materials: Vec<Material>,
    ) -> Scene {
        let bounds = triangles.iter().fold(Aabb::EMPTY, |b, t| b.grow(t[0]).grow(t[1]).grow(t[2]));
        let degenerate_count = triangles.iter().filter(|t| is_zero_area(t)).count();
        Scene {
            path,
            triangles,
            material_ids,
            materials,
            bounds,
            degenerate_count,
            geometries: Vec::new(),
            camera: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri(a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> [Vec3; 3] {
        [a.into(), b.into(), c.into()]
    }

    #[test]
    fn default_material() {
        let m = Material::default();
        assert_eq!(m.kd, Vec3::splat(0.8));
        assert_eq!((m.ks, m.ns, m.illum, m.ke), (Vec3::ZERO, 0.0, 0, Vec3::ZERO));
        assert!(!m.is_emissive());
    }

    #[test]
    fn from_triangles_counts_degenerates_and_bounds() {
        let s = Scene::from_triangles(vec![
            tri([0., 0., 0.], [1., 0., 0.], [0., 1., 0.]),
            tri([0., 0., 0.], [1., 1., 1.], [2., 2., 2.]),
            tri([5., 0., -1.], [5., 0., -1.], [0., 3., 0.]),
        ])
        .unwrap();
        assert_eq!(s.degenerate_count, 2);
        assert_eq!(s.bounds, Aabb::new(Vec3::new(0., 0., -1.), Vec3::new(5., 3., 2.)));
        assert_eq!(s.material_ids, [0, 0, 0]);
        assert_eq!(s.materials, [Material::default()]);
        assert_eq!(s.material(2).name, "default");
        assert!(s.path.is_none());
    }

    #[test]
    fn from_triangles_rejects_empty_and_non_finite() {
        let e = Scene::from_triangles(vec![]).unwrap_err();
        assert!(e.to_string().contains("no triangles"), "{e}");
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            let e = Scene::from_triangles(vec![
                tri([0., 0., 0.], [1., 0., 0.], [0., 1., 0.]),
                tri([0., 0., 0.], [1., bad, 0.], [0., 1., 0.]),
            ])
            .unwrap_err();
            assert!(matches!(e, Error::InvalidInput(_)));
            assert!(e.to_string().contains("triangle 1"), "{e}");
        }
    }

    #[test]
    fn material_from_tobj_fills_gaps_with_defaults() {
        let mut t = tobj::Material { name: "m".into(), illumination_model: Some(3), ..Default::default() };
        t.unknown_param.insert("Ke".into(), "1 2 3".into());
        let m = Material::from_tobj(t);
        assert_eq!(m.kd, Vec3::splat(0.8));
        assert_eq!(m.illum, 3);
        assert_eq!(m.ke, Vec3::new(1., 2., 3.));
        assert!(m.is_emissive());
    }
}
