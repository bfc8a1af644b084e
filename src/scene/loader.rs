//! `scene.toml` read key by key into a [`Scene`]: each value checked where
//! it is read, each error naming the key.

use std::sync::Arc;

use super::*;

mod objects;
mod showing;
mod variants;

pub use showing::Showing;

/// A table's `surface` key: the name and the index of the real surface it names.
pub(super) fn real_surface<'a>(r: &Fields<'a>, surfaces: &[Surface]) -> Result<(&'a str, usize)> {
    let name = r.req_str("surface")?;
    let index = surfaces
        .iter()
        .position(|s| s.name == name)
        .ok_or_else(|| {
            let names: Vec<&str> = surfaces.iter().map(|s| s.name.as_str()).collect();
            r.error(
                "surface",
                format!(
                    "no real surface named '{name}' (surfaces: {})",
                    list(&names)
                ),
            )
        })?;
    Ok((name, index))
}

/// Refuses a pose that places any of the object's vertices beyond
/// [`geometry::MAX_COORDINATE`] (a huge scale, or a far translation).
pub(super) fn within_reach(object: &VirtualObject, pose: &Pose) -> std::result::Result<(), String> {
    let reach = object.reach(pose);
    let max = geometry::MAX_COORDINATE as f64;
    if reach.is_finite() && reach <= max {
        return Ok(());
    }
    Err(format!(
        "places '{}' up to {reach:.3e} m from the origin, beyond ±{max} m: single-precision rays cannot resolve it there",
        object.name
    ))
}

/// What a mesh held that arlux leaves out: degenerate triangles, and
/// material parts it does not use (said once per file).
fn mesh_warnings(path: &Path, mesh: &geometry::Mesh, is_virtual: bool) -> Vec<String> {
    let mut out = Vec::new();
    if mesh.dropped_triangles > 0 {
        out.push(format!(
            "{}: dropped {} degenerate or non-finite triangles",
            path.display(),
            mesh.dropped_triangles
        ));
    }
    if is_virtual && !mesh.unsupported.is_empty() {
        out.push(format!(
            "{}: read but not honoured: {}",
            path.display(),
            mesh.unsupported.join("; ")
        ));
    }
    if !is_virtual && !mesh.unused_material_parts.is_empty() {
        out.push(format!(
            "{}: material {} has a texture (map_Kd) or a specular part (Ks) that arlux does not use: each surface is diffuse with its Kd (or the scene's rgb), and the photo carries the texture",
            path.display(),
            mesh.unused_material_parts.join(", ")
        ));
    }
    out
}

/// An optional key whose value lies in [0, 1].
pub(super) fn unit_interval(v: &Fields, key: &'static str) -> Result<Option<f64>> {
    match v.opt_f64(key)? {
        Some(x) if !(0.0..=1.0).contains(&x) => Err(v.error(key, "lies in [0, 1]")),
        x => Ok(x),
    }
}

pub(super) fn list(names: &[&str]) -> String {
    if names.is_empty() {
        "none".into()
    } else {
        names.join(", ")
    }
}

/// The longest image side arlux renders, pixels.
pub(super) const MAX_SIDE: u32 = 1 << 15;

/// A surface of a mesh file: the file, the surface's index, whether it is
/// turned Y-up from a Z-up export.
type SurfaceKey = (PathBuf, usize, bool);

/// Reads one scene file; holds what every part needs to resolve paths and
/// report errors.
pub(super) struct Loader<'a> {
    pub(super) file: &'a Path,
    pub(super) dir: PathBuf,
    /// Each mesh file read once, whatever the number of objects using it:
    /// their materials then share one copy of every texture.
    pub(super) meshes: std::cell::RefCell<HashMap<PathBuf, std::rc::Rc<geometry::Mesh>>>,
    /// A shaded surface's per-corner attributes (with the tangent frames a
    /// normal map needs), by mesh file and surface: shared the same way.
    shading: std::cell::RefCell<HashMap<SurfaceKey, Arc<crate::materials::Attributes>>>,
    /// Surface triangles by the same key: every object of one file holds one array.
    triangles: std::cell::RefCell<HashMap<SurfaceKey, Arc<[Triangle]>>>,
    /// The objects whose meshes are read (None: all of them).
    pub(super) shown: Option<std::collections::HashSet<String>>,
}

