//! Static tracing: subfield against obvhs' CWBVH and brute force, same triangles, same
//! rays, same run. Scenes of about 10k and 100k triangles built in code; coherent camera
//! rays and incoherent random rays; every structure traced through a rayon batch.
//! `cargo bench --bench trace`; throughput is printed as elements (rays) per second.

#[path = "common.rs"]
mod common;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use rayon::prelude::*;
use subfield::{BruteForce, Intersector, Psf, PsfParams, Ray};

fn bench(c: &mut Criterion) {
    for n in [10_000usize, 100_000] {
        let tris = common::room(n);
        let psf = Psf::build(&tris, &PsfParams::default()).unwrap();
        let ob = common::Obvhs::build(&tris);
        let brute = BruteForce::new(&tris);
        let sets: [(&str, Vec<Ray>); 2] = [
            ("camera", common::camera_rays(320, 240)),
            ("random", common::random_rays(76_800)),
        ];
        for (kind, rays) in &sets {
            let mut g = c.benchmark_group(format!("trace/{}k/{kind}", n / 1000));
            g.sample_size(10);
            g.warm_up_time(std::time::Duration::from_secs(1));
            g.measurement_time(std::time::Duration::from_secs(3));
            g.throughput(Throughput::Elements(rays.len() as u64));
            let mut out = vec![None; rays.len()];
            g.bench_function("subfield", |b| {
                b.iter(|| psf.intersect_batch(rays, &mut out))
            });
            let mut ob_out = vec![None; rays.len()];
            g.bench_function("obvhs", |b| {
                b.iter(|| {
                    rays.par_iter()
                        .zip(ob_out.par_iter_mut())
                        .with_min_len(64)
                        .for_each(|(r, o)| *o = ob.intersect(r))
                })
            });
            // Brute force on a slice of the rays: it is the floor, not a contender.
            let few = &rays[..rays.len() / if n > 50_000 { 256 } else { 32 }];
            g.throughput(Throughput::Elements(few.len() as u64));
            let mut br_out = vec![None; few.len()];
            g.bench_function("brute", |b| {
                b.iter(|| brute.intersect_batch(few, &mut br_out))
            });
            g.finish();
        }
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
