//! Meshes besides OBJ: glTF 2.0 (`.gltf`, `.glb`; the `gltf` crate) and
//! PLY (`.ply`, ASCII or binary; `ply-rs-bw`), read into the same
//! [`Mesh`] as an OBJ: named surfaces of triangles, an optional colour each.

use std::path::Path;

use glam::{DMat4, Vec2, Vec3, Vec4};

use super::{MAX_COORDINATE, Mesh, MeshSurface, Triangle, is_degenerate};
use crate::error::{Error, Result};
use crate::materials::Attributes;

/// Loads a mesh by its file's extension: `.obj`, `.gltf`/`.glb`, `.ply`.
pub fn load_mesh(path: &Path) -> Result<Mesh> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    match ext.as_str() {
        "obj" => super::load_obj(path),
        "gltf" | "glb" => load_gltf(path),
        "ply" => load_ply(path),
        _ => Err(Error::file(
            path,
            format!("unknown mesh type '.{ext}' (use .obj, .gltf, .glb or .ply)"),
        )),
    }
}

/// Triangles kept, and how many were dropped (degenerate); an error names
/// a corner beyond [`MAX_COORDINATE`] or not finite.
struct Collect {
    dropped: usize,
}

impl Collect {
    /// Keeps `t` unless degenerate; returns whether it was kept.
    fn keep(&mut self, path: &Path, t: Triangle, out: &mut Vec<Triangle>) -> Result<bool> {
        if let Some(far) = t
            .iter()
            .flat_map(|p| p.to_array())
            .find(|c| c.abs() > MAX_COORDINATE)
        {
            return Err(Error::file(
                path,
                format!(
                    "vertex coordinate {far} lies beyond ±{MAX_COORDINATE} m: single-precision rays cannot resolve a room there (move the model near the origin)"
                ),
            ));
        }
        if is_degenerate(&t) {
            self.dropped += 1;
            Ok(false)
        } else {
            out.push(t);
            Ok(true)
        }
    }
}

/// Fans a polygon's corner indices into triangles (0, i, i+1), as OBJ
/// readers do.
fn fan(corners: &[usize]) -> impl Iterator<Item = [usize; 3]> + '_ {
    (1..corners.len().saturating_sub(1)).map(|i| [corners[0], corners[i], corners[i + 1]])
}

/// A glTF's triangles as placed by its default scene: one surface per
/// node with a mesh, named by the node (else its mesh, else `mesh<i>`);
/// the material's base colour as the surface's colour.
fn load_gltf(path: &Path) -> Result<Mesh> {
    // The gltf crate trusts a validated document in places fuzzing showed
    // it should not (an index's type, an accessor's range): what the
    // checks below do not catch is contained, and reported as malformed.
    crate::util::guard::contain(|| read_gltf(path)).unwrap_or_else(|| {
        Err(Error::file(
            path,
            "malformed glTF: the glTF reader failed on it",
        ))
    })
}

/// What the glTF reader would misread or panic on, refused with the reason.
fn check_gltf_json(path: &Path, root: &gltf::json::Root) -> Result<()> {
    // A required extension changes how the data is read (Draco or meshopt
    // compression, quantized or basis-compressed data): none is read here.
    if let Some(ext) = root.extensions_required.first() {
        let hint = match ext.as_str() {
            "KHR_draco_mesh_compression" | "EXT_meshopt_compression" => {
                "decompress it first (gltf-transform copy IN OUT, or Blender's export without compression)"
            }
            _ => "export it without that extension (gltf-transform can convert most)",
        };
        return Err(Error::file(
            path,
            format!(
                "the file requires the glTF extension {ext}, which arlux does not read: {hint}"
            ),
        ));
    }
    // gltf-json 1.4 looks up a primitive's POSITION accessor before it
    // checks the index (and panics on a bad one, as fuzzing found): check
    // it here, then let the crate validate the rest.
    let accessors = root.accessors.len();
    let positions = gltf::json::validation::Checked::Valid(gltf::Semantic::Positions);
    for (m, mesh) in root.meshes.iter().enumerate() {
        for p in &mesh.primitives {
            if p.attributes
                .get(&positions)
                .is_some_and(|i| i.value() >= accessors)
            {
                return Err(Error::file(
                    path,
                    format!(
                        "malformed glTF: mesh {m}'s POSITION names an accessor past its {accessors}"
                    ),
                ));
            }
        }
    }
    Ok(())
}