/// A warning per reference file that is not there: the scene loads and
/// renders, and what compares against it stops with the key.
fn missing_references(variants: &[Variant], motions: &[Motion]) -> Vec<String> {
    let mut files: Vec<(String, &Path)> = Vec::new();
    for v in variants {
        if let Some(r) = &v.reference {
            files.push((format!("variant '{}'.reference", v.name), r));
        }
        if let Some(super::ReferenceNoise::Twin(t)) = &v.reference_noise {
            files.push((format!("variant '{}'.reference_twin", v.name), t));
        }
    }
    for m in motions {
        for (i, r) in m.references.iter().enumerate() {
            files.push((format!("motion '{}'.references[{i}]", m.name), r));
        }
    }
    (files.into_iter())
        .filter(|(_, f)| !f.is_file())
        .map(|(key, f)| {
            format!(
                "{key}: file not found: {} (what compares against it will stop)",
                f.display()
            )
        })
        .collect()
}

impl<'a> Loader<'a> {
    pub(super) fn new(file: &'a Path, dir: PathBuf) -> Self {
        Loader {
            file,
            dir,
            meshes: Default::default(),
            shading: Default::default(),
            triangles: Default::default(),
            shown: None,
        }
    }

    /// The loader for `table`, reading only the meshes `showing` needs.
    pub(super) fn showing(
        file: &'a Path,
        dir: PathBuf,
        table: &toml::Table,
        showing: Showing,
    ) -> Self {
        Loader {
            shown: showing::shown_names(table, showing),
            ..Loader::new(file, dir)
        }
    }

    /// The mesh at `path`, read on first use (its warnings given then).
    pub(super) fn mesh(
        &self,
        path: &Path,
        is_virtual: bool,
        warnings: &mut Vec<String>,
    ) -> Result<std::rc::Rc<geometry::Mesh>> {
        if let Some(m) = self.meshes.borrow().get(path) {
            return Ok(m.clone());
        }
        let mesh = std::rc::Rc::new(geometry::load_mesh(path)?);
        warnings.extend(mesh_warnings(path, &mesh, is_virtual));
        self.meshes
            .borrow_mut()
            .insert(path.to_path_buf(), mesh.clone());
        Ok(mesh)
    }

    /// A path from the file, resolved and checked to exist.
    pub(super) fn existing_path(
        &self,
        f: &Fields,
        key: &'static str,
        rel: &str,
    ) -> Result<PathBuf> {
        let p = self.dir.join(rel);
        match std::fs::metadata(&p) {
            Ok(m) if m.is_file() => Ok(p),
            Ok(_) => Err(f.error(key, format!("{} is not a file", p.display()))),
            Err(_) => Err(f.error(key, format!("file not found: {}", p.display()))),
        }
    }

    /// A reference image's path, resolved. A missing one is not an error
    /// here: only a command that compares against it needs it (it stops
    /// then, naming the key); loading warns ([`missing_references`]).
    pub(super) fn reference_path(
        &self,
        f: &Fields,
        key: &'static str,
        rel: &str,
    ) -> Result<PathBuf> {
        match self.dir.join(rel).exists() {
            true => self.existing_path(f, key, rel),
            false => Ok(self.dir.join(rel)),
        }
    }

