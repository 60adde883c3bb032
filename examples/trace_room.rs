//! Library use end to end: build a room of triangles in code, bake its parallel
//! subfields, trace one primary ray per pixel and one shadow ray per hit through the
//! batch calls, and write a shaded picture.
//!
//! `cargo run --release --example trace_room [-- OUT.png]` (default `out/trace_room.png`).

use std::time::Instant;

use glam::Vec3;
use subfield::gen::synth::{self, Rng};
use subfield::{Intersector, Psf, PsfParams, Ray};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "out/trace_room.png".into());
    let tris = synth::room(&mut Rng::new(42), 100_000);
    let t = Instant::now();
    let psf = Psf::build(&tris, &PsfParams::default())?;
    let bake = t.elapsed();

    let (w, h) = (640usize, 480usize);
    let eye = Vec3::new(0.5, 3.0, -9.5);
    let fwd = Vec3::new(0.05, -0.1, 1.0).normalize();
    let right = fwd.cross(Vec3::Y).normalize();
    let up = right.cross(fwd);
    let tan = (50f32.to_radians() / 2.0).tan();
    let rays: Vec<Ray> = (0..w * h)
        .map(|i| {
            let (x, y) = ((i % w) as f32, (i / w) as f32);
            let px = (2.0 * (x + 0.5) / w as f32 - 1.0) * (w as f32 / h as f32) * tan;
            let py = (1.0 - 2.0 * (y + 0.5) / h as f32) * tan;
            Ray::new(eye, fwd + right * px + up * py)
        })
        .collect();

    let t = Instant::now();
    let mut hits = vec![None; rays.len()];
    psf.intersect_batch(&rays, &mut hits);
    let light = Vec3::new(2.0, 5.5, 0.0);
    let mut shadow = Vec::with_capacity(rays.len());
    let mut normals = Vec::with_capacity(rays.len());
    for (r, hit) in rays.iter().zip(&hits) {
        match hit {
            Some(hit) => {
                let tri = &tris[hit.tri as usize];
                let mut n = (tri[1] - tri[0]).cross(tri[2] - tri[0]).normalize_or_zero();
                if n.dot(r.dir) > 0.0 {
                    n = -n;
                }
                let p = r.at(hit.t) + n * 1e-4;
                shadow.push(Ray::segment(p, light - p, 0.0, 1.0));
                normals.push(n);
            }
            None => {
                shadow.push(Ray::segment(Vec3::ZERO, Vec3::X, 1.0, 0.0)); // empty segment: never occluded
                normals.push(Vec3::ZERO);
            }
        }
    }
    let mut occluded = vec![false; rays.len()];
    psf.occluded_batch(&shadow, &mut occluded);
    let trace = t.elapsed();

    let mut img = image::RgbImage::new(w as u32, h as u32);
    for i in 0..rays.len() {
        let c = if hits[i].is_none() {
            0.0
        } else {
            let l = (light - shadow[i].origin).normalize();
            let direct = if occluded[i] {
                0.0
            } else {
                normals[i].dot(l).max(0.0)
            };
            0.15 + 0.85 * direct
        };
        let v = (c.powf(1.0 / 2.2) * 255.0) as u8;
        img.put_pixel((i % w) as u32, (i / w) as u32, image::Rgb([v, v, v]));
    }
    if let Some(dir) = std::path::Path::new(&out).parent() {
        std::fs::create_dir_all(dir)?;
    }
    img.save(&out)?;
    let st = psf.stats();
    println!(
        "{} triangles, {} subfields, {:.1} MiB, baked in {:.2} s; {} primary + {} shadow rays in {:.3} s ({:.2} Mrays/s); wrote {out}",
        tris.len(),
        st.subfields,
        st.bytes as f64 / (1 << 20) as f64,
        bake.as_secs_f64(),
        rays.len(),
        hits.iter().filter(|h| h.is_some()).count(),
        trace.as_secs_f64(),
        (rays.len() + hits.iter().filter(|h| h.is_some()).count()) as f64 / trace.as_secs_f64() / 1e6
    );
    Ok(())
}
