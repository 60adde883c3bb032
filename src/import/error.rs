//! Typed errors of the import layer (glTF reader, AFF / NFF reader, glTF writer). Each
//! variant carries the evidence: the file, and the accessor, node, buffer, image, URI or
//! line at fault, so the CLI can print one clear line.

use std::path::PathBuf;

/// Everything that can go wrong while reading a scene file or writing a glTF one.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ImportError {
    /// The file (or a file it refers to) could not be read.
    #[error("{path}: cannot read: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },

    /// A buffer or image file named by a URI could not be read.
    #[error("{path}: {what} URI {uri:?}: cannot read {resolved}: {source}")]
    MissingFile {
        path: PathBuf,
        /// `"buffers[2]"` or `"images[0]"`.
        what: String,
        uri: String,
        resolved: PathBuf,
        #[source]
        source: std::io::Error,
    },

    /// A URI that would leave the scene's folder (absolute, `..` above the folder, or a
    /// scheme such as `http:`): refused, never followed.
    #[error("{path}: {what} URI {uri:?} leaves the scene's folder; refused")]
    UriOutsideFolder {
        path: PathBuf,
        what: String,
        uri: String,
    },

    /// A `data:` URI that cannot be decoded.
    #[error("{path}: {what}: {reason}")]
    BadUri {
        path: PathBuf,
        what: String,
        reason: String,
    },

    /// A USD stage that cannot be opened or composed (a truncated `.usdc`, a `.usda`
    /// syntax error, a missing sublayer, reference or clip, a cycle of layers).
    #[error("{path}: cannot read the USD stage: {}", printable(.reason))]
    UsdStage { path: PathBuf, reason: String },

    /// A USD prim or attribute that cannot be read onto the model: the prim's path and
    /// the attribute (`/World/Debris.faceVertexIndices`).
    #[error(
        "{path}: {}{}: {}",
        printable(.prim),
        printable(&.attribute.as_ref().map(|a| format!(".{a}")).unwrap_or_default()),
        printable(.reason)
    )]
    Usd {
        path: PathBuf,
        /// The prim's path (`/World/Debris`); empty for the stage itself.
        prim: String,
        attribute: Option<String>,
        reason: String,
    },

    /// A USD file, in a build without the `usd` feature.
    #[error(
        "{path}: a USD file, and this build of subfield has no USD reader (the `usd` feature)"
    )]
    UsdNotBuilt { path: PathBuf },

    /// The binary container (GLB) is malformed.
    #[error("{path}: malformed GLB: {reason}")]
    Glb { path: PathBuf, reason: String },

    /// A Blender `.blend` file (by its extension or its `BLENDER` magic), which only
    /// Blender reads: the scene is to be exported as glTF first.
    #[error("{path}: a Blender file, which subfield does not read: export the scene from Blender as glTF (File > Export > glTF 2.0, .glb) and render that file")]
    BlendFile { path: PathBuf },

    /// A baked file (`.psf`, from `subfield bake`) given where the scene goes: it holds
    /// the static part only, and goes beside its scene with `--baked`.
    #[error("{path}: a baked file (from `subfield bake`), not a scene: give the scene it was baked from, and this file with --baked (subfield render SCENE --baked {path} ...)")]
    BakedFile { path: PathBuf },

    /// A file of a format subfield does not read, by its extension and first bytes
    /// (neither a GLB's `glTF` nor JSON's `{`): `.obj`, `.fbx`, `.ply` and the like.
    #[error("{path}: a .{ext} file, which subfield does not read: give a scene as .gltf or .glb, USD (.usd, .usda, .usdc, .usdz) or BART (.aff, .nff), exported from the tool that made it (Blender: File > Export > glTF 2.0)")]
    UnknownFormat { path: PathBuf, ext: String },

    /// The JSON could not be parsed as glTF.
    #[error("{path}: not valid glTF JSON: {reason}")]
    Json { path: PathBuf, reason: String },

    /// The glTF failed structural validation (bad indices, missing required fields).
    /// Each entry names the JSON path, e.g. `skins[0].joints[1]: Index out of range`.
    #[error("{path}: invalid glTF: {}", .problems.join("; "))]
    Invalid {
        path: PathBuf,
        problems: Vec<String>,
    },

    /// A buffer's data is unusable (too short, bad data URI).
    #[error("{path}: buffers[{buffer}]: {reason}")]
    Buffer {
        path: PathBuf,
        buffer: usize,
        reason: String,
    },

    /// A compressed buffer view (`EXT_meshopt_compression`, `KHR_meshopt_compression`)
    /// is malformed or its data does not decode.
    #[error("{path}: bufferViews[{view}]: {reason}")]
    BufferView {
        path: PathBuf,
        view: usize,
        reason: String,
    },

    /// An accessor's data is unusable: outside its buffer view, wrong type for its use,
    /// a non-finite float, an index past the vertex count.
    #[error("{path}: accessors[{accessor}] ({usage}): {reason}")]
    Accessor {
        path: PathBuf,
        accessor: usize,
        /// What the accessor was read for, e.g. `"meshes[0].primitives[1].POSITION"`.
        usage: String,
        reason: String,
    },

    /// A node is unusable (cycle, two parents, a skin whose joints cannot deform its mesh).
    #[error("{path}: nodes[{node}]{}: {reason}", name_suffix(.name))]
    Node {
        path: PathBuf,
        node: usize,
        name: Option<String>,
        reason: String,
    },

    /// A skin is unusable (joint missing, too few inverse bind matrices).
    #[error("{path}: skins[{skin}]: {reason}")]
    Skin {
        path: PathBuf,
        skin: usize,
        reason: String,
    },

    /// An animation channel or sampler is unusable.
    #[error("{path}: animations[{animation}].channels[{channel}]: {reason}")]
    Animation {
        path: PathBuf,
        animation: usize,
        channel: usize,
        reason: String,
    },

    /// An image could not be decoded.
    #[error("{path}: images[{image}]: {reason}")]
    Image {
        path: PathBuf,
        image: usize,
        reason: String,
    },

    /// Something in the model itself is inconsistent (raised by [`super::validate`], which
    /// every importer calls before handing a scene out).
    #[error("{path}: inconsistent scene: {reason}")]
    Model { path: PathBuf, reason: String },

    /// A feature the importer does not handle.
    #[error("{path}: unsupported: {what}")]
    Unsupported { path: PathBuf, what: String },

    /// The glTF writer was given inconsistent input (it refuses to write a file that the
    /// importer would reject).
    #[error("glTF writer: {reason}")]
    Write { reason: String },

    /// Malformed AFF / NFF input: unknown keyword, too few numbers, a missing include, a
    /// `k` block naming nothing, an index out of range... (the line of an included file
    /// where the problem is there).
    #[error("{path}:{line}: {message}")]
    Syntax {
        path: PathBuf,
        line: u32,
        message: String,
    },

    /// An AFF texture named at `path:line` could not be read or decoded.
    #[error("{path}:{line}: texture {name:?}: {reason}")]
    Texture {
        path: PathBuf,
        line: u32,
        name: String,
        reason: String,
    },

    /// An AFF include or texture name that would leave the scene's folder (an absolute
    /// path, `..` above it, a symbolic link out; the policy of glTF URIs): refused, never
    /// opened.
    #[error("{path}:{line}: {what} {name:?} leaves the scene's folder {folder} ({why}); refused")]
    OutsideFolder {
        path: PathBuf,
        line: u32,
        /// `"include"` or `"texture"`.
        what: &'static str,
        name: String,
        folder: PathBuf,
        why: super::Outside,
    },

    /// The scene is fine as AFF but the model (and so glTF) cannot hold it: a time range
    /// too short for its frames in single precision.
    #[error("{path}: cannot map onto the scene model: {reason}")]
    Convert { path: PathBuf, reason: String },

    /// The glTF writer could not write its output.
    #[error("{path}: cannot write: {source}")]
    WriteIo {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

fn name_suffix(name: &Option<String>) -> String {
    match name {
        Some(n) => format!(" ({n:?})"),
        None => String::new(),
    }
}

/// `s` with its control characters escaped (`\n`): prim names, attribute names and
/// the USD reader's messages come from the file, and an error is one line.
pub(crate) fn printable(s: &str) -> std::borrow::Cow<'_, str> {
    if s.chars().any(char::is_control) {
        s.chars()
            .map(|c| {
                if c.is_control() {
                    c.escape_default().to_string()
                } else {
                    c.to_string()
                }
            })
            .collect::<String>()
            .into()
    } else {
        s.into()
    }
}
