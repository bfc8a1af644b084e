//! [`Scene`]: everything `scene.toml` describes (see `docs/scene-format.md`),
//! loaded, checked and resolved into plain data: the camera, the photo, the
//! real surfaces, the lights, the virtual objects, the variants and motions.
//!
//! [`Scene::load`] reads and validates the whole file; [`Scene::with_variant`]
//! and [`Scene::with_motion_pose`] give the effective scene of a variant or a
//! motion pose. Every error names the file and the key path.

mod fields;

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::{DMat3, DVec3, Vec3};

use crate::camera::{Camera, Projection};
use crate::error::{Error, Result};
use crate::geometry::{self, Triangle};
use crate::ies::IesProfile;
use crate::image_io::{self, Image};
use fields::Fields;

/// Lights closer than this to a surface are refused: irradiance ~1/d² has no
/// meaningful value there (millimetres are fine and tested).
pub const MIN_LIGHT_CLEARANCE_M: f64 = 1e-5;

/// A loaded, validated scene.
#[derive(Debug, Clone)]
pub struct Scene {
    pub name: String,
    /// The `scene.toml` this came from; relative paths were resolved against its folder.
    pub file: PathBuf,
    pub camera: Camera,
    pub photo: Photo,
    /// Real surfaces, numbered as arlux numbers them everywhere: `[[real]]`
    /// meshes in manifest order, then `o`/`g` names in file order.
    pub surfaces: Vec<Surface>,
    pub reflectances: Vec<KnownReflectance>,
    /// `[[texture_reference]]`: per surface, a point the user knows lies in
    /// full light of every real lamp (Loscos §4.3's default reference patch).
    pub texture_references: Vec<TextureReference>,
    pub lights: Vec<Light>,
    pub objects: Vec<VirtualObject>,
    pub variants: Vec<Variant>,
    pub motions: Vec<Motion>,
    /// Non-fatal findings (dropped triangles), for the user to read.
    pub warnings: Vec<String>,
}

/// One real surface.
#[derive(Debug, Clone)]
pub struct Surface {
    pub name: String,
    pub mesh: PathBuf,
    pub triangles: Vec<Triangle>,
}

/// Where the photograph comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum Photo {
    Image(PathBuf),
    Brackets(Vec<Bracket>),
}

/// One 8-bit exposure of a bracket set; exposure time = t0 · 2^ev.
#[derive(Debug, Clone, PartialEq)]
pub struct Bracket {
    pub image: PathBuf,
    pub ev: f64,
}

/// A point of a real surface in full light, for the texture path.
#[derive(Debug, Clone, PartialEq)]
pub struct TextureReference {
    pub surface: usize,
    pub point: DVec3,
}

/// A known diffuse reflectance of a real surface.
#[derive(Debug, Clone, PartialEq)]
pub struct KnownReflectance {
    pub surface: usize,
    pub rgb: DVec3,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Light {
    pub name: String,
    /// False for a light the user adds (it is not in the photo).
    pub real: bool,
    pub position: LightPosition,
    /// Relighting factor; 0 is off.
    pub scale: f64,
    pub shape: LightShape,
    pub intensity: Intensity,
}

impl Light {
    pub fn is_on(&self) -> bool {
        self.scale > 0.0
    }