fn read_gltf(path: &Path) -> Result<Mesh> {
    let bad = |e: gltf::Error| Error::file(path, format!("malformed glTF: {e}"));
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, &e))?;
    let raw = gltf::Gltf::from_slice_without_validation(&bytes).map_err(bad)?;
    let root = raw.document.into_json();
    check_gltf_json(path, &root)?;
    let doc = gltf::Document::from_json(root).map_err(bad)?;
    let base = path.parent().unwrap_or(Path::new("."));
    let buffers = gltf::import_buffers(&doc, Some(base), raw.blob).map_err(bad)?;
    let scene = doc
        .default_scene()
        .or_else(|| doc.scenes().next())
        .ok_or_else(|| Error::file(path, "no scene"))?;
    let mut surfaces: Vec<MeshSurface> = Vec::new();
    let mut collect = Collect { dropped: 0 };
    let mut materials = super::gltf_material::GltfMaterials::new(path, &doc, &buffers);
    // Depth first in document order: the surfaces come in the order the file lists them.
    let mut stack: Vec<(gltf::Node, DMat4)> = scene.nodes().map(|n| (n, DMat4::IDENTITY)).collect();
    stack.reverse();
    let mut visited = 0usize;
    while let Some((node, parent)) = stack.pop() {
        visited += 1;
        if visited > 1_000_000 {
            return Err(Error::file(
                path,
                "its node hierarchy does not end (a cycle)",
            ));
        }
        let local = DMat4::from_cols_array_2d(&node.transform().matrix().map(|c| c.map(f64::from)));
        let world = parent * local;
        let children: Vec<_> = node.children().map(|c| (c, world)).collect();
        stack.extend(children.into_iter().rev());
        let Some(mesh) = node.mesh() else { continue };
        let name = node
            .name()
            .or(mesh.name())
            .map_or_else(|| format!("mesh{}", mesh.index()), str::to_string);
        // One surface per material the node's primitives use (named by
        // the node alone when it uses one).
        let mut parts: Vec<(Option<usize>, MeshSurface)> = Vec::new();
        for prim in mesh.primitives() {
            use gltf::mesh::Mode;
            if !matches!(
                prim.mode(),
                Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
            ) {
                materials.note(format!(
                    "primitives of mode {:?} (points and lines are not surfaces)",
                    prim.mode()
                ));
                continue;
            }
            let key = prim.material().index();
            let at = match parts.iter().position(|(k, _)| *k == key) {
                Some(i) => i,
                None => {
                    let c = prim.material().pbr_metallic_roughness().base_color_factor();
                    parts.push((
                        key,
                        MeshSurface {
                            name: name.clone(),
                            triangles: Vec::new(),
                            material_rgb: Some(Vec3::new(c[0], c[1], c[2])),
                            // A primitive without a material takes glTF's
                            // default (a rough white metal) only in viewers:
                            // here it stays clay of the scene's `rgb`.
                            material: match key {
                                Some(_) => Some(materials.get(prim.material())?),
                                None => None,
                            },
                            attributes: Attributes::default(),
                        },
                    ));
                    parts.len() - 1
                }
            };
            let placed = Placed {
                path,
                name: &name,
                world,
            };
            let s = &mut parts[at].1;
            placed.triangles(&prim, &buffers, &mut collect, s)?;
        }
        let several = parts.len() > 1;
        for (_, mut s) in parts {
            if several {
                let m = s.material.as_ref().map_or("default", |m| m.name.as_str());
                s.name = format!("{}.{m}", s.name);
            }
            if !s.triangles.is_empty() {
                surfaces.push(s);
            }
        }
    }
    let unsupported = materials.unsupported();
    if surfaces.is_empty() && collect.dropped == 0 && !unsupported.is_empty() {
        return Err(Error::file(
            path,
            format!("no triangles to read: it has {}", unsupported.join(", ")),
        ));
    }
    let mut mesh = finish(path, surfaces, collect.dropped)?;
    mesh.unsupported = unsupported;
    Ok(mesh)
}

