//! [`Scene`]: everything `scene.toml` describes (see `docs/scene-format.md`),
//! loaded, checked and resolved into plain data: the camera, the photo, the
//! real surfaces, the lights, the virtual objects, the variants and motions.
//!
//! [`Scene::load`] reads and validates the whole file; [`Scene::with_variant`]
//! and [`Scene::with_motion_pose`] give the effective scene of a variant or a
//! motion pose. Every error names the file and the key path.

pub mod calibration;
mod fields;
mod loader;
mod materials;
mod placement;
mod stand;

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
pub(crate) const MIN_LIGHT_CLEARANCE_M: f64 = 1e-5;

/// A loaded, validated scene.
#[derive(Debug, Clone)]
pub struct Scene {
    pub name: String,
    /// The `scene.toml` this came from; relative paths were resolved against its folder.
    pub file: PathBuf,
    /// Its text as read: what a saved variant appends to, whatever the
    /// file holds by then.
    pub source: String,
    pub camera: Camera,
    /// The photo's and the references' size: the camera's before its
    /// `scale` (equal to the camera's size without one).
    pub photo_size: (u32, u32),
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

/// A virtual object's placement: p' = translate + rotation·(scale·p).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    pub translate: DVec3,
    /// A rotation (orthonormal, determinant 1).
    pub rotation: DMat3,
    pub scale: f64,
}

impl Pose {
    pub fn apply(&self, p: Vec3) -> Vec3 {
        (self.translate + self.rotation * (p.as_dvec3() * self.scale)).as_vec3()
    }

    /// The rotation about +y by `degrees`, counter-clockwise seen from above.
    pub(crate) fn about_y(degrees: f64) -> DMat3 {
        DMat3::from_rotation_y(degrees.to_radians())
    }

    /// The rotation as angles about x, then y, then z (degrees): the
    /// rotation is R_z·R_y·R_x, Blender's XYZ Euler order.
    pub fn euler_xyz_deg(&self) -> [f64; 3] {
        let r = |i: usize, j: usize| self.rotation.col(j)[i];
        let y = (-r(2, 0)).clamp(-1.0, 1.0).asin();
        let (x, z) = if r(2, 0).abs() < 1.0 - 1e-12 {
            (r(2, 1).atan2(r(2, 2)), r(1, 0).atan2(r(0, 0)))
        } else {
            // Gimbal lock: z is taken as 0.
            ((-r(1, 2)).atan2(r(1, 1)), 0.0)
        };
        [x, y, z].map(f64::to_degrees)
    }
}

/// One surface of a virtual object, in the object's own frame.
#[derive(Debug, Clone)]
pub struct ObjectSurface {
    pub name: String,
    /// Shared: objects read from one file, and every copy of the scene
    /// (a variant's, a session's), hold one array (an 80k-triangle mesh
    /// is 2.9 MB a copy).
    pub triangles: std::sync::Arc<[Triangle]>,
    /// Diffuse reflectance as radiosity exchanges light: the scene's `rgb`,
    /// else the OBJ material's Kd; with a material, its mean hemispherical albedo.
    pub rgb: DVec3,
    /// The material its pixels are shaded with (None: diffuse `rgb`).
    pub material: Option<crate::materials::SurfaceMaterial>,
}

#[derive(Debug, Clone)]
pub struct VirtualObject {
    pub name: String,
    pub mesh: PathBuf,
    pub surfaces: Vec<ObjectSurface>,
    pub pose: Pose,
    pub enabled: bool,
    /// Whether its mesh was read: a scene loaded for one variant or motion
    /// ([`Scene::load_showing`]) leaves the others' unread (no surfaces),
    /// and refuses to show them.
    pub mesh_read: bool,
    /// `stand = "below"`: dropped onto the real surface under it wherever
    /// it is placed ([`Scene::stand_objects`]).
    pub stand_below: bool,
}

