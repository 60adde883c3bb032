//! USD scenes (`.usd`, `.usda`, `.usdc`, `.usdz`) onto the one [`Scene`] model, through
//! the pure-Rust `openusd` crate (its composed stage: sublayers, references, payloads,
//! value clips, instance proxies).
//!
//! What is read (docs/INPUTS.md has the table):
//! * the prim hierarchy as nodes, each with its xformOps' local transform; time-sampled
//!   xformOps become one clip of linear TRS channels keyed at their sample times;
//! * `UsdGeomMesh`: `points`, `faceVertexCounts` / `faceVertexIndices` (polygons as
//!   fans, `orientation = leftHanded` reversed), `normals` and `primvars:st` (vertex or
//!   face-varying, indexed or not; `t` flipped into the model's `v`), the bound
//!   `UsdPreviewSurface` (with a `diffuseColor` texture), else `primvars:displayColor`
//!   (its first value) as the base colour;
//!   time-sampled `points` (and per-sample face lists, `velocities`) become a
//!   [`PointCache`];
//! * `UsdGeomCamera` (focal length, apertures, clipping range, projection);
//! * `UsdLux` sphere and distant lights, and rect and disk lights as emitting cards
//!   (units in docs/INPUTS.md);
//! * the stage's `metersPerUnit` and `upAxis` (one root node that scales to metres and
//!   turns Z up into Y up), `timeCodesPerSecond` (the scene's fps, so frame `i` is time
//!   code `i`), `startTimeCode` / `endTimeCode` (the default frames).
//!
//! Anything else is named once in a warning. Every layer the stage opens passes the
//! folder policy ([`resolver`]).

mod cap;
mod mesh;
mod paths;
mod resolver;

pub use cap::allocation_cap;

use std::cell::RefCell;
use std::collections::{BTreeMap, HashMap, HashSet};
use std::panic::{self, AssertUnwindSafe};
use std::path::Path;

use glam::{Mat4, Quat, Vec2, Vec3, Vec4};
use openusd::schemas::geom::{Imageable, Xformable};
use openusd::usd::{self, Prim, SchemaBase, SchemaKind, Stage, TimeCode};
use openusd::{sdf, tf};

use crate::scene::{
    AlphaMode, Animation, CameraDef, Channel, Falloff, Image, Interpolation, LightDef, LightKind,
    Material, Mesh, Node, NodeTransform, PointCache, PointSample, Primitive, Projection, Property,
    Scene, Texture, TextureRef, Topology, Warning, Wrap, LUMENS_PER_WATT,
};

use super::ImportError;
use mesh::{Interp, Primvar};

/// Reads a USD file and its composition.
///
/// The `openusd` crate (0.6) can panic on damaged data where it should return an error:
/// an array's length read from a corrupt `.usdc` overflows its allocation (found by
/// `fuzz/fuzz_targets/usd_import.rs`). Everything that touches the crate runs here under
/// `catch_unwind`, so such a file is an error naming it (and the prim being read), like
/// any other damaged input, not a crash of the whole command. The crate is used at import
/// only: the scene it fills holds none of its values.
pub(super) fn load(path: &Path) -> Result<Scene, ImportError> {
    let reading = RefCell::new(String::new());
    // AssertUnwindSafe: after a panic nothing made inside is used again (the stage and
    // the half-read scene are dropped), and `reading` is only ever a complete string.
    match panic::catch_unwind(AssertUnwindSafe(|| load_stage(path, &reading))) {
        Ok(read) => read,
        Err(payload) => {
            let what = payload
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "no message".into());
            let reason = format!(
                "the USD reader stopped on data it cannot make sense of ({}); the file is \
                 probably damaged (if usdcat reads it, please report it)",
                what.replace('\n', " ")
            );
            let prim = reading.into_inner();
            Err(if prim.is_empty() {
                ImportError::UsdStage {
                    path: path.to_path_buf(),
                    reason,
                }
            } else {
                ImportError::Usd {
                    path: path.to_path_buf(),
                    prim,
                    attribute: None,
                    reason,
                }
            })
        }
    }
}