    pub(super) fn scene(&self, table: &toml::Table) -> Result<Scene> {
        let top = Fields::of_table(self.file, "", table);
        let name = match top.opt_str("name")? {
            Some(n) => n.to_string(),
            None => self
                .file
                .parent()
                .and_then(|d| d.file_name())
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
        };
        let (camera, photo_size) = self.camera_with_lens(&top.req_table("camera")?)?;
        let photo = self.photo(&top.req_table("photo")?)?;

        let mut warnings = Vec::new();
        let surfaces = self.real_surfaces(&top, &mut warnings)?;

        let reflectances = known_reflectances(&top, &surfaces)?;
        let texture_references = texture_references(&top, &surfaces)?;

        let mut lights: Vec<Light> = Vec::new();
        for l in top.tables("light")? {
            let light = self.light(&l, !reflectances.is_empty())?;
            if lights.iter().any(|o| o.name == light.name) {
                return Err(l.error("name", format!("light name '{}' is used twice", light.name)));
            }
            lights.push(light);
        }

        let mut objects: Vec<VirtualObject> = Vec::new();
        for v in top.tables("virtual")? {
            let object = self.object(&v, &mut warnings)?;
            if objects.iter().any(|o| o.name == object.name)
                || lights.iter().any(|l| l.name == object.name)
            {
                return Err(v.error(
                    "name",
                    format!("'{}' already names a light or object", object.name),
                ));
            }
            objects.push(object);
        }

        let mut variants: Vec<Variant> = Vec::new();
        for v in top.tables("variant")? {
            let variant = self.variant(&v, &lights, &objects)?;
            if variants.iter().any(|o| o.name == variant.name) {
                return Err(v.error(
                    "name",
                    format!("variant name '{}' is used twice", variant.name),
                ));
            }
            variants.push(variant);
        }
        let mut motions: Vec<Motion> = Vec::new();
        for m in top.tables("motion")? {
            let motion = self.motion(&m, &lights, &objects, &variants)?;
            if motions.iter().any(|o| o.name == motion.name) {
                return Err(m.error(
                    "name",
                    format!("motion name '{}' is used twice", motion.name),
                ));
            }
            motions.push(motion);
        }
        top.finish()?;
        warnings.extend(missing_references(&variants, &motions));

        let mut scene = Scene {
            name,
            file: self.file.to_path_buf(),
            source: String::new(),
            camera,
            photo_size,
            photo,
            surfaces,
            reflectances,
            texture_references,
            lights,
            objects,
            variants,
            motions,
            warnings,
        };
        scene.stand_objects()?;
        scene.check_light_clearance()?;
        Ok(scene)
    }

    /// The surfaces of the `[[real]]` meshes, their names unique.
    fn real_surfaces(&self, top: &Fields, warnings: &mut Vec<String>) -> Result<Vec<Surface>> {
        let reals = top.tables("real")?;
        if reals.is_empty() {
            return Err(top.error(
                "real",
                "missing: the scene needs at least one [[real]] mesh",
            ));
        }
        let mut surfaces: Vec<Surface> = Vec::new();
        for r in &reals {
            let rel = r.req_str("mesh")?;
            let path = self.existing_path(r, "mesh", rel)?;
            r.finish()?;
            let mesh =
                geometry::load_mesh(&path).map_err(|e| e.within(self.file, r.key_path("mesh")))?;
            warnings.extend(mesh_warnings(&path, &mesh, false));
            for s in mesh.surfaces {
                if let Some(other) = surfaces.iter().find(|o| o.name == s.name) {
                    return Err(r.error(
                        "mesh",
                        format!(
                            "surface '{}' is also defined in {}; surface names must be unique",
                            s.name,
                            other.mesh.display()
                        ),
                    ));
                }
                surfaces.push(Surface {
                    name: s.name,
                    mesh: path.clone(),
                    triangles: s.triangles,
                });
            }
        }
        Ok(surfaces)
    }