/// The corners of a primitive's triangles: in threes, or as a strip
/// (every other triangle turned back to keep the winding) or a fan.
fn triangle_corners(mode: gltf::mesh::Mode, indices: &[usize]) -> Vec<[usize; 3]> {
    use gltf::mesh::Mode;
    let n = indices.len();
    match mode {
        Mode::TriangleStrip => (0..n.saturating_sub(2))
            .map(|i| match i % 2 {
                0 => [indices[i], indices[i + 1], indices[i + 2]],
                _ => [indices[i + 1], indices[i], indices[i + 2]],
            })
            .collect(),
        Mode::TriangleFan => (1..n.saturating_sub(1))
            .map(|i| [indices[0], indices[i], indices[i + 1]])
            .collect(),
        _ => indices
            .chunks_exact(3)
            .map(|t| [t[0], t[1], t[2]])
            .collect(),
    }
}

/// Refuses an accessor whose elements do not all lie within its
/// bufferView, or a bufferView that does not lie within its buffer: the
/// crate's reader would give fewer elements than the accessor claims, and
/// a surface would lose triangles, or its normals, without a word.
fn check_accessor(
    a: &gltf::Accessor,
    buffers: &[gltf::buffer::Data],
) -> std::result::Result<(), String> {
    let Some(view) = a.view() else {
        // No bufferView: all zeros (or a sparse accessor), per the specification.
        return Ok(());
    };
    let b = view.buffer().index();
    let held = buffers.get(b).map_or(0, |d| d.len());
    let view_end = view.offset().checked_add(view.length());
    if view_end.is_none_or(|end| end > held) {
        return Err(format!(
            "bufferView {} spans bytes {}..{} of buffer {b}, which holds {held}",
            view.index(),
            view.offset(),
            view.offset().saturating_add(view.length())
        ));
    }
    let element = a.size();
    let stride = view.stride().unwrap_or(element).max(element);
    let needed = match a.count() {
        0 => Some(a.offset()),
        n => (n - 1)
            .checked_mul(stride)
            .and_then(|x| x.checked_add(element))
            .and_then(|x| x.checked_add(a.offset())),
    };
    if needed.is_none_or(|n| n > view.length()) {
        return Err(format!(
            "accessor {} claims {} elements from byte {} of bufferView {}, past its {} bytes",
            a.index(),
            a.count(),
            a.offset(),
            view.index(),
            view.length()
        ));
    }
    Ok(())
}

/// A glTF mesh node: its file, name and world transform.
struct Placed<'a> {
    path: &'a Path,
    name: &'a str,
    world: DMat4,
}