/// [`load`]'s work; `reading` names the prim being read.
fn load_stage(path: &Path, reading: &RefCell<String>) -> Result<Scene, ImportError> {
    let folder = path.parent().unwrap_or(Path::new("."));
    let folder = if folder.as_os_str().is_empty() {
        Path::new(".")
    } else {
        folder
    };
    let canonical = std::fs::canonicalize(folder).map_err(|source| ImportError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    // Look at the file here first: a missing or unreadable file is an I/O error like
    // any other scene's, not a composition message.
    std::fs::metadata(path).map_err(|source| ImportError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    // What the reader allocates stays within what the layers can hold ([`cap`]) until
    // the stage is read (the resolver counts each layer, this file first, as it opens
    // it); the scene built from it is not the reader's.
    let capped = cap::Capped::new();
    let refused = resolver::Refused::default();
    let opened = Stage::builder()
        .resolver(resolver::FolderResolver::new(canonical, refused.clone()))
        .open(&path.to_string_lossy());
    let outside = |refused: &resolver::Refused| {
        refused
            .borrow()
            .first()
            .map(|(asset, why)| ImportError::Usd {
                path: path.to_path_buf(),
                prim: String::new(),
                attribute: None,
                reason: format!("layer {asset:?} leaves the scene's folder ({why}); refused"),
            })
    };
    let stage = match opened {
        Ok(s) => s,
        Err(e) => {
            return Err(outside(&refused).unwrap_or_else(|| ImportError::UsdStage {
                path: path.to_path_buf(),
                reason: one_line(&e),
            }))
        }
    };
    let mut r = Reader::new(path, stage, reading);
    r.read()?;
    if let Some(e) = outside(&refused) {
        return Err(e);
    }
    let errors = r.stage.composition_errors();
    if let Some(first) = errors.first() {
        return Err(ImportError::UsdStage {
            path: path.to_path_buf(),
            reason: format!(
                "composition: {first}{}",
                match errors.len() {
                    1 => String::new(),
                    n => format!(" (and {} more)", n - 1),
                }
            ),
        });
    }
    drop(capped);
    let scene = r.finish();
    super::validate(&scene)?;
    Ok(scene)
}

/// An anyhow chain on one line.
fn one_line(e: &anyhow::Error) -> String {
    format!("{e:#}").replace('\n', " ")
}

/// Any prim seen as `Xformable`, to evaluate its xformOps.
struct AnyXformable(Prim);

impl SchemaBase for AnyXformable {
    const KIND: SchemaKind = SchemaKind::ConcreteTyped;
    fn prim(&self) -> &Prim {
        &self.0
    }
}
impl Imageable for AnyXformable {}
impl Xformable for AnyXformable {}

/// Prim types whose subtrees hold no geometry to place (read through bindings or not
/// at all).
const SKIPPED_SUBTREES: &[&str] = &["Material", "Shader", "NodeGraph", "GeomSubset"];

/// Prim types that only group (a node, nothing else).
const GROUPS: &[&str] = &["", "Xform", "Scope", "SkelRoot"];

struct Reader<'a> {
    path: &'a Path,
    /// The prim being read, for an error if the USD reader panics ([`load`]).
    reading: &'a RefCell<String>,
    stage: Stage,
    /// Time codes per second.
    tcps: f64,
    /// The time code that static values are read at.
    t0: f64,
    scene: Scene,
    /// Prim path → node.
    nodes: HashMap<String, usize>,
    /// Prims in subtrees not placed (materials, shaders), by path.
    skipped: HashSet<String>,
    /// Unread prim types → the first path of that type and how many.
    unread: BTreeMap<String, (String, usize)>,
    /// Things read partly: one warning each.
    notes: BTreeMap<&'static str, String>,
    channels: Vec<Channel>,
    /// Material prim path (or `displayColor:` and the colour's bits) → material index.
    materials: HashMap<String, u32>,
    meters: f32,
}

impl<'a> Reader<'a> {
    fn new(path: &'a Path, stage: Stage, reading: &'a RefCell<String>) -> Self {
        let tcps = stage.time_codes_per_second();
        let t0 = if stage.has_authored_time_code_range() {
            stage.start_time_code()
        } else {
            0.0
        };
        Reader {
            path,
            reading,
            stage,
            tcps,
            t0,
            scene: Scene {
                source: path.to_path_buf(),
                ..Scene::default()
            },
            nodes: HashMap::new(),
            skipped: HashSet::new(),
            unread: BTreeMap::new(),
            notes: BTreeMap::new(),
            channels: Vec::new(),
            materials: HashMap::new(),
            meters: 1.0,
        }
    }

    fn err(&self, prim: &str, attribute: Option<&str>, reason: impl Into<String>) -> ImportError {
        ImportError::Usd {
            path: self.path.to_path_buf(),
            prim: prim.to_string(),
            attribute: attribute.map(str::to_string),
            reason: reason.into(),
        }
    }

    fn seconds(&self, tc: f64) -> f32 {
        (tc / self.tcps) as f32
    }

    fn read(&mut self) -> Result<(), ImportError> {
        if !(self.tcps.is_finite() && self.tcps > 0.0) {
            return Err(self.err(
                "/",
                Some("timeCodesPerSecond"),
                format!("{} is not a positive rate", self.tcps),
            ));
        }
        self.scene.fps = Some(self.tcps as f32);
        if self.stage.has_authored_time_code_range() {
            let (a, b) = (self.stage.start_time_code(), self.stage.end_time_code());
            if !(a.is_finite() && b.is_finite() && a <= b) {
                return Err(self.err(
                    "/",
                    Some("startTimeCode"),
                    format!("{a}..{b} is not a time range"),
                ));
            }
            self.scene.time_range = Some((self.seconds(a), self.seconds(b)));
        }
        // The stage's units and up axis: one root node carries both.
        let meters = match self.stage.stage_metadata("metersPerUnit") {
            Ok(Some(v)) => scalar(&v).unwrap_or(0.01),
            // Unauthored: USD's fallback is centimetres.
            _ => 0.01,
        };
        if !(meters.is_finite() && meters > 0.0) {
            return Err(self.err(
                "/",
                Some("metersPerUnit"),
                format!("{meters} is not a positive scale"),
            ));
        }
        self.meters = meters as f32;
        let z_up = matches!(
            self.stage.stage_metadata("upAxis"),
            Ok(Some(v)) if token(&v).as_deref() == Some("Z")
        );
        let turn = if z_up {
            Quat::from_rotation_x(-std::f32::consts::FRAC_PI_2)
        } else {
            Quat::IDENTITY
        };
        self.scene.nodes.push(Node {
            name: Some("usd:stage".into()),
            transform: NodeTransform::Matrix(Mat4::from_scale_rotation_translation(
                Vec3::splat(self.meters),
                turn,
                Vec3::ZERO,
            )),
            ..Node::default()
        });
        self.scene.roots.push(0);

        let mut paths = Vec::new();
        self.stage
            .traverse(usd::PrimPredicate::DEFAULT_PROXIES, |p| {
                paths.push(p.clone())
            })
            .map_err(|e| self.err("/", None, one_line(&e)))?;
        for p in paths {
            self.prim(&p)?;
        }
        self.reading.replace(String::new());
        Ok(())
    }

    fn prim(&mut self, path: &sdf::Path) -> Result<(), ImportError> {
        let name = path.as_str().to_string();
        self.reading.replace(name.clone());
        let parent_path = path.parent();
        let parent_name = parent_path.as_ref().map(|p| p.as_str().to_string());
        if parent_name
            .as_ref()
            .is_some_and(|p| self.skipped.contains(p))
        {
            self.skipped.insert(name);
            return Ok(());
        }
        let prim = self.stage.prim(path.clone());
        let ty = prim
            .type_name()
            .map_err(|e| self.err(&name, None, one_line(&e)))?
            .map(|t| t.as_str().to_string())
            .unwrap_or_default();
        if SKIPPED_SUBTREES.contains(&ty.as_str()) {
            self.skipped.insert(name);
            return Ok(());
        }
        let parent = parent_name
            .and_then(|p| self.nodes.get(&p).copied())
            .unwrap_or(0);
        let node = self.node(&prim, &name, parent)?;
        match ty.as_str() {
            "Mesh" => self.mesh(&prim, &name, node)?,
            "Camera" => self.camera(&prim, &name, node)?,
            "SphereLight" | "DistantLight" => self.light(&prim, &name, &ty, node)?,
            "RectLight" | "DiskLight" => self.area_light(&prim, &name, &ty, node)?,
            t if GROUPS.contains(&t) => {}
            t => {
                let e = self.unread.entry(t.to_string()).or_insert((name, 0));
                e.1 += 1;
            }
        }
        Ok(())
    }

    /// The node of a prim: its local transform, animated when its xformOps are
    /// time-sampled.
    fn node(&mut self, prim: &Prim, name: &str, parent: usize) -> Result<usize, ImportError> {
        let x = AnyXformable(prim.clone());
        let bad = |r: &Self, e: anyhow::Error| r.err(name, Some("xformOpOrder"), one_line(&e));
        let order = x
            .xform_op_order()
            .map_err(|e| bad(self, e))?
            .unwrap_or_default();
        let mut times: Vec<f64> = Vec::new();
        for op in &order {
            let op = op.strip_prefix("!invert!").unwrap_or(op);
            if op == "!resetXformStack!" {
                self.notes.entry("reset").or_insert_with(|| {
                    format!(
                        "{name}: !resetXformStack! not read (the parent's transform still applies)"
                    )
                });
                continue;
            }
            // A name from the file: the USD reader loops without end on a property path
            // made from one that is no attribute name (found by the fuzz target).
            if op.contains('.') || !sdf::Path::is_valid_namespace_identifier(op) {
                return Err(self.err(
                    name,
                    Some("xformOpOrder"),
                    format!("\"{}\" is not an attribute name", paths::shown(op)),
                ));
            }
            let t = prim
                .attribute(op)
                .time_sample_times()
                .map_err(|e| self.err(name, Some(op), one_line(&e)))?;
            times.extend(t);
        }
        times.sort_by(f64::total_cmp);
        times.dedup();
        let local = |r: &Self, tc: f64| -> Result<Mat4, ImportError> {
            let m = x
                .local_to_parent_transform(TimeCode::new(tc))
                .map_err(|e| bad(r, e))?;
            let m = Mat4::from_cols_array(&m.0.map(|v| v as f32));
            if !m.is_finite() {
                return Err(r.err(name, Some("xformOpOrder"), "a non-finite transform"));
            }
            Ok(m)
        };
        let rest = local(self, times.first().copied().unwrap_or(self.t0))?;
        let index = self.scene.nodes.len();
        if times.len() > 1 {
            let mut tr = Vec::with_capacity(times.len() * 3);
            let mut rot = Vec::with_capacity(times.len() * 4);
            let mut sc = Vec::with_capacity(times.len() * 3);
            let mut prev = Quat::IDENTITY;
            for &tc in &times {
                let (s, r, t) = local(self, tc)?.to_scale_rotation_translation();
                // The same rotation's sign nearest the last key (slerp takes the short
                // arc anyway; this keeps the keys themselves continuous).
                let r = if r.dot(prev) < 0.0 { -r } else { r };
                prev = r;
                tr.extend(t.to_array());
                rot.extend(r.to_array());
                sc.extend(s.to_array());
            }
            let secs: Vec<f32> = times.iter().map(|&t| self.seconds(t)).collect();
            for (property, values) in [
                (Property::Translation, tr),
                (Property::Rotation, rot),
                (Property::Scale, sc),
            ] {
                self.channels.push(Channel {
                    node: index,
                    property,
                    interpolation: Interpolation::Linear,
                    times: secs.clone(),
                    values,
                });
            }
        }
        self.scene.nodes.push(Node {
            name: Some(name.to_string()),
            parent: Some(parent),
            transform: NodeTransform::Matrix(rest),
            ..Node::default()
        });
        self.scene.nodes[parent].children.push(index);
        self.nodes.insert(name.to_string(), index);
        Ok(index)
    }

    /// A value at a time code (the default where nothing is sampled).
    fn value(
        &self,
        prim: &Prim,
        name: &str,
        attr: &str,
        tc: f64,
    ) -> Result<Option<sdf::Value>, ImportError> {
        let a = prim.attribute(attr);
        let at = a
            .get_at::<sdf::Value>(TimeCode::new(tc))
            .map_err(|e| self.err(name, Some(attr), one_line(&e)))?;
        match at {
            Some(v) => Ok(Some(v)),
            None => a
                .get::<sdf::Value>()
                .map_err(|e| self.err(name, Some(attr), one_line(&e))),
        }
    }

    fn times(&self, prim: &Prim, name: &str, attr: &str) -> Result<Vec<f64>, ImportError> {
        prim.attribute(attr)
            .time_sample_times()
            .map_err(|e| self.err(name, Some(attr), one_line(&e)))
    }

    fn vec3s(
        &self,
        prim: &Prim,
        name: &str,
        attr: &str,
        tc: f64,
    ) -> Result<Option<Vec<Vec3>>, ImportError> {
        match self.value(prim, name, attr, tc)? {
            None => Ok(None),
            Some(v) => vec3s(&v).map(Some).ok_or_else(|| {
                self.err(
                    name,
                    Some(attr),
                    format!("expected an array of 3-vectors, found {}", kind(&v)),
                )
            }),
        }
    }

    fn ints(
        &self,
        prim: &Prim,
        name: &str,
        attr: &str,
        tc: f64,
    ) -> Result<Option<Vec<i32>>, ImportError> {
        match self.value(prim, name, attr, tc)? {
            None => Ok(None),
            Some(sdf::Value::IntVec(v)) => Ok(Some(v)),
            Some(v) => Err(self.err(
                name,
                Some(attr),
                format!("expected int[], found {}", kind(&v)),
            )),
        }
    }

    fn interp(&self, prim: &Prim, attr: &str, default: Interp) -> Interp {
        let tok = prim
            .attribute(attr)
            .get_metadata::<sdf::Value>("interpolation")
            .ok()
            .flatten()
            .and_then(|v| token(&v));
        Interp::from_token(tok.as_deref(), default)
    }

    fn primvar2(
        &self,
        prim: &Prim,
        name: &str,
        attr: &str,
        tc: f64,
    ) -> Result<Option<Primvar<Vec2>>, ImportError> {
        let Some(v) = self.value(prim, name, attr, tc)? else {
            return Ok(None);
        };
        let values = vec2s(&v)
            .ok_or_else(|| {
                self.err(
                    name,
                    Some(attr),
                    format!("expected an array of 2-vectors, found {}", kind(&v)),
                )
            })?
            .into_iter()
            // USD's `t` runs up the image, the model's `v` (glTF's) down it.
            .map(|st| Vec2::new(st.x, 1.0 - st.y))
            .collect();
        let indices = self.ints(prim, name, &format!("{attr}:indices"), tc)?;
        Ok(Some(Primvar {
            values,
            indices,
            interp: Some(self.interp(prim, attr, Interp::Point)),
        }))
    }

    fn mesh(&mut self, prim: &Prim, name: &str, node: usize) -> Result<(), ImportError> {
        let times = self.times(prim, name, "points")?;
        let material = self.material(prim, name)?;
        let left = matches!(
            self.value(prim, name, "orientation", self.t0)?,
            Some(v) if token(&v).as_deref() == Some("leftHanded")
        );
        for attr in ["primvars:normals", "subdivisionScheme"] {
            if attr == "subdivisionScheme" {
                let scheme = self
                    .value(prim, name, attr, self.t0)?
                    .and_then(|v| token(&v));
                if scheme.as_deref().is_some_and(|s| s != "none") {
                    self.notes.entry("subdiv").or_insert_with(|| {
                        format!("{name}: subdivisionScheme {:?} not applied (the control cage is rendered)", scheme.unwrap_or_default())
                    });
                }
            } else if self.value(prim, name, attr, self.t0)?.is_some() {
                self.notes
                    .entry("pvnormals")
                    .or_insert_with(|| format!("{name}: primvars:normals not read (normals is)"));
            }
        }
        let sampled = times.len() > 1;
        let sample_times = if sampled {
            times.clone()
        } else {
            vec![times.first().copied().unwrap_or(self.t0)]
        };
        let mut topologies: Vec<Topology> = Vec::new();
        let mut samples = Vec::with_capacity(sample_times.len());
        let mut first: Option<(Vec<Vec3>, Option<Vec<Vec3>>)> = None;
        for &tc in &sample_times {
            let Some(points) = self.vec3s(prim, name, "points", tc)? else {
                self.notes
                    .entry("nopoints")
                    .or_insert_with(|| format!("{name}: a mesh without points, skipped"));
                return Ok(());
            };
            let counts = self
                .ints(prim, name, "faceVertexCounts", tc)?
                .unwrap_or_default();
            let indices = self
                .ints(prim, name, "faceVertexIndices", tc)?
                .unwrap_or_default();
            let st = self.primvar2(prim, name, "primvars:st", tc)?;
            let st = match st {
                Some(pv) if pv.interp == Some(Interp::Other) => {
                    self.notes.entry("st").or_insert_with(|| {
                        format!("{name}: constant or uniform primvars:st not read")
                    });
                    None
                }
                s => s,
            };
            // Normals only where the points hold still: a cache gets flat normals.
            let normals = if sampled {
                if self.value(prim, name, "normals", tc)?.is_some() {
                    self.notes.entry("cachenormals").or_insert_with(|| {
                        format!("{name}: normals of time-sampled points not read (flat normals)")
                    });
                }
                None
            } else {
                match self.vec3s(prim, name, "normals", tc)? {
                    Some(values) => {
                        let interp = self.interp(prim, "normals", Interp::Point);
                        if interp == Interp::Other {
                            self.notes
                                .entry("normals")
                                .or_insert_with(|| format!("{name}: uniform normals not read"));
                            None
                        } else {
                            Some(Primvar {
                                values,
                                indices: None,
                                interp: Some(interp),
                            })
                        }
                    }
                    None => None,
                }
            };
            let (topo, vnormals, dropped) = mesh::triangulate(
                &counts,
                &indices,
                points.len(),
                left,
                st.as_ref(),
                normals.as_ref(),
            )
            .map_err(|e| {
                self.err(
                    name,
                    Some(e.attribute),
                    format!("at time {tc}: {}", e.reason),
                )
            })?;
            if dropped > 0 {
                self.notes.entry("faces").or_insert_with(|| {
                    format!("{name}: {dropped} faces of fewer than 3 vertices skipped")
                });
            }
            if points.iter().any(|p| !p.is_finite()) {
                return Err(self.err(
                    name,
                    Some("points"),
                    format!("at time {tc}: a non-finite point"),
                ));
            }
            let velocities = if sampled {
                self.vec3s(prim, name, "velocities", tc)?
            } else {
                None
            };
            if let Some(v) = &velocities {
                if v.len() != points.len() {
                    return Err(self.err(
                        name,
                        Some("velocities"),
                        format!(
                            "at time {tc}: {} velocities for {} points",
                            v.len(),
                            points.len()
                        ),
                    ));
                }
            }
            let topology = match topologies.last() {
                Some(t) if *t == topo => topologies.len() - 1,
                _ => {
                    topologies.push(topo);
                    topologies.len() - 1
                }
            };
            if first.is_none() {
                first = Some((points.clone(), vnormals));
            }
            samples.push(PointSample {
                points,
                // UsdGeomPointBased: units per second, as the model's.
                velocities,
                topology: topology as u32,
            });
        }
        let Some((points, normals)) = first else {
            return Ok(());
        };
        let topo = &topologies[samples[0].topology as usize];
        let positions: Vec<Vec3> = match &topo.vertex_point {
            Some(map) => map.iter().map(|&p| points[p as usize]).collect(),
            None => points,
        };
        let primitive = Primitive {
            positions,
            normals,
            uvs: topo.uvs.clone(),
            triangles: topo.triangles.clone(),
            material,
            ..Primitive::default()
        };
        let mesh = self.scene.meshes.len();
        self.scene.meshes.push(Mesh {
            name: Some(name.to_string()),
            primitives: vec![primitive],
            weights: Vec::new(),
        });
        self.scene.nodes[node].mesh = Some(mesh);
        if sampled {
            self.scene.point_caches.push(PointCache {
                mesh,
                primitive: 0,
                times: sample_times.iter().map(|&t| self.seconds(t)).collect(),
                samples,
                topologies,
            });
        }
        Ok(())
    }

    /// The mesh's material: the `UsdPreviewSurface` of the material bound to it (or to
    /// its nearest ancestor that has a binding), else its constant `displayColor` as a
    /// plastic-like base colour, else the default material.
    fn material(&mut self, prim: &Prim, name: &str) -> Result<u32, ImportError> {
        if let Some(m) = self.bound_material(prim, name)? {
            return Ok(m);
        }
        let color = self
            .value(prim, name, "primvars:displayColor", self.t0)?
            .and_then(|v| vec3s(&v))
            .and_then(|c| c.first().copied())
            .filter(|c| c.is_finite());
        let Some(c) = color else {
            return Ok(self.scene.default_material_index());
        };
        let key = format!("displayColor:{:?}", c.to_array().map(f32::to_bits));
        if let Some(&m) = self.materials.get(&key) {
            return Ok(m);
        }
        let m = self.scene.materials.len() as u32;
        self.scene.materials.push(Material {
            name: Some(format!("usd:displayColor({}, {}, {})", c.x, c.y, c.z)),
            base_color: Vec4::new(c.x, c.y, c.z, 1.0),
            metallic: 0.0,
            roughness: 0.5,
            ..Material::default()
        });
        self.materials.insert(key, m);
        Ok(m)
    }

    /// The bound `UsdPreviewSurface` as a model material (one per material prim):
    /// `diffuseColor`, `metallic`, `roughness`, `emissiveColor`, `opacity` (blended, or
    /// masked at `opacityThreshold`), `ior`; a `diffuseColor` texture (`UsdUVTexture`
    /// `inputs:file`, beside the scene). `None` when nothing is bound.
    fn bound_material(&mut self, prim: &Prim, name: &str) -> Result<Option<u32>, ImportError> {
        use openusd::schemas::shade::{read_preview_surface, Channel, MaterialBindingAPI};
        let bad = |r: &Self, e: anyhow::Error| r.err(name, Some("material:binding"), one_line(&e));
        // The nearest prim (itself, then its ancestors) that applies the binding API.
        let mut at = Some(prim.path().clone());
        let mut api = None;
        while let Some(p) = at {
            if p.as_str() == "/" {
                break;
            }
            if let Some(a) =
                MaterialBindingAPI::get(&self.stage, p.clone()).map_err(|e| bad(self, e))?
            {
                api = Some(a);
                break;
            }
            at = p.parent();
        }
        let Some(api) = api else {
            return Ok(None);
        };
        let Some(material) = api.compute_bound_material("").map_err(|e| bad(self, e))? else {
            return Ok(None);
        };
        let key = material.as_str().to_string();
        if let Some(&m) = self.materials.get(&key) {
            return Ok(Some(m));
        }
        let Some(ps) = read_preview_surface(&self.stage, &material).map_err(|e| bad(self, e))?
        else {
            self.notes.entry("surface").or_insert_with(|| {
                format!("{key}: a material without a UsdPreviewSurface, not read")
            });
            return Ok(None);
        };
        let color = |c: &Channel<openusd::gf::Vec3f>, d: Vec3| match c {
            Channel::Value(v) => Vec3::new(v.x, v.y, v.z),
            _ => d,
        };
        let num = |c: &Channel<f32>, d: f32| match c {
            Channel::Value(v) => *v,
            _ => d,
        };
        // UsdPreviewSurface's defaults where an input is not authored.
        let opacity = num(&ps.opacity, 1.0);
        let mut m = Material {
            name: Some(key.clone()),
            base_color: color(&ps.diffuse_color, Vec3::splat(0.18)).extend(opacity),
            metallic: num(&ps.metallic, 0.0),
            roughness: num(&ps.roughness, 0.5),
            emissive: color(&ps.emissive_color, Vec3::ZERO),
            ior: num(&ps.ior, 1.5),
            ..Material::default()
        };
        let threshold = num(&ps.opacity_threshold, 0.0);
        if threshold > 0.0 {
            m.alpha_mode = AlphaMode::Mask { cutoff: threshold };
        } else if opacity < 1.0 {
            m.alpha_mode = AlphaMode::Blend;
        }
        let finite = m.base_color.is_finite()
            && m.emissive.is_finite()
            && [m.metallic, m.roughness, m.ior, threshold]
                .iter()
                .all(|x| x.is_finite());
        if !finite {
            return Err(self.err(&ps.shader, None, "a non-finite UsdPreviewSurface input"));
        }
        if let Some(file) = ps.diffuse_color.texture() {
            m.base_color = Vec3::ONE.extend(opacity);
            m.base_color_texture = Some(self.texture(&ps.shader, file)?);
        }
        let others = [
            ("emissiveColor", ps.emissive_color.texture().is_some()),
            ("metallic", ps.metallic.texture().is_some()),
            ("roughness", ps.roughness.texture().is_some()),
            ("normal", ps.normal.is_set()),
            ("opacity", ps.opacity.texture().is_some()),
        ];
        for (input, textured) in others {
            if textured {
                self.notes.entry("textures").or_insert_with(|| {
                    format!("{key}: a UsdUVTexture on inputs:{input} not read (diffuseColor textures are)")
                });
            }
        }
        let index = self.scene.materials.len() as u32;
        self.scene.materials.push(m);
        self.materials.insert(key, index);
        Ok(Some(index))
    }

    /// A `UsdUVTexture` file (relative to the scene's folder, and inside it), decoded.
    fn texture(&mut self, shader: &str, file: &str) -> Result<TextureRef, ImportError> {
        // An image is not the layers' data: its file and its pixels may be far larger
        // than the layers ([`cap`]).
        let _uncapped = cap::Uncapped::new();
        let folder = self.path.parent().unwrap_or(Path::new(""));
        let bad = |r: &Self, reason: String| r.err(shader, Some("diffuseColor"), reason);
        let resolved = super::folder::resolve_inside(folder, Path::new(file)).map_err(|why| {
            bad(
                self,
                format!("texture {file:?} leaves the scene's folder ({why}); refused"),
            )
        })?;
        let bytes = std::fs::read(&resolved).map_err(|e| {
            bad(
                self,
                format!("texture {file:?}: cannot read {}: {e}", resolved.display()),
            )
        })?;
        let decoded = image::load_from_memory(&bytes)
            .map_err(|e| bad(self, format!("texture {file:?}: {e}")))?;
        let rgba = decoded.to_rgba8();
        let image = self.scene.images.len() as u32;
        self.scene.images.push(Image {
            name: Some(file.to_string()),
            width: rgba.width(),
            height: rgba.height(),
            rgba8: rgba.into_raw(),
        });
        let texture = self.scene.textures.len() as u32;
        self.scene.textures.push(Texture {
            image,
            wrap_s: Wrap::Repeat,
            wrap_t: Wrap::Repeat,
            nearest: false,
        });
        Ok(TextureRef {
            texture,
            tex_coord: 0,
            transform: None,
        })
    }

    fn float(&self, prim: &Prim, name: &str, attr: &str, default: f64) -> Result<f64, ImportError> {
        match self.value(prim, name, attr, self.t0)? {
            None => Ok(default),
            Some(v) => scalar(&v).filter(|x| x.is_finite()).ok_or_else(|| {
                self.err(
                    name,
                    Some(attr),
                    format!("expected a finite number, found {}", kind(&v)),
                )
            }),
        }
    }

    fn camera(&mut self, prim: &Prim, name: &str, node: usize) -> Result<(), ImportError> {
        for attr in [
            "focalLength",
            "horizontalAperture",
            "verticalAperture",
            "clippingRange",
        ] {
            if self.times(prim, name, attr)?.len() > 1 {
                self.notes.entry("camanim").or_insert_with(|| {
                    format!("{name}.{attr}: time samples not read (its value at the start is)")
                });
            }
        }
        // UsdGeomCamera's fallbacks: a 50 mm lens on a 35 mm academy aperture.
        let focal = self.float(prim, name, "focalLength", 50.0)?;
        let h_ap = self.float(prim, name, "horizontalAperture", 20.955)?;
        let v_ap = self.float(prim, name, "verticalAperture", 15.2908)?;
        let (near, far) = match self.value(prim, name, "clippingRange", self.t0)? {
            None => (1.0, 1_000_000.0),
            Some(v) => vec2s(&sdf_array1(v.clone()))
                .and_then(|a| a.first().copied())
                .map(|c| (f64::from(c.x), f64::from(c.y)))
                .ok_or_else(|| {
                    self.err(
                        name,
                        Some("clippingRange"),
                        format!("expected a float2, found {}", kind(&v)),
                    )
                })?,
        };
        if !(focal > 0.0 && h_ap > 0.0 && v_ap > 0.0 && near > 0.0 && far > near) {
            return Err(self.err(
                name,
                None,
                format!("focalLength {focal}, apertures {h_ap} x {v_ap}, clippingRange ({near}, {far}): not a camera"),
            ));
        }
        let ortho = matches!(
            self.value(prim, name, "projection", self.t0)?,
            Some(v) if token(&v).as_deref() == Some("orthographic")
        );
        let m = f64::from(self.meters);
        let projection = if ortho {
            // Apertures in tenths of a scene unit, as for the lens.
            Projection::Orthographic {
                xmag: (h_ap * 0.05 * m) as f32,
                ymag: (v_ap * 0.05 * m) as f32,
                znear: (near * m) as f32,
                zfar: (far * m) as f32,
            }
        } else {
            Projection::Perspective {
                yfov: (2.0 * (v_ap / (2.0 * focal)).atan()) as f32,
                aspect: Some((h_ap / v_ap) as f32),
                znear: (near * m) as f32,
                zfar: Some((far * m) as f32),
            }
        };
        let c = self.scene.cameras.len();
        self.scene.cameras.push(CameraDef {
            name: Some(name.to_string()),
            projection,
        });
        self.scene.nodes[node].camera = Some(c);
        Ok(())
    }

    /// A light's radiance in the model's units, `intensity · 2^exposure / 683` (USD's
    /// nits over 683 lm/W), and its `color` (white when unauthored).
    fn light_inputs(&self, prim: &Prim, name: &str) -> Result<(f64, Vec3), ImportError> {
        let intensity = self.float(prim, name, "inputs:intensity", 1.0)?;
        let exposure = self.float(prim, name, "inputs:exposure", 0.0)?;
        let color = match self.value(prim, name, "inputs:color", self.t0)? {
            Some(v) => vec3s(&sdf_array1(v))
                .and_then(|c| c.first().copied())
                .unwrap_or(Vec3::ONE),
            None => Vec3::ONE,
        };
        Ok((intensity * exposure.exp2() / LUMENS_PER_WATT, color))
    }

    /// A sphere light as a point light, a distant light as a directional one. USD gives
    /// luminance in nits (`intensity · 2^exposure`, times `color`); the model's radiance
    /// is nits / 683 (as glTF's candela / 683). A sphere of radius `r` (metres) shows
    /// `π r²` of it: radiant intensity `L π r²` W/sr; a distant light of angular
    /// diameter `θ` gives irradiance `L · π sin²(θ/2)` W/m².
    fn light(&mut self, prim: &Prim, name: &str, ty: &str, node: usize) -> Result<(), ImportError> {
        let (nits, color) = self.light_inputs(prim, name)?;
        let (kind, amount, falloff) = if ty == "SphereLight" {
            let r = self.float(prim, name, "inputs:radius", 0.5)? * f64::from(self.meters);
            (
                LightKind::Point,
                nits * std::f64::consts::PI * r * r,
                Falloff::InverseSquare,
            )
        } else {
            let angle = self.float(prim, name, "inputs:angle", 0.53)?.to_radians();
            let s = (angle * 0.5).sin();
            (
                LightKind::Directional,
                nits * std::f64::consts::PI * s * s,
                Falloff::InverseSquare,
            )
        };
        if !(amount.is_finite() && amount >= 0.0 && color.is_finite()) {
            return Err(self.err(
                name,
                Some("inputs:intensity"),
                "not a finite, non-negative light",
            ));
        }
        let l = self.scene.lights.len();
        self.scene.lights.push(LightDef {
            name: Some(name.to_string()),
            kind,
            color,
            intensity: amount as f32,
            range: None,
            falloff,
        });
        self.scene.nodes[node].light = Some(l);
        Ok(())
    }

    /// A rect or disk light as an emitting card: a mesh in the light's local XY plane
    /// (a `width × height` rectangle, or a disk of `radius` as a fan of
    /// [`DISK_SEGMENTS`] triangles) whose front faces look down local −Z, the way the
    /// light shines, with a black, one-sided emissive material of radiance
    /// `intensity · 2^exposure · color / 683` (nits / 683, as the sphere light), divided
    /// by the area when `inputs:normalize` is set. The renderer samples it as any
    /// emissive surface (an area light with soft shadows); the card is seen by the camera
    /// and casts shadows as an emissive surface does. It moves with its transform.
    fn area_light(
        &mut self,
        prim: &Prim,
        name: &str,
        ty: &str,
        node: usize,
    ) -> Result<(), ImportError> {
        let (mut nits, color) = self.light_inputs(prim, name)?;
        let normalize = matches!(
            self.value(prim, name, "inputs:normalize", self.t0)?,
            Some(sdf::Value::Bool(true))
        );
        if self
            .value(prim, name, "inputs:texture:file", self.t0)?
            .is_some()
        {
            self.notes.entry("lighttexture").or_insert_with(|| {
                format!("{name}: inputs:texture:file not read (the light's colour is uniform)")
            });
        }
        let (positions, triangles, area) = if ty == "RectLight" {
            let w = self.float(prim, name, "inputs:width", 1.0)?;
            let h = self.float(prim, name, "inputs:height", 1.0)?;
            if !(w > 0.0 && h > 0.0) {
                return Err(self.err(
                    name,
                    Some("inputs:width"),
                    "a rect light needs a positive width and height",
                ));
            }
            let (x, y) = ((w * 0.5) as f32, (h * 0.5) as f32);
            (
                vec![
                    Vec3::new(-x, -y, 0.0),
                    Vec3::new(x, -y, 0.0),
                    Vec3::new(x, y, 0.0),
                    Vec3::new(-x, y, 0.0),
                ],
                // Clockwise seen from +Z: the front faces look down −Z.
                vec![[0, 2, 1], [0, 3, 2]],
                w * h,
            )
        } else {
            let radius = self.float(prim, name, "inputs:radius", 0.5)?;
            if radius.is_nan() || radius <= 0.0 {
                return Err(self.err(
                    name,
                    Some("inputs:radius"),
                    "a disk light needs a positive radius",
                ));
            }
            let n = DISK_SEGMENTS;
            let mut positions = vec![Vec3::ZERO];
            positions.extend((0..n).map(|k| {
                let a = std::f64::consts::TAU * f64::from(k) / f64::from(n);
                Vec3::new((radius * a.cos()) as f32, (radius * a.sin()) as f32, 0.0)
            }));
            let triangles = (0..n).map(|k| [0, 1 + (k + 1) % n, 1 + k]).collect();
            // The polygon's area, so that `normalize` divides by what is drawn.
            let area =
                0.5 * f64::from(n) * radius * radius * (std::f64::consts::TAU / f64::from(n)).sin();
            (positions, triangles, area)
        };
        if normalize {
            // In the light's own units: the stage's scale is applied to the card later.
            nits /= area;
        }
        if !(nits.is_finite() && nits >= 0.0 && color.is_finite()) {
            return Err(self.err(
                name,
                Some("inputs:intensity"),
                "not a finite, non-negative light",
            ));
        }
        let material = self.scene.materials.len() as u32;
        self.scene.materials.push(Material {
            name: Some(name.to_string()),
            // Black metal: no diffuse and no reflection (F0 = 0), only the emission.
            base_color: Vec4::new(0.0, 0.0, 0.0, 1.0),
            metallic: 1.0,
            roughness: 1.0,
            emissive: color,
            emissive_strength: nits as f32,
            double_sided: false,
            ..Material::default()
        });
        let mesh = self.scene.meshes.len();
        self.scene.meshes.push(Mesh {
            name: Some(name.to_string()),
            primitives: vec![Primitive {
                positions,
                triangles,
                material,
                ..Primitive::default()
            }],
            weights: Vec::new(),
        });
        self.scene.nodes[node].mesh = Some(mesh);
        Ok(())
    }

    fn finish(mut self) -> Scene {
        if !self.channels.is_empty() {
            self.scene.animations.push(Animation {
                name: Some("usd:timeSamples".into()),
                channels: std::mem::take(&mut self.channels),
            });
        }
        if !self.unread.is_empty() {
            let list: Vec<String> = self
                .unread
                .iter()
                .map(|(t, (first, n))| format!("{t} x{n} (first {first})"))
                .collect();
            self.scene
                .warnings
                .push(Warning(format!("USD prims not read: {}", list.join(", "))));
        }
        for note in self.notes.into_values() {
            self.scene.warnings.push(Warning(note));
        }
        self.scene
    }
}

/// Triangles of a disk light's fan.
pub const DISK_SEGMENTS: u32 = 32;

/// A single value seen as a one-element array, so the array readers take it.
fn sdf_array1(v: sdf::Value) -> sdf::Value {
    match v {
        sdf::Value::Vec3f(x) => sdf::Value::Vec3fVec(vec![x]),
        sdf::Value::Vec3d(x) => sdf::Value::Vec3dVec(vec![x]),
        sdf::Value::Vec2f(x) => sdf::Value::Vec2fVec(vec![x]),
        sdf::Value::Vec2d(x) => sdf::Value::Vec2dVec(vec![x]),
        v => v,
    }
}

fn vec3s(v: &sdf::Value) -> Option<Vec<Vec3>> {
    match v {
        sdf::Value::Vec3fVec(a) => Some(a.iter().map(|p| Vec3::new(p.x, p.y, p.z)).collect()),
        sdf::Value::Vec3dVec(a) => Some(
            a.iter()
                .map(|p| Vec3::new(p.x as f32, p.y as f32, p.z as f32))
                .collect(),
        ),
        _ => None,
    }
}

fn vec2s(v: &sdf::Value) -> Option<Vec<Vec2>> {
    match v {
        sdf::Value::Vec2fVec(a) => Some(a.iter().map(|p| Vec2::new(p.x, p.y)).collect()),
        sdf::Value::Vec2dVec(a) => Some(
            a.iter()
                .map(|p| Vec2::new(p.x as f32, p.y as f32))
                .collect(),
        ),
        _ => None,
    }
}

fn scalar(v: &sdf::Value) -> Option<f64> {
    match v {
        sdf::Value::Double(x) => Some(*x),
        sdf::Value::Float(x) => Some(f64::from(*x)),
        sdf::Value::Int(x) => Some(f64::from(*x)),
        _ => None,
    }
}

fn token(v: &sdf::Value) -> Option<String> {
    match v {
        sdf::Value::Token(t) => Some(tf::Token::as_str(t).to_string()),
        sdf::Value::String(s) => Some(s.clone()),
        _ => None,
    }
}

/// The value's kind, for messages (`Vec3fVec`, `IntVec`, ...).
fn kind(v: &sdf::Value) -> String {
    let s = format!("{v:?}");
    s.split(['(', ' ', '{'])
        .next()
        .unwrap_or("a value")
        .to_string()
}