    /// The emitter's centre, when it is given rather than to be estimated.
    pub fn known_position(&self) -> Option<DVec3> {
        match self.position {
            LightPosition::Known(p) => Some(p),
            LightPosition::FromShadows(_) => None,
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub enum LightPosition {
    Known(DVec3),
    /// To be estimated as the least-squares point nearest these lines and planes.
    FromShadows(ShadowConstraints),
}

#[derive(Debug, Clone, PartialEq, Default)]
pub struct ShadowConstraints {
    pub lines: Vec<ShadowLine>,
    pub planes: Vec<ShadowPlane>,
}

/// A line from a shadow corner through the object vertex that casts it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShadowLine {
    pub shadow: DVec3,
    pub vertex: DVec3,
}

/// A plane through a shadow edge and the object edge that casts it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShadowPlane {
    pub shadow: [DVec3; 2],
    pub edge: [DVec3; 2],
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LightShape {
    Point,
    /// Spans position ± u/2 ± v/2 and emits on the side of u×v.
    Rect {
        u: DVec3,
        v: DVec3,
    },
}

/// Goniometric intensity I(direction), RGB in W/sr, before `scale`.
// A scene holds a handful of lights: boxing the table-holding variant would save nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq)]
pub enum Intensity {
    Uniform(DVec3),
    /// I0·max(cosθ, 0) about the unit `normal`.
    Lambertian {
        normal: DVec3,
        rgb: DVec3,
    },
    /// Full inside `beam_deg` of the unit `direction`, linear in angle to 0 at `cutoff_deg`.
    Spot {
        direction: DVec3,
        rgb: DVec3,
        beam_deg: f64,
        cutoff_deg: f64,
    },
    /// An IES LM-63 candela table times `rgb`; vertical 0 along `direction`,
    /// horizontal 0 towards `reference` (both unit, orthogonalised).
    Ies {
        file: PathBuf,
        profile: IesProfile,
        rgb: DVec3,
        direction: DVec3,
        reference: DVec3,
    },
    /// To be recovered from the photo.
    Reconstruct,
}

/// A virtual object's placement: p' = translate + R_y(rotate_y_deg)·(scale·p).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    pub translate: DVec3,
    pub rotate_y_deg: f64,
    pub scale: f64,
}

impl Pose {
    pub fn apply(&self, p: Vec3) -> Vec3 {
        let r = DMat3::from_rotation_y(self.rotate_y_deg.to_radians());
        (self.translate + r * (p.as_dvec3() * self.scale)).as_vec3()
    }
}

/// One surface of a virtual object, in the object's own frame.
#[derive(Debug, Clone)]
pub struct ObjectSurface {
    pub name: String,
    pub triangles: Vec<Triangle>,
    /// Diffuse reflectance: the scene's `rgb`, else the OBJ material's Kd.
    pub rgb: DVec3,
}

#[derive(Debug, Clone)]
pub struct VirtualObject {
    pub name: String,
    pub mesh: PathBuf,
    pub surfaces: Vec<ObjectSurface>,
    pub pose: Pose,
    pub enabled: bool,
}

impl VirtualObject {
    /// The triangles of surface `i` placed in the world.
    pub fn world_triangles(&self, i: usize) -> Vec<Triangle> {
        self.surfaces[i]
            .triangles
            .iter()
            .map(|t| t.map(|p| self.pose.apply(p)))
            .collect()
    }
}

/// A change of one object's pose by a variant; what is absent is kept.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PoseChange {
    pub translate: Option<DVec3>,
    pub rotate_y_deg: Option<f64>,
    pub scale: Option<f64>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Variant {
    pub name: String,
    /// (light index, new scale)
    pub lights: Vec<(usize, f64)>,
    /// (object index, pose change): enables and poses the object.
    pub objects: Vec<(usize, PoseChange)>,
    pub hide_objects: Vec<usize>,
    pub hide_lights: Vec<usize>,
    pub reference: Option<PathBuf>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Motion {
    pub name: String,
    pub object: usize,
    pub translations: Vec<DVec3>,
    /// Empty, or one reference photograph per pose.
    pub references: Vec<PathBuf>,
}

impl Scene {
    /// Reads and validates `scene.toml` and every file it names (meshes are
    /// loaded; images are checked to exist and read later, when needed).
    pub fn load(file: impl AsRef<Path>) -> Result<Scene> {
        let file = file.as_ref();
        let text = std::fs::read_to_string(file).map_err(|e| Error::io(file, &e))?;
        let table: toml::Table = text.parse().map_err(|e: toml::de::Error| {
            let line = e.span().map(|s| text[..s.start].lines().count().max(1));
            let msg = format!("malformed TOML: {}", e.message());
            match line {
                Some(l) => Error::line(file, l, msg),
                None => Error::file(file, msg),
            }
        })?;
        let dir = file.parent().unwrap_or(Path::new("")).to_path_buf();
        Loader { file, dir }.scene(&table)
    }

    /// Every file this scene reads: the manifest, meshes, photo or
    /// brackets, IES files, references. An output must be none of them.
    pub fn input_files(&self) -> Vec<PathBuf> {
        let mut files = vec![self.file.clone()];
        files.extend(self.surfaces.iter().map(|s| s.mesh.clone()));
        files.extend(self.objects.iter().map(|o| o.mesh.clone()));
        match &self.photo {
            Photo::Image(p) => files.push(p.clone()),
            Photo::Brackets(b) => files.extend(b.iter().map(|b| b.image.clone())),
        }
        for l in &self.lights {
            if let Intensity::Ies { file, .. } = &l.intensity {
                files.push(file.clone());
            }
        }
        files.extend(self.variants.iter().filter_map(|v| v.reference.clone()));
        for m in &self.motions {
            files.extend(m.references.iter().cloned());
        }
        files
    }

    /// The folder relative paths of this scene are resolved against.
    pub fn dir(&self) -> &Path {
        self.file.parent().unwrap_or(Path::new(""))
    }

    /// Names of all surfaces in arlux's numbering: real surfaces, then each
    /// virtual object's surfaces (as `object/surface`) in manifest order.
    pub fn surface_names(&self) -> Vec<String> {
        let mut names: Vec<String> = self.surfaces.iter().map(|s| s.name.clone()).collect();
        for o in &self.objects {
            names.extend(o.surfaces.iter().map(|s| format!("{}/{}", o.name, s.name)));
        }
        names
    }

    pub fn surface_index(&self, name: &str) -> Option<usize> {
        self.surfaces.iter().position(|s| s.name == name)
    }

    pub fn light_index(&self, name: &str) -> Option<usize> {
        self.lights.iter().position(|l| l.name == name)
    }

    pub fn triangle_count(&self) -> usize {
        self.surfaces.iter().map(|s| s.triangles.len()).sum()
    }

    pub fn variant(&self, name: &str) -> Result<&Variant> {
        self.variants
            .iter()
            .find(|v| v.name == name)
            .ok_or_else(|| {
                let have: Vec<&str> = self.variants.iter().map(|v| v.name.as_str()).collect();
                Error::key(
                    &self.file,
                    "variant",
                    format!("no variant named '{name}' (the scene has: {})", list(&have)),
                )
            })
    }

    pub fn motion(&self, name: &str) -> Result<&Motion> {
        self.motions.iter().find(|m| m.name == name).ok_or_else(|| {
            let have: Vec<&str> = self.motions.iter().map(|m| m.name.as_str()).collect();
            Error::key(
                &self.file,
                "motion",
                format!("no motion named '{name}' (the scene has: {})", list(&have)),
            )
        })
    }

    /// The effective scene of variant `name`: starting from this (base)
    /// scene, set light scales, enable and pose objects, hide what it hides.
    pub fn with_variant(&self, name: &str) -> Result<Scene> {
        let variant = self.variant(name)?.clone();
        let mut s = self.clone();
        for &(light, scale) in &variant.lights {
            s.lights[light].scale = scale;
        }
        for &(object, change) in &variant.objects {
            let o = &mut s.objects[object];
            o.enabled = true;
            o.pose.translate = change.translate.unwrap_or(o.pose.translate);
            o.pose.rotate_y_deg = change.rotate_y_deg.unwrap_or(o.pose.rotate_y_deg);
            o.pose.scale = change.scale.unwrap_or(o.pose.scale);
        }
        for &o in &variant.hide_objects {
            s.objects[o].enabled = false;
        }
        for &l in &variant.hide_lights {
            s.lights[l].scale = 0.0;
        }
        let key = format!(
            "variant[{}]",
            self.variants
                .iter()
                .position(|v| v.name == name)
                .unwrap_or(0)
        );
        s.check_light_clearance()
            .map_err(|e| e.within(&self.file, key))?;
        Ok(s)
    }

    /// The effective scene at pose `index` of motion `name`: the motion's
    /// object enabled and translated, its base rotation and scale kept.
    pub fn with_motion_pose(&self, name: &str, index: usize) -> Result<Scene> {
        let motion = self.motion(name)?;
        let Some(&t) = motion.translations.get(index) else {
            return Err(Error::key(
                &self.file,
                format!("motion '{name}'"),
                format!(
                    "has {} poses, pose {index} asked for",
                    motion.translations.len()
                ),
            ));
        };
        let mut s = self.clone();
        let o = &mut s.objects[motion.object];
        o.enabled = true;
        o.pose.translate = t;
        s.check_light_clearance()
            .map_err(|e| e.within(&self.file, format!("motion '{name}' pose {index}")))?;
        Ok(s)
    }

    /// The photo (or the merged brackets), with its negative pixels
    /// clamped to zero (a photo's radiance cannot be negative: they come from
    /// a merge's or a denoiser's ringing) and their count. Non-finite pixels
    /// are an error, as is a photo whose size is not the camera's.
    pub fn read_photo(&self) -> Result<(Image, usize)> {
        let (mut img, key, file) = match &self.photo {
            Photo::Image(path) => (
                image_io::read_image(path).map_err(|e| e.within(&self.file, "photo.image"))?,
                "photo.image",
                path.clone(),
            ),
            Photo::Brackets(brackets) => {
                let list: Vec<(PathBuf, f64)> =
                    brackets.iter().map(|b| (b.image.clone(), b.ev)).collect();
                (
                    crate::hdr::merge_cached(self.dir(), &list)
                        .map_err(|e| e.within(&self.file, "photo.brackets"))?,
                    "photo.brackets",
                    brackets
                        .first()
                        .map(|b| b.image.clone())
                        .unwrap_or_default(),
                )
            }
        };
        let (w, h) = (self.camera.width, self.camera.height);
        if (img.width, img.height) != (w, h) {
            return Err(Error::key(
                &self.file,
                key,
                format!(
                    "{} is {}x{} but the camera is {w}x{h}",
                    file.display(),
                    img.width,
                    img.height
                ),
            ));
        }
        let mut negative = 0;
        for p in &mut img.pixels {
            if p.min_element() < 0.0 {
                negative += 1;
                *p = p.max(glam::Vec3::ZERO);
            }
        }
        Ok((img, negative))
    }

    /// [`Scene::read_photo`]'s image.
    pub fn load_photo(&self) -> Result<Image> {
        self.read_photo().map(|(img, _)| img)
    }

    /// Whether the photo's radiance is known only up to a global factor
    /// (merged brackets: the base exposure time is unknown).
    pub fn photo_is_relative(&self) -> bool {
        matches!(self.photo, Photo::Brackets(_))
    }

    /// Errors unless `img` has the camera's size; `key` names where it came from.
    pub fn check_size(&self, img: &Image, key: &str) -> Result<()> {
        let (w, h) = (self.camera.width, self.camera.height);
        if (img.width, img.height) != (w, h) {
            return Err(Error::key(
                &self.file,
                key,
                format!(
                    "the image is {}x{} but the camera is {w}x{h}",
                    img.width, img.height
                ),
            ));
        }
        Ok(())
    }

    /// World-space triangles of every enabled virtual object's surfaces, with
    /// their ids (numbered after the real surfaces, as [`Scene::surface_names`]).
    pub fn virtual_world_surfaces(&self) -> Vec<(u32, Vec<Triangle>)> {
        let mut id = self.surfaces.len() as u32;
        let mut out = Vec::new();
        for o in &self.objects {
            for i in 0..o.surfaces.len() {
                if o.enabled {
                    out.push((id, o.world_triangles(i)));
                }
                id += 1;
            }
        }
        out
    }

    /// Diffuse reflectance of every virtual surface id (enabled or not).
    pub fn virtual_surface_rgb(&self) -> HashMap<u32, DVec3> {
        let mut id = self.surfaces.len() as u32;
        let mut out = HashMap::new();
        for o in &self.objects {
            for s in &o.surfaces {
                out.insert(id, s.rgb);
                id += 1;
            }
        }
        out
    }

    /// Whether this scene differs from what the photo shows: an enabled
    /// virtual object, a real light not at scale 1, or a virtual light on.
    pub fn changes_the_photo(&self) -> bool {
        self.objects.iter().any(|o| o.enabled)
            || self
                .lights
                .iter()
                .any(|l| l.scale != if l.real { 1.0 } else { 0.0 })
    }

    /// Refuses a light whose centre lies on a surface or inside a closed
    /// solid (real, or an enabled virtual object): its light cannot reach the
    /// room, or its irradiance is singular.
    pub fn check_light_clearance(&self) -> Result<()> {
        let mut solids: Vec<(String, Vec<Triangle>)> = self
            .surfaces
            .iter()
            .map(|s| (s.name.clone(), s.triangles.clone()))
            .collect();
        for o in self.objects.iter().filter(|o| o.enabled) {
            for i in 0..o.surfaces.len() {
                solids.push((
                    format!("{}/{}", o.name, o.surfaces[i].name),
                    o.world_triangles(i),
                ));
            }
        }
        for (li, light) in self.lights.iter().enumerate() {
            let Some(p) = light.known_position() else {
                continue;
            };
            let key = format!("light[{li}].position");
            for (name, tris) in &solids {
                let d = tris
                    .iter()
                    .map(|t| geometry::distance_to_triangle(p, t))
                    .fold(f64::INFINITY, f64::min);
                if d < MIN_LIGHT_CLEARANCE_M {
                    return Err(Error::key(
                        &self.file,
                        key,
                        format!(
                            "light '{}' lies on surface '{name}' ({d:.2e} m away)",
                            light.name
                        ),
                    ));
                }
                if geometry::is_closed(tris) && geometry::encloses(tris, p) {
                    return Err(Error::key(
                        &self.file,
                        key,
                        format!(
                            "light '{}' lies inside the closed surface '{name}'",
                            light.name
                        ),
                    ));
                }
            }
        }
        Ok(())
    }
}

/// A table's `surface` key: the name and the index of the real surface it names.
fn real_surface<'a>(r: &Fields<'a>, surfaces: &[Surface]) -> Result<(&'a str, usize)> {
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

fn list(names: &[&str]) -> String {
    if names.is_empty() {
        "none".into()
    } else {
        names.join(", ")
    }
}

/// Reads one scene file; holds what every part needs to resolve paths and
/// report errors.
struct Loader<'a> {
    file: &'a Path,
    dir: PathBuf,
}

impl Loader<'_> {
    /// A path from the file, resolved and checked to exist.
    fn existing_path(&self, f: &Fields, key: &'static str, rel: &str) -> Result<PathBuf> {
        let p = self.dir.join(rel);
        match std::fs::metadata(&p) {
            Ok(m) if m.is_file() => Ok(p),
            Ok(_) => Err(f.error(key, format!("{} is not a file", p.display()))),
            Err(_) => Err(f.error(key, format!("file not found: {}", p.display()))),
        }
    }

