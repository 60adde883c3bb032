//! Frames read back with the `exr` crate (a reader that is not ours): width, height and
//! every channel's samples as f32.
#![allow(dead_code)]

use std::path::Path;

/// Width, height and channels (name → samples as f32, rows top to bottom) of the first
/// layer of an EXR file.
pub fn read_exr(path: &Path) -> (usize, usize, Vec<(String, Vec<f32>)>) {
    let img = exr::prelude::read_first_flat_layer_from_file(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let layer = img.layer_data;
    let chans = layer
        .channel_data
        .list
        .iter()
        .map(|c| {
            (
                c.name.to_string(),
                c.sample_data.values_as_f32().collect::<Vec<f32>>(),
            )
        })
        .collect();
    (layer.size.0, layer.size.1, chans)
}

/// The samples of channel `name`; panics naming it when it is absent.
pub fn channel<'a>(chans: &'a [(String, Vec<f32>)], name: &str) -> &'a [f32] {
    &chans
        .iter()
        .find(|(n, _)| n == name)
        .unwrap_or_else(|| panic!("no channel {name}"))
        .1
}