    pub(super) fn camera(&self, c: &Fields) -> Result<Camera> {
        if c.has("colmap") || c.has("fspy") {
            return self.solved_camera(c);
        }
        let width = c.req_count("width")?;
        let height = c.req_count("height")?;
        for (key, v) in [("width", width), ("height", height)] {
            if v > MAX_SIDE {
                return Err(c.error(
                    key,
                    format!("{v} pixels is more than arlux supports ({MAX_SIDE})"),
                ));
            }
        }
        let position = c.req_place("position")?;
        let look_at = c.req_place("look_at")?;
        let up = c.opt_vec3("up")?.unwrap_or(DVec3::Y);
        let projection = match (c.opt_f64("fov_y_deg")?, c.opt_table("intrinsics")?) {
            (Some(_), Some(_)) => {
                return Err(c.error("intrinsics", "give fov_y_deg or intrinsics, not both"));
            }
            (None, None) => return Err(c.error("fov_y_deg", "missing (or give intrinsics)")),
            (Some(degrees), None) => Projection::FovY { degrees },
            (None, Some(i)) => {
                let p = Projection::Intrinsics {
                    fx: i.req_f64("fx")?,
                    fy: i.req_f64("fy")?,
                    cx: i.req_f64("cx")?,
                    cy: i.req_f64("cy")?,
                };
                i.finish()?;
                p
            }
        };
        c.finish()?;
        Camera::new(width, height, position, look_at, up, projection)
            .map_err(|(key, msg)| c.error(key, msg))
    }

    pub(super) fn photo(&self, p: &Fields) -> Result<Photo> {
        let photo = match (p.opt_str("image")?, p.has("brackets")) {
            (Some(_), true) => return Err(p.error("brackets", "give image or brackets, not both")),
            (None, false) => return Err(p.error("image", "missing (or give brackets)")),
            (Some(rel), false) => Photo::Image(self.existing_path(p, "image", rel)?),
            (None, true) => {
                let mut brackets: Vec<Bracket> = Vec::new();
                let tables = p.tables("brackets")?;
                let given = tables.iter().filter(|b| b.has("ev")).count();
                if given != 0 && given != tables.len() {
                    return Err(p.error(
                        "brackets",
                        "give ev for every bracket, or for none (then each image's EXIF exposure time gives it)",
                    ));
                }
                let mut first_time = None;
                for b in tables {
                    let image = self.existing_path(&b, "image", b.req_str("image")?)?;
                    let ev = match b.opt_f64("ev")? {
                        Some(ev) => ev,
                        // Relative to the first bracket: radiance is relative anyway.
                        None => {
                            let t = image_io::exif_exposure_time(&image)
                                .map_err(|e| e.within(self.file, b.key_path("ev")))?;
                            (t / *first_time.get_or_insert(t)).log2()
                        }
                    };
                    if brackets.iter().any(|o| o.ev == ev) {
                        return Err(b.error(
                            "ev",
                            format!("two brackets have ev = {ev}; each exposure needs its own"),
                        ));
                    }
                    b.finish()?;
                    brackets.push(Bracket { image, ev });
                }
                if brackets.len() < 2 {
                    return Err(p.error(
                        "brackets",
                        format!(
                            "{} exposure(s): merging needs at least two different exposures",
                            brackets.len()
                        ),
                    ));
                }
                Photo::Brackets(brackets)
            }
        };
        p.finish()?;
        Ok(photo)
    }

    pub(super) fn light(&self, l: &Fields, has_known_reflectance: bool) -> Result<Light> {
        let name = l.req_str("name")?.to_string();
        let real = l.opt_bool("real")?.unwrap_or(true);
        let scale = l.opt_f64("scale")?.unwrap_or(1.0);
        if scale < 0.0 {
            return Err(l.error("scale", "must not be negative"));
        }
        let position = match l.get("position") {
            None => return Err(l.error("position", "missing")),
            Some(toml::Value::Table(_)) => {
                let p = l.req_table("position")?;
                let c = self.shadow_constraints(&p)?;
                p.finish()?;
                LightPosition::FromShadows(c)
            }
            Some(_) => LightPosition::Known(l.req_place("position")?),
        };
        let shape = match l.opt_table("shape")? {
            None => LightShape::Point,
            Some(s) => {
                let r = s.req_table("rect")?;
                s.finish()?;
                let (u, v) = (r.req_place("u")?, r.req_place("v")?);
                r.finish()?;
                // Name the vector at fault: a zero one, else v (parallel to u).
                for (key, side) in [("u", u), ("v", v)] {
                    if side.length() < 1e-9 {
                        return Err(r.error(key, "must not be zero: a rect light needs a side"));
                    }
                }
                if u.cross(v).length() < 1e-12 {
                    return Err(r.error("v", "is parallel to u: u and v must span a rectangle"));
                }
                LightShape::Rect { u, v }
            }
        };
        let intensity = self.intensity(l, &shape, has_known_reflectance)?;
        l.finish()?;
        Ok(Light {
            name,
            real,
            position,
            scale,
            shape,
            intensity,
        })
    }

