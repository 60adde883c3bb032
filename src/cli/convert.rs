//! `subfield convert INPUT.aff -o OUTPUT.glb|.gltf`: a BART AFF / NFF scene to glTF 2.0,
//! keyframes included: parsed, mapped onto the one `Scene` model (see
//! `subfield::import::aff` for the mapping) and written by the glTF writer, atomically.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use subfield::import::aff::AffScene;

#[derive(clap::Args, Debug)]
pub struct Args {
    /// The scene: a BART .aff or .nff file (includes and textures beside it).
    pub input: PathBuf,
    /// The glTF file to write: .glb (binary) or .gltf (JSON with an embedded buffer); its
    /// folder is created.
    #[arg(short, long)]
    pub output: PathBuf,
    /// No report.
    #[arg(long, short)]
    pub quiet: bool,
}

pub fn run(a: Args) -> anyhow::Result<ExitCode> {
    let ext = a
        .input
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    if !matches!(ext.as_deref(), Some("aff") | Some("nff")) {
        anyhow::bail!(
            "{}: convert reads BART .aff / .nff files (glTF is already glTF)",
            a.input.display()
        );
    }
    let out_ext = a
        .output
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    if !matches!(out_ext.as_deref(), Some("glb") | Some("gltf")) {
        anyhow::bail!(
            "{}: the output must end in .glb or .gltf",
            a.output.display()
        );
    }
    super::prepare_output(&a.output)?;
    let aff = AffScene::load(&a.input)?;
    if !a.quiet {
        for w in &aff.warnings {
            eprintln!("warning: {w}");
        }
    }
    let scene = aff
        .to_scene()
        .with_context(|| format!("cannot convert {}", a.input.display()))?;
    subfield::import::write_gltf(&scene, &a.output)
        .with_context(|| format!("cannot write {}", a.output.display()))?;
    if !a.quiet {
        let frames = aff.frame_times().len();
        let fps = scene
            .fps
            .map_or("no animation".to_string(), |f| format!("{f} fps"));
        eprintln!(
            "wrote {}: {} ({} animated), {}, {}, {}, {} ({fps})",
            a.output.display(),
            subfield::plural(aff.triangle_count() as u64, "triangle"),
            aff.animated_triangle_count(),
            subfield::plural(scene.materials.len() as u64, "material"),
            subfield::plural(scene.textures.len() as u64, "texture"),
            subfield::plural(aff.lights.len() as u64, "light"),
            subfield::plural(frames as u64, "frame"),
        );
    }
    Ok(ExitCode::SUCCESS)
}