impl Placed<'_> {
    /// A triangle primitive's triangles, placed in the world.
    fn triangles(
        &self,
        prim: &gltf::Primitive,
        buffers: &[gltf::buffer::Data],
        collect: &mut Collect,
        out: &mut MeshSurface,
    ) -> Result<()> {
        let (path, name, world) = (self.path, self.name, self.world);
        // The crate's readers assume these types (and panic otherwise).
        use gltf::accessor::{DataType, Dimensions};
        let position = prim.get(&gltf::Semantic::Positions);
        if position
            .as_ref()
            .is_some_and(|a| a.data_type() != DataType::F32 || a.dimensions() != Dimensions::Vec3)
        {
            return Err(Error::file(
                path,
                format!("malformed glTF: mesh '{name}': POSITION is not float VEC3"),
            ));
        }
        if prim.indices().is_some_and(|a| {
            !matches!(a.data_type(), DataType::U8 | DataType::U16 | DataType::U32)
                || a.dimensions() != Dimensions::Scalar
        }) {
            return Err(Error::file(
                path,
                format!("malformed glTF: mesh '{name}': indices are not unsigned integer scalars"),
            ));
        }
        let Some(position) = position else {
            return Err(Error::file(
                path,
                format!("mesh '{name}': a triangle primitive without POSITION"),
            ));
        };
        let used = [
            Some(("POSITION", position)),
            prim.indices().map(|a| ("indices", a)),
            prim.get(&gltf::Semantic::Normals).map(|a| ("NORMAL", a)),
            prim.get(&gltf::Semantic::TexCoords(0))
                .map(|a| ("TEXCOORD_0", a)),
            prim.get(&gltf::Semantic::Tangents).map(|a| ("TANGENT", a)),
        ];
        for (what, accessor) in used.into_iter().flatten() {
            check_accessor(&accessor, buffers).map_err(|m| {
                Error::file(path, format!("malformed glTF: mesh '{name}': {what}: {m}"))
            })?;
        }
        let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d[..]));
        let Some(positions) = reader.read_positions() else {
            return Err(Error::file(
                path,
                format!("malformed glTF: mesh '{name}': its POSITION cannot be read"),
            ));
        };
        let place = |p: [f32; 3]| -> Vec3 {
            if world == DMat4::IDENTITY {
                Vec3::from_array(p)
            } else {
                world
                    .transform_point3(Vec3::from_array(p).as_dvec3())
                    .as_vec3()
            }
        };
        let points: Vec<Vec3> = positions.map(place).collect();
        let indices: Vec<usize> = match reader.read_indices() {
            Some(i) => i.into_u32().map(|i| i as usize).collect(),
            None => (0..points.len()).collect(),
        };
        let vertex = VertexAttributes::read(&reader, world, points.len());
        for t in triangle_corners(prim.mode(), &indices) {
            let corner = |i: usize| {
                points.get(i).copied().ok_or_else(|| {
                    Error::file(
                        path,
                        format!(
                            "mesh '{name}': index {i} past its {} vertices",
                            points.len()
                        ),
                    )
                })
            };
            let tri = [corner(t[0])?, corner(t[1])?, corner(t[2])?];
            if collect.keep(path, tri, &mut out.triangles)? {
                vertex.push([t[0], t[1], t[2]], &mut out.attributes);
            }
        }
        // A primitive without an attribute its siblings have: the surface
        // goes without it (flat, untextured) rather than misaligned.
        let (n, a) = (out.triangles.len(), &mut out.attributes);
        a.normals.truncate(if a.normals.len() == n { n } else { 0 });
        a.uvs.truncate(if a.uvs.len() == n { n } else { 0 });
        a.tangents
            .truncate(if a.tangents.len() == n { n } else { 0 });
        Ok(())
    }
}

/// A primitive's per-vertex normals, texture coordinates and tangents,
/// placed in the world (each list empty when the file has none, or too few).
struct VertexAttributes {
    normals: Vec<Vec3>,
    uvs: Vec<Vec2>,
    tangents: Vec<Vec4>,
}