impl VirtualObject {
    /// The farthest any vertex can lie from the origin under `pose`:
    /// |translate| + scale · (largest vertex distance in the object's frame).
    pub fn reach(&self, pose: &Pose) -> f64 {
        let radius = self
            .surfaces
            .iter()
            .flat_map(|s| s.triangles.iter())
            .flat_map(|t| t.iter().copied())
            .map(|p| p.as_dvec3().length())
            .fold(0.0, f64::max);
        pose.translate.length() + pose.scale * radius
    }

    /// The triangles of surface `i` placed in the world.
    pub(crate) fn world_triangles(&self, i: usize) -> Vec<Triangle> {
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
    pub rotation: Option<DMat3>,
    pub scale: Option<f64>,
}

impl PoseChange {
    /// `pose` with this change made.
    pub(crate) fn applied_to(&self, pose: &Pose) -> Pose {
        Pose {
            translate: self.translate.unwrap_or(pose.translate),
            rotation: self.rotation.unwrap_or(pose.rotation),
            scale: self.scale.unwrap_or(pose.scale),
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct Variant {
    pub name: String,
    /// (light index, new scale)
    pub lights: Vec<(usize, f64)>,
    /// (light index, new position): a virtual light moved.
    pub light_positions: Vec<(usize, DVec3)>,
    /// (object index, pose change): enables and poses the object.
    pub objects: Vec<(usize, PoseChange)>,
    pub hide_objects: Vec<usize>,
    pub hide_lights: Vec<usize>,
    pub reference: Option<PathBuf>,
    /// What the reference's own Monte Carlo noise is, when known.
    pub reference_noise: Option<ReferenceNoise>,
}

/// A reference's own noise: declared as a relative per-pixel RMSE (each
/// dataset's `NOISE.txt`: RMSE between two independent renders / √2 /
/// their mean), or measured from a second independent render of it.
#[derive(Debug, Clone, PartialEq)]
pub enum ReferenceNoise {
    Declared(f64),
    Twin(PathBuf),
}

#[derive(Debug, Clone, PartialEq)]
pub struct Motion {
    pub name: String,
    pub object: usize,
    /// What the poses start from (`variant`, `hide`): None for the scene
    /// as written.
    pub start: Option<Variant>,
    pub translations: Vec<DVec3>,
    /// Empty, or one reference photograph per pose.
    pub references: Vec<PathBuf>,
    /// The references' own noise, when declared (relative per-pixel RMSE).
    pub reference_noise: Option<f64>,
}

impl Scene {
    /// Reads and validates `scene.toml` and every file it names (meshes are
    /// loaded; images are checked to exist and read later, when needed).
    pub fn load(file: impl AsRef<Path>) -> Result<Scene> {
        Scene::load_showing(file, Showing::Everything)
    }

    /// [`Scene::load`], reading the meshes of only the objects `showing`
    /// shows: a variant, a motion or the base scene does not pay for the
    /// objects it leaves out. Every key is still checked.
    pub fn load_showing(file: impl AsRef<Path>, showing: Showing) -> Result<Scene> {
        let file = file.as_ref();
        let text = std::fs::read_to_string(file).map_err(|e| Error::io(file, &e))?;
        Scene::from_text(file, text, showing)
    }

    /// The scene `text` describes, read as if it were `file`'s (paths are
    /// relative to its folder): what a front end that adds to a scene's
    /// text (`arlux serve --assets`) renders, as the saved file will read.
    pub fn from_text(file: &Path, text: String, showing: Showing) -> Result<Scene> {
        let table: toml::Table = text.parse().map_err(|e: toml::de::Error| {
            let line = e.span().map(|s| text[..s.start].lines().count().max(1));
            let msg = format!("malformed TOML: {}", e.message());
            match line {
                Some(l) => Error::line(file, l, msg),
                None => Error::file(file, msg),
            }
        })?;
        let dir = file.parent().unwrap_or(Path::new("")).to_path_buf();
        let mut scene = Loader::showing(file, dir, &table, showing).scene(&table)?;
        scene.source = text;
        Ok(scene)
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
        files.extend(
            self.variants
                .iter()
                .filter_map(|v| match &v.reference_noise {
                    Some(ReferenceNoise::Twin(t)) => Some(t.clone()),
                    _ => None,
                }),
        );
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

    /// The bounding box of the real geometry.
    pub fn real_bounds(&self) -> (DVec3, DVec3) {
        geometry::bounds(
            self.surfaces
                .iter()
                .flat_map(|s| s.triangles.iter().flatten())
                .map(|p| p.as_dvec3()),
        )
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
        let key = format!(
            "variant[{}]",
            self.variants
                .iter()
                .position(|v| v.name == name)
                .unwrap_or(0)
        );
        self.with_given_variant(&variant)
            .map_err(|e| e.within(&self.file, key))
    }

    /// Reads one `[[variant]]` table as the scene file would hold it (its
    /// names resolved against this scene's lights and objects): what a front
    /// end that edits the scene (`arlux serve`) builds, so that what it
    /// renders is what the variant, once written, renders.
    pub fn parse_variant(&self, table: &toml::Table) -> Result<Variant> {
        let loader = Loader::new(&self.file, self.dir().to_path_buf());
        let fields = fields::Fields::of_table(&self.file, "variant", table);
        loader.variant(&fields, &self.lights, &self.objects)
    }

    /// The effective scene of `variant` (see [`Scene::with_variant`]).
    pub fn with_given_variant(&self, variant: &Variant) -> Result<Scene> {
        let mut s = self.clone();
        for &(light, scale) in &variant.lights {
            s.lights[light].scale = scale;
        }
        for &(light, p) in &variant.light_positions {
            s.lights[light].position = LightPosition::Known(p);
        }
        for &(object, change) in &variant.objects {
            let o = &mut s.objects[object];
            o.enabled = true;
            o.pose = change.applied_to(&o.pose);
        }
        for &o in &variant.hide_objects {
            s.objects[o].enabled = false;
        }
        s.check_shown_read(&format!("variant '{}'", variant.name))?;
        s.stand_objects()?;
        for &l in &variant.hide_lights {
            s.lights[l].scale = 0.0;
        }
        s.check_light_clearance()?;
        Ok(s)
    }

    /// An error when an enabled object's mesh was not read (the scene was
    /// loaded for something else): never an image silently without it.
    fn check_shown_read(&self, what: &str) -> Result<()> {
        match self.objects.iter().find(|o| o.enabled && !o.mesh_read) {
            None => Ok(()),
            Some(o) => Err(Error::key(
                &self.file,
                what,
                format!(
                    "shows '{}', whose mesh was not read: load the scene for it (Scene::load_showing)",
                    o.name
                ),
            )),
        }
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
        let mut s = match &motion.start {
            Some(v) => self.with_given_variant(v)?,
            None => self.clone(),
        };
        let o = &mut s.objects[motion.object];
        o.enabled = true;
        o.pose.translate = t;
        s.check_shown_read(&format!("motion '{name}'"))?;
        (s.stand_objects())
            .and_then(|_| s.check_light_clearance())
            .map_err(|e| e.within(&self.file, format!("motion '{name}' pose {index}")))?;
        Ok(s)
    }

    /// The photo (or the merged brackets), with its negative pixels
    /// clamped to zero (a photo's radiance cannot be negative: they come from
    /// a merge's or a denoiser's ringing) and their count. Non-finite pixels
    /// are an error, as is a photo whose size is not the camera's.
    pub fn read_photo(&self) -> Result<(Image, usize)> {
        let (img, key, file) = match &self.photo {
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
        let mut img = self.fit_size(img, key, &file)?;
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

    /// Reads the reference photograph `file` (given at `key`) whole and
    /// checks it fits the camera ([`Scene::fit_size`]): what a command does
    /// before any work, so that a bad reference stops it before the render.
    pub fn check_reference(&self, key: &str, file: &Path) -> Result<()> {
        self.reference_rows(key, file).map(drop)
    }

    /// The reference photograph `file` (given at `key`) at the camera's
    /// size, to be read a few rows at a time: an EXR of the camera's size
    /// is read from its file as rows are asked for (all of it decoded once
    /// now, to refuse a damaged one, but not held); any other is read whole
    /// now, as [`Scene::read_reference`].
    pub fn reference_rows(&self, key: &str, file: &Path) -> Result<image_io::RowReader> {
        if !file.is_file() {
            return self
                .read_reference(key, file)
                .map(image_io::RowReader::from_image);
        }
        let mut rows = image_io::RowReader::open(file)?;
        if (rows.width, rows.height) == (self.camera.width, self.camera.height) {
            // Every block decoded once now, none kept: a cut or damaged
            // file, or a NaN, is refused before any work.
            while !rows.rows(64)?.is_empty() {}
            return image_io::RowReader::open(file);
        }
        // Rare (a reference of the photo's size, the camera scaled): read again, whole.
        self.read_reference(key, file)
            .map(image_io::RowReader::from_image)
    }

    /// The reference photograph `file` (given at `key`) at the camera's
    /// size; a missing file is an error naming the key (loading only warns).
    pub fn read_reference(&self, key: &str, file: &Path) -> Result<Image> {
        if !file.is_file() {
            return Err(Error::key(
                &self.file,
                key,
                format!("file not found: {}", file.display()),
            ));
        }
        self.fit_size(image_io::read_image(file)?, key, file)
    }

    /// `img`, read from `file`, at the camera's size: as it is when it has
    /// that size, averaged down when it has the photo's size and the camera
    /// renders at a `scale`; otherwise an error (`key` names where the scene
    /// gave the file).
    pub fn fit_size(&self, img: Image, key: &str, file: &Path) -> Result<Image> {
        let (w, h) = (self.camera.width, self.camera.height);
        if (img.width, img.height) == (w, h) {
            return Ok(img);
        }
        if (img.width, img.height) == self.photo_size {
            return Ok(img.area_resampled(w, h));
        }
        let (pw, ph) = self.photo_size;
        let scaled = if (pw, ph) != (w, h) {
            format!(" ({pw}x{ph} before its scale)")
        } else {
            String::new()
        };
        Err(Error::key(
            &self.file,
            key,
            format!(
                "{} is {}x{} but the camera is {w}x{h}{scaled}",
                file.display(),
                img.width,
                img.height
            ),
        ))
    }

    /// Every virtual object's surfaces with their ids, numbered after the
    /// real surfaces over every object, enabled or not (as
    /// [`Scene::surface_names`]): (id, object, the surface's index in it).
    pub fn virtual_surfaces(&self) -> impl Iterator<Item = (u32, &VirtualObject, usize)> {
        (self.objects.iter())
            .flat_map(|o| (0..o.surfaces.len()).map(move |i| (o, i)))
            .zip(self.surfaces.len() as u32..)
            .map(|((o, i), id)| (id, o, i))
    }

    /// World-space triangles of every enabled virtual object's surfaces, with
    /// their ids ([`Scene::virtual_surfaces`]).
    pub fn virtual_world_surfaces(&self) -> Vec<(u32, Vec<Triangle>)> {
        (self.virtual_surfaces())
            .filter(|(_, o, _)| o.enabled)
            .map(|(id, o, i)| (id, o.world_triangles(i)))
            .collect()
    }

    /// Diffuse reflectance of every virtual surface id (enabled or not).
    pub(crate) fn virtual_surface_rgb(&self) -> HashMap<u32, DVec3> {
        (self.virtual_surfaces())
            .map(|(id, o, i)| (id, o.surfaces[i].rgb))
            .collect()
    }

    /// Radiosity emitted (π × the mean emitted radiance) by every virtual
    /// surface whose material glows; the others are absent.
    pub(crate) fn virtual_surface_emission(&self) -> HashMap<u32, DVec3> {
        (self.virtual_surfaces())
            .filter_map(|(id, o, i)| {
                let m = o.surfaces[i].material.as_ref()?;
                let glow = m.material.mean_emission();
                (glow != DVec3::ZERO).then(|| (id, glow * std::f64::consts::PI))
            })
            .collect()
    }

    /// Whether this scene differs from what the photo shows: an enabled
    /// virtual object, a real light not at scale 1, or a virtual light on.
    pub(crate) fn changes_the_photo(&self) -> bool {
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

pub use loader::Showing;
use loader::*;

#[cfg(test)]
mod tests;
