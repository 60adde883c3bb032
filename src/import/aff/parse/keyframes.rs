//! `k name { ... }` blocks: translation, rotation, scale and visibility tracks.

use super::*;

impl Parser {
    pub(super) fn keyframes(&mut self, src: &mut Src, line: u32) -> Result<(), ImportError> {
        let (name, _) = src.token("keyframe block name")?;
        let name = name.to_string();
        src.expect("{", "k")?;
        let mut tracks = Tracks::default();
        loop {
            let (word, wline) = src.token("a track or '}'")?;
            let tcb = |src: &mut Src| -> Result<Tcb, ImportError> {
                Ok(Tcb {
                    tension: src.num("tension")?,
                    continuity: src.num("continuity")?,
                    bias: src.num("bias")?,
                })
            };
            match word {
                "}" => break,
                "transl" | "scale" => {
                    let n = src.count("number of keys")?;
                    let mut keys = Vec::new();
                    for _ in 0..n {
                        let time = src.num("key time")?;
                        let value = src.dvec3(word)?;
                        keys.push(VecKey {
                            time,
                            value,
                            tcb: tcb(src)?,
                        });
                    }
                    if n < spline::MIN_KEYS {
                        return Err(src.err(wline, format!("{word} track of 'k {name}' has {n} keys; a spline needs at least {}", spline::MIN_KEYS)));
                    }
                    if word == "transl" {
                        tracks.translation = keys;
                    } else {
                        tracks.scale = keys;
                    }
                }
                "rot" => {
                    let n = src.count("number of keys")?;
                    let mut keys = Vec::new();
                    for _ in 0..n {
                        let time = src.num("key time")?;
                        let axis = src.dvec3("rotation axis")?;
                        let angle = src.num("rotation angle")?.to_radians();
                        keys.push(RotKey {
                            time,
                            axis,
                            angle,
                            tcb: tcb(src)?,
                        });
                    }
                    if n < spline::MIN_KEYS {
                        return Err(src.err(
                            wline,
                            format!(
                                "rot track of 'k {name}' has {n} keys; a spline needs at least {}",
                                spline::MIN_KEYS
                            ),
                        ));
                    }
                    tracks.rotation = keys;
                }
                "visibility" => {
                    let n = src.count("number of keys")?;
                    let mut keys = Vec::new();
                    for _ in 0..n {
                        let time = src.num("key time")?;
                        let flag = src.num("visibility flag")?;
                        keys.push((time, flag != 0.0));
                    }
                    if keys.windows(2).any(|w| w[1].0 < w[0].0) {
                        return Err(src.err(
                            wline,
                            format!("visibility keys of 'k {name}' go back in time"),
                        ));
                    }
                    tracks.visibility = keys;
                }
                other => {
                    return Err(src.err(
                        wline,
                        format!(
                        "unknown track {other:?} in 'k {name}' (transl, rot, scale, visibility)"
                    ),
                    ))
                }
            }
        }
        self.key_sites.push(Site {
            name: name.clone(),
            path: src.path.to_path_buf(),
            line,
        });
        self.scene.tracks.insert(name, tracks);
        Ok(())
    }
}
