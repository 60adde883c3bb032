//! The baked-file reader against arbitrary damage. The input builds a small PSF (its
//! triangles, level, tile count and codec come from the first bytes), writes it, then
//! pokes bytes of the file (offset, value pairs from the rest of the input); half the
//! time the checksums are recomputed afterwards so the damage reaches the structural
//! checks and the tracer. The claim: `from_bytes` returns an error or a PSF that traces
//! and inspects without panicking. The raw input is also offered as a file of its own.
#![no_main]

use std::sync::Arc;

use glam::Vec3;
use libfuzzer_sys::fuzz_target;
use subfield::format::{from_bytes, to_bytes, Codec, Inspection, OpenOptions, WriteOptions};
use subfield::geometry::{Intersector, Ray};
use subfield::{Psf, PsfParams};

#[path = "../../tests/common/reseal.rs"]
mod reseal;

/// Reads bytes off the front of the input.
struct Input<'a>(&'a [u8]);

impl Input<'_> {
    fn byte(&mut self) -> Option<u8> {
        let (&b, rest) = self.0.split_first()?;
        self.0 = rest;
        Some(b)
    }

    fn u32(&mut self) -> Option<u32> {
        let b: [u8; 4] = self.0.get(..4)?.try_into().ok()?;
        self.0 = &self.0[4..];
        Some(u32::from_le_bytes(b))
    }

    /// A coordinate on a coarse lattice in [-8, 8]: finite, with shared vertices likely.
    fn coord(&mut self) -> Option<f32> {
        Some(self.byte()? as f32 / 16.0 - 8.0)
    }
}

fn open_and_use(bytes: Vec<u8>, rays: &[Ray]) {
    if let Ok(baked) = from_bytes(Arc::new(bytes), &OpenOptions::default()) {
        for r in rays {
            let _ = baked.psf.intersect(r);
            let _ = baked.psf.occluded(r);
        }
        let _ = Inspection::of(&baked, Default::default()).to_json();
    }
}

fuzz_target!(|data: &[u8]| {
    // The raw input as a file.
    open_and_use(data.to_vec(), &[]);

    let mut input = Input(data);
    let Some(head) = input.byte() else { return };
    let n = 1 + (head & 15) as usize;
    let mut tris = Vec::with_capacity(n);
    for _ in 0..n {
        let mut v = [Vec3::ZERO; 3];
        for p in &mut v {
            let (Some(x), Some(y), Some(z)) = (input.coord(), input.coord(), input.coord()) else {
                return;
            };
            *p = Vec3::new(x, y, z);
        }
        tris.push(v);
    }
    let Some(knobs) = input.byte() else { return };
    let params = PsfParams {
        level: (knobs & 1) as u32,
        tiles: 1 + ((knobs >> 1) & 7) as u32,
    };
    let codec = if knobs & 16 != 0 {
        Codec::Zstd
    } else {
        Codec::None
    };
    let resealed = knobs & 32 != 0;
    let Ok(psf) = Psf::build(&tris, &params) else {
        return;
    };
    let opts = WriteOptions {
        codec,
        ..Default::default()
    };
    let Ok(mut file) = to_bytes(&psf, &opts) else {
        return;
    };
    while let (Some(at), Some(v)) = (input.u32(), input.byte()) {
        let len = file.len();
        file[at as usize % len] = v;
    }
    if resealed {
        reseal::reseal(&mut file);
    }
    let rays: Vec<Ray> = [
        (Vec3::new(0.1, 0.2, -9.0), Vec3::Z),
        (Vec3::new(-9.0, 0.3, 0.1), Vec3::X),
        (Vec3::new(0.0, 9.0, 0.0), Vec3::new(0.1, -1.0, 0.2)),
    ]
    .iter()
    .map(|&(o, d)| Ray::new(o, d.normalize()))
    .collect();
    open_and_use(file, &rays);
});