impl VertexAttributes {
    fn read<'a, 's, F>(reader: &gltf::mesh::Reader<'a, 's, F>, world: DMat4, count: usize) -> Self
    where
        F: Clone + Fn(gltf::Buffer<'a>) -> Option<&'s [u8]>,
    {
        let linear = glam::DMat3::from_mat4(world);
        let normal_matrix = linear.inverse().transpose();
        let full = |n: usize| n == count;
        let normals: Vec<Vec3> = reader
            .read_normals()
            .map(|n| {
                n.map(|n| {
                    (normal_matrix * Vec3::from_array(n).as_dvec3())
                        .normalize_or_zero()
                        .as_vec3()
                })
                .collect()
            })
            .unwrap_or_default();
        let uvs: Vec<Vec2> = reader
            .read_tex_coords(0)
            .map(|t| t.into_f32().map(Vec2::from_array).collect())
            .unwrap_or_default();
        let tangents: Vec<Vec4> = reader
            .read_tangents()
            .map(|t| {
                t.map(|t| {
                    let xyz = (linear * Vec3::new(t[0], t[1], t[2]).as_dvec3()).normalize_or_zero();
                    xyz.as_vec3().extend(t[3])
                })
                .collect()
            })
            .unwrap_or_default();
        VertexAttributes {
            normals: if full(normals.len()) {
                normals
            } else {
                Vec::new()
            },
            uvs: if full(uvs.len()) { uvs } else { Vec::new() },
            tangents: if full(tangents.len()) {
                tangents
            } else {
                Vec::new()
            },
        }
    }

    fn push(&self, t: [usize; 3], out: &mut Attributes) {
        if !self.normals.is_empty() {
            out.normals.push(t.map(|i| self.normals[i]));
        }
        if !self.uvs.is_empty() {
            out.uvs.push(t.map(|i| self.uvs[i]));
        }
        if !self.tangents.is_empty() {
            out.tangents.push(t.map(|i| self.tangents[i]));
        }
    }
}

/// A PLY's faces as one surface named after the file (its stem): PLY has
/// no object names. Polygons are fanned into triangles.
fn load_ply(path: &Path) -> Result<Mesh> {
    use ply_rs_bw::ply::Property;
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, &e))?;
    let parser = ply_rs_bw::parser::Parser::<ply_rs_bw::ply::DefaultElement>::new();
    let ply = parser
        .read_ply(&mut bytes.as_slice())
        .map_err(|e| Error::file(path, format!("malformed PLY: {e}")))?;
    let scalar = |p: Option<&Property>| p.and_then(Property::to_f32_lossy);
    let vertices = ply.payload.get("vertex").map(Vec::as_slice).unwrap_or(&[]);
    let points: Vec<Vec3> = vertices
        .iter()
        .enumerate()
        .map(
            |(i, v)| match (scalar(v.get("x")), scalar(v.get("y")), scalar(v.get("z"))) {
                (Some(x), Some(y), Some(z)) => Ok(Vec3::new(x, y, z)),
                _ => Err(Error::file(
                    path,
                    format!("vertex {i} has no numeric x, y, z"),
                )),
            },
        )
        .collect::<Result<_>>()?;
    let mut triangles = Vec::new();
    let mut collect = Collect { dropped: 0 };
    let faces = ply.payload.get("face").map(Vec::as_slice).unwrap_or(&[]);
    for (f, face) in faces.iter().enumerate() {
        let list = face
            .get("vertex_indices")
            .or_else(|| face.get("vertex_index"));
        let corners: Option<Vec<i64>> = match list {
            Some(Property::ListInt(v)) => Some(v.iter().map(|&i| i64::from(i)).collect()),
            Some(Property::ListUInt(v)) => Some(v.iter().map(|&i| i64::from(i)).collect()),
            Some(Property::ListShort(v)) => Some(v.iter().map(|&i| i64::from(i)).collect()),
            Some(Property::ListUShort(v)) => Some(v.iter().map(|&i| i64::from(i)).collect()),
            Some(Property::ListChar(v)) => Some(v.iter().map(|&i| i64::from(i)).collect()),
            Some(Property::ListUChar(v)) => Some(v.iter().map(|&i| i64::from(i)).collect()),
            _ => None,
        };
        let corners = corners
            .ok_or_else(|| Error::file(path, format!("face {f} has no vertex_indices list")))?;
        let corners: Vec<usize> = corners
            .iter()
            .map(|&i| {
                usize::try_from(i)
                    .ok()
                    .filter(|&i| i < points.len())
                    .ok_or_else(|| {
                        Error::file(
                            path,
                            format!("face {f}: vertex {i} is not one of its {}", points.len()),
                        )
                    })
            })
            .collect::<Result<_>>()?;
        if corners.len() < 3 {
            return Err(Error::file(
                path,
                format!(
                    "face {f} has {} vertices: a face needs at least 3",
                    corners.len()
                ),
            ));
        }
        for [a, b, c] in fan(&corners) {
            collect.keep(path, [points[a], points[b], points[c]], &mut triangles)?;
        }
    }
    let name = path
        .file_stem()
        .map_or_else(|| "ply".to_string(), |s| s.to_string_lossy().into_owned());
    let surfaces = vec![MeshSurface {
        name,
        triangles,
        material_rgb: None,
        material: None,
        attributes: Attributes::default(),
    }];
    finish(path, surfaces, collect.dropped)
}

fn finish(path: &Path, mut surfaces: Vec<MeshSurface>, dropped: usize) -> Result<Mesh> {
    surfaces.retain(|s| !s.triangles.is_empty());
    if surfaces.is_empty() {
        return Err(Error::file(
            path,
            format!("no usable triangles ({dropped} degenerate triangles dropped)"),
        ));
    }
    Ok(Mesh {
        surfaces,
        dropped_triangles: dropped,
        unused_material_parts: Vec::new(),
        unsupported: Vec::new(),
    })
}