    fn scene(&self, table: &toml::Table) -> Result<Scene> {
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
        let camera = self.camera(&top.req_table("camera")?)?;
        let photo = self.photo(&top.req_table("photo")?)?;

        let mut surfaces: Vec<Surface> = Vec::new();
        let mut warnings = Vec::new();
        let reals = top.tables("real")?;
        if reals.is_empty() {
            return Err(top.error(
                "real",
                "missing: the scene needs at least one [[real]] mesh",
            ));
        }
        for r in &reals {
            let rel = r.req_str("mesh")?;
            let path = self.existing_path(r, "mesh", rel)?;
            r.finish()?;
            let mesh =
                geometry::load_obj(&path).map_err(|e| e.within(self.file, r.key_path("mesh")))?;
            if mesh.dropped_triangles > 0 {
                warnings.push(format!(
                    "{}: dropped {} degenerate or non-finite triangles",
                    path.display(),
                    mesh.dropped_triangles
                ));
            }
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

        let mut reflectances = Vec::new();
        for r in top.tables("reflectance")? {
            let (sname, surface) = real_surface(&r, &surfaces)?;
            let rgb = r.req_rgb("rgb")?;
            if rgb.max_element() > 1.0 {
                return Err(r.error("rgb", "a reflectance lies in [0, 1]"));
            }
            if reflectances
                .iter()
                .any(|k: &KnownReflectance| k.surface == surface)
            {
                return Err(r.error("surface", format!("'{sname}' is given twice")));
            }
            r.finish()?;
            reflectances.push(KnownReflectance { surface, rgb });
        }

        let mut texture_references: Vec<TextureReference> = Vec::new();
        for r in top.tables("texture_reference")? {
            let (sname, surface) = real_surface(&r, &surfaces)?;
            let point = r.req_vec3("point")?;
            if texture_references.iter().any(|k| k.surface == surface) {
                return Err(r.error("surface", format!("'{sname}' is given twice")));
            }
            r.finish()?;
            texture_references.push(TextureReference { surface, point });
        }

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
            let motion = self.motion(&m, &objects)?;
            if motions.iter().any(|o| o.name == motion.name) {
                return Err(m.error(
                    "name",
                    format!("motion name '{}' is used twice", motion.name),
                ));
            }
            motions.push(motion);
        }
        top.finish()?;

        let scene = Scene {
            name,
            file: self.file.to_path_buf(),
            camera,
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
        scene.check_light_clearance()?;
        Ok(scene)
    }

    fn camera(&self, c: &Fields) -> Result<Camera> {
        let width = c.req_count("width")?;
        let height = c.req_count("height")?;
        const MAX_SIDE: u32 = 1 << 15;
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

    fn photo(&self, p: &Fields) -> Result<Photo> {
        let photo = match (p.opt_str("image")?, p.has("brackets")) {
            (Some(_), true) => return Err(p.error("brackets", "give image or brackets, not both")),
            (None, false) => return Err(p.error("image", "missing (or give brackets)")),
            (Some(rel), false) => Photo::Image(self.existing_path(p, "image", rel)?),
            (None, true) => {
                let mut brackets: Vec<Bracket> = Vec::new();
                for b in p.tables("brackets")? {
                    let image = self.existing_path(&b, "image", b.req_str("image")?)?;
                    let ev = b.req_f64("ev")?;
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

    fn light(&self, l: &Fields, has_known_reflectance: bool) -> Result<Light> {
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

    fn shadow_constraints(&self, p: &Fields) -> Result<ShadowConstraints> {
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

    fn intensity(
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

    fn object(&self, v: &Fields, warnings: &mut Vec<String>) -> Result<VirtualObject> {
        let name = v.req_str("name")?.to_string();
        let path = self.existing_path(v, "mesh", v.req_str("mesh")?)?;
        let rgb = v.opt_vec3("rgb")?;
        if let Some(rgb) = rgb
            && (rgb.min_element() < 0.0 || rgb.max_element() > 1.0)
        {
            return Err(v.error("rgb", "a reflectance lies in [0, 1]"));
        }
        let pose = Pose {
            translate: v.opt_place("translate")?.unwrap_or(DVec3::ZERO),
            rotate_y_deg: v.opt_f64("rotate_y_deg")?.unwrap_or(0.0),
            scale: v.opt_f64("scale")?.unwrap_or(1.0),
        };
        if pose.scale <= 0.0 {
            return Err(v.error("scale", "must be positive"));
        }
        let enabled = v.opt_bool("enabled")?.unwrap_or(true);
        v.finish()?;
        let mesh =
            geometry::load_obj(&path).map_err(|e| e.within(self.file, v.key_path("mesh")))?;
        if mesh.dropped_triangles > 0 {
            warnings.push(format!(
                "{}: dropped {} degenerate or non-finite triangles",
                path.display(),
                mesh.dropped_triangles
            ));
        }
        let mut surfaces = Vec::new();
        for s in mesh.surfaces {
            let rgb = match (rgb, s.material_rgb) {
                (Some(rgb), _) => rgb,
                (None, Some(kd)) => kd.as_dvec3().clamp(DVec3::ZERO, DVec3::ONE),
                (None, None) => {
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
                name: s.name,
                triangles: s.triangles,
                rgb,
            });
        }
        Ok(VirtualObject {
            name,
            mesh: path,
            surfaces,
            pose,
            enabled,
        })
    }

    fn variant(&self, v: &Fields, lights: &[Light], objects: &[VirtualObject]) -> Result<Variant> {
        let name = v.req_str("name")?.to_string();
        let mut variant = Variant {
            name,
            lights: vec![],
            objects: vec![],
            hide_objects: vec![],
            hide_lights: vec![],
            reference: None,
        };
        if let Some(t) = v.opt_table("lights")? {
            for (lname, value) in t.entries() {
                let key = t.key_path(lname);
                let index = lights.iter().position(|l| l.name == lname).ok_or_else(|| {
                    Error::key(self.file, key.clone(), format!("no light named '{lname}'"))
                })?;
                let scale =
                    fields::number(value).map_err(|m| Error::key(self.file, key.clone(), m))?;
                if scale < 0.0 {
                    return Err(Error::key(
                        self.file,
                        key,
                        "a light's scale must not be negative",
                    ));
                }
                variant.lights.push((index, scale));
            }
        }
        if let Some(t) = v.opt_table("objects")? {
            for (oname, value) in t.entries() {
                let key = t.key_path(oname);
                let index = objects
                    .iter()
                    .position(|o| o.name == oname)
                    .ok_or_else(|| {
                        Error::key(
                            self.file,
                            key.clone(),
                            format!("no virtual object named '{oname}'"),
                        )
                    })?;
                let p = Fields::new(self.file, key, value)?;
                let change = PoseChange {
                    translate: p.opt_place("translate")?,
                    rotate_y_deg: p.opt_f64("rotate_y_deg")?,
                    scale: p.opt_f64("scale")?,
                };
                if change.scale.is_some_and(|s| s <= 0.0) {
                    return Err(p.error("scale", "must be positive"));
                }
                p.finish()?;
                variant.objects.push((index, change));
            }
        }
        if let Some(items) = v.opt_array("hide")? {
            for (path, item) in items {
                let toml::Value::String(n) = item else {
                    return Err(Error::key(
                        self.file,
                        path,
                        "must be the name of a virtual object or light",
                    ));
                };
                if let Some(o) = objects.iter().position(|o| &o.name == n) {
                    if variant.objects.iter().any(|(i, _)| *i == o) {
                        return Err(Error::key(
                            self.file,
                            path,
                            format!("'{n}' is both posed and hidden"),
                        ));
                    }
                    variant.hide_objects.push(o);
                } else if let Some(l) = lights.iter().position(|l| &l.name == n) {
                    if variant.lights.iter().any(|(i, _)| *i == l) {
                        return Err(Error::key(
                            self.file,
                            path,
                            format!("'{n}' is both given a scale and hidden"),
                        ));
                    }
                    variant.hide_lights.push(l);
                } else {
                    return Err(Error::key(
                        self.file,
                        path,
                        format!("no virtual object or light named '{n}'"),
                    ));
                }
            }
        }
        if let Some(rel) = v.opt_str("reference")? {
            variant.reference = Some(self.existing_path(v, "reference", rel)?);
        }
        v.finish()?;
        Ok(variant)
    }

    fn motion(&self, m: &Fields, objects: &[VirtualObject]) -> Result<Motion> {
        let name = m.req_str("name")?.to_string();
        let oname = m.req_str("object")?;
        let object = objects
            .iter()
            .position(|o| o.name == oname)
            .ok_or_else(|| m.error("object", format!("no virtual object named '{oname}'")))?;
        let items = m
            .opt_array("translations")?
            .ok_or_else(|| m.error("translations", "missing"))?;
        if items.is_empty() {
            return Err(m.error("translations", "needs at least one pose"));
        }
        let translations = items
            .iter()
            .map(|(path, v)| {
                fields::place(v).map_err(|msg| Error::key(self.file, path.clone(), msg))
            })
            .collect::<Result<Vec<_>>>()?;
        let mut references = Vec::new();
        if let Some(refs) = m.opt_array("references")? {
            if refs.len() != translations.len() {
                return Err(m.error(
                    "references",
                    format!(
                        "{} references for {} poses: give one per pose",
                        refs.len(),
                        translations.len()
                    ),
                ));
            }
            for (path, v) in refs {
                let toml::Value::String(rel) = v else {
                    return Err(Error::key(self.file, path, "must be a file name"));
                };
                let p = self.dir.join(rel);
                if !p.is_file() {
                    return Err(Error::key(
                        self.file,
                        path,
                        format!("file not found: {}", p.display()),
                    ));
                }
                references.push(p);
            }
        }
        m.finish()?;
        Ok(Motion {
            name,
            object,
            translations,
            references,
        })
    }
}

#[cfg(test)]
mod tests;