    pub(super) fn shadow_constraints(&self, p: &Fields) -> Result<ShadowConstraints> {
        let mut c = ShadowConstraints::default();
        for line in p.tables("shadow_lines")? {
            let sl = ShadowLine {
                shadow: line.req_vec3("shadow")?,
                vertex: line.req_vec3("vertex")?,
            };
            if (sl.shadow - sl.vertex).length() < 1e-9 {
                return Err(line.error(
                    "vertex",
                    "coincides with the shadow point: the line has no direction",
                ));
            }
            line.finish()?;
            c.lines.push(sl);
        }
        for plane in p.tables("shadow_planes")? {
            let pair = |key: &'static str| -> Result<[DVec3; 2]> {
                let items = plane
                    .opt_array(key)?
                    .ok_or_else(|| plane.error(key, "missing"))?;
                if items.len() != 2 {
                    return Err(
                        plane.error(key, format!("must be two points, found {}", items.len()))
                    );
                }
                let mut out = [DVec3::ZERO; 2];
                for (o, (path, v)) in out.iter_mut().zip(&items) {
                    *o = fields::vec3(v).map_err(|m| Error::key(self.file, path.clone(), m))?;
                }
                Ok(out)
            };
            let sp = ShadowPlane {
                shadow: pair("shadow")?,
                edge: pair("edge")?,
            };
            plane.finish()?;
            c.planes.push(sp);
        }
        if c.lines.is_empty() && c.planes.is_empty() {
            return Err(
                p.table_error("needs shadow_lines or shadow_planes to estimate the position from")
            );
        }
        Ok(c)
    }

    pub(super) fn intensity(
        &self,
        l: &Fields,
        shape: &LightShape,
        has_known_reflectance: bool,
    ) -> Result<Intensity> {
        let unit = |f: &Fields, key: &'static str| -> Result<DVec3> {
            let d = f.req_vec3(key)?;
            if d.length() < 1e-12 {
                return Err(f.error(key, "must not be zero"));
            }
            Ok(d.normalize())
        };
        match l.get("intensity") {
            None => Err(l.error("intensity", "missing")),
            Some(toml::Value::String(s)) if s == "reconstruct" => {
                if !has_known_reflectance {
                    return Err(l.error(
                        "intensity",
                        "\"reconstruct\" needs at least one [[reflectance]] to fix the scale of light against reflectance",
                    ));
                }
                Ok(Intensity::Reconstruct)
            }
            Some(toml::Value::String(s)) => Err(l.error(
                "intensity",
                format!("'{s}' is not a kind of intensity (the only string is \"reconstruct\")"),
            )),
            Some(_) => {
                let i = l.req_table("intensity")?;
                let kinds = ["uniform", "lambertian", "spot", "ies"];
                let given: Vec<&str> = kinds.iter().copied().filter(|k| i.has(k)).collect();
                if given.len() != 1 {
                    for k in kinds {
                        i.get(k);
                    }
                    i.finish()?;
                    return Err(i.table_error(format!(
                        "must have exactly one of uniform, lambertian, spot, ies (found {})",
                        list(&given)
                    )));
                }
                let out = match given[0] {
                    "uniform" => {
                        let rgb = i.req_rgb("uniform")?;
                        Intensity::Uniform(rgb)
                    }
                    "lambertian" => {
                        let t = i.req_table("lambertian")?;
                        let normal = unit(&t, "normal")?;
                        let rgb = t.req_rgb("rgb")?;
                        t.finish()?;
                        if let LightShape::Rect { u, v } = shape
                            && normal.dot(u.cross(*v).normalize()) < 0.99
                        {
                            return Err(t.error(
                                "normal",
                                "disagrees with the shape: a rect emits on the side of u×v, which must be the lambertian normal",
                            ));
                        }
                        Intensity::Lambertian { normal, rgb }
                    }
                    "spot" => {
                        let t = i.req_table("spot")?;
                        let direction = unit(&t, "direction")?;
                        let rgb = t.req_rgb("rgb")?;
                        let beam_deg = t.req_f64("beam_deg")?;
                        let cutoff_deg = t.req_f64("cutoff_deg")?;
                        t.finish()?;
                        if !(0.0..180.0).contains(&beam_deg) {
                            return Err(t.error(
                                "beam_deg",
                                format!("must lie in [0, 180), found {beam_deg}"),
                            ));
                        }
                        if cutoff_deg <= beam_deg {
                            return Err(t.error("cutoff_deg", "must be greater than beam_deg"));
                        }
                        if cutoff_deg > 180.0 {
                            return Err(t.error(
                                "cutoff_deg",
                                format!("must be at most 180, found {cutoff_deg}"),
                            ));
                        }
                        Intensity::Spot {
                            direction,
                            rgb,
                            beam_deg,
                            cutoff_deg,
                        }
                    }
                    _ => {
                        let rel = i.req_str("ies")?;
                        let file = self.existing_path(&i, "ies", rel)?;
                        let profile = IesProfile::load(&file)
                            .map_err(|e| e.within(self.file, i.key_path("ies")))?;
                        let rgb = i.req_rgb("rgb")?;
                        let direction = unit(&i, "direction")?;
                        let reference = unit(&i, "reference")?;
                        let reference = reference - direction * reference.dot(direction);
                        if reference.length() < 1e-6 {
                            return Err(i.error("reference", "must not be parallel to direction"));
                        }
                        Intensity::Ies {
                            file,
                            profile,
                            rgb,
                            direction,
                            reference: reference.normalize(),
                        }
                    }
                };
                i.finish()?;
                Ok(out)
            }
        }
    }
}

