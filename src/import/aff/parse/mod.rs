//! The AFF / NFF parser: one pass over whitespace-separated tokens (`#` and `%` start
//! comments to the end of the line; `{` and `}` are tokens of their own), includes parsed
//! in place when their detail level allows. Geometry is appended to per-block batches
//! found through hash maps, so a file of any size is read in linear time.

mod keyframes;
mod lexer;
mod mesh;

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};

use self::lexer::{Lexer, Src};
use super::shapes::{self, Tessellation};
use super::spline::{self, RotKey, Tcb, VecKey};
use super::{
    AffLight, AffMaterial, AffNode, AffScene, AffTexture, AffTransform, Batch, ImportError,
    MorphBatch, TimeRange, Tracks, View, MAX_FRAMES,
};

/// Includes nested deeper than this are refused (an include cycle ends here).
const MAX_INCLUDE_DEPTH: usize = 32;
/// Largest count accepted for a list (`p`, `m` sections, `tpa` keys, track keys).
const MAX_COUNT: u64 = 1 << 26;

pub(super) fn parse_file(path: &Path) -> Result<AffScene, ImportError> {
    let bytes = std::fs::read(path).map_err(|source| ImportError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_text(&bytes, path, &crate::atomic::folder_of(path))
}

pub(super) fn parse_text(
    bytes: &[u8],
    path: &Path,
    folder: &Path,
) -> Result<AffScene, ImportError> {
    let mut p = Parser::new(path, folder);
    p.parse_source(bytes, path, 0)?;
    p.finish()
}

/// Where a `k` block was read (to report one that names nothing).
struct Site {
    name: String,
    path: PathBuf,
    line: u32,
}

/// An open block: its node, and where its `{` was.
struct Open {
    node: usize,
    path: PathBuf,
    line: u32,
}

type BatchKey = (usize, u32, Option<u32>, bool);
type MorphKey = (usize, u32, Vec<u64>);

struct Parser {
    scene: AffScene,
    folder: PathBuf,
    stack: Vec<Open>,
    detail: i64,
    material: Option<u32>,
    material_index: HashMap<[u32; 12], u32>,
    texture_index: HashMap<String, u32>,
    batch_index: HashMap<BatchKey, usize>,
    morph_index: HashMap<MorphKey, usize>,
    key_sites: Vec<Site>,
    animated_names: HashSet<String>,
    light_names: HashSet<String>,
}

fn face_normal(a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    let n = (b - a).cross(c - a).normalize_or_zero();
    if n == Vec3::ZERO {
        Vec3::Z
    } else {
        n
    }
}

impl Parser {
    fn new(path: &Path, folder: &Path) -> Self {
        Parser {
            scene: AffScene {
                source: path.to_path_buf(),
                view: None,
                background: Vec3::ZERO,
                ambient: Vec3::ONE,
                time: None,
                lights: Vec::new(),
                materials: Vec::new(),
                textures: Vec::new(),
                nodes: vec![AffNode {
                    parent: None,
                    children: Vec::new(),
                    transform: AffTransform::Root,
                    batches: Vec::new(),
                    morphs: Vec::new(),
                }],
                tracks: Default::default(),
                warnings: Vec::new(),
            },
            folder: folder.to_path_buf(),
            stack: vec![Open {
                node: 0,
                path: path.to_path_buf(),
                line: 0,
            }],
            detail: 0,
            material: None,
            material_index: HashMap::new(),
            texture_index: HashMap::new(),
            batch_index: HashMap::new(),
            morph_index: HashMap::new(),
            key_sites: Vec::new(),
            animated_names: HashSet::new(),
            light_names: HashSet::new(),
        }
    }

    fn finish(self) -> Result<AffScene, ImportError> {
        if let Some(open) = self.stack.get(1) {
            return Err(ImportError::Syntax {
                path: open.path.clone(),
                line: open.line,
                message: "this '{' is never closed".into(),
            });
        }
        let mut scene = self.scene;
        // BART's own parser ignores keyframes nobody uses (robots' `k old_camera`), so
        // they are a warning here rather than an error.
        for site in &self.key_sites {
            if site.name != "camera"
                && !self.animated_names.contains(&site.name)
                && !self.light_names.contains(&site.name)
            {
                scene.warnings.push(format!(
                    "{}:{}: keyframes 'k {}' name no transform 'x {}', light 'la {}' or the camera; ignored",
                    site.path.display(),
                    site.line,
                    site.name,
                    site.name,
                    site.name
                ));
            }
        }
        let mut missing: Vec<&String> = self
            .animated_names
            .iter()
            .filter(|n| !scene.tracks.contains_key(*n))
            .collect();
        missing.sort();
        for name in missing {
            scene.warnings.push(format!(
                "{}: transform 'x {name}' has no 'k {name}' keyframes; it stays the identity",
                scene.source.display()
            ));
        }
        Ok(scene)
    }

    fn current(&self) -> usize {
        self.stack.last().map_or(0, |o| o.node)
    }

    fn material(&mut self) -> u32 {
        if let Some(m) = self.material {
            return m;
        }
        let m = self.intern_material(AffMaterial::default());
        self.material = Some(m);
        m
    }

    fn intern_material(&mut self, m: AffMaterial) -> u32 {
        let key = [
            m.ambient.x,
            m.ambient.y,
            m.ambient.z,
            m.diffuse.x,
            m.diffuse.y,
            m.diffuse.z,
            m.specular.x,
            m.specular.y,
            m.specular.z,
            m.shine,
            m.transmittance,
            m.ior,
        ]
        .map(f32::to_bits);
        if let Some(&i) = self.material_index.get(&key) {
            return i;
        }
        self.scene.materials.push(m);
        let i = (self.scene.materials.len() - 1) as u32;
        self.material_index.insert(key, i);
        i
    }

    fn texture(&mut self, src: &Src, line: u32, name: &str) -> Result<u32, ImportError> {
        if let Some(&i) = self.texture_index.get(name) {
            return Ok(i);
        }
        let bad = |reason: String| ImportError::Texture {
            path: src.path.to_path_buf(),
            line,
            name: name.to_string(),
            reason,
        };
        let file = self.inside(src, line, "texture", name)?;
        let bytes = std::fs::read(&file)
            .map_err(|e| bad(format!("cannot read {}: {e}", file.display())))?;
        let img = image::load_from_memory(&bytes)
            .map_err(|e| bad(format!("cannot decode {}: {e}", file.display())))?
            .to_rgb8();
        if img.width() == 0 || img.height() == 0 {
            return Err(bad("empty image".into()));
        }
        self.scene.textures.push(AffTexture {
            name: name.to_string(),
            width: img.width(),
            height: img.height(),
            rgb8: img.into_raw(),
        });
        let i = (self.scene.textures.len() - 1) as u32;
        self.texture_index.insert(name.to_string(), i);
        Ok(i)
    }

    /// The batch of the current block for the current material, `texture` and normals.
    fn batch(&mut self, texture: Option<u32>, normals: bool) -> &mut Batch {
        let node = self.current();
        let material = self.material();
        let key = (node, material, texture, normals);
        let nodes = &mut self.scene.nodes;
        let i = *self.batch_index.entry(key).or_insert_with(|| {
            nodes[node].batches.push(Batch {
                material,
                texture,
                normals: normals.then(Vec::new),
                uvs: texture.map(|_| Vec::new()),
                ..Batch::default()
            });
            nodes[node].batches.len() - 1
        });
        &mut nodes[node].batches[i]
    }

    /// Appends loose triangles (`3·k` vertices).
    fn add_triangles(
        &mut self,
        texture: Option<u32>,
        positions: &[Vec3],
        normals: Option<&[Vec3]>,
        uvs: Option<&[Vec2]>,
    ) {
        let b = self.batch(texture, normals.is_some());
        let base = b.positions.len() as u32;
        b.positions.extend_from_slice(positions);
        if let (Some(dst), Some(src)) = (b.normals.as_mut(), normals) {
            dst.extend(
                src.iter()
                    .zip(positions.chunks_exact(3).flat_map(|t| [t, t, t]))
                    .map(|(n, tri)| {
                        let u = n.normalize_or_zero();
                        if u == Vec3::ZERO {
                            face_normal(tri[0], tri[1], tri[2])
                        } else {
                            u
                        }
                    }),
            );
        }
        if let (Some(dst), Some(src)) = (b.uvs.as_mut(), uvs) {
            dst.extend_from_slice(src);
        }
        b.indices.extend(base..base + positions.len() as u32);
    }

    fn add_tessellation(&mut self, t: Tessellation) {
        if t.indices.is_empty() {
            return;
        }
        let b = self.batch(None, true);
        let base = b.positions.len() as u32;
        b.positions.extend_from_slice(&t.positions);
        if let Some(n) = b.normals.as_mut() {
            n.extend_from_slice(&t.normals);
        }
        b.indices.extend(t.indices.iter().map(|i| base + i));
    }

    fn push_node(&mut self, transform: AffTransform, src: &Src, line: u32) -> usize {
        let parent = self.current();
        self.scene.nodes.push(AffNode {
            parent: Some(parent),
            children: Vec::new(),
            transform,
            batches: Vec::new(),
            morphs: Vec::new(),
        });
        let i = self.scene.nodes.len() - 1;
        self.scene.nodes[parent].children.push(i);
        self.stack.push(Open {
            node: i,
            path: src.path.to_path_buf(),
            line,
        });
        i
    }

    fn parse_source(&mut self, bytes: &[u8], path: &Path, depth: usize) -> Result<(), ImportError> {
        let mut src = Src {
            lex: Lexer::new(bytes),
            path,
            line: 1,
        };
        while let Some((raw, line)) = src.lex.next() {
            src.line = line;
            let Ok(kw) = std::str::from_utf8(raw) else {
                return Err(src.err(line, "non-UTF-8 text where a keyword was expected"));
            };
            self.statement(&mut src, kw, line, depth)?;
        }
        Ok(())
    }

    fn statement(
        &mut self,
        src: &mut Src,
        kw: &str,
        line: u32,
        depth: usize,
    ) -> Result<(), ImportError> {
        match kw {
            "v" => self.view(src)?,
            "b" => self.scene.background = src.vec3("background colour")?,
            "am" => self.scene.ambient = src.vec3("ambient colour")?,
            "a" => {
                let start = src.num("start time")?;
                let end = src.num("end time")?;
                let frames = src.count("number of frames")?;
                if frames == 0 || frames > MAX_FRAMES as usize {
                    return Err(src.err(
                        line,
                        format!("number of frames {frames} is not in 1..={MAX_FRAMES}"),
                    ));
                }
                if frames > 1 && end <= start {
                    return Err(src.err(
                        line,
                        format!("end time {end} is not after start time {start}"),
                    ));
                }
                self.scene.time = Some(TimeRange {
                    start,
                    end,
                    frames: frames as u32,
                });
            }
            "d" => self.detail = src.int("detail level")?,
            "i" => {
                let level = src.int("detail level of the include")?;
                let (name, _) = src.token("file name")?;
                if level <= self.detail {
                    self.include(src, line, name, depth)?;
                }
            }
            "l" | "la" => {
                let name = if kw == "la" {
                    Some(src.token("light name")?.0.to_string())
                } else {
                    None
                };
                let position = src.vec3("light position")?;
                let color = if src.next_is_number() {
                    src.vec3("light colour")?
                } else {
                    Vec3::ONE
                };
                if let Some(n) = &name {
                    self.light_names.insert(n.clone());
                }
                self.scene.lights.push(AffLight {
                    name,
                    position,
                    color,
                });
            }
            "f" => {
                let color = src.vec3("material colour")?;
                let kd = src.f("Kd")?;
                let ks = src.f("Ks")?;
                let shine = src.f("shine")?;
                let transmittance = src.f("T")?;
                let ior = src.f("index of refraction")?;
                let m = AffMaterial {
                    ambient: color * kd,
                    diffuse: color * kd,
                    specular: Vec3::splat(ks),
                    shine,
                    transmittance,
                    ior,
                };
                self.material = Some(self.intern_material(m));
            }
            "fm" => {
                let m = AffMaterial {
                    ambient: src.vec3("ambient colour")?,
                    diffuse: src.vec3("diffuse colour")?,
                    specular: src.vec3("specular colour")?,
                    shine: src.f("shine")?,
                    transmittance: src.f("T")?,
                    ior: src.f("index of refraction")?,
                };
                self.material = Some(self.intern_material(m));
            }
            "p" | "pp" => {
                let n = src.count("number of vertices")?;
                if n < 3 {
                    return Err(
                        src.err(line, format!("polygon with {n} vertices (needs 3 or more)"))
                    );
                }
                let mut pos = Vec::new();
                let mut nor = Vec::new();
                for k in 0..n {
                    pos.push(src.vec3(&format!("vertex {} of {kw}", k + 1))?);
                    if kw == "pp" {
                        nor.push(src.vec3(&format!("normal {} of pp", k + 1))?);
                    }
                }
                let mut tp = Vec::with_capacity(3 * (n - 2));
                let mut tn = Vec::new();
                for k in 1..n - 1 {
                    tp.extend([pos[0], pos[k], pos[k + 1]]);
                    if kw == "pp" {
                        tn.extend([nor[0], nor[k], nor[k + 1]]);
                    }
                }
                let normals = (kw == "pp").then_some(tn.as_slice());
                self.add_triangles(None, &tp, normals, None);
            }
            "tt" | "ttp" => {
                let (name, tline) = src.token("texture name")?;
                let name = name.to_string();
                let mut pos = Vec::new();
                let mut nor = Vec::new();
                let mut uv = Vec::new();
                for k in 0..3 {
                    pos.push(src.vec3(&format!("vertex {} of {kw}", k + 1))?);
                    if kw == "ttp" {
                        nor.push(src.vec3(&format!("normal {} of ttp", k + 1))?);
                    }
                    uv.push(Vec2::new(src.f("texture u")?, src.f("texture v")?));
                }
                let tex = self.texture(src, tline, &name)?;
                let normals = (kw == "ttp").then_some(nor.as_slice());
                self.add_triangles(Some(tex), &pos, normals, Some(&uv));
            }
            "s" => {
                let c = src.vec3("sphere centre")?;
                let r = src.f("sphere radius")?;
                self.add_tessellation(shapes::sphere(c, r));
            }
            "c" => {
                let b = src.vec3("cone base")?;
                let r0 = src.f("cone base radius")?;
                let a = src.vec3("cone apex")?;
                let r1 = src.f("cone apex radius")?;
                self.add_tessellation(shapes::cone(b, r0, a, r1));
            }
            "m" => self.mesh(src, line)?,
            "tpa" => self.tpa(src, line)?,
            "xs" => {
                let scale = src.vec3("xs scale")?;
                let axis = src.vec3("xs rotation axis")?;
                let angle = src.f("xs rotation angle")?;
                let translation = src.vec3("xs translation")?;
                src.expect("{", "xs")?;
                self.push_node(
                    AffTransform::Static {
                        scale,
                        axis,
                        angle,
                        translation,
                    },
                    src,
                    line,
                );
            }
            "x" => {
                let (name, _) = src.token("transform name")?;
                let name = name.to_string();
                src.expect("{", "x")?;
                self.animated_names.insert(name.clone());
                self.push_node(AffTransform::Animated(name), src, line);
            }
            "}" => {
                if self.stack.len() <= 1 {
                    return Err(src.err(line, "'}' without an open block"));
                }
                self.stack.pop();
            }
            "k" => self.keyframes(src, line)?,
            "{" => return Err(src.err(line, "'{' without 'x' or 'xs' before it")),
            other => return Err(src.err(line, format!("unknown keyword {other:?}"))),
        }
        Ok(())
    }

    fn view(&mut self, src: &mut Src) -> Result<(), ImportError> {
        let mut v = self.scene.view.clone().unwrap_or(View {
            from: Vec3::ZERO,
            at: Vec3::NEG_Z,
            up: Vec3::Y,
            angle: 45.0,
            hither: 1.0,
            resolution: (640, 480),
        });
        while let Some(word) = src.peek_str() {
            match word {
                "from" => {
                    src.token("from")?;
                    v.from = src.vec3("from")?;
                }
                "at" => {
                    src.token("at")?;
                    v.at = src.vec3("at")?;
                }
                "up" => {
                    src.token("up")?;
                    v.up = src.vec3("up")?;
                }
                "angle" => {
                    src.token("angle")?;
                    v.angle = src.f("angle")?;
                }
                "hither" => {
                    src.token("hither")?;
                    v.hither = src.f("hither")?;
                }
                "resolution" => {
                    src.token("resolution")?;
                    let w = src.count("resolution width")?;
                    let h = src.count("resolution height")?;
                    v.resolution = (w as u32, h as u32);
                }
                _ => break,
            }
        }
        self.scene.view = Some(v);
        Ok(())
    }

    /// The file `name` (an include or a texture) in the scene's folder, under the policy
    /// of glTF URIs (`import::folder`): nothing outside the folder is opened.
    fn inside(
        &self,
        src: &Src,
        line: u32,
        what: &'static str,
        name: &str,
    ) -> Result<PathBuf, ImportError> {
        crate::import::folder::resolve_inside(&self.folder, Path::new(name)).map_err(|why| {
            ImportError::OutsideFolder {
                path: src.path.to_path_buf(),
                line,
                what,
                name: name.to_string(),
                folder: self.folder.clone(),
                why,
            }
        })
    }

    fn include(
        &mut self,
        src: &Src,
        line: u32,
        name: &str,
        depth: usize,
    ) -> Result<(), ImportError> {
        if depth >= MAX_INCLUDE_DEPTH {
            return Err(src.err(
                line,
                format!("include {name:?}: includes nested more than {MAX_INCLUDE_DEPTH} deep (a cycle?)"),
            ));
        }
        let file = self.inside(src, line, "include", name)?;
        let bytes = std::fs::read(&file).map_err(|e| {
            src.err(
                line,
                format!("cannot read include {name:?} ({}): {e}", file.display()),
            )
        })?;
        self.parse_source(&bytes, &file, depth + 1)
    }
}
