//! A `[[virtual]]` table read into a [`VirtualObject`]: its mesh (read
//! once per file, turned Y-up for a Z-up export), its materials with the
//! scene's keys over them, its placement.

use std::sync::Arc;

use super::*;

/// A Z-up file's point or direction in the scene's Y-up frame: (x, y, z)
/// becomes (x, z, −y), a quarter turn about x (right-handed kept).
fn turned_up(p: Vec3) -> Vec3 {
    Vec3::new(p.x, p.z, -p.y)
}

/// Surface `s` of a Z-up file turned Y-up: its triangles, vertex normals
/// and tangents.
fn z_up_to_y_up(s: &geometry::MeshSurface) -> geometry::MeshSurface {
    let mut out = s.clone();
    for t in &mut out.triangles {
        *t = t.map(turned_up);
    }
    for n in &mut out.attributes.normals {
        *n = n.map(turned_up);
    }
    for t in &mut out.attributes.tangents {
        *t = t.map(|t| turned_up(t.truncate()).extend(t.w));
    }
    out
}

/// `up`: which axis of the file points up ("y", glTF's and the default;
/// "z", as some exporters write).
fn up_is_z(v: &Fields) -> Result<bool> {
    match v.opt_str("up")? {
        None | Some("y") => Ok(false),
        Some("z") => Ok(true),
        Some(other) => Err(v.error("up", format!("\"y\" or \"z\", not \"{other}\""))),
    }
}

/// `stand = "below"`: the object is dropped onto the real surface under
/// its footprint ([`Scene::stand_objects`]).
fn stand(v: &Fields) -> Result<bool> {
    match v.opt_str("stand")? {
        None => Ok(false),
        Some("below") => Ok(true),
        Some(other) => Err(v.error(
            "stand",
            format!("\"below\" (onto the real surface under it), not \"{other}\""),
        )),
    }
}

/// `emission`: a scale on the file's emitted light (0 turns it off).
fn emission(v: &Fields) -> Result<Option<f64>> {
    match v.opt_f64("emission")? {
        Some(e) if !(e.is_finite() && e >= 0.0) => {
            Err(v.error("emission", "a scale of 0 (off) or more"))
        }
        e => Ok(e),
    }
}

impl Loader<'_> {
    /// Surface `i` of the mesh at `path` (turned Y-up when `z_up`): its
    /// attributes for shading, with
    /// MikkTSpace tangents when its material has a normal map.
    fn attributes(
        &self,
        (path, i, z_up): (&Path, usize, bool),
        s: &geometry::MeshSurface,
    ) -> Arc<crate::materials::Attributes> {
        let key = (path.to_path_buf(), i, z_up);
        if let Some(a) = self.shading.borrow().get(&key) {
            return a.clone();
        }
        let normal_map = s
            .material
            .as_ref()
            .is_some_and(|m| m.normal_texture.is_some());
        let a = Arc::new(match normal_map {
            true => s.attributes.clone().with_mikktspace(&s.triangles),
            false => s.attributes.clone(),
        });
        self.shading.borrow_mut().insert(key, a.clone());
        a
    }

    /// Surface `i`'s triangles (turned Y-up when `z_up`), shared by every
    /// object that reads them.
    fn triangles(
        &self,
        (path, i, z_up): (&Path, usize, bool),
        s: &geometry::MeshSurface,
    ) -> Arc<[Triangle]> {
        let key = (path.to_path_buf(), i, z_up);
        let mut kept = self.triangles.borrow_mut();
        kept.entry(key)
            .or_insert_with(|| s.triangles.as_slice().into())
            .clone()
    }

    pub(super) fn object(&self, v: &Fields, warnings: &mut Vec<String>) -> Result<VirtualObject> {
        let name = v.req_str("name")?.to_string();
        let path = self.existing_path(v, "mesh", v.req_str("mesh")?)?;
        let rgb = v.opt_vec3("rgb")?;
        if let Some(rgb) = rgb
            && (rgb.min_element() < 0.0 || rgb.max_element() > 1.0)
        {
            return Err(v.error("rgb", "a reflectance lies in [0, 1]"));
        }
        let pose = crate::scene::placement::pose_change(v)?.applied_to(&Pose {
            translate: DVec3::ZERO,
            rotation: DMat3::IDENTITY,
            scale: 1.0,
        });
        let enabled = v.opt_bool("enabled")?.unwrap_or(true);
        let looks = crate::scene::materials::Overrides {
            metallic: unit_interval(v, "metallic")?,
            roughness: unit_interval(v, "roughness")?,
            emission: emission(v)?,
        };
        let z_up = up_is_z(v)?;
        let stand_below = stand(v)?;
        v.finish()?;
        if self
            .shown
            .as_ref()
            .is_some_and(|shown| !shown.contains(&name))
        {
            return Ok(VirtualObject {
                name,
                mesh: path,
                surfaces: Vec::new(),
                pose,
                enabled,
                mesh_read: false,
                stand_below,
            });
        }
        let mesh = (self.mesh(&path, true, warnings))
            .map_err(|e| e.within(self.file, v.key_path("mesh")))?;
        let mut surfaces = Vec::new();
        for (i, s) in mesh.surfaces.iter().enumerate() {
            let turned;
            let s = match z_up {
                true => {
                    turned = z_up_to_y_up(s);
                    &turned
                }
                false => s,
            };
            let attributes = || self.attributes((&path, i, z_up), s);
            let material = crate::scene::materials::surface_material(s, rgb, looks, attributes)
                .map_err(|m| v.error("rgb", m))?;
            let rgb = match (&material, rgb, s.material_rgb) {
                (Some(m), _, _) => m.material.mean_albedo(),
                (None, Some(rgb), _) => rgb,
                (None, None, Some(kd)) => kd.as_dvec3().clamp(DVec3::ZERO, DVec3::ONE),
                (None, None, None) => {
                    return Err(v.error(
                        "rgb",
                        format!(
                            "missing, and surface '{}' of {} has no material Kd to take it from",
                            s.name,
                            path.display()
                        ),
                    ));
                }
            };
            surfaces.push(ObjectSurface {
                name: s.name.clone(),
                triangles: self.triangles((&path, i, z_up), s),
                rgb,
                material,
            });
        }
        let object = VirtualObject {
            name,
            mesh: path,
            surfaces,
            pose,
            enabled,
            mesh_read: true,
            stand_below,
        };
        within_reach(&object, &pose).map_err(|m| v.error("scale", m))?;
        Ok(object)
    }
}