/// The `[[reflectance]]` tables: one per surface, each in [0, 1].
fn known_reflectances(top: &Fields, surfaces: &[Surface]) -> Result<Vec<KnownReflectance>> {
    let mut reflectances: Vec<KnownReflectance> = Vec::new();
    for r in top.tables("reflectance")? {
        let (sname, surface) = real_surface(&r, surfaces)?;
        let rgb = r.req_rgb("rgb")?;
        if rgb.max_element() > 1.0 {
            return Err(r.error("rgb", "a reflectance lies in [0, 1]"));
        }
        if reflectances.iter().any(|k| k.surface == surface) {
            return Err(r.error("surface", format!("'{sname}' is given twice")));
        }
        r.finish()?;
        reflectances.push(KnownReflectance { surface, rgb });
    }
    Ok(reflectances)
}

/// The `[[texture_reference]]` tables: one per surface.
fn texture_references(top: &Fields, surfaces: &[Surface]) -> Result<Vec<TextureReference>> {
    let mut references: Vec<TextureReference> = Vec::new();
    for r in top.tables("texture_reference")? {
        let (sname, surface) = real_surface(&r, surfaces)?;
        let point = r.req_vec3("point")?;
        if references.iter().any(|k| k.surface == surface) {
            return Err(r.error("surface", format!("'{sname}' is given twice")));
        }
        r.finish()?;
        references.push(TextureReference { surface, point });
    }
    Ok(references)
}
